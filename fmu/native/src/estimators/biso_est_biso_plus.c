/* biso_plus: the BISO structure with what a vehicle needs (gyro-bias Kalman filter after
 * VQF, Laidig & Seel 2023; acceleration compensation from speed; tilt low-pass in the
 * quasi-inertial frame I; magnetic disturbance detection; hard-iron estimation; decoupled
 * tilt and heading corrections; the cross-link on the rotation error). The attitude is
 * lambda = q_c o q_I. Port of biso_cosim/estimators/biso_plus.py (biso_plus_coefficients,
 * biso_plus_initial_state, and one sample of _biso_plus_batch with _biso_plus_start,
 * _offset_update and _bias_update); the module docstring there explains each part. */
#include <math.h>
#include <string.h>

#include "biso_est_internal.h"
#include "biso_est_kernels.h"

#define P(name) BISO_EST_BISO_PLUS_P_##name
#define C(name) BISO_EST_BISO_PLUS_C_##name
#define S(name) BISO_EST_BISO_PLUS_S_##name

/* pow as CPython's float ** calls it (a call of libm's pow, which the compiler may not fold) */
static double (*volatile libm_pow)(double, double) = pow;

/* ---- coefficients ------------------------------------------------------------------- */

/* per-sample gain of a first-order low-pass with time constant tau (1 at tau = 0) (_alpha) */
static double alpha_of(double h, double tau) { return tau == 0.0 ? 1.0 : 1.0 - exp(-h / tau); }

/* measurement variance whose steady-state estimate variance with random walk v is sigma^2 (_kalman_noise) */
static double kalman_noise(double sigma, double v) {
    double p = sigma * sigma;
    return p * p / v + p;
}

/* second-order Butterworth low-pass (b0, b1, b2, a1, a2), cut-off sqrt(2)/(2 pi tau), bilinear
 * with pre-warping (_butterworth2; VQF filterCoeffs) */
static void butterworth2(double h, double tau, double *out) {
    double fc = sqrt(2.0) / (2.0 * BISO_EST_K_PI * tau);
    double cw = tan(BISO_EST_K_PI * fc * h);
    double d = cw * cw + sqrt(2.0) * cw + 1.0;
    double b0 = cw * cw / d;
    out[0] = b0; out[1] = 2.0 * b0; out[2] = b0;
    out[3] = 2.0 * (cw * cw - 1.0) / d;
    out[4] = (1.0 - sqrt(2.0) * cw + cw * cw) / d;
}

static int plus_coefficients(const char *kind, const double *p, double fs_hz, double *c, char *msg, size_t size) {
    double h = 1.0 / fs_hz, decl = p[P(DECLINATION_RAD)], dt_off;
    memset(c, 0, BISO_EST_BISO_PLUS_COEF_SIZE * sizeof(double));
    c[C(H)] = h;
    c[C(A_ACC)] = alpha_of(h, p[P(TAU_ACC_S)]);
    c[C(A_ACCV)] = alpha_of(h, p[P(TAU_ACC_SPEED_S)]);
    c[C(K_T)] = p[P(K_TILT)];
    c[C(K_H)] = p[P(K_HEADING)];
    c[C(K_P)] = p[P(K_P)];
    c[C(GATE)] = p[P(ACCEL_GATE)];
    c[C(T0)] = py_max(p[P(TAU_ACC_S)], h);
    /* bias Kalman filter (VQF's design: variances in (rad/s)^2) */
    c[C(BIAS_P0)] = libm_pow(p[P(BIAS_SIGMA_INIT_RAD_S)], 2.0);
    c[C(BIAS_V)] = libm_pow(0.1 * BISO_EST_K_DEG, 2.0) * h / p[P(BIAS_FORGETTING_S)];
    c[C(BIAS_W_MOTION)] = kalman_noise(p[P(BIAS_SIGMA_MOTION_RAD_S)], c[C(BIAS_V)]);
    c[C(BIAS_W_VERTICAL)] = c[C(BIAS_W_MOTION)] / py_max(p[P(BIAS_HEADING_FACTOR)], 1e-10);
    c[C(BIAS_W_VERTICAL_FREE)] = c[C(BIAS_W_MOTION)] / py_max(p[P(BIAS_HEADING_FACTOR_FREE)], 1e-10);
    c[C(BIAS_W_REST)] = kalman_noise(p[P(BIAS_SIGMA_REST_RAD_S)], c[C(BIAS_V)]);
    c[C(BIAS_LIMIT)] = p[P(BIAS_LIMIT_RAD_S)];
    c[C(REST_TIME)] = p[P(REST_TIME_S)];
    c[C(A_REST)] = alpha_of(h, p[P(REST_FILTER_TAU_S)]);
    c[C(REST_W)] = p[P(REST_GYRO_RAD_S)];
    c[C(REST_A)] = p[P(REST_ACCEL_MPS2)];
    c[C(REST_V)] = p[P(REST_SPEED_MPS)];
    c[C(B_TOL)] = p[P(MAG_NORM_TOL)];
    c[C(DIP_TOL)] = p[P(MAG_DIP_TOL_RAD)];
    c[C(REJECT_MAX)] = p[P(MAG_REJECT_MAX_S)];
    c[C(A_FIELD)] = alpha_of(h, p[P(TAU_FIELD_S)]);
    c[C(B_NORM)] = isnan(p[P(FIELD_NORM_UT)]) ? -1.0 : p[P(FIELD_NORM_UT)];
    c[C(DIP)] = p[P(DIP_RAD)];  /* NaN: learned */
    c[C(OFFSET_ON)] = p[P(ESTIMATE_MAG_OFFSET)] != 0.0 ? 1.0 : 0.0;
    {   /* max(1, int(round(interval * fs))): round half to even, as Python's round */
        double n = nearbyint(p[P(MAG_OFFSET_INTERVAL_S)] * fs_hz);
        c[C(OFFSET_N)] = n < 1.0 ? 1.0 : n;
    }
    dt_off = c[C(OFFSET_N)] * h;
    c[C(Q_OFFSET)] = libm_pow(p[P(MAG_OFFSET_SIGMA_UT)], 2.0) / p[P(TAU_MAG_OFFSET_S)] * dt_off;
    c[C(Q_FIELD)] = BISO_EST_K_FIELD_WALK_UT2_PER_S * dt_off;
    c[C(R_MAG)] = libm_pow(p[P(MAG_NOISE_UT)], 2.0);
    c[C(OFFSET_BIAS2)] = libm_pow(p[P(MAG_OFFSET_BIAS_SIGMA_RAD_S)], 2.0);
    c[C(DECL)] = decl;
    c[C(CDH)] = cos(0.5 * decl);
    c[C(SDH)] = sin(0.5 * decl);
    c[C(R_V)] = p[P(SPEED_POINT_B_M_1)];
    c[C(R_V) + 1] = p[P(SPEED_POINT_B_M_2)];
    c[C(R_V) + 2] = p[P(SPEED_POINT_B_M_3)];
    c[C(A_SPEED)] = alpha_of(h, p[P(TAU_SPEED_S)]);
    c[C(G)] = p[P(GRAVITY_MPS2)];
    c[C(GYRO_RANGE)] = isnan(p[P(GYRO_RANGE_RAD_S)]) ? HUGE_VAL
                                                    : BISO_EST_K_SATURATION_FRACTION * p[P(GYRO_RANGE_RAD_S)];
    c[C(ACCEL_RANGE)] = isnan(p[P(ACCEL_RANGE_MPS2)]) ? HUGE_VAL
                                                     : BISO_EST_K_SATURATION_FRACTION * p[P(ACCEL_RANGE_MPS2)];
    c[C(FS)] = fs_hz;
    c[C(INV_GATE_G)] = 1.0 / (c[C(G)] * c[C(GATE)]);
    if (!isnan(p[P(DIP_RAD)])) {
        c[C(DIP_C)] = cos(c[C(DIP)]);
        c[C(DIP_S)] = sin(c[C(DIP)]);
    }
    /* |delta| > theta ⟺ cos delta < cos theta for |delta| <= pi; theta >= pi: never */
    c[C(COS_DIP_TOL)] = c[C(DIP_TOL)] < BISO_EST_K_PI ? cos(c[C(DIP_TOL)]) : -2.0;
    /* without a speed input: Butterworth (all 0: first order), gate (0: none), heading variance */
    if (p[P(TILT_LP_ORDER)] == 2.0 && p[P(TAU_ACC_S)] > 0.0) butterworth2(h, p[P(TAU_ACC_S)], c + C(ACC_BW));
    c[C(INV_GATE_FREE_G)] = isnan(p[P(ACCEL_GATE_FREE)]) ? 0.0 : 1.0 / (c[C(G)] * p[P(ACCEL_GATE_FREE)]);
    c[C(R_HEAD)] = libm_pow(p[P(MAG_HEADING_NOISE_UT)], 2.0);
    c[C(KAPPA)] = p[P(MAG_DISTURBANCE_GAIN)];
    c[C(A_DIST)] = alpha_of(h, p[P(TAU_MAG_DISTURBANCE_S)]);
    c[C(TAU_M2)] = libm_pow(p[P(MAG_TIME_SKEW_S)], 2.0);
    c[C(SLIP_ACCEL)] = p[P(SPEED_SLIP_ACCEL_MPS2)];
    c[C(SLIP_HOLD)] = p[P(SPEED_SLIP_HOLD_S)];
    c[C(REAR_SLIP)] = p[P(REAR_SLIP_GRADIENT_RAD_PER_G)] / BISO_EST_K_G0;  /* rad per m/s^2 */
    /* the offset's norm test: 1/Theta_o (0: off, the offset always used) */
    c[C(INV_OFFSET_TEST)] = p[P(MAG_OFFSET_TEST_ANGLE_RAD)] == 0.0 ? 0.0 : 1.0 / p[P(MAG_OFFSET_TEST_ANGLE_RAD)];
    /* the tyres' linear range: a_l^2 (0: no limit) */
    c[C(LINEAR_ACCEL2)] = p[P(LINEAR_ACCEL_MPS2)] * p[P(LINEAR_ACCEL_MPS2)];
    c[C(LINEAR_HOLD)] = p[P(LINEAR_HOLD_S)];
    /* the offset's shrink toward 0 while the test uses it: sigma_s^2 (0: o whole) */
    c[C(OFFSET_SHRINK2)] = p[P(MAG_OFFSET_SHRINK_UT)] * p[P(MAG_OFFSET_SHRINK_UT)];
    /* what the Python estimator refuses with an OverflowError (**, round) or runs on as inf */
    if (biso_est_need_finite(kind, c[C(BIAS_P0)], "initial bias variance", "bias_sigma_init_rad_s", msg, size)
        || biso_est_need_finite(kind, c[C(BIAS_V)], "bias random walk", "bias_forgetting_s", msg, size)
        || biso_est_need_finite(kind, c[C(BIAS_W_MOTION)], "bias measurement noise in motion",
                                "bias_sigma_motion_rad_s, bias_forgetting_s", msg, size)
        || biso_est_need_finite(kind, c[C(BIAS_W_VERTICAL)], "vertical bias measurement noise",
                                "bias_sigma_motion_rad_s, bias_forgetting_s, bias_heading_factor", msg, size)
        || biso_est_need_finite(kind, c[C(BIAS_W_VERTICAL_FREE)], "vertical bias measurement noise without speed",
                                "bias_sigma_motion_rad_s, bias_forgetting_s, bias_heading_factor_free", msg, size)
        || biso_est_need_finite(kind, c[C(BIAS_W_REST)], "bias measurement noise at rest",
                                "bias_sigma_rest_rad_s, bias_forgetting_s", msg, size)
        || biso_est_need_finite(kind, c[C(OFFSET_N)], "offset update interval in samples", "mag_offset_interval_s",
                                msg, size)
        || biso_est_need_finite(kind, c[C(Q_OFFSET)], "offset random walk",
                                "mag_offset_sigma_ut, tau_mag_offset_s, mag_offset_interval_s", msg, size)
        || biso_est_need_finite(kind, c[C(R_MAG)], "magnetometer noise variance", "mag_noise_ut", msg, size)
        || biso_est_need_finite(kind, c[C(OFFSET_BIAS2)], "offset learning threshold",
                                "mag_offset_bias_sigma_rad_s", msg, size)
        || biso_est_need_finite(kind, c[C(INV_GATE_G)], "gate scale 1/(g gamma)", "gravity_mps2, accel_gate", msg,
                                size)
        || biso_est_need_finite(kind, c[C(INV_GATE_FREE_G)], "gate scale 1/(g gamma_f)",
                                "gravity_mps2, accel_gate_free", msg, size)
        || biso_est_need_finite(kind, c[C(R_HEAD)], "heading noise variance", "mag_heading_noise_ut", msg, size)
        || biso_est_need_finite(kind, c[C(TAU_M2)], "squared time skew", "mag_time_skew_s", msg, size))
        return -1;
    return 0;
}

static void plus_initial_state(const double *p, const double *q0, double *st) {
    double so = libm_pow(p[P(MAG_OFFSET_SIGMA_UT)], 2.0);
    double sb = libm_pow(p[P(BIAS_SIGMA_INIT_RAD_S)], 2.0);
    int i;
    memset(st, 0, BISO_EST_BISO_PLUS_STATE_SIZE * sizeof(double));
    st[S(LAM)] = st[S(Q_I)] = st[S(Q_C)] = 1.0;
    for (i = 0; i < 3; i++) {
        st[S(BIAS_COV) + 4 * i] = 1.0 * sb;  /* np.eye(3) * sigma^2 */
        st[S(OFFSET_COV) + 7 * i] = 1.0 * BISO_EST_K_P0_FIELD;
        st[S(OFFSET_COV) + 7 * (3 + i)] = 1.0 * so;
    }
    if (q0 != NULL) {
        st[S(INITIALIZED)] = 2.0;
        memcpy(st + S(LAM), q0, 4 * sizeof(double));
        memcpy(st + S(Q_I), q0, 4 * sizeof(double));
    }
}

/* ---- pieces of the update ------------------------------------------------------------ */

/* atan(t)/t for t^2 <= 0.01 (_atan_series) */
static inline double atan_series(double t2) {
    return 1.0 - t2 * (BISO_EST_K_A3 - t2 * (BISO_EST_K_A5 - t2 * (BISO_EST_K_A7 - t2 * (BISO_EST_K_A9
                                                                                     - t2 * BISO_EST_K_A11))));
}

/* atan2 with a series for small angles (_atan2) */
static inline double atan2_fast(double y, double x) {
    if (x > 0.0 && fabs(y) <= 0.1 * x) {
        double t = y / x;
        return t * atan_series(t * t);
    }
    return atan2(y, x);
}

/* atan2(s, c)/s for s = sqrt(s2) >= 0 (0 at s = 0) (_angle_over_sine) */
static inline double angle_over_sine(double s2, double c) {
    if (c > 0.0 && s2 <= 0.01 * c * c) {
        double i = 1.0 / c;
        return i * atan_series(s2 * i * i);
    }
    if (s2 > 0.0) {
        double s = sqrt(s2);
        return atan2(s, c) / s;
    }
    return 0.0;
}

/* q/|q|, by 1 - z/2 + 3z^2/8 near |q| = 1 (_unit) */
static inline bq unit_q(double w, double x, double y, double z) {
    double z2 = w * w + x * x + y * y + z * z - 1.0, n;
    if (fabs(z2) < 1.0e-6)
        n = 1.0 - z2 * (0.5 - 0.375 * z2);
    else
        n = 1.0 / sqrt(1.0 + z2);
    return bq_make(w * n, x * n, y * n, z * n);
}

/* one Kalman step of m = R_Ib^T B_I + o for x = (B_I, o), random walks on both (_offset_update) */
static void offset_update(const double *c, double *st, double mx, double my, double mz) {
    const double qw = st[S(Q_I)], qx = st[S(Q_I) + 1], qy = st[S(Q_I) + 2], qz = st[S(Q_I) + 3];
    double *pm = st + S(OFFSET_COV);  /* P (6x6, row-major, symmetric) */
    const double meas[3] = {mx, my, mz};
    int i, j, comp;
    if (st[S(OFFSET_STARTED)] == 0.0) {
        /* start: B_I = R_Ib (m - o) with o ~ (0, sigma_o^2 I): the field is known up to the offset */
        bv b = bq_rot(qw, qx, qy, qz, mx, my, mz);
        bm r = bm_from_q(qw, qx, qy, qz);
        double so = pm[21];  /* P[3, 3] */
        st[S(OFFSET_STARTED)] = 1.0;
        st[S(FIELD_I)] = b.x; st[S(FIELD_I) + 1] = b.y; st[S(FIELD_I) + 2] = b.z;
        for (i = 0; i < 3; i++)
            for (j = 0; j < 3; j++) {
                pm[6 * i + j] = i == j ? so : 0.0;
                pm[6 * i + 3 + j] = -so * r.r[3 * i + j];
                pm[6 * (3 + j) + i] = -so * r.r[3 * i + j];
            }
        return;
    }
    for (i = 0; i < 3; i++) {
        pm[7 * i] += c[C(Q_FIELD)];
        pm[7 * (3 + i)] += c[C(Q_OFFSET)];
    }
    for (comp = 0; comp < 3; comp++) {
        bv rr = bq_rot(qw, qx, qy, qz, comp == 0 ? 1.0 : 0.0, comp == 1 ? 1.0 : 0.0, comp == 2 ? 1.0 : 0.0);
        const double rx = rr.x, ry = rr.y, rz = rr.z;  /* body axis comp in I: row of R_Ib^T */
        double ph[6], den, res;
        int e = 3 + comp;  /* P[0, 3 + comp] */
        for (i = 0; i < 6; i++)
            ph[i] = 0.0 + pm[6 * i] * rx + pm[6 * i + 1] * ry + pm[6 * i + 2] * rz + pm[6 * i + e];
        den = c[C(R_MAG)] + rx * ph[0] + ry * ph[1] + rz * ph[2] + ph[3 + comp];
        res = meas[comp] - (rx * st[S(FIELD_I)] + ry * st[S(FIELD_I) + 1] + rz * st[S(FIELD_I) + 2]
                            + st[S(MAG_OFFSET_B) + comp]);
        if (res * res > 25.0 * den) continue;  /* beyond 5 sigma: a magnet nearby */
        for (i = 0; i < 3; i++) {
            st[S(FIELD_I) + i] += ph[i] * res / den;
            st[S(MAG_OFFSET_B) + i] += ph[3 + i] * res / den;
        }
        /* P <- P - (P h^T)(P h^T)^T/den: the upper triangle, mirrored */
        for (i = 0; i < 6; i++)
            for (j = i; j < 6; j++) {
                double v = pm[6 * i + j] - ph[i] * ph[j] / den;
                pm[6 * i + j] = v;
                pm[6 * j + i] = v;
            }
    }
}

typedef struct { double bx, by, bz, p00, p01, p02, p11, p12, p22; } bias_kf;

/* Kalman update of the gyro bias (covariance P, upper triangle): measurement
 * e = H (b - b^) + noise, noise diag(w), each e clipped to +-lim; 0 (unchanged) if S is
 * not positive (_bias_update) */
static inline int bias_update(bias_kf *b, const double *hm, double e0, double e1, double e2, double w0, double w1,
                              double w2, double lim) {
    const double h00 = hm[0], h01 = hm[1], h02 = hm[2], h10 = hm[3], h11 = hm[4], h12 = hm[5];
    const double h20 = hm[6], h21 = hm[7], h22 = hm[8];
    const double p00 = b->p00, p01 = b->p01, p02 = b->p02, p11 = b->p11, p12 = b->p12, p22 = b->p22;
    double a00, a10, a20, a01, a11, a21, a02, a12, a22, s00, s01, s02, s11, s12, s22;
    double i00, i01, i02, i11, i12, i22, det, inv, k00, k01, k02, k10, k11, k12, k20, k21, k22;
    e0 = py_min(py_max(e0, -lim), lim);
    e1 = py_min(py_max(e1, -lim), lim);
    e2 = py_min(py_max(e2, -lim), lim);
    /* A = P H^T */
    a00 = p00 * h00 + p01 * h01 + p02 * h02;
    a10 = p01 * h00 + p11 * h01 + p12 * h02;
    a20 = p02 * h00 + p12 * h01 + p22 * h02;
    a01 = p00 * h10 + p01 * h11 + p02 * h12;
    a11 = p01 * h10 + p11 * h11 + p12 * h12;
    a21 = p02 * h10 + p12 * h11 + p22 * h12;
    a02 = p00 * h20 + p01 * h21 + p02 * h22;
    a12 = p01 * h20 + p11 * h21 + p12 * h22;
    a22 = p02 * h20 + p12 * h21 + p22 * h22;
    /* S = H A + W */
    s00 = h00 * a00 + h01 * a10 + h02 * a20 + w0;
    s01 = h00 * a01 + h01 * a11 + h02 * a21;
    s02 = h00 * a02 + h01 * a12 + h02 * a22;
    s11 = h10 * a01 + h11 * a11 + h12 * a21 + w1;
    s12 = h10 * a02 + h11 * a12 + h12 * a22;
    s22 = h20 * a02 + h21 * a12 + h22 * a22 + w2;
    /* S^-1 = adj(S)/det(S) */
    i00 = s11 * s22 - s12 * s12;
    i01 = s02 * s12 - s01 * s22;
    i02 = s01 * s12 - s02 * s11;
    i11 = s00 * s22 - s02 * s02;
    i12 = s01 * s02 - s00 * s12;
    i22 = s00 * s11 - s01 * s01;
    det = s00 * i00 + s01 * i01 + s02 * i02;
    if (!(det > 0.0)) return 0;
    inv = 1.0 / det;
    k00 = a00 * i00 + a01 * i01 + a02 * i02;
    k01 = a00 * i01 + a01 * i11 + a02 * i12;
    k02 = a00 * i02 + a01 * i12 + a02 * i22;
    k10 = a10 * i00 + a11 * i01 + a12 * i02;
    k11 = a10 * i01 + a11 * i11 + a12 * i12;
    k12 = a10 * i02 + a11 * i12 + a12 * i22;
    k20 = a20 * i00 + a21 * i01 + a22 * i02;
    k21 = a20 * i01 + a21 * i11 + a22 * i12;
    k22 = a20 * i02 + a21 * i12 + a22 * i22;
    b->bx = py_min(py_max(b->bx + (k00 * e0 + k01 * e1 + k02 * e2) * inv, -lim), lim);
    b->by = py_min(py_max(b->by + (k10 * e0 + k11 * e1 + k12 * e2) * inv, -lim), lim);
    b->bz = py_min(py_max(b->bz + (k20 * e0 + k21 * e1 + k22 * e2) * inv, -lim), lim);
    /* P <- P - K A^T */
    b->p00 = p00 - (k00 * a00 + k01 * a01 + k02 * a02) * inv;
    b->p01 = p01 - (k00 * a10 + k01 * a11 + k02 * a12) * inv;
    b->p02 = p02 - (k00 * a20 + k01 * a21 + k02 * a22) * inv;
    b->p11 = p11 - (k10 * a10 + k11 * a11 + k12 * a12) * inv;
    b->p12 = p12 - (k10 * a20 + k11 * a21 + k12 * a22) * inv;
    b->p22 = p22 - (k20 * a20 + k21 * a21 + k22 * a22) * inv;
    return 1;
}

/* first sample: the attitude (unless q0 was given) and every filter start from it (_biso_plus_start) */
static void plus_start(const double *c, double *st, double gx, double gy, double gz, double ax, double ay, double az,
                       double fn, double mx, double my, double mz, int acc_ok, int mag_ok, double speed) {
    int i;
    bq qi;
    bm r;
    const double fy = acc_ok ? ay : 0.0;  /* the lateral specific force, before the centripetal part below */
    if (st[S(INITIALIZED)] == 0.0) {
        bq q;
        if (isfinite(speed)) {
            /* centripetal part of the vehicle's acceleration (v' unknown yet): w x (v, 0, 0) */
            ay = ay - gz * speed;
            az = az + gy * speed;
            fn = sqrt(ax * ax + ay * ay + az * az);
            if (!(fn > 0.0)) { ax = 0.0; ay = 0.0; az = 1.0; fn = 1.0; }
        }
        q = ref_vector(ax / fn, ay / fn, az / fn, mx, my, mz, mag_ok, 1.0, 0.0, 0.0, 0.0, c[C(CDH)], c[C(SDH)]);
        st[S(LAM)] = st[S(Q_I)] = q.w;
        st[S(LAM) + 1] = st[S(Q_I) + 1] = q.x;
        st[S(LAM) + 2] = st[S(Q_I) + 2] = q.y;
        st[S(LAM) + 3] = st[S(Q_I) + 3] = q.z;
    }
    st[S(INITIALIZED)] = 1.0;
    qi = bq_make(st[S(Q_I)], st[S(Q_I) + 1], st[S(Q_I) + 2], st[S(Q_I) + 3]);
    {
        bv f = acc_ok ? bq_rot(qi.w, qi.x, qi.y, qi.z, ax, ay, az) : bq_rot(qi.w, qi.x, qi.y, qi.z, 0.0, 0.0, c[C(G)]);
        st[S(ACCEL_LP_I)] = f.x; st[S(ACCEL_LP_I) + 1] = f.y; st[S(ACCEL_LP_I) + 2] = f.z;
    }
    r = bm_from_q(qi.w, qi.x, qi.y, qi.z);
    for (i = 0; i < 9; i++) st[S(ROT_LP) + i] = r.r[i];
    st[S(REST_GYRO_LP)] = st[S(GYRO_PREV)] = gx;
    st[S(REST_GYRO_LP) + 1] = st[S(GYRO_PREV) + 1] = gy;
    st[S(REST_GYRO_LP) + 2] = st[S(GYRO_PREV) + 2] = gz;
    st[S(REST_ACCEL_LP)] = acc_ok ? ax : 0.0;
    st[S(REST_ACCEL_LP) + 1] = acc_ok ? ay : 0.0;
    st[S(REST_ACCEL_LP) + 2] = acc_ok ? az : 0.0;
    st[S(SPEED_PREV)] = speed;
    st[S(SPEED_PREV_OK)] = isfinite(speed) ? 1.0 : 0.0;
    st[S(SPEED_HELD)] = isfinite(speed) ? speed : 0.0;
    st[S(FORWARD_ACCEL_LP)] = acc_ok ? ax : 0.0;
    st[S(LATERAL_ACCEL_LP)] = fy;
    st[S(LATERAL_SPEED_PREV)] = isfinite(speed) ? -c[C(REAR_SLIP)] * fabs(speed) * fy : 0.0;
}

/* ---- the per-sample update ------------------------------------------------------------- */

static void plus_update(const double *c, double *st, const biso_est_input *in, biso_est_output *out) {
    const double ax = in->accel_b[0], ay = in->accel_b[1], az = in->accel_b[2];
    const double mx = in->mag_b[0], my = in->mag_b[1], mz = in->mag_b[2];
    const double v = in->speed_mps;  /* NaN: not given or unknown (the same in the Python kernel) */
    int64_t flags;
    sample_checks chk = input_checks(in->gyro_b[0], in->gyro_b[1], in->gyro_b[2], ax, ay, az, mx, my, mz,
                                     st[S(GYRO_HOLD)], st[S(GYRO_HOLD) + 1], st[S(GYRO_HOLD) + 2], in->imu_flags,
                                     c[C(GYRO_RANGE)], c[C(ACCEL_RANGE)]);
    const double gx = chk.gx, gy = chk.gy, gz = chk.gz;
    st[S(GYRO_HOLD)] = gx; st[S(GYRO_HOLD) + 1] = gy; st[S(GYRO_HOLD) + 2] = gz;
    flags = chk.flags;

    if (st[S(INITIALIZED)] != 1.0) {  /* until initialised: the start */
        int i;
        if (st[S(INITIALIZED)] == 0.0 && !chk.acc_ok)
            flags |= BISO_EST_FLAG_UNINITIALIZED;
        else
            plus_start(c, st, gx, gy, gz, ax, ay, az, sqrt(chk.f2), mx, my, mz, chk.acc_ok, chk.mag_ok, v);
        out->flags = flags;
        for (i = 0; i < 4; i++) out->q_wb[i] = st[S(LAM) + i];
        for (i = 0; i < 3; i++) out->gyro_bias_b[i] = st[S(GYRO_BIAS_B) + i];
        return;
    }
    {
        /* ---- coefficients */
        const double h = c[C(H)], fs = c[C(FS)];
        const double a_acc = c[C(A_ACC)], a_accv = c[C(A_ACCV)], a_v = c[C(A_SPEED)], ar = c[C(A_REST)];
        const double af = c[C(A_FIELD)];
        const double dx = -c[C(R_V)], dy = -c[C(R_V) + 1], dz = -c[C(R_V) + 2];  /* d = -r_v */
        const double thw = c[C(REST_W)];
        const double thw2 = thw * thw, tha2 = c[C(REST_A)] * c[C(REST_A)];
        const double rest_n = c[C(REST_TIME)], rest_v = c[C(REST_V)];
        const double g = c[C(G)], inv_gate_g = c[C(INV_GATE_G)];
        const int offset_on = c[C(OFFSET_ON)] != 0.0;
        const double off_bias2 = c[C(OFFSET_BIAS2)], off_n = c[C(OFFSET_N)];
        const double inv_otest = c[C(INV_OFFSET_TEST)], off_shrink2 = c[C(OFFSET_SHRINK2)];
        const double c_bnorm = c[C(B_NORM)], c_dip = c[C(DIP)], c_dipc = c[C(DIP_C)], c_dips = c[C(DIP_S)];
        const int learn_norm = c_bnorm < 0.0, learn_dip = isnan(c_dip);
        const double btol = c[C(B_TOL)], cos_dtol = c[C(COS_DIP_TOL)], rej_n = c[C(REJECT_MAX)];
        /* (cos D, sin D): the horizontal field turned by -D */
        const double cd = c[C(CDH)] * c[C(CDH)] - c[C(SDH)] * c[C(SDH)];
        const double sd = 2.0 * c[C(SDH)] * c[C(CDH)];
        const double kt = c[C(K_T)], kh0 = c[C(K_H)], kp = c[C(K_P)], t0 = c[C(T0)];
        const double bp0 = c[C(BIAS_P0)], bv_ = c[C(BIAS_V)], bwm = c[C(BIAS_W_MOTION)];
        const double bwv = c[C(BIAS_W_VERTICAL)], bwr = c[C(BIAS_W_REST)], blim = c[C(BIAS_LIMIT)];
        const double bwvf = c[C(BIAS_W_VERTICAL_FREE)], dtol2 = c[C(DIP_TOL)] * c[C(DIP_TOL)];
        const double *bw = c + C(ACC_BW);
        const int bw_on = bw[0] != 0.0;
        const double inv_gate_free = c[C(INV_GATE_FREE_G)];
        const double r_head = c[C(R_HEAD)], kappa = c[C(KAPPA)], a_dist = c[C(A_DIST)], tau_m2 = c[C(TAU_M2)];
        const double slip_a = c[C(SLIP_ACCEL)], slip_hold = c[C(SLIP_HOLD)], rear_slip = c[C(REAR_SLIP)];
        const double lin2 = c[C(LINEAR_ACCEL2)], lin_hold = c[C(LINEAR_HOLD)];
        const int lin_on = lin2 > 0.0;

        /* ---- state */
        double lw, lx, ly, lz;
        double qiw = st[S(Q_I)], qix = st[S(Q_I) + 1], qiy = st[S(Q_I) + 2], qiz = st[S(Q_I) + 3];
        double qcw = st[S(Q_C)], qcx = st[S(Q_C) + 1], qcy = st[S(Q_C) + 2], qcz = st[S(Q_C) + 3];
        bias_kf b;
        double *pb = st + S(BIAS_COV);
        double *flp = st + S(ACCEL_LP_I), *rlp = st + S(ROT_LP), *rblp = st + S(ROT_BIAS_LP);
        double *wl = st + S(REST_GYRO_LP), *al = st + S(REST_ACCEL_LP);
        double rest_t = st[S(REST_TIME_S)], vprev = st[S(SPEED_PREV)], dvdt = st[S(DVDT)];
        double vok_prev = st[S(SPEED_PREV_OK)];
        double wpx = st[S(GYRO_PREV)], wpy = st[S(GYRO_PREV) + 1], wpz = st[S(GYRO_PREV) + 2];
        double wdx = st[S(ANGULAR_ACCEL_LP)], wdy = st[S(ANGULAR_ACCEL_LP) + 1], wdz = st[S(ANGULAR_ACCEL_LP) + 2];
        double ox = st[S(MAG_OFFSET_B)], oy = st[S(MAG_OFFSET_B) + 1], oz = st[S(MAG_OFFSET_B) + 2];
        double off_k = st[S(OFFSET_COUNT)], bnorm = st[S(FIELD_NORM)], dip = st[S(FIELD_DIP)];
        double field_ok = st[S(FIELD_KNOWN)], rej_t = st[S(MAG_REJECTED_S)];
        double dipc = st[S(FIELD_DIP_CS)], dips = st[S(FIELD_DIP_CS) + 1];
        double t = st[S(TIME_S)];
        double head_t = st[S(HEADING_START_S)], tcx = st[S(TILT_CORR_START)], tcy = st[S(TILT_CORR_START) + 1];
        double slip_t = st[S(SPEED_SLIP_S)], vheld = st[S(SPEED_HELD)], fxlp = st[S(FORWARD_ACCEL_LP)];
        double fylp = st[S(LATERAL_ACCEL_LP)], vyprev = st[S(LATERAL_SPEED_PREV)], dvydt = st[S(LATERAL_DVDT)];
        double lim_t = st[S(LINEAR_LIMIT_S)];
        double vu = v, a_fwd = 0.0;
        int slipping = 0, limited = 0;
        double tw;
        int head_start;
        double wx, wy, wz, comp_x = 0.0, comp_y = 0.0, comp_z = 0.0, ex = 0.0, ey = 0.0, ez = 0.0;
        double ux, uy, uz, kh, alpha, mag_w = 1.0;
        double *bs = st + S(ACCEL_BW_I);
        int v_ok, rest = 0, updated = 0, k;
        bq eb, q;
        bm r;
        b.bx = st[S(GYRO_BIAS_B)]; b.by = st[S(GYRO_BIAS_B) + 1]; b.bz = st[S(GYRO_BIAS_B) + 2];
        b.p00 = pb[0]; b.p01 = pb[1]; b.p02 = pb[2]; b.p11 = pb[4]; b.p12 = pb[5]; b.p22 = pb[8];
        t += h;

        /* ---- gyro: bias-corrected strapdown of q_I over the interval (held rate) */
        wx = gx - b.bx; wy = gy - b.by; wz = gz - b.bz;
        eb = qexp_fast(wx * h, wy * h, wz * h);
        q = unit_q(qiw, qix, qiy, qiz);
        q = bq_mul(q.w, q.x, q.y, q.z, eb.w, eb.x, eb.y, eb.z);
        qiw = q.w; qix = q.x; qiy = q.y; qiz = q.z;
        q = bq_mul(qcw, qcx, qcy, qcz, qiw, qix, qiy, qiz);
        lw = q.w; lx = q.x; ly = q.y; lz = q.z;

        /* ---- speed: acceleration of the IMU from the speed v of the point r_v of the vehicle */
        wdx += a_v * ((wx - wpx) * fs - wdx);
        wdy += a_v * ((wy - wpy) * fs - wdy);
        wdz += a_v * ((wz - wpz) * fs - wdz);
        wpx = wx; wpy = wy; wpz = wz;
        v_ok = isfinite(v);
        if (chk.acc_ok) {
            fxlp += a_v * (ax - fxlp);
            if (rear_slip != 0.0 || lin_on) fylp += a_v * (ay - fylp);
        }
        if (v_ok) {
            double vx_, vy_, vz_;
            if (vok_prev != 0.0) dvdt += a_v * ((v - vprev) * fs - dvdt);
            vprev = v;
            /* a wheel that does not roll on the road: its v' is not what the accelerometer feels */
            if (fabs(dvdt - fxlp) > slip_a) {
                slip_t = slip_hold;
                slipping = 1;
            } else if (slip_t > 0.0) {
                slip_t -= h;
                slipping = slip_t > 0.0;
            }
            if (slipping) {
                /* the vehicle's speed carried on by the IMU's forward acceleration f_x - g (R^T e_z)_x */
                a_fwd = chk.acc_ok ? ax - g * 2.0 * (lx * lz - lw * ly) : 0.0;
                vheld += h * a_fwd;
                vu = vheld;
                flags |= BISO_EST_FLAG_ACCEL_GATED;
            } else {
                vheld = v;
            }
            /* beyond the tyres' linear range (the horizontal specific force is the tyres' force per
               mass): the sideslip and the odometry are not the model's; the tilt is the gyro's */
            if (lin_on) {
                if (fxlp * fxlp + fylp * fylp > lin2) {
                    lim_t = lin_hold;
                    limited = 1;
                } else if (lim_t > 0.0) {
                    lim_t -= h;
                    limited = lim_t > 0.0;
                }
            }
            /* IMU velocity u = (v, v_y, 0) + w x d, d = -r_v; acceleration u' + w x u */
            vx_ = vu + wy * dz - wz * dy; vy_ = wz * dx - wx * dz; vz_ = wx * dy - wy * dx;
            if (rear_slip != 0.0) {
                /* the axle's sideslip: slip angle (D_r/g0) f_y (single-track model), outward of the bend */
                double vy = -rear_slip * fabs(vu) * fylp;
                if (vok_prev != 0.0) dvydt += a_v * ((vy - vyprev) * fs - dvydt);
                vyprev = vy;
                vy_ += vy;
            }
            if (slipping)  /* the estimate's own gravity along x: no say in the tilt */
                comp_x = a_fwd;
            else
                comp_x = dvdt + (wdy * dz - wdz * dy) + (wy * vz_ - wz * vy_);
            comp_y = (wdz * dx - wdx * dz) + (wz * vx_ - wx * vz_);
            if (rear_slip != 0.0) comp_y += dvydt;
            comp_z = (wdx * dy - wdy * dx) + (wx * vy_ - wy * vx_);
            flags |= BISO_EST_FLAG_ACCEL_COMPENSATED;
        }
        vok_prev = v_ok ? 1.0 : 0.0;

        /* ---- rest detection (steady gyro and accelerometer; with speed: standing still) */
        wl[0] = wl[0] + ar * (gx - wl[0]);
        wl[1] = wl[1] + ar * (gy - wl[1]);
        wl[2] = wl[2] + ar * (gz - wl[2]);
        if (chk.acc_ok) {
            double dw2, da2;
            int still;
            al[0] = al[0] + ar * (ax - al[0]);
            al[1] = al[1] + ar * (ay - al[1]);
            al[2] = al[2] + ar * (az - al[2]);
            dw2 = (gx - wl[0]) * (gx - wl[0]) + (gy - wl[1]) * (gy - wl[1]) + (gz - wl[2]) * (gz - wl[2]);
            da2 = (ax - al[0]) * (ax - al[0]) + (ay - al[1]) * (ay - al[1]) + (az - al[2]) * (az - al[2]);
            still = dw2 < thw2 && da2 < tha2;
            if (still) {
                /* not turning either: the bias-corrected rate within the threshold plus 3 sigma of the bias */
                double thr = thw + 3.0 * sqrt(py_max(py_max(b.p00, b.p11), b.p22));
                double rw2 = (wl[0] - b.bx) * (wl[0] - b.bx) + (wl[1] - b.by) * (wl[1] - b.by)
                             + (wl[2] - b.bz) * (wl[2] - b.bz);
                still = rw2 < thr * thr;
            }
            if (v_ok) still = still && fabs(vu) < rest_v;
            rest_t = still ? rest_t + h : 0.0;
            rest = rest_t >= rest_n;
        }
        if (rest) flags |= BISO_EST_FLAG_REST;

        /* ---- tilt error: low-pass of the (compensated) specific force in I, gated */
        if (chk.acc_ok) {
            double fx, fy, fz, fnorm, d, weight, ang;
            int start;
            bv fi, n;
            if (v_ok) {
                fx = ax - comp_x; fy = ay - comp_y; fz = az - comp_z;
                fnorm = sqrt(fx * fx + fy * fy + fz * fz);
            } else {
                fx = ax; fy = ay; fz = az; fnorm = sqrt(chk.f2);
            }
            d = fabs(fnorm - g) * (v_ok ? inv_gate_g : inv_gate_free);
            weight = 1.0 / (1.0 + d * d);
            if (limited) weight = 0.0;
            if (weight < 0.5) flags |= BISO_EST_FLAG_ACCEL_GATED;
            alpha = v_ok ? a_accv : a_acc;
            start = h > alpha * (t + h);
            if (start) alpha = h / (t + h);  /* start: a running mean (as VQF) */
            fi = bq_rot(qiw, qix, qiy, qiz, fx, fy, fz);
            if (bw_on && !(v_ok || start)) {
                /* second order, transposed direct form II (bs[0..2], bs[3..5]: the two delays per axis),
                 * entered from the first order's output at that output's steady state */
                double xi[3];
                if (st[S(ACCEL_BW_READY)] == 0.0) {
                    st[S(ACCEL_BW_READY)] = 1.0;
                    for (k = 0; k < 3; k++) {
                        bs[k] = (1.0 - bw[0]) * flp[k];
                        bs[3 + k] = (bw[2] - bw[4]) * flp[k];
                    }
                }
                xi[0] = fi.x; xi[1] = fi.y; xi[2] = fi.z;
                for (k = 0; k < 3; k++) {
                    double y;
                    if (weight < 1.0) xi[k] = flp[k] + weight * (xi[k] - flp[k]);  /* gated */
                    y = bw[0] * xi[k] + bs[k];
                    bs[k] = bw[1] * xi[k] - bw[3] * y + bs[3 + k];
                    bs[3 + k] = bw[2] * xi[k] - bw[4] * y;
                    flp[k] = y;
                }
            } else {
                st[S(ACCEL_BW_READY)] = 0.0;
                alpha *= weight;
                flp[0] = flp[0] + alpha * (fi.x - flp[0]);
                flp[1] = flp[1] + alpha * (fi.y - flp[1]);
                flp[2] = flp[2] + alpha * (fi.z - flp[2]);
            }
            n = bq_rot(qcw, qcx, qcy, qcz, flp[0], flp[1], flp[2]);
            ang = angle_over_sine(n.x * n.x + n.y * n.y, n.z);
            ex = n.y * ang; ey = -n.x * ang;  /* rotate about n x up by the angle between n and up */
        }

        /* ---- heading error from the magnetometer (offset removed), disturbance detection */
        if (chk.mag_ok) {
            double mh, norm, c0, s0, dcos, dsin;
            bv mw;
            if (offset_on && py_max(py_max(b.p00, b.p11), b.p22) < off_bias2) {
                off_k += 1.0;
                if (off_k >= off_n) {
                    off_k = 0.0;
                    st[S(Q_I)] = qiw; st[S(Q_I) + 1] = qix; st[S(Q_I) + 2] = qiy; st[S(Q_I) + 3] = qiz;
                    offset_update(c, st, mx, my, mz);
                    ox = st[S(MAG_OFFSET_B)]; oy = st[S(MAG_OFFSET_B) + 1]; oz = st[S(MAG_OFFSET_B) + 2];
                }
            }
            if (inv_otest != 0.0 && offset_on && !v_ok) {
                /* the offset's norm test (without a speed input): the variances of |m - o| and |m| about their means, low-passed
                 * over the last Theta_o of rotation (alpha = |w| h / Theta_o); o used only while it makes
                 * the norm steadier */
                double a_ot = py_min(1.0, sqrt(wx * wx + wy * wy + wz * wz) * h * inv_otest);
                double n0 = sqrt(mx * mx + my * my + mz * mz);
                double dmx = mx - ox, dmy = my - oy, dmz = mz - oz;
                double n1 = sqrt(dmx * dmx + dmy * dmy + dmz * dmz), d0, d1;
                double *ot = st + S(OFFSET_NORM_TEST);
                if (ot[0] == 0.0) {  /* the first field: both means from it */
                    ot[0] = n1;
                    ot[2] = n0;
                }
                ot[0] += a_ot * (n1 - ot[0]);
                d1 = n1 - ot[0];
                ot[1] += a_ot * (d1 * d1 - ot[1]);
                ot[2] += a_ot * (n0 - ot[2]);
                d0 = n0 - ot[2];
                ot[3] += a_ot * (d0 * d0 - ot[3]);
                if (ot[1] < ot[3]) {
                    if (off_shrink2 > 0.0) {  /* shrunk toward 0 by |o|^2/(|o|^2 + sigma_s^2) */
                        double o2 = ox * ox + oy * oy + oz * oz;
                        double sh = o2 / (o2 + off_shrink2);
                        dmx = mx - sh * ox;
                        dmy = my - sh * oy;
                        dmz = mz - sh * oz;
                    }
                    mw = bq_rot(lw, lx, ly, lz, dmx, dmy, dmz);
                } else
                    mw = bq_rot(lw, lx, ly, lz, mx, my, mz);
            } else {
                mw = bq_rot(lw, lx, ly, lz, mx - ox, my - oy, mz - oz);
            }
            mh = sqrt(mw.x * mw.x + mw.y * mw.y);
            norm = sqrt(mh * mh + mw.z * mw.z);
            if (field_ok == 2.0 && tcx * tcx + tcy * tcy > dtol2) {
                /* provisional, and the tilt corrected by more than theta_delta since: learn the
                 * field and the heading again */
                field_ok = 0.0;
                head_t = t;
                tcx = tcy = 0.0;
            }
            if (field_ok == 0.0) {
                bnorm = learn_norm ? norm : c_bnorm;
                if (learn_dip) {
                    dip = atan2(-mw.z, mh);
                    if (norm > 0.0) { dipc = mh / norm; dips = -mw.z / norm; }
                    else { dipc = 1.0; dips = 0.0; }
                } else {
                    dip = c_dip; dipc = c_dipc; dips = c_dips;
                }
                field_ok = t >= t0 ? 1.0 : 2.0;  /* learned before the tilt settled: provisional */
            }
            /* the dip against the expected one: norm (cos, sin)(delta_m - delta) */
            c0 = dipc; s0 = dips;
            dcos = mh * c0 - mw.z * s0;
            dsin = -mw.z * c0 - mh * s0;
            if (!v_ok) {
                /* the heading's weight sigma_h^2 / (sigma_h^2 + kappa D + (|B| |w| tau_m)^2),
                 * D = LP[(|m - o| - |B|)^2] */
                double dn = norm - bnorm;
                st[S(MAG_DISTURBANCE)] += a_dist * (dn * dn - st[S(MAG_DISTURBANCE)]);
                mag_w = r_head / (r_head + kappa * st[S(MAG_DISTURBANCE)]
                                  + bnorm * bnorm * (wx * wx + wy * wy + wz * wz) * tau_m2);
            }
            if (fabs(norm - bnorm) > btol * bnorm || dcos < cos_dtol * norm) {
                flags |= BISO_EST_FLAG_MAG_DISTURBED;
                rej_t += h;
                /* disturbed for too long, or a provisional field: take this as the new field */
                if (rej_t > rej_n || field_ok == 2.0) {
                    if (field_ok == 2.0) {  /* and the heading of the start with it */
                        head_t = t;
                        tcx = tcy = 0.0;
                    }
                    field_ok = 0.0;
                    rej_t = 0.0;
                }
            } else {
                rej_t = 0.0;
                if (field_ok == 2.0 && t >= t0) field_ok = 1.0;  /* passed with the settled tilt */
                if (learn_norm) bnorm += af * (norm - bnorm);
                if (learn_dip) {  /* delta += alpha (delta_m - delta), and (cos, sin) turned with it */
                    double e = af * atan2_fast(dsin, dcos);
                    double ce = 1.0 - 0.5 * e * e, se = e * (1.0 - e * e * (1.0 / 6.0));
                    dip += e;
                    dipc = c0 * ce - s0 * se;
                    dips = s0 * ce + c0 * se;
                }
                if (mh > 0.0)  /* the field's azimuth minus D */
                    ez = atan2_fast(mw.x * cd - mw.y * sd, mw.y * cd + mw.x * sd);
            }
        }

        /* ---- the correction w_c = K e + k_p n x e as a rotation of q_c (world frame) */
        kh = kh0;
        /* start: heading follows the settling tilt, k_h = max(k_h, 1/(t - t_h + t_w)); t_w = t0 from
         * t_h = 0, one sample from a t_h > 0 (a provisional field replaced) */
        tw = head_t == 0.0 ? t0 : h;
        head_start = kh * ((t - head_t) + tw) < 1.0;
        if (head_start) kh = 1.0 / ((t - head_t) + tw);
        if (mag_w != 1.0) kh *= mag_w;
        if (kp == 0.0) {
            ux = kt * ex; uy = kt * ey; uz = kh * ez;
        } else {
            ux = kt * ex + kp * (ez - ey);
            uy = kt * ey + kp * (ex - ez);
            uz = kh * ez + kp * (ey - ex);
        }
        if (field_ok == 2.0) {  /* the tilt correction since the provisional field was learned */
            tcx += ux * h;
            tcy += uy * h;
        }
        if (ux != 0.0 || uy != 0.0 || uz != 0.0) {
            bq dq = qexp_fast(ux * h, uy * h, uz * h);
            q = unit_q(qcw, qcx, qcy, qcz);
            q = bq_mul(dq.w, dq.x, dq.y, dq.z, q.w, q.x, q.y, q.z);
            qcw = q.w; qcx = q.x; qcy = q.y; qcz = q.z;
            q = bq_mul(qcw, qcx, qcy, qcz, qiw, qix, qiy, qiz);
            lw = q.w; lx = q.x; ly = q.y; lz = q.z;
        }

        /* ---- gyro bias: Kalman filter (VQF): the correction rate seen through the tilt low-pass */
        if (b.p00 < bp0) b.p00 += bv_;
        if (b.p11 < bp0) b.p11 += bv_;
        if (b.p22 < bp0) b.p22 += bv_;
        r = bm_from_q(lw, lx, ly, lz);  /* body -> world */
        alpha = v_ok ? a_accv : a_acc;
        for (k = 0; k < 9; k++) rlp[k] = rlp[k] + alpha * (r.r[k] - rlp[k]);
        rblp[0] = rblp[0] + alpha * ((r.r[0] * b.bx + r.r[1] * b.by + r.r[2] * b.bz) - rblp[0]);
        rblp[1] = rblp[1] + alpha * ((r.r[3] * b.bx + r.r[4] * b.by + r.r[5] * b.bz) - rblp[1]);
        rblp[2] = rblp[2] + alpha * ((r.r[6] * b.bx + r.r[7] * b.by + r.r[8] * b.bz) - rblp[2]);
        if (rest) {
            static const double eye[9] = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
            updated = bias_update(&b, eye, wl[0] - b.bx, wl[1] - b.by, wl[2] - b.bz, bwr, bwr, bwr, blim);
        } else if (chk.acc_ok && t > t0) {  /* not during the start, while the low-pass settles */
            double e0 = rblp[0] - (rlp[0] * b.bx + rlp[1] * b.by + rlp[2] * b.bz) - ux;
            double e1 = rblp[1] - (rlp[3] * b.bx + rlp[4] * b.by + rlp[5] * b.bz) - uy;
            double e2 = rblp[2] - (rlp[6] * b.bx + rlp[7] * b.by + rlp[8] * b.bz) - uz;
            double wv;
            if (v_ok) wv = ez != 0.0 ? bwv : bwv * 1e6;
            else  /* the heading's variance (1/mag_w), and not its start's convergence */
                wv = ez != 0.0 && !head_start ? bwvf / mag_w : bwvf * 1e6;
            updated = bias_update(&b, rlp, e0, e1, e2, bwm, bwm, wv, blim);
        }
        q = unit_q(lw, lx, ly, lz);

        /* ---- locals back into the state */
        st[S(LAM)] = q.w; st[S(LAM) + 1] = q.x; st[S(LAM) + 2] = q.y; st[S(LAM) + 3] = q.z;
        st[S(Q_I)] = qiw; st[S(Q_I) + 1] = qix; st[S(Q_I) + 2] = qiy; st[S(Q_I) + 3] = qiz;
        st[S(Q_C)] = qcw; st[S(Q_C) + 1] = qcx; st[S(Q_C) + 2] = qcy; st[S(Q_C) + 3] = qcz;
        st[S(GYRO_BIAS_B)] = b.bx; st[S(GYRO_BIAS_B) + 1] = b.by; st[S(GYRO_BIAS_B) + 2] = b.bz;
        pb[0] = b.p00; pb[1] = b.p01; pb[2] = b.p02; pb[4] = b.p11; pb[5] = b.p12; pb[8] = b.p22;
        if (updated) { pb[3] = b.p01; pb[6] = b.p02; pb[7] = b.p12; }
        st[S(REST_TIME_S)] = rest_t; st[S(SPEED_PREV)] = vprev; st[S(DVDT)] = dvdt; st[S(SPEED_PREV_OK)] = vok_prev;
        st[S(GYRO_PREV)] = wpx; st[S(GYRO_PREV) + 1] = wpy; st[S(GYRO_PREV) + 2] = wpz;
        st[S(ANGULAR_ACCEL_LP)] = wdx; st[S(ANGULAR_ACCEL_LP) + 1] = wdy; st[S(ANGULAR_ACCEL_LP) + 2] = wdz;
        st[S(OFFSET_COUNT)] = off_k; st[S(FIELD_NORM)] = bnorm; st[S(FIELD_DIP)] = dip;
        st[S(FIELD_KNOWN)] = field_ok; st[S(MAG_REJECTED_S)] = rej_t;
        st[S(HEADING_START_S)] = head_t; st[S(TILT_CORR_START)] = tcx; st[S(TILT_CORR_START) + 1] = tcy;
        st[S(FIELD_DIP_CS)] = dipc; st[S(FIELD_DIP_CS) + 1] = dips;
        st[S(TIME_S)] = t;
        st[S(SPEED_SLIP_S)] = slip_t; st[S(SPEED_HELD)] = vheld; st[S(FORWARD_ACCEL_LP)] = fxlp;
        st[S(LATERAL_ACCEL_LP)] = fylp; st[S(LATERAL_SPEED_PREV)] = vyprev; st[S(LATERAL_DVDT)] = dvydt;
        st[S(LINEAR_LIMIT_S)] = lim_t;
        out->q_wb[0] = q.w; out->q_wb[1] = q.x; out->q_wb[2] = q.y; out->q_wb[3] = q.z;
        out->flags = flags;
        out->gyro_bias_b[0] = b.bx; out->gyro_bias_b[1] = b.by; out->gyro_bias_b[2] = b.bz;
    }
}

const biso_est_family biso_est_family_biso_plus = {
    plus_coefficients, plus_initial_state, plus_update, BISO_EST_BISO_PLUS_STATE_SIZE,
    BISO_EST_BISO_PLUS_COEF_SIZE, BISO_EST_BISO_PLUS_S_GYRO_BIAS_B, 1,
};
