/* BisoEstimator's model: gyro, accelerometer, magnetometer (and speed, sensor flags) in,
 * attitude out. Timing (as the Python FMU had it): a communication step of n/fs_hz seconds
 * feeds the inputs set at its start to the estimator n times (sample and hold), so with
 * steps of 1/fs_hz the output after step i is the estimate of sample i. Non-finite,
 * absurd or flagged samples go to the estimator like any other: it flags them and goes on
 * (estimate.flags), as the Python estimator does. */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "fmu_core.h"
#include "fmu_estimate.h"

void model_start(biso_instance *inst) {
    biso_est_output out;
    /* before initialization the outputs hold their start values (identity, uninitialized) */
    memset(&out, 0, sizeof out);
    out.q_wb[0] = 1.0;
    out.flags = BISO_EST_FLAG_UNINITIALIZED;
    biso_put_estimate(inst, &out);
}

int model_check_real(biso_instance *inst, const biso_var_info *v, double value, char *msg, size_t len) {
    (void)inst;
    if (strcmp(v->name, "fs_hz") == 0 && !(value > 0.0)) {
        snprintf(msg, len, "allowed > 0 Hz, got %.17g", value);
        return 1;
    }
    return 0;
}

int model_check_string(biso_instance *inst, const biso_var_info *v, const char *value, char *msg, size_t len) {
    (void)inst;
    (void)v;
    (void)value;
    (void)msg;
    (void)len;
    return 0;
}

int model_configure(biso_instance *inst, char *msg, size_t len) {
    biso_model *m = &inst->core.model;
    const double *r = inst->core.real;
    double params[BISO_EST_MAX_PARAMS];
    biso_est_output out;
    int others;
    m->kind = biso_estimator_kind(inst);
    others = biso_estimator_params(inst, m->kind, params);
    if (biso_est_init(&m->est, m->kind, r[R_FS_HZ], params, msg, len) != 0) return 1;
    if (others)
        biso_log(inst, BISO_WARNING, "%d parameter(s) of estimators other than %s were set: ignored", others,
                 biso_est_kind_name(m->kind));
    m->use_speed = inst->core.boolean[B_USE_SPEED];
    if (m->use_speed && !(biso_est_inputs(m->kind) & BISO_EST_INPUT_SPEED_MPS)) {
        snprintf(msg, len, "use_speed: estimator '%s' takes no speed input (only biso_plus does)",
                 biso_est_kind_name(m->kind));
        return 1;
    }
    m->mounted = r[R_MOUNTING_ROLL] != 0.0 || r[R_MOUNTING_PITCH] != 0.0 || r[R_MOUNTING_YAW] != 0.0;
    if (m->mounted) {
        double q[4], n[4];
        biso_q_from_euler(r[R_MOUNTING_ROLL], r[R_MOUNTING_PITCH], r[R_MOUNTING_YAW], q);
        biso_q_normalize(q, n); /* frames.quat_to_matrix */
        m->r_bs[0][0] = 1.0 - 2.0 * (n[2] * n[2] + n[3] * n[3]);
        m->r_bs[0][1] = 2.0 * (n[1] * n[2] - n[0] * n[3]);
        m->r_bs[0][2] = 2.0 * (n[1] * n[3] + n[0] * n[2]);
        m->r_bs[1][0] = 2.0 * (n[1] * n[2] + n[0] * n[3]);
        m->r_bs[1][1] = 1.0 - 2.0 * (n[1] * n[1] + n[3] * n[3]);
        m->r_bs[1][2] = 2.0 * (n[2] * n[3] - n[0] * n[1]);
        m->r_bs[2][0] = 2.0 * (n[1] * n[3] - n[0] * n[2]);
        m->r_bs[2][1] = 2.0 * (n[2] * n[3] + n[0] * n[1]);
        m->r_bs[2][2] = 1.0 - 2.0 * (n[1] * n[1] + n[2] * n[2]);
    }
    biso_est_peek(&m->est, &out);
    biso_put_estimate(inst, &out);
    return 0;
}

int model_apply_tunables(biso_instance *inst, char *msg, size_t len) {
    biso_model *m = &inst->core.model;
    double params[BISO_EST_MAX_PARAMS];
    if (biso_estimator_params(inst, m->kind, params))
        biso_log(inst, BISO_WARNING, "parameters of estimators other than %s: ignored", biso_est_kind_name(m->kind));
    return biso_est_set_params(&m->est, params, msg, len) != 0;
}

static void rotate(const double r[3][3], const double *v, double *out) {
    int i;
    for (i = 0; i < 3; i++) out[i] = r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2];
}

void model_derive_outputs(biso_instance *inst) { biso_derive_estimate(inst); }

int model_step(biso_instance *inst, double t, double h, char *msg, size_t len) {
    biso_model *m = &inst->core.model;
    const double *r = inst->core.real;
    double fs = m->est.fs_hz, n_float = h * fs, n = nearbyint(n_float);
    biso_est_input in;
    biso_est_output out;
    long i;
    (void)t;
    if (n < 1.0 || fabs(n_float - n) > 1e-6) {
        snprintf(msg, len, "the communication step %.17g s is not a whole number of sample periods (1/fs_hz = "
                 "%.17g s); allowed steps: n * %.17g s for n = 1, 2, 3, ...", h, 1.0 / fs, 1.0 / fs);
        return BISO_ERROR;
    }
    memset(&in, 0, sizeof in);
    if (m->mounted) {
        double v[3];
        v[0] = r[R_GYRO_S_X], v[1] = r[R_GYRO_S_Y], v[2] = r[R_GYRO_S_Z];
        rotate(m->r_bs, v, in.gyro_b);
        v[0] = r[R_ACCEL_S_X], v[1] = r[R_ACCEL_S_Y], v[2] = r[R_ACCEL_S_Z];
        rotate(m->r_bs, v, in.accel_b);
        v[0] = r[R_MAG_S_X], v[1] = r[R_MAG_S_Y], v[2] = r[R_MAG_S_Z];
        rotate(m->r_bs, v, in.mag_b);
    } else {
        in.gyro_b[0] = r[R_GYRO_S_X], in.gyro_b[1] = r[R_GYRO_S_Y], in.gyro_b[2] = r[R_GYRO_S_Z];
        in.accel_b[0] = r[R_ACCEL_S_X], in.accel_b[1] = r[R_ACCEL_S_Y], in.accel_b[2] = r[R_ACCEL_S_Z];
        in.mag_b[0] = r[R_MAG_S_X], in.mag_b[1] = r[R_MAG_S_Y], in.mag_b[2] = r[R_MAG_S_Z];
    }
    in.speed_mps = m->use_speed ? r[R_SPEED] : NAN; /* NaN: no speed, as when the input is not given */
    in.imu_flags = inst->core.integer[I_IMU_FLAGS];
    for (i = 0; i < (long)n; i++) biso_est_update(&m->est, &in, &out);
    biso_put_estimate(inst, &out);
    return BISO_OK;
}
