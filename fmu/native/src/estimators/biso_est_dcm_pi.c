/* dcm_pi: DCM with proportional-integral drift correction, Premerlani W., Bizard P. (2009),
 * "Direction Cosine Matrix IMU: Theory" (Aleshkin et al. 2024, ref. [8]): R <- R (I + [w_c h]x)
 * (their eq. 17), renormalisation (eqs. 18-21), PI correction w_c = w + k_P e + w_I
 * (eqs. 25-27). Port of biso_cosim/estimators/dcm_pi.py (dcm_pi_coefficients and one
 * sample of _dcm_batch). */
#include <math.h>
#include <string.h>

#include "biso_est_internal.h"
#include "biso_est_kernels.h"

#define P(name) BISO_EST_DCM_PI_P_##name
#define C(name) BISO_EST_DCM_PI_C_##name
#define S(name) BISO_EST_DCM_PI_S_##name

static int dcm_coefficients(const char *kind, const double *p, double fs_hz, double *c, char *msg, size_t size) {
    double d = p[P(DECLINATION_RAD)];
    (void)kind; (void)msg; (void)size;  /* every value is checked on its own (its range) */
    memset(c, 0, BISO_EST_DCM_PI_COEF_SIZE * sizeof(double));
    c[C(H)] = 1.0 / fs_hz;
    c[C(KP_RP)] = p[P(KP_RP)];
    c[C(KI_RP)] = p[P(KI_RP)];
    c[C(KP_YAW)] = p[P(KP_YAW)];
    c[C(KI_YAW)] = p[P(KI_YAW)];
    c[C(I_LIMIT)] = p[P(INTEGRAL_LIMIT_RAD_S)];
    c[C(G)] = p[P(GRAVITY_MPS2)];
    c[C(SD)] = sin(d);
    c[C(CD)] = cos(d);
    c[C(CDH)] = cos(0.5 * d);
    c[C(SDH)] = sin(0.5 * d);
    c[C(GYRO_LIMIT)] = isnan(p[P(GYRO_RANGE_RAD_S)]) ? HUGE_VAL
                                                     : BISO_EST_K_SATURATION_FRACTION * p[P(GYRO_RANGE_RAD_S)];
    c[C(ACCEL_LIMIT)] = isnan(p[P(ACCEL_RANGE_MPS2)]) ? HUGE_VAL
                                                      : BISO_EST_K_SATURATION_FRACTION * p[P(ACCEL_RANGE_MPS2)];
    return 0;
}

static void dcm_initial_state(const double *p, const double *q0, double *st) {
    (void)p;
    memset(st, 0, BISO_EST_DCM_PI_STATE_SIZE * sizeof(double));
    st[S(LAM)] = 1.0;
    st[S(DCM)] = st[S(DCM) + 4] = st[S(DCM) + 8] = 1.0;
    if (q0 != NULL) {
        bm r = bm_from_q(q0[0], q0[1], q0[2], q0[3]);
        st[S(INITIALIZED)] = 2.0;
        memcpy(st + S(LAM), q0, 4 * sizeof(double));
        memcpy(st + S(DCM), r.r, 9 * sizeof(double));
    }
}

static void dcm_update(const double *c, double *st, const biso_est_input *in, biso_est_output *out) {
    const double h = c[C(H)];
    const double kprp = c[C(KP_RP)], kirp = c[C(KI_RP)], kpy = c[C(KP_YAW)], kiy = c[C(KI_YAW)];
    const double lim = c[C(I_LIMIT)], g0 = c[C(G)], sd = c[C(SD)], cd = c[C(CD)];
    const double ax = in->accel_b[0], ay = in->accel_b[1], az = in->accel_b[2];
    const double mx = in->mag_b[0], my = in->mag_b[1], mz = in->mag_b[2];
    double init = st[S(INITIALIZED)];
    double lw = st[S(LAM)], lx = st[S(LAM) + 1], ly = st[S(LAM) + 2], lz = st[S(LAM) + 3];
    /* rows of R (body -> world): (r0, r1, r2) east, (r3, r4, r5) north, (r6, r7, r8) up, in body axes */
    double *r = st + S(DCM);
    double wix = st[S(OMEGA_I)], wiy = st[S(OMEGA_I) + 1], wiz = st[S(OMEGA_I) + 2];
    int64_t flags;
    sample_checks chk = input_checks(in->gyro_b[0], in->gyro_b[1], in->gyro_b[2], ax, ay, az, mx, my, mz,
                                     st[S(GYRO_HOLD)], st[S(GYRO_HOLD) + 1], st[S(GYRO_HOLD) + 2], in->imu_flags,
                                     c[C(GYRO_LIMIT)], c[C(ACCEL_LIMIT)]);
    st[S(GYRO_HOLD)] = chk.gx; st[S(GYRO_HOLD) + 1] = chk.gy; st[S(GYRO_HOLD) + 2] = chk.gz;
    flags = chk.flags;
    if (init == 0.0 && chk.acc_ok) {  /* the first valid sample: R from the accelerometer and magnetometer */
        bq q = ref_triad(ax, ay, az, chk.f2, chk.ex, chk.ey, chk.ez, chk.e2, chk.mag_ok, 1.0, 0.0, 0.0, 0.0,
                         c[C(CDH)], c[C(SDH)]);
        bm m = bm_from_q(q.w, q.x, q.y, q.z);
        lw = q.w; lx = q.x; ly = q.y; lz = q.z;
        memcpy(r, m.r, 9 * sizeof(double));
        init = 1.0;
    } else if (init == 0.0) {
        flags |= BISO_EST_FLAG_UNINITIALIZED;
    } else if (init == 2.0) {  /* q0 from reset(): the attitude at this sample */
        init = 1.0;
    } else {
        double px = 0.0, py = 0.0, pz = 0.0;  /* w_P = K_P e (body axes) */
        double ix = 0.0, iy = 0.0, iz = 0.0;  /* K_I e */
        double wx, wy, wz, n0, n1, n2, n3, n4, n5, err, x0, x1, x2, y0, y1, y2, z0, z1, z2, sx, sy_, sz;
        bq q;
        if (chk.acc_ok) {
            /* roll-pitch error f^ x r_z, weighted by the closeness of |f| to g */
            double fn = sqrt(chk.f2);
            double wgt = py_min(py_max(1.0 - 2.0 * fabs(1.0 - fn / g0), 0.0), 1.0);
            double fx = ax / fn, fy = ay / fn, fz = az / fn;
            double ux = wgt * (fy * r[8] - fz * r[7]);
            double uy = wgt * (fz * r[6] - fx * r[8]);
            double uz = wgt * (fx * r[7] - fy * r[6]);
            px = kprp * ux; py = kprp * uy; pz = kprp * uz;
            ix = kirp * ux; iy = kirp * uy; iz = kirp * uz;
        }
        if (chk.mag_ok) {
            /* field in world axes; its horizontal direction against magnetic north (sin D, cos D) */
            double we = r[0] * mx + r[1] * my + r[2] * mz;
            double wn = r[3] * mx + r[4] * my + r[5] * mz;
            double hn = sqrt(we * we + wn * wn);
            if (hn > 0.0) {
                /* sine of the turn about Up (r_z in body axes) that brings the field to D */
                double sy = (we * cd - wn * sd) / hn;
                px = px + kpy * sy * r[6]; py = py + kpy * sy * r[7]; pz = pz + kpy * sy * r[8];
                ix = ix + kiy * sy * r[6]; iy = iy + kiy * sy * r[7]; iz = iz + kiy * sy * r[8];
            }
        }
        wix = py_min(py_max(wix + ix * h, -lim), lim);
        wiy = py_min(py_max(wiy + iy * h, -lim), lim);
        wiz = py_min(py_max(wiz + iz * h, -lim), lim);
        wx = (chk.gx + px + wix) * h; wy = (chk.gy + py + wiy) * h; wz = (chk.gz + pz + wiz) * h;
        /* R <- R (I + [w]x), then the renormalisation of P&B eqs. 18-21 on the rows X, Y */
        n0 = r[0] + r[1] * wz - r[2] * wy; n1 = r[1] + r[2] * wx - r[0] * wz; n2 = r[2] + r[0] * wy - r[1] * wx;
        n3 = r[3] + r[4] * wz - r[5] * wy; n4 = r[4] + r[5] * wx - r[3] * wz; n5 = r[5] + r[3] * wy - r[4] * wx;
        err = n0 * n3 + n1 * n4 + n2 * n5;
        x0 = n0 - 0.5 * err * n3; x1 = n1 - 0.5 * err * n4; x2 = n2 - 0.5 * err * n5;
        y0 = n3 - 0.5 * err * n0; y1 = n4 - 0.5 * err * n1; y2 = n5 - 0.5 * err * n2;
        z0 = x1 * y2 - x2 * y1; z1 = x2 * y0 - x0 * y2; z2 = x0 * y1 - x1 * y0;
        sx = 0.5 * (3.0 - (x0 * x0 + x1 * x1 + x2 * x2));
        sy_ = 0.5 * (3.0 - (y0 * y0 + y1 * y1 + y2 * y2));
        sz = 0.5 * (3.0 - (z0 * z0 + z1 * z1 + z2 * z2));
        r[0] = x0 * sx; r[1] = x1 * sx; r[2] = x2 * sx;
        r[3] = y0 * sy_; r[4] = y1 * sy_; r[5] = y2 * sy_;
        r[6] = z0 * sz; r[7] = z1 * sz; r[8] = z2 * sz;
        q = bq_from_mat(r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8]);
        if (q.w * lw + q.x * lx + q.y * ly + q.z * lz < 0.0) {  /* keep the quaternion's sign continuous */
            q.w = -q.w; q.x = -q.x; q.y = -q.y; q.z = -q.z;
        }
        lw = q.w; lx = q.x; ly = q.y; lz = q.z;
    }
    st[S(INITIALIZED)] = init;
    st[S(LAM)] = lw; st[S(LAM) + 1] = lx; st[S(LAM) + 2] = ly; st[S(LAM) + 3] = lz;
    st[S(OMEGA_I)] = wix; st[S(OMEGA_I) + 1] = wiy; st[S(OMEGA_I) + 2] = wiz;
    out->q_wb[0] = lw; out->q_wb[1] = lx; out->q_wb[2] = ly; out->q_wb[3] = lz;
    out->flags = flags;
    out->gyro_bias_b[0] = -wix; out->gyro_bias_b[1] = -wiy; out->gyro_bias_b[2] = -wiz;
}

const biso_est_family biso_est_family_dcm_pi = {
    dcm_coefficients, dcm_initial_state, dcm_update, BISO_EST_DCM_PI_STATE_SIZE, BISO_EST_DCM_PI_COEF_SIZE,
    BISO_EST_DCM_PI_S_OMEGA_I, -1,
};
