/* biso_cosim tyre forces: a MuJoCo engine plugin ("biso.tyres"), passive forces from slip.
 *
 * Method (docs/vehicle.md, section "Tyres"; biso_cosim/vehicle/tyres.py holds the parameters
 * with their sources):
 *
 * - Each tyre's longitudinal and lateral force comes from the Magic Formula of Pacejka,
 *   "Tyre and Vehicle Dynamics" (3rd ed., 2012, section 4.3: pure slip with load sensitivity,
 *   combined slip by the weighting functions G_xa, G_yk), without camber, without the
 *   asymmetric shifts (the curve is odd in each slip), scaled by the surface's friction
 *   lambda_mu (friction[0] of the ground geom the tyre touches, 1 = dry asphalt, or the
 *   friction scale of the last surface patch, a rectangle of the road, holding the contact).
 * - The slips are first-order relaxation states (Pacejka 2012, section 7.2.2, "transient
 *   slip"): sigma_x dk/dt + |V_x| k = -V_sx and sigma_y db/dt + |V_x| b = V_sy, with V_x the
 *   wheel centre's velocity along the tyre's heading, V_sx, V_sy the slip velocity of the
 *   wheel's material point at the contact (b = tan(alpha)). At rest they are springs (the
 *   tyre's deflection), so a parked car stays parked; below v_low a damping on the slip
 *   velocity fades in (Pacejka's low-speed damping, cos-shaped).
 * - The vertical load is MuJoCo's: the normal forces of the tyre's contacts solved in the
 *   step before (the plugin's advance stores them; the tyre geoms have condim 1, so MuJoCo's
 *   contact carries the normal load only and these forces carry all friction), held at
 *   fzmax_n in the formulas (MF-Tyre's FZMAX, the top of the fit's range of validity).
 * - In a step: compute (passive stage) applies the forces of the current states at the
 *   contact point (mj_applyFT into qfrc_passive); advance (after MuJoCo's velocity update)
 *   integrates the states with the new velocities (semi-implicit, the |V_x| term implicit)
 *   and stores the normal loads. One mj_step(m, d, n) call advances n steps, no Python.
 * - ABS (here, at the physics rate: a modulator's valves act within milliseconds, and a
 *   wheel past its peak slip locks within a few 20 ms control periods or fewer): each
 *   wheel's release R of its brake torque follows dR/dt = k_abs (s - s_abs lambda_mu) in [0, 1]
 *   (integral control of the braking slip s = V_sx sign(V_x)/|V_x|, the true slip: an ideal
 *   wheel-speed and reference-speed estimate), none while the brake command is 0 or below
 *   the cut-out speed; compute subtracts R times the brake damper's torque of the step. The
 *   target scales with the surface's lambda_mu as the tyre's peak slip does (lambda_mu scales
 *   the peak force, not the slip stiffness), as a real ABS finds the peak on any surface.
 * - Brake build-up: a brake's torque limit (its actuator's force range) rises linearly
 *   from 0 over brake_build_up_s after its command turns positive (the hydraulic pressure's
 *   build-up time) and falls to 0 when the command returns to 0; compute caps the brake's
 *   torque of the step (after the ABS's release) at that share of the limit.
 * - Compliance steer: the front tyres' lateral force F_yf turns the road wheels against it
 *   by c_delta F_yf: a torque -c_delta kp F_yf on the steering hinge, kp its servo's stiffness.
 * - A non-finite force stops the run: mju_error naming the time and the wheel.
 *
 * Plugin state per wheel (STRIDE numbers, tyres.py reads it): slip ratio, lateral slip
 * tan(alpha), normal load (N), longitudinal and lateral force (N, along the tyre's heading and
 * its left), in contact (0/1), the ABS's release of the brake torque (0-1), the surface's
 * friction scale under the tyre, the brake's built-up share of its torque limit (0-1), then the contact geometry of the step (heading, left, point).
 */

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#define BISO_EXPORT __attribute__((visibility("default")))

#define NWHEEL 4
#define PI 3.14159265358979323846

/* the parameters, by name (the MJCF config keys; tyres.py writes every one) */
#define PARAMS(X) \
  X(fz0_n) X(fzmax_n) X(pcx1) X(pdx1) X(pdx2) X(pex1) X(pex2) X(pex3) X(pkx1) X(pkx2) X(pkx3) \
  X(pcy1) X(pdy1) X(pdy2) X(pey1) X(pey2) X(pky1) X(pky2) \
  X(rbx1) X(rbx2) X(rcx1) X(rby1) X(rby2) X(rcy1) \
  X(sigma_x_m) X(sigma_y_m) X(v_low_mps) X(damping_x_ns_per_m) X(damping_y_ns_per_m) \
  X(brake_build_up_s) X(abs_slip_target) X(abs_gain_per_s) X(abs_speed_min_mps) X(compliance_steer_rad_per_n)

#define ENUM(name) P_##name,
enum { PARAMS(ENUM) NPARAM };
#define NAME(name) #name,
static const char* const param_names[] = {PARAMS(NAME) "wheels", "brakes", "steer", "surfaces"};
#define NCONFIG (NPARAM + 4)
/* surface patches: rectangles of the road with their own friction scale, each given by
   7 numbers (centre x, y; unit vector along u_x, u_y; half length; half width; lambda_mu) */
#define MAX_SURFACES 64
#define SURFACE_STRIDE 7

/* state layout per wheel */
enum { S_KAPPA, S_SLIPY, S_FZ, S_FX, S_FY, S_CONTACT, S_RELEASE, S_LAMBDA, S_BUILD, S_EX, S_EY = S_EX + 3, S_POINT = S_EY + 3,
       STRIDE = S_POINT + 3 };

typedef struct {
  double p[NPARAM];
  int geom[NWHEEL];
  int body[NWHEEL];
  int brake[NWHEEL];     /* each wheel's brake actuator */
  int spin_dof[NWHEEL];  /* the dof of its spin joint (the brake's joint) */
  int steer_dof;         /* the steering hinge's dof (compliance steer) */
  double steer_kp;       /* the steering servo's stiffness, N m/rad */
  int nsurface;
  double surface[MAX_SURFACES * SURFACE_STRIDE];
} Tyres;

BISO_EXPORT int biso_tyres_param_count(void) { return NPARAM; }
BISO_EXPORT const char* biso_tyres_param_name(int i) { return (i >= 0 && i < NPARAM) ? param_names[i] : NULL; }
BISO_EXPORT int biso_tyres_state_stride(void) { return STRIDE; }

/* Magic Formula forces (N) of one tyre at load fz (N), slip ratio kappa, lateral slip
 * slipy = tan(alpha), surface friction scale lam: fx along the heading (positive when the
 * wheel turns faster than it rolls), fy along the left (opposing the lateral slip velocity).
 * The load the formulas see is held at fzmax_n, the top of the tyre's range of validity
 * (MF-Tyre's FZMAX: beyond it the fit extrapolates, and a contact's impact load of an
 * unsettled placement, 1e6 N or more, would turn into a friction force as large). */
BISO_EXPORT void biso_tyres_magic_formula(const double* p, double fz, double kappa, double slipy, double lam,
                                          double* fx, double* fy) {
  if (!(fz > 0.0)) {
    *fx = 0.0;
    *fy = 0.0;
    return;
  }
  fz = fmin(fz, p[P_fzmax_n]);
  const double fz0 = p[P_fz0_n];
  const double dfz = (fz - fz0) / fz0;
  const double alpha = atan(slipy);
  /* longitudinal, pure slip */
  const double cx = p[P_pcx1];
  const double dx = (p[P_pdx1] + p[P_pdx2] * dfz) * lam * fz;
  double ex = p[P_pex1] + p[P_pex2] * dfz + p[P_pex3] * dfz * dfz;
  if (ex > 1.0) ex = 1.0;
  const double kx = fz * (p[P_pkx1] + p[P_pkx2] * dfz) * exp(p[P_pkx3] * dfz);
  const double bx = kx / (cx * dx);
  const double bxk = bx * kappa;
  const double fx0 = dx * sin(cx * atan(bxk - ex * (bxk - atan(bxk))));
  /* lateral, pure slip */
  const double cy = p[P_pcy1];
  const double dy = (p[P_pdy1] + p[P_pdy2] * dfz) * lam * fz;
  double ey = p[P_pey1] + p[P_pey2] * dfz;
  if (ey > 1.0) ey = 1.0;
  const double ky = p[P_pky1] * fz0 * sin(2.0 * atan(fz / (p[P_pky2] * fz0)));
  const double by = ky / (cy * dy);
  const double bya = by * alpha;
  const double fy0 = dy * sin(cy * atan(bya - ey * (bya - atan(bya))));
  /* combined slip: weighting functions */
  const double bxa = p[P_rbx1] * cos(atan(p[P_rbx2] * kappa));
  const double gxa = cos(p[P_rcx1] * atan(bxa * alpha));
  const double byk = p[P_rby1] * cos(atan(p[P_rby2] * alpha));
  const double gyk = cos(p[P_rcy1] * atan(byk * kappa));
  *fx = gxa * fx0;
  *fy = -gyk * fy0;
}

static const char* geom_name(const mjModel* m, int g) { return m->names + m->name_geomadr[g]; }

/* the deepest active contact of geom g, or -1 */
static int wheel_contact(const mjData* d, int g) {
  int best = -1;
  for (int i = 0; i < d->ncon; i++) {
    const mjContact* c = d->contact + i;
    if (c->exclude || (c->geom[0] != g && c->geom[1] != g)) continue;
    if (best < 0 || c->dist < d->contact[best].dist) best = i;
  }
  return best;
}

static void cross(const double a[3], const double b[3], double out[3]) {
  out[0] = a[1] * b[2] - a[2] * b[1];
  out[1] = a[2] * b[0] - a[0] * b[2];
  out[2] = a[0] * b[1] - a[1] * b[0];
}

static double dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* velocities with qvel at the tyre's stored contact point: (V_x, V_sx, V_sy) */
static void slip_velocities(const mjModel* m, mjData* d, int body, const double* s, double out[3]) {
  mj_markStack(d);
  mjtNum* jacp = mj_stackAllocNum(d, 3 * m->nv);
  mjtNum* jacr = mj_stackAllocNum(d, 3 * m->nv);
  mj_jac(m, d, jacp, jacr, s + S_POINT, body);
  double vp[3], w[3];
  mju_mulMatVec(vp, jacp, d->qvel, 3, m->nv);
  mju_mulMatVec(w, jacr, d->qvel, 3, m->nv);
  mj_freeStack(d);
  double r[3] = {d->xpos[3 * body] - s[S_POINT], d->xpos[3 * body + 1] - s[S_POINT + 1],
                 d->xpos[3 * body + 2] - s[S_POINT + 2]};
  double wr[3], vc[3];
  cross(w, r, wr);
  for (int k = 0; k < 3; k++) vc[k] = vp[k] + wr[k];
  out[0] = dot(vc, s + S_EX);
  out[1] = dot(vp, s + S_EX);
  out[2] = dot(vp, s + S_EY);
}

static int nstate(const mjModel* m, int instance) {
  (void)m;
  (void)instance;
  return NWHEEL * STRIDE;
}

static int init(const mjModel* m, mjData* d, int instance) {
  Tyres* t = (Tyres*)calloc(1, sizeof(Tyres));
  if (!t) return -1;
  for (int i = 0; i < NPARAM; i++) {
    const char* text = mj_getPluginConfig(m, instance, param_names[i]);
    char* end = NULL;
    double v = (text && *text) ? strtod(text, &end) : NAN;
    if (!isfinite(v) || (end && *end)) {
      free(t);
      mju_error("biso.tyres: parameter %s must be a finite number, got '%s'", param_names[i], text ? text : "");
      return -1;
    }
    t->p[i] = v;
  }
  const char* wheels = mj_getPluginConfig(m, instance, "wheels");
  char buf[256];
  strncpy(buf, wheels ? wheels : "", sizeof(buf) - 1);
  buf[sizeof(buf) - 1] = '\0';
  int n = 0;
  for (char* tok = strtok(buf, " "); tok; tok = strtok(NULL, " ")) {
    int g = n < NWHEEL ? mj_name2id(m, mjOBJ_GEOM, tok) : -1;
    if (g < 0) {
      free(t);
      mju_error("biso.tyres: wheels must name %d tyre geoms of the model, got '%s'", NWHEEL, wheels ? wheels : "");
      return -1;
    }
    t->geom[n] = g;
    t->body[n] = m->geom_bodyid[g];
    n++;
  }
  if (n != NWHEEL) {
    free(t);
    mju_error("biso.tyres: wheels must name %d tyre geoms, got '%s'", NWHEEL, wheels ? wheels : "");
    return -1;
  }
  /* the brake actuators (damper actuators on the wheels' spin joints), one per wheel */
  const char* brakes = mj_getPluginConfig(m, instance, "brakes");
  strncpy(buf, brakes ? brakes : "", sizeof(buf) - 1);
  buf[sizeof(buf) - 1] = '\0';
  n = 0;
  for (char* tok = strtok(buf, " "); tok; tok = strtok(NULL, " ")) {
    int a = n < NWHEEL ? mj_name2id(m, mjOBJ_ACTUATOR, tok) : -1;
    if (a < 0 || m->actuator_trntype[a] != mjTRN_JOINT) {
      free(t);
      mju_error("biso.tyres: brakes must name %d joint actuators of the model, got '%s'", NWHEEL, brakes ? brakes : "");
      return -1;
    }
    t->brake[n] = a;
    t->spin_dof[n] = m->jnt_dofadr[m->actuator_trnid[2 * a]];
    n++;
  }
  if (n != NWHEEL) {
    free(t);
    mju_error("biso.tyres: brakes must name %d brake actuators, got '%s'", NWHEEL, brakes ? brakes : "");
    return -1;
  }
  /* the steering servo (a position actuator on the steering hinge) */
  const char* steer = mj_getPluginConfig(m, instance, "steer");
  const int sa = (steer && *steer) ? mj_name2id(m, mjOBJ_ACTUATOR, steer) : -1;
  if (sa < 0 || m->actuator_trntype[sa] != mjTRN_JOINT || !(m->actuator_gainprm[mjNGAIN * sa] > 0.0)) {
    free(t);
    mju_error("biso.tyres: steer must name the steering's position actuator, got '%s'", steer ? steer : "");
    return -1;
  }
  t->steer_dof = m->jnt_dofadr[m->actuator_trnid[2 * sa]];
  t->steer_kp = m->actuator_gainprm[mjNGAIN * sa];
  /* the surface patches (none: every ground geom's own friction) */
  const char* surfaces = mj_getPluginConfig(m, instance, "surfaces");
  const char* c = surfaces ? surfaces : "";
  int count = 0;
  for (;;) {
    char* end = NULL;
    double v = strtod(c, &end);
    if (end == c) break;
    if (count >= MAX_SURFACES * SURFACE_STRIDE || !isfinite(v)) {
      free(t);
      mju_error("biso.tyres: surfaces must be at most %d patches of %d finite numbers", MAX_SURFACES, SURFACE_STRIDE);
      return -1;
    }
    t->surface[count++] = v;
    c = end;
  }
  while (*c == ' ') c++;
  if (*c || count % SURFACE_STRIDE) {
    free(t);
    mju_error("biso.tyres: surfaces must be groups of %d numbers, got '%s'", SURFACE_STRIDE, surfaces);
    return -1;
  }
  t->nsurface = count / SURFACE_STRIDE;
  d->plugin_data[instance] = (uintptr_t)t;
  return 0;
}

static void destroy(mjData* d, int instance) {
  free((Tyres*)d->plugin_data[instance]);
  d->plugin_data[instance] = 0;
}

static void copy(mjData* dest, const mjModel* m, const mjData* src, int instance) {
  (void)m;
  Tyres* t = (Tyres*)malloc(sizeof(Tyres));
  if (!t) mju_error("biso.tyres: out of memory");
  memcpy(t, (const Tyres*)src->plugin_data[instance], sizeof(Tyres));
  /* (dest's slot may hold src's pointer, copied with the data: not freed here) */
  dest->plugin_data[instance] = (uintptr_t)t;
}

static void reset(const mjModel* m, mjtNum* plugin_state, void* plugin_data, int instance) {
  (void)m;
  (void)plugin_data;
  (void)instance;
  memset(plugin_state, 0, sizeof(mjtNum) * NWHEEL * STRIDE);
}

/* the friction scale at the contact point: the last surface patch that holds it, else the
   ground geom's own (friction[0]) */
static double surface_friction(const Tyres* t, const double* pos, double ground) {
  for (int k = t->nsurface - 1; k >= 0; k--) {
    const double* q = t->surface + k * SURFACE_STRIDE;
    const double dx = pos[0] - q[0], dy = pos[1] - q[1];
    if (fabs(dx * q[2] + dy * q[3]) <= q[4] && fabs(-dx * q[3] + dy * q[2]) <= q[5]) return q[6];
  }
  return ground;
}

/* the brake actuator a's command, within its control range */
static double brake_command(const mjModel* m, const mjData* d, int a) {
  double u = d->ctrl[a];
  if (m->actuator_ctrllimited[a]) u = fmin(fmax(u, m->actuator_ctrlrange[2 * a]), m->actuator_ctrlrange[2 * a + 1]);
  return u;
}

/* passive stage: the forces of the current slip states, applied at the contact points */
static void compute(const mjModel* m, mjData* d, int instance, int capability_bit) {
  if (!(capability_bit & mjPLUGIN_PASSIVE)) return;
  const Tyres* t = (const Tyres*)d->plugin_data[instance];
  const double* p = t->p;
  mjtNum* state = d->plugin_state + m->plugin_stateadr[instance];
  for (int w = 0; w < NWHEEL; w++) {
    mjtNum* s = state + w * STRIDE;
    const int c = wheel_contact(d, t->geom[w]);
    if (c < 0) {
      /* no contact (a wheel hop, or a step without a contact on a height field's kink): no
         force; the slip states are kept for the landing, as the tyre's deflection would be */
      s[S_FX] = s[S_FY] = s[S_CONTACT] = 0.0;
      continue;
    }
    const mjContact* con = d->contact + c;
    const int tyre_second = con->geom[1] == t->geom[w];
    const int ground = con->geom[tyre_second ? 0 : 1];
    const double sign = tyre_second ? 1.0 : -1.0; /* the normal from the ground into the tyre */
    double n[3] = {sign * con->frame[0], sign * con->frame[1], sign * con->frame[2]};
    const int b = t->body[w];
    const double axis[3] = {d->xmat[9 * b + 1], d->xmat[9 * b + 4], d->xmat[9 * b + 7]};
    double ex[3], ey[3];
    cross(axis, n, ex);
    const double norm = sqrt(dot(ex, ex));
    if (!(norm > 1e-9)) { /* wheel lying flat on the ground: no tyre force */
      s[S_FX] = s[S_FY] = s[S_CONTACT] = 0.0;
      continue;
    }
    for (int k = 0; k < 3; k++) ex[k] /= norm;
    cross(n, ex, ey);
    for (int k = 0; k < 3; k++) {
      s[S_EX + k] = ex[k];
      s[S_EY + k] = ey[k];
      s[S_POINT + k] = con->pos[k];
    }
    s[S_CONTACT] = 1.0;
    const double lam = surface_friction(t, con->pos, m->geom_friction[3 * ground]);
    s[S_LAMBDA] = lam;
    double fx, fy;
    biso_tyres_magic_formula(p, s[S_FZ], s[S_KAPPA], s[S_SLIPY], lam, &fx, &fy);
    /* low-speed damping on the slip velocity, faded in below v_low */
    double v[3];
    slip_velocities(m, d, b, s, v);
    const double speed = fabs(v[0]);
    if (speed < p[P_v_low_mps] && s[S_FZ] > 0.0) {
      const double fade = 0.5 * (1.0 + cos(PI * speed / p[P_v_low_mps]));
      fx -= fade * p[P_damping_x_ns_per_m] * v[1];
      fy -= fade * p[P_damping_y_ns_per_m] * v[2];
      /* never more than the friction allows */
      const double limit = fmax(p[P_pdx1], p[P_pdy1]) * lam * fmin(s[S_FZ], p[P_fzmax_n]);
      const double f = sqrt(fx * fx + fy * fy);
      if (f > limit) {
        fx *= limit / f;
        fy *= limit / f;
      }
    }
    if (!isfinite(fx) || !isfinite(fy)) {
      mju_error("biso.tyres: the tyre force of wheel %s is not finite at t = %.6f s (load %g N, slip ratio %g, "
                "lateral slip %g)", geom_name(m, t->geom[w]), d->time, s[S_FZ], s[S_KAPPA], s[S_SLIPY]);
    }
    s[S_FX] = fx;
    s[S_FY] = fy;
    double force[3], torque[3] = {0.0, 0.0, 0.0};
    for (int k = 0; k < 3; k++) force[k] = fx * ex[k] + fy * ey[k];
    mj_applyFT(m, d, force, torque, s + S_POINT, b, d->qfrc_passive);
  }
  /* brakes: the ABS's modulator releases the share S_RELEASE of each brake's torque (the
     damper actuator's torque of this step, computed as MuJoCo will: gain (kv) times the
     joint velocity times the command, within the force range), and the build-up caps what
     is left at the share S_BUILD of the force range */
  for (int w = 0; w < NWHEEL; w++) {
    const double release = state[w * STRIDE + S_RELEASE], build = state[w * STRIDE + S_BUILD];
    if (!(release > 0.0) && !(build < 1.0)) continue;
    const int a = t->brake[w];
    const double gear = m->actuator_gear[6 * a];
    const double* g = m->actuator_gainprm + mjNGAIN * a;
    const double* bias = m->actuator_biasprm + mjNBIAS * a;
    const double velocity = gear * d->qvel[t->spin_dof[w]];
    const double u = brake_command(m, d, a);
    double force = (g[0] + g[2] * velocity) * u + bias[0] + bias[2] * velocity;
    if (m->actuator_forcelimited[a]) {
      force = fmin(fmax(force, m->actuator_forcerange[2 * a]), m->actuator_forcerange[2 * a + 1]);
    }
    double applied = (1.0 - release) * force;
    if (m->actuator_forcelimited[a]) {
      const double cap = build * fmax(-m->actuator_forcerange[2 * a], m->actuator_forcerange[2 * a + 1]);
      applied = fmin(fmax(applied, -cap), cap);
    }
    d->qfrc_passive[t->spin_dof[w]] += gear * (applied - force);
  }
  /* compliance steer: the front tyres' lateral force turns the road wheels against it by
     c_delta per newton, as a torque on the steering hinge that deflects its servo so */
  const double fy_front = state[0 * STRIDE + S_FY] + state[1 * STRIDE + S_FY];
  d->qfrc_passive[t->steer_dof] -= p[P_compliance_steer_rad_per_n] * t->steer_kp * fy_front;
}

/* after MuJoCo's velocity update: integrate the slip states, store the solved normal loads */
static void advance(const mjModel* m, mjData* d, int instance) {
  const Tyres* t = (const Tyres*)d->plugin_data[instance];
  const double* p = t->p;
  const double dt = m->opt.timestep;
  mjtNum* state = d->plugin_state + m->plugin_stateadr[instance];
  for (int w = 0; w < NWHEEL; w++) {
    mjtNum* s = state + w * STRIDE;
    double fz = 0.0;
    for (int i = 0; i < d->ncon; i++) {
      const mjContact* c = d->contact + i;
      if (c->exclude || c->efc_address < 0 || (c->geom[0] != t->geom[w] && c->geom[1] != t->geom[w])) continue;
      mjtNum f[6];
      mj_contactForce(m, d, i, f);
      fz += f[0];
    }
    s[S_FZ] = fz;
    /* brake build-up: the share of the torque limit rises over brake_build_up_s while braking */
    if (brake_command(m, d, t->brake[w]) > 0.0) {
      s[S_BUILD] = p[P_brake_build_up_s] > 0.0 ? fmin(s[S_BUILD] + dt / p[P_brake_build_up_s], 1.0) : 1.0;
    } else {
      s[S_BUILD] = 0.0;
    }
    if (s[S_CONTACT] == 0.0) continue;
    double v[3];
    slip_velocities(m, d, t->body[w], s, v);
    const double speed = fabs(v[0]);
    double kappa = (s[S_KAPPA] - dt * v[1] / p[P_sigma_x_m]) / (1.0 + dt * speed / p[P_sigma_x_m]);
    double slipy = (s[S_SLIPY] + dt * v[2] / p[P_sigma_y_m]) / (1.0 + dt * speed / p[P_sigma_y_m]);
    /* bounded deflection: beyond these the force curve is flat anyway */
    s[S_KAPPA] = fmin(fmax(kappa, -10.0), 10.0);
    s[S_SLIPY] = fmin(fmax(slipy, -10.0), 10.0);
    /* ABS: integral control of the braking slip (the wheel's slip velocity over its speed,
       in the direction of travel) to abs_slip_target: the release grows while the slip is
       beyond the target and shrinks below it; none while not braking or below the cut-out speed */
    if (brake_command(m, d, t->brake[w]) > 0.0 && speed > p[P_abs_speed_min_mps]) {
      const double slip = (v[0] > 0.0 ? v[1] : -v[1]) / speed;
      const double target = p[P_abs_slip_target] * s[S_LAMBDA];
      const double release = s[S_RELEASE] + dt * p[P_abs_gain_per_s] * (slip - target);
      s[S_RELEASE] = fmin(fmax(release, 0.0), 1.0);
    } else {
      s[S_RELEASE] = 0.0;
    }
  }
}

mjPLUGIN_LIB_INIT(biso_tyres) {
  mjpPlugin plugin;
  mjp_defaultPlugin(&plugin);
  plugin.name = "biso.tyres";
  plugin.capabilityflags = mjPLUGIN_PASSIVE;
  plugin.nattribute = NCONFIG;
  plugin.attributes = param_names;
  plugin.nstate = nstate;
  plugin.init = init;
  plugin.destroy = destroy;
  plugin.copy = copy;
  plugin.reset = reset;
  plugin.compute = compute;
  plugin.advance = advance;
  mjp_registerPlugin(&plugin);
}
