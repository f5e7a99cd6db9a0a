/* BISO (biso, positional, poisson): the quaternion Poisson equation with cross-linked
 * positional correction, Aleshkin, Zdrazhevsky, Efremov, Skibin (2024), Izv. vuzov.
 * Priborostroenie 67(8), 678-688, "reading D" of eqs. (2), (8), (9) (docs/design.md §5).
 *
 * Port of biso_cosim/estimators/biso.py: biso_coefficients (validation and the
 * coefficient array) and one sample of _biso_batch (its two passes over a block do the
 * arithmetic of one pass per sample). The discretisation (exact error dynamics at any
 * rate) is explained in the Python module's docstring. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "biso_est_internal.h"
#include "biso_est_kernels.h"

#define P(name) BISO_EST_BISO_P_##name
#define C(name) BISO_EST_BISO_C_##name
#define S(name) BISO_EST_BISO_S_##name

static const double T_GOST[16] = BISO_EST_K_T_GOST;
static const double PATTERN_12[16] = BISO_EST_K_PATTERN_12;
static const double PATTERN_13[16] = BISO_EST_K_PATTERN_13;

/* pow as CPython's float ** calls it (a call of libm's pow, which the compiler may not fold) */
static double (*volatile libm_pow)(double, double) = pow;

/* ---- coefficients ------------------------------------------------------------------- */

/* out (16) = (t^T g t) row-major: G of the paper's lambda components in q_wb components (_g_in_q) */
static void g_in_q(const double *g, const double *t, double *out) {
    int i, j, a, b;
    for (i = 0; i < 4; i++)
        for (j = 0; j < 4; j++) {
            double total = 0.0;
            for (b = 0; b < 4; b++) {
                double m = 0.0;
                for (a = 0; a < 4; a++) m += t[4 * a + i] * g[4 * a + b];
                total += m * t[4 * b + j];
            }
            out[4 * i + j] = total;
        }
}

/* e^{a'h} for a = (-k, k_p, k_p, k_p), a' = a - w_g/2 (_closed_transition) */
static bq closed_transition(double k, double kp, double wgx, double wgy, double wgz, double h) {
    double d = exp(-k * h);
    bq q = bq_exp_rotvec(2.0 * h * (kp - 0.5 * wgx), 2.0 * h * (kp - 0.5 * wgy), 2.0 * h * (kp - 0.5 * wgz));
    return bq_make(d * q.w, d * q.x, d * q.y, d * q.z);
}

/* all roots of s^4 + a1 s^3 + a2 s^2 + a3 s + a4 in the open left half-plane (Hurwitz) */
static int hurwitz4(const double *m) {
    /* Faddeev-LeVerrier: the characteristic polynomial's coefficients */
    double mk[16], am[16], c[5];
    int i, j, l, k;
    memset(mk, 0, sizeof mk);
    c[0] = 1.0;
    for (k = 1; k <= 4; k++) {
        double tr = 0.0;
        for (i = 0; i < 4; i++)
            for (j = 0; j < 4; j++) {
                double s = 0.0;
                for (l = 0; l < 4; l++) s += m[4 * i + l] * mk[4 * l + j];
                am[4 * i + j] = s + (i == j ? c[k - 1] : 0.0);
            }
        memcpy(mk, am, sizeof mk);
        for (i = 0; i < 4; i++)
            for (l = 0; l < 4; l++) tr += m[4 * i + l] * mk[4 * l + i];
        c[k] = -tr / k;
    }
    return c[1] > 0.0 && c[3] > 0.0 && c[4] > 0.0 && c[1] * c[2] * c[3] > c[3] * c[3] + c[1] * c[1] * c[4];
}

/* the frozen-rate stability check of stability(): at rest, and at the 26 axis and diagonal
 * directions at 11 magnitudes up to rate_max (paper axes); 0, or -1 with the message */
static int check_stability(const char *kind, const double *g, double rate_max, char *msg, size_t size) {
    double z[16];
    int ix, iy, iz, m, i;
    if (!hurwitz4(g))
        return biso_est_fail(msg, size, "%s: unstable gains: the poles at rest must all have negative real parts "
                             "(eq. (10) with omega = 0); raise %s.k", kind, kind);
    for (m = 1; m < 12; m++) {
        /* np.linspace(0, rate_max, 12)[1:] */
        double mag = m == 11 ? rate_max : m * (rate_max / 11.0);
        /* np.meshgrid([-1, 0, 1], ...) flattened: x varies fastest along the second axis */
        for (iy = -1; iy <= 1; iy++)
            for (ix = -1; ix <= 1; ix++)
                for (iz = -1; iz <= 1; iz++) {
                    double n, wx, wy, wz;
                    if (ix == 0 && iy == 0 && iz == 0) continue;
                    n = sqrt((double)(ix * ix + iy * iy + iz * iz));
                    wx = mag * (ix / n); wy = mag * (iy / n); wz = mag * (iz / n);
                    /* g + 1/2 R((0, w)) */
                    {
                        const double r[16] = {0.0, -wx, -wy, -wz, wx, 0.0, wz, -wy, wy, -wz, 0.0, wx, wz, wy, -wx, 0.0};
                        for (i = 0; i < 16; i++) z[i] = g[i] + 0.5 * r[i];
                    }
                    if (!hurwitz4(z))
                        return biso_est_fail(msg, size, "%s: unstable gains: at the body rate [%.3f, %.3f, %.3f] rad/s "
                                             "(paper axes) a pole has real part >= 0 (checked up to "
                                             "%s.stability_rate_rad_s = %g)", kind, wx, wy, wz, kind, rate_max);
                }
    }
    return 0;
}

static int biso_coefficients(const char *kind, const double *p, double fs_hz, double *c, char *msg, size_t size) {
    double k, kp, h, scale, decl, norm_gain, altitude, glim, alim, e, g[16], wg[3];
    const double *pattern;
    int mode, i;
    int closed_pattern = p[P(PATTERN)] == 12.0;
    int reading_l = p[P(READING)] == 1.0;

    decl = p[P(DECLINATION_RAD)];
    norm_gain = p[P(NORM_GAIN)];
    altitude = p[P(ALTITUDE_M)];
    glim = isnan(p[P(GYRO_RANGE_RAD_S)]) ? HUGE_VAL : BISO_EST_K_SATURATION_FRACTION * p[P(GYRO_RANGE_RAD_S)];
    alim = isnan(p[P(ACCEL_RANGE_MPS2)]) ? HUGE_VAL : BISO_EST_K_SATURATION_FRACTION * p[P(ACCEL_RANGE_MPS2)];

    /* _resolved_gains: the gains as the user means them (before the reading's factor) */
    if (!isnan(p[P(CUTOFF_HZ)])) {
        double wn;
        if (!isnan(p[P(K)]) || !isnan(p[P(K_P)]))
            return biso_est_fail(msg, size, "%s: give either %s.cutoff_hz or %s.k and %s.k_p, not both "
                                 "(set the others to NaN)", kind, kind, kind, kind);
        wn = 2.0 * BISO_EST_K_PI * p[P(CUTOFF_HZ)];  /* _cutoff_gains */
        k = wn / sqrt(2.0);
        kp = wn / sqrt(6.0);
        if (reading_l) { k = 2.0 * k; kp = 2.0 * kp; }
    } else {
        k = isnan(p[P(K)]) ? BISO_EST_K_PAPER_K : p[P(K)];
        kp = isnan(p[P(K_P)]) ? BISO_EST_K_PAPER_K_P : p[P(K_P)];
    }

    if (biso_est_need_finite(kind, k + kp, "gain", "cutoff_hz, k, k_p", msg, size) != 0) return -1;

    /* correction_matrix: G = -diag(k) - pattern * k_p (paper components), the reading applied */
    pattern = closed_pattern ? PATTERN_12 : PATTERN_13;
    for (i = 0; i < 16; i++) {
        double diag = (i % 5 == 0) ? -k : -0.0;
        g[i] = diag - pattern[i] * kp;
        if (reading_l) g[i] = 0.5 * g[i];
    }
    h = 1.0 / fs_hz;

    if (k == 0.0 && kp == 0.0) {
        mode = BISO_EST_MODE_NONE;
    } else if (closed_pattern) {
        if (k == 0.0) {
            char v[32];
            snprintf(v, sizeof v, "%g", kp);
            return biso_est_fail(msg, size, "%s: k = 0 with k_p = %s is not asymptotically stable (poles +-i*sqrt(3)*k_p); "
                                 "use %s.k > 0", kind, v, kind);
        }
        mode = BISO_EST_MODE_CLOSED;
    } else {
        mode = BISO_EST_MODE_GENERAL;
        if (check_stability(kind, g, p[P(STABILITY_RATE_RAD_S)], msg, size) != 0) return -1;
    }

    memset(c, 0, BISO_EST_BISO_COEF_SIZE * sizeof(double));
    wg[0] = wg[1] = wg[2] = 0.0;
    if (!isnan(p[P(LATITUDE_RAD)])) {
        /* geographic_rate(lat) with zero velocity, and _radii(lat, altitude) */
        double lat = p[P(LATITUDE_RAD)];
        double s2 = libm_pow(sin(lat), 2.0);
        double w = 1.0 - BISO_EST_K_WGS84_E2 * s2;
        double rm = BISO_EST_K_WGS84_A * (1.0 - BISO_EST_K_WGS84_E2) / libm_pow(w, 1.5) + altitude;
        double rn = BISO_EST_K_WGS84_A / sqrt(w) + altitude;
        double tan_lat = tan(lat);
        wg[0] = BISO_EST_K_EARTH_RATE * 0.0 + (-0.0) / rm;
        wg[1] = BISO_EST_K_EARTH_RATE * cos(lat) + 0.0 / rn;
        wg[2] = BISO_EST_K_EARTH_RATE * sin(lat) + 0.0 * tan_lat / rn;
        c[C(GEO)] = 1.0;
        c[C(INV_RM)] = 1.0 / rm;
        c[C(INV_RN)] = 1.0 / rn;
        c[C(TAN_LAT)] = tan_lat;
    }

    scale = reading_l ? 0.5 : 1.0;
    c[C(MODE)] = mode;
    c[C(H)] = h;
    c[C(REF)] = p[P(REFERENCE)];
    c[C(DECL)] = decl;
    c[C(CDH)] = cos(0.5 * decl);
    c[C(SDH)] = sin(0.5 * decl);
    e = p[P(RENORMALIZE)] != 0.0 ? 1.0 : exp(2.0 * scale * norm_gain * h);
    if (biso_est_need_finite(kind, (e - 1.0) / e, "norm flow e^(2 g_n h)", "norm_gain", msg, size) != 0) return -1;
    c[C(NORM_E)] = e;
    c[C(NORM_A)] = (e - 1.0) / e;
    c[C(RENORM)] = p[P(RENORMALIZE)] != 0.0 ? 1.0 : 0.0;
    c[C(K)] = scale * k;
    c[C(K_P)] = scale * kp;
    if (wg[0] != 0.0 || wg[1] != 0.0 || wg[2] != 0.0) {
        bq eg = bq_exp_rotvec(-wg[0] * h, -wg[1] * h, -wg[2] * h);
        bq egi = bq_exp_rotvec(wg[0] * h, wg[1] * h, wg[2] * h);
        c[C(EG)] = eg.w; c[C(EG) + 1] = eg.x; c[C(EG) + 2] = eg.y; c[C(EG) + 3] = eg.z;
        c[C(EGI)] = egi.w; c[C(EGI) + 1] = egi.x; c[C(EGI) + 2] = egi.y; c[C(EGI) + 3] = egi.z;
    } else {
        c[C(EG)] = c[C(EGI)] = 1.0;
    }
    c[C(WG)] = wg[0]; c[C(WG) + 1] = wg[1]; c[C(WG) + 2] = wg[2];
    g_in_q(g, T_GOST, c + C(G));
    for (i = 0; i < 16; i++)
        if (biso_est_need_finite(kind, c[C(G) + i], "correction matrix G", "cutoff_hz, k, k_p", msg, size) != 0)
            return -1;
    c[C(GYRO_LIMIT)] = glim;
    c[C(ACCEL_LIMIT)] = alim;
    if (mode == BISO_EST_MODE_CLOSED) {
        bq ea = closed_transition(c[C(K)], c[C(K_P)], wg[0], wg[1], wg[2], h);
        c[C(EA)] = ea.w; c[C(EA) + 1] = ea.x; c[C(EA) + 2] = ea.y; c[C(EA) + 3] = ea.z;
    }
    return 0;
}

static void biso_initial_state(const double *p, const double *q0, double *st) {
    (void)p;
    memset(st, 0, BISO_EST_BISO_STATE_SIZE * sizeof(double));
    st[S(LAM)] = 1.0;
    if (q0 != NULL) {
        st[S(INITIALIZED)] = 2.0;
        memcpy(st + S(LAM), q0, 4 * sizeof(double));
    }
}

/* ---- the per-sample update ---------------------------------------------------------- */

/* exp(z) of a 4x4 matrix: Taylor series (order 14) with scaling and squaring (_expm_small) */
static void expm4(const double *z, double *e) {
    double norm = 0.0, scale = 1.0, zs[16], t[16];
    int squarings = 0, i, j, l, order;
    for (i = 0; i < 4; i++) {
        double row = 0.0;
        for (j = 0; j < 4; j++) row += fabs(z[4 * i + j]);
        norm = py_max(norm, row);
    }
    while (norm > 0.25) {
        norm *= 0.5;
        squarings += 1;
    }
    for (i = 0; i < squarings; i++) scale *= 0.5;  /* 0.5 ** squarings, exact */
    for (i = 0; i < 16; i++) zs[i] = z[i] * scale;
    for (i = 0; i < 16; i++) e[i] = (i % 5 == 0) ? 1.0 : 0.0;
    for (order = 14; order > 0; order--) {  /* Horner: I + Z(I + Z/2(I + ...)) */
        for (i = 0; i < 4; i++)
            for (j = 0; j < 4; j++) {
                double s = 0.0;
                for (l = 0; l < 4; l++) s += zs[4 * i + l] * e[4 * l + j];
                t[4 * i + j] = ((i == j) ? 1.0 : 0.0) + s / order;
            }
        memcpy(e, t, sizeof t);
    }
    for (; squarings > 0; squarings--) {
        for (i = 0; i < 4; i++)
            for (j = 0; j < 4; j++) {
                double s = 0.0;
                for (l = 0; l < 4; l++) s += e[4 * i + l] * e[4 * l + j];
                t[4 * i + j] = s;
            }
        memcpy(e, t, sizeof t);
    }
}

/* Phi = exp(h(G - L(w_g)/2 + R(b))) for the general mode (_error_transition) */
static void error_transition(const double *c, double wgx, double wgy, double wgz, double bx, double by, double bz,
                             double *phi) {
    double z[16];
    double gx = -0.5 * wgx, gy = -0.5 * wgy, gz = -0.5 * wgz;
    const double lm[16] = {0.0, -gx, -gy, -gz, gx, 0.0, -gz, gy, gy, gz, 0.0, -gx, gz, -gy, gx, 0.0};
    const double rm[16] = {0.0, -bx, -by, -bz, bx, 0.0, bz, -by, by, -bz, 0.0, bx, bz, by, -bx, 0.0};
    int i;
    for (i = 0; i < 16; i++) z[i] = (c[C(G) + i] + lm[i] + rm[i]) * c[C(H)];
    expm4(z, phi);
}

/* lambda (1 - y)^{-1/2}: the series for |y| < 0.01, else 1/sqrt(1 - y) (_inv_sqrt_1m) */
static inline double inv_sqrt_1m(double y) {
    if (fabs(y) < 0.01) {
        double y2 = y * y, y4 = y2 * y2;
        return (((1.0 + BISO_EST_K_R1 * y) + y2 * (BISO_EST_K_R2 + BISO_EST_K_R3 * y))
                + y4 * ((BISO_EST_K_R4 + BISO_EST_K_R5 * y) + y2 * (BISO_EST_K_R6 + BISO_EST_K_R7 * y)
                        + y4 * BISO_EST_K_R8));
    }
    return 1.0 / sqrt(1.0 - y);
}

/* exact flow over h of lambda' = g_n lambda (1 - |lambda|^2) (_norm_flow) */
static inline bq norm_flow(double e, double a, double lw, double lx, double ly, double lz) {
    double n2 = lw * lw + lx * lx + ly * ly + lz * lz;
    double y = a * (1.0 - n2);
    double f = fabs(y) < 0.01 ? inv_sqrt_1m(y) : sqrt(e / (1.0 + n2 * (e - 1.0)));
    return bq_make(lw * f, lx * f, ly * f, lz * f);
}

static void biso_update(const double *c, double *st, const biso_est_input *in, biso_est_output *out) {
    const int mode = (int)c[C(MODE)];
    const int ref = (int)c[C(REF)];
    const double h = c[C(H)];
    const double decl = c[C(DECL)], cdh = c[C(CDH)], sdh = c[C(SDH)];
    const int geo = c[C(GEO)] != 0.0;
    const int has_vel = in->has_velocity && geo;
    double init = st[S(INITIALIZED)];
    double lw = st[S(LAM)], lx = st[S(LAM) + 1], ly = st[S(LAM) + 2], lz = st[S(LAM) + 3];
    const double ax = in->accel_b[0], ay = in->accel_b[1], az = in->accel_b[2];
    const double mx = in->mag_b[0], my = in->mag_b[1], mz = in->mag_b[2];
    double kw = 0.0, kx = 0.0, ky = 0.0, kz = 0.0, usable = 0.0, f;
    int64_t flags;
    bq eb;
    sample_checks chk = input_checks(in->gyro_b[0], in->gyro_b[1], in->gyro_b[2], ax, ay, az, mx, my, mz,
                                     st[S(GYRO_HOLD)], st[S(GYRO_HOLD) + 1], st[S(GYRO_HOLD) + 2], in->imu_flags,
                                     c[C(GYRO_LIMIT)], c[C(ACCEL_LIMIT)]);
    st[S(GYRO_HOLD)] = chk.gx; st[S(GYRO_HOLD) + 1] = chk.gy; st[S(GYRO_HOLD) + 2] = chk.gz;
    flags = chk.flags;

    /* what does not depend on the estimate: e^{bh} (b = w/2), lambda_k from a usable field */
    eb = qexp_fast(chk.gx * h, chk.gy * h, chk.gz * h);
    if (chk.acc_ok) {
        usable = 1.0;
        if (chk.mag_ok && (mode != BISO_EST_MODE_NONE || init != 1.0)) {
            bq k = reference(ref, ax, ay, az, chk.f2, chk.ex, chk.ey, chk.ez, chk.e2, mx, my, mz, 1, 1.0, 0.0, 0.0,
                             0.0, decl, cdh, sdh);
            kw = k.w; kx = k.x; ky = k.y; kz = k.z;
            usable = 2.0;
        }
    }

    if (init == 1.0) {
        double wgx = c[C(WG)], wgy = c[C(WG) + 1], wgz = c[C(WG) + 2];
        double ea0 = c[C(EA)], ea1 = c[C(EA) + 1], ea2 = c[C(EA) + 2], ea3 = c[C(EA) + 3];
        double eg0 = c[C(EG)], eg1 = c[C(EG) + 1], eg2 = c[C(EG) + 2], eg3 = c[C(EG) + 3];
        double ei0 = c[C(EGI)], ei1 = c[C(EGI) + 1], ei2 = c[C(EGI) + 2], ei3 = c[C(EGI) + 3];
        bq p;
        if (has_vel) {  /* w_g with the transport rate of this sample's velocity (unknown: 0) */
            double ve = in->velocity_enu_mps[0], vn = in->velocity_enu_mps[1];
            bq ei;
            if (!(isfinite(ve) && isfinite(vn))) ve = vn = 0.0;
            wgx = c[C(WG)] - vn * c[C(INV_RM)];
            wgy = c[C(WG) + 1] + ve * c[C(INV_RN)];
            wgz = c[C(WG) + 2] + ve * c[C(TAN_LAT)] * c[C(INV_RN)];
            ei = qexp_fast(wgx * h, wgy * h, wgz * h);
            ei0 = ei.w; ei1 = ei.x; ei2 = ei.y; ei3 = ei.z;
            eg0 = ei0; eg1 = -ei1; eg2 = -ei2; eg3 = -ei3;
            if (mode == BISO_EST_MODE_CLOSED) {
                bq ea = closed_transition(c[C(K)], c[C(K_P)], wgx, wgy, wgz, h);
                ea0 = ea.w; ea1 = ea.x; ea2 = ea.y; ea3 = ea.z;
            }
        }
        p = bq_mul(lw, lx, ly, lz, eb.w, eb.x, eb.y, eb.z);  /* lambda_{i-1} o e^{bh} */
        if (usable != 0.0 && mode != BISO_EST_MODE_NONE) {
            double rw, rx, ry, rz;
            if (usable == 1.0) {  /* no usable field: lambda_k keeps the heading of the propagated estimate */
                bq k = reference(ref, ax, ay, az, chk.f2, 0.0, 0.0, 0.0, 0.0, mx, my, mz, 0, p.w, p.x, p.y, p.z,
                                 decl, cdh, sdh);
                kw = k.w; kx = k.x; ky = k.y; kz = k.z;
            }
            if (kw * lw + kx * lx + ky * ly + kz * lz < 0.0) {  /* same hemisphere as lambda */
                kw = -kw; kx = -kx; ky = -ky; kz = -kz;
            }
            rw = kw; rx = kx; ry = ky; rz = kz;
            if (geo) {  /* lambda_k,i carried back to t_{i-1} on the left: e^{w_g h/2} o lambda_k,i */
                bq r = bq_mul(ei0, ei1, ei2, ei3, kw, kx, ky, kz);
                rw = r.w; rx = r.x; ry = r.y; rz = r.z;
            }
            if (mode == BISO_EST_MODE_CLOSED) {
                /* lambda_i = lambda_k,i + e^{a'h} o (lambda_{i-1} o e^{bh} - e^{w_g h/2} o lambda_k,i) */
                bq d = bq_mul(ea0, ea1, ea2, ea3, p.w - rw, p.x - rx, p.y - ry, p.z - rz);
                lw = kw + d.w; lx = kx + d.x; ly = ky + d.y; lz = kz + d.z;
            } else {
                /* e_{i-1} = lambda_{i-1} - e^{w_g h/2} o lambda_k,i o e^{-bh};  lambda_i = lambda_k,i + Phi e_{i-1} */
                double phi[16], e0, e1, e2, e3;
                bq q = bq_mul(rw, rx, ry, rz, eb.w, -eb.x, -eb.y, -eb.z);
                e0 = lw - q.w; e1 = lx - q.x; e2 = ly - q.y; e3 = lz - q.z;
                error_transition(c, wgx, wgy, wgz, 0.5 * chk.gx, 0.5 * chk.gy, 0.5 * chk.gz, phi);
                lw = kw + phi[0] * e0 + phi[1] * e1 + phi[2] * e2 + phi[3] * e3;
                lx = kx + phi[4] * e0 + phi[5] * e1 + phi[6] * e2 + phi[7] * e3;
                ly = ky + phi[8] * e0 + phi[9] * e1 + phi[10] * e2 + phi[11] * e3;
                lz = kz + phi[12] * e0 + phi[13] * e1 + phi[14] * e2 + phi[15] * e3;
            }
        } else if (geo) {
            bq q = bq_mul(eg0, eg1, eg2, eg3, p.w, p.x, p.y, p.z);
            lw = q.w; lx = q.x; ly = q.y; lz = q.z;
        } else {
            lw = p.w; lx = p.x; ly = p.y; lz = p.z;
        }
        if (c[C(RENORM)] != 0.0) {
            f = 1.0 / sqrt(lw * lw + lx * lx + ly * ly + lz * lz);
            lw = lw * f; lx = lx * f; ly = ly * f; lz = lz * f;
        } else if (c[C(NORM_E)] != 1.0) {
            bq q = norm_flow(c[C(NORM_E)], c[C(NORM_A)], lw, lx, ly, lz);
            lw = q.w; lx = q.x; ly = q.y; lz = q.z;
        }
    } else if (init == 2.0) {  /* q0 from reset(): it is the attitude at this first sample */
        init = 1.0;
    } else if (usable != 0.0) {  /* eq. (7): the first valid sample sets the attitude */
        if (usable == 1.0) {
            bq k = reference(ref, ax, ay, az, chk.f2, 0.0, 0.0, 0.0, 0.0, mx, my, mz, 0, 1.0, 0.0, 0.0, 0.0, decl,
                             cdh, sdh);
            kw = k.w; kx = k.x; ky = k.y; kz = k.z;
        }
        lw = kw; lx = kx; ly = ky; lz = kz;
        init = 1.0;
    } else {  /* nothing to initialise from yet */
        flags |= BISO_EST_FLAG_UNINITIALIZED;
    }
    st[S(INITIALIZED)] = init;
    st[S(LAM)] = lw; st[S(LAM) + 1] = lx; st[S(LAM) + 2] = ly; st[S(LAM) + 3] = lz;
    /* lambda/|lambda| (_unit_output) */
    f = inv_sqrt_1m(1.0 - (lw * lw + lx * lx + ly * ly + lz * lz));
    out->q_wb[0] = lw * f; out->q_wb[1] = lx * f; out->q_wb[2] = ly * f; out->q_wb[3] = lz * f;
    out->flags = flags;
    out->gyro_bias_b[0] = out->gyro_bias_b[1] = out->gyro_bias_b[2] = 0.0;
}

const biso_est_family biso_est_family_biso = {
    biso_coefficients, biso_initial_state, biso_update, BISO_EST_BISO_STATE_SIZE, BISO_EST_BISO_COEF_SIZE, -1, 1,
};
