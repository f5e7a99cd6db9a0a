/* The estimator side both native FMUs share: see fmu_estimate.h. */
#include "fmu_estimate.h"

#include <math.h>
#include <string.h>

#define PI 3.141592653589793

int biso_estimator_kind(biso_instance *inst) {
    int i;
    for (i = 0; i < BISO_N_VARS; i++)
        if (biso_vars[i].role == BISO_ROLE_ESTIMATOR) return biso_est_kind(inst->core.string[biso_vars[i].slot]);
    return -1;
}

int biso_estimator_params(biso_instance *inst, int kind, double *params) {
    const char *name = biso_est_kind_name(kind);
    const biso_core *c = &inst->core;
    int i, others = 0;
    biso_est_params_default(kind, params);
    for (i = 0; i < BISO_N_VARS; i++) {
        const biso_var_info *v = &biso_vars[i];
        int index;
        double value;
        if (v->role != BISO_ROLE_PARAM) continue;
        if (strcmp(v->param_kind, name) != 0) {
            switch (v->type) {
            case BISO_REAL: others += c->real[v->slot] != v->start_real; break;
            case BISO_INTEGER: others += c->integer[v->slot] != v->start_int; break;
            case BISO_BOOLEAN: others += c->boolean[v->slot] != v->start_int; break;
            default: others += strcmp(c->string[v->slot], v->start_string) != 0; break;
            }
            continue;
        }
        index = biso_est_param_find(kind, v->param_name);
        if (index < 0) continue; /* a Python-only parameter (none is generated) */
        switch (v->type) {
        case BISO_REAL: value = c->real[v->slot]; break;
        case BISO_INTEGER: value = (double)c->integer[v->slot]; break;
        case BISO_BOOLEAN: value = c->boolean[v->slot] ? 1.0 : 0.0; break;
        default: value = (double)biso_est_choice_find(biso_est_param_at(kind, index), c->string[v->slot]); break;
        }
        if (v->given_slot >= 0 && !c->boolean[v->given_slot]) value = NAN; /* None */
        params[index] = value;
    }
    return others;
}

void biso_q_from_euler(double roll, double pitch, double yaw, double q[4]) {
    double cr = cos(0.5 * roll), sr = sin(0.5 * roll);
    double cp = cos(0.5 * pitch), sp = sin(0.5 * pitch);
    double cy = cos(0.5 * yaw), sy = sin(0.5 * yaw);
    q[0] = cy * cp * cr + sy * sp * sr;
    q[1] = cy * cp * sr - sy * sp * cr;
    q[2] = cy * sp * cr + sy * cp * sr;
    q[3] = sy * cp * cr - cy * sp * sr;
}

void biso_q_normalize(const double q[4], double out[4]) {
    double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    out[0] = q[0] / n;
    out[1] = q[1] / n;
    out[2] = q[2] / n;
    out[3] = q[3] / n;
}

void biso_euler_from_q(const double q[4], double *roll, double *pitch, double *yaw) {
    double w = q[0], x = q[1], y = q[2], z = q[3];
    double r20 = 2.0 * (x * z - w * y), r21 = 2.0 * (y * z + w * x), r22 = 1.0 - 2.0 * (x * x + y * y);
    double r10 = 2.0 * (x * y + w * z), r00 = 1.0 - 2.0 * (y * y + z * z);
    double cos_pitch = sqrt(r00 * r00 + r10 * r10);
    *pitch = atan2(-r20, cos_pitch);
    if (cos_pitch < 1e-9) { /* gimbal lock: roll 0 */
        double r01 = 2.0 * (x * y - w * z), r11 = 1.0 - 2.0 * (x * x + z * z);
        *roll = 0.0;
        *yaw = atan2(-r01, r11);
        return;
    }
    *roll = atan2(r21, r22);
    *yaw = atan2(r10, r00);
}

double biso_py_mod(double a, double b) {
    double m = fmod(a, b);
    if (m != 0.0) {
        if ((b < 0.0) != (m < 0.0)) m += b;
    } else {
        m = copysign(0.0, b);
    }
    return m;
}

double biso_heading(double yaw) {
    double h = biso_py_mod(0.5 * PI - yaw, 2.0 * PI);
    return h >= 2.0 * PI ? 0.0 : h;
}

void biso_derive_estimate(biso_instance *inst) {
    double *r = inst->core.real;
    double q[4], roll, pitch, yaw;
    q[0] = r[R_ESTIMATE_Q_WB_W], q[1] = r[R_ESTIMATE_Q_WB_X], q[2] = r[R_ESTIMATE_Q_WB_Y], q[3] = r[R_ESTIMATE_Q_WB_Z];
    biso_euler_from_q(q, &roll, &pitch, &yaw);
    r[R_ESTIMATE_ROLL] = roll;
    r[R_ESTIMATE_PITCH] = pitch;
    r[R_ESTIMATE_YAW] = yaw;
    r[R_ESTIMATE_HEADING] = biso_heading(yaw);
}

void biso_put_estimate(biso_instance *inst, const biso_est_output *out) {
    double *r = inst->core.real;
    r[R_ESTIMATE_Q_WB_W] = out->q_wb[0];
    r[R_ESTIMATE_Q_WB_X] = out->q_wb[1];
    r[R_ESTIMATE_Q_WB_Y] = out->q_wb[2];
    r[R_ESTIMATE_Q_WB_Z] = out->q_wb[3];
    inst->core.derived_stale = 1;
    inst->core.integer[I_ESTIMATE_FLAGS] = (int32_t)out->flags;
    r[R_ESTIMATE_GYRO_BIAS_B_X] = out->gyro_bias_b[0];
    r[R_ESTIMATE_GYRO_BIAS_B_Y] = out->gyro_bias_b[1];
    r[R_ESTIMATE_GYRO_BIAS_B_Z] = out->gyro_bias_b[2];
}
