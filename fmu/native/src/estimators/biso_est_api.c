/* The public API of biso_estimators.h: kinds, parameter tables and checks, the life
 * cycle, dispatch to the families (biso_est_biso.c, biso_est_dcm_pi.c, biso_est_biso_plus.c). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "biso_est_internal.h"

static const biso_est_family *const families[] = {
    &biso_est_family_biso, &biso_est_family_dcm_pi, &biso_est_family_biso_plus,
};

static const biso_est_kind_info *kind_info(int kind) {
    return (kind >= 0 && kind < BISO_EST_N_KINDS) ? &biso_est_kinds[kind] : NULL;
}

static const biso_est_family *family_of(int kind) { return families[biso_est_kinds[kind].family]; }

int biso_est_fail(char *msg, size_t size, const char *format, ...) {
    if (msg != NULL && size > 0) {
        va_list args;
        va_start(args, format);
        vsnprintf(msg, size, format, args);
        va_end(args);
    }
    return -1;
}

/* the shortest %g form of x that reads back as x (Python's repr, for messages) */
static const char *shortest(double x, char *buf, size_t size) {
    int digits;
    for (digits = 1; digits < 17; digits++) {
        snprintf(buf, size, "%.*g", digits, x);
        if (strtod(buf, NULL) == x) return buf;
    }
    snprintf(buf, size, "%.17g", x);
    return buf;
}

int biso_est_check_real(const char *kind, const char *name, double value, double lo, double hi, int lo_open,
                        char *msg, size_t size) {
    char v[32], a[32], b[32];
    int has_lo = lo > -HUGE_VAL, has_hi = hi < HUGE_VAL;
    if (isfinite(value) && (!has_lo || value > lo || (!lo_open && value == lo)) && (!has_hi || value <= hi))
        return 0;
    shortest(value, v, sizeof v);
    shortest(lo, a, sizeof a);
    shortest(hi, b, sizeof b);
    if (has_lo && has_hi)
        return biso_est_fail(msg, size, "%s.%s must be finite and in %s%s, %s], got %s", kind, name,
                             lo_open ? "(" : "[", a, b, v);
    if (has_lo)
        return biso_est_fail(msg, size, "%s.%s must be finite and %s %s, got %s", kind, name, lo_open ? ">" : ">=",
                             a, v);
    if (has_hi)
        return biso_est_fail(msg, size, "%s.%s must be finite and <= %s, got %s", kind, name, b, v);
    return biso_est_fail(msg, size, "%s.%s must be finite, got %s", kind, name, v);
}

int biso_est_need_finite(const char *kind, double value, const char *what, const char *names, char *msg,
                         size_t size) {
    char list[256] = "";
    const char *p = names;
    if (isfinite(value)) return 0;
    while (*p) {  /* "a, b" -> "kind.a, kind.b" */
        size_t n = strlen(list), len = strcspn(p, ",");
        snprintf(list + n, sizeof list - n, "%s%s.%.*s", n ? ", " : "", kind, (int)len, p);
        p += len;
        while (*p == ',' || *p == ' ') p++;
    }
    return biso_est_fail(msg, size, "%s: the values of %s give a non-finite %s (a value too large or too small "
                         "for the arithmetic at this sample rate)", kind, list, what);
}

/* ---- kinds and tables ----------------------------------------------------------------- */

int biso_est_kind(const char *name) {
    int k;
    if (name == NULL) return -1;
    for (k = 0; k < BISO_EST_N_KINDS; k++)
        if (strcmp(name, biso_est_kinds[k].name) == 0) return k;
    return -1;
}

const char *biso_est_kind_name(int kind) { return kind_info(kind) ? biso_est_kinds[kind].name : NULL; }
const char *biso_est_kind_summary(int kind) { return kind_info(kind) ? biso_est_kinds[kind].summary : NULL; }
int biso_est_inputs(int kind) { return kind_info(kind) ? biso_est_kinds[kind].inputs : 0; }
int biso_est_estimates_bias(int kind) { return kind_info(kind) ? biso_est_kinds[kind].estimates_bias : 0; }
int biso_est_param_count(int kind) { return kind_info(kind) ? biso_est_kinds[kind].n_params : -1; }
int biso_est_state_size(int kind) { return kind_info(kind) ? family_of(kind)->state_size : -1; }
int biso_est_coef_size(int kind) { return kind_info(kind) ? family_of(kind)->coef_size : -1; }

const biso_est_param *biso_est_param_at(int kind, int index) {
    const biso_est_kind_info *info = kind_info(kind);
    if (info == NULL || index < 0 || index >= info->n_params) return NULL;
    return &info->params[index];
}

int biso_est_param_find(int kind, const char *name) {
    const biso_est_kind_info *info = kind_info(kind);
    int i;
    if (info == NULL || name == NULL) return -1;
    for (i = 0; i < info->n_params; i++)
        if (strcmp(name, info->params[i].name) == 0) return i;
    return -1;
}

int biso_est_choice_find(const biso_est_param *param, const char *choice) {
    int i;
    if (param == NULL || choice == NULL || param->choices == NULL) return -1;
    for (i = 0; i < param->n_choices; i++)
        if (strcmp(choice, param->choices[i]) == 0) return i;
    return -1;
}

void biso_est_params_default(int kind, double *params) {
    const biso_est_kind_info *info = kind_info(kind);
    int i;
    if (info == NULL) return;
    for (i = 0; i < info->n_params; i++) params[i] = info->params[i].default_value;
}

int biso_est_check_param(int kind, int index, double value, char *msg, size_t msg_size) {
    const biso_est_param *p = biso_est_param_at(kind, index);
    const char *kname = biso_est_kind_name(kind);
    char v[32];
    if (p == NULL) {
        if (kname == NULL) return biso_est_fail(msg, msg_size, "unknown estimator kind %d", kind);
        return biso_est_fail(msg, msg_size, "%s has no parameter %d (it has %d)", kname, index,
                             biso_est_param_count(kind));
    }
    switch (p->type) {
    case BISO_EST_REAL:
        if (p->optional && isnan(value)) return 0;
        if (biso_est_check_real(kname, p->name, value, p->min, p->max, p->min_open, msg, msg_size) == 0) return 0;
        if (p->optional) {  /* say that NaN (None) is allowed too */
            size_t n = msg ? strlen(msg) : 0;
            if (msg && n + 1 < msg_size) snprintf(msg + n, msg_size - n, " (or NaN: none)");
        }
        return -1;
    case BISO_EST_INTEGER:
        if (isfinite(value) && value == floor(value) && value >= p->min && value <= p->max) return 0;
        shortest(value, v, sizeof v);
        {
            char a[32], b[32];
            return biso_est_fail(msg, msg_size, "%s.%s must be a whole number in [%s, %s], got %s", kname, p->name,
                                 shortest(p->min, a, sizeof a), shortest(p->max, b, sizeof b), v);
        }
    case BISO_EST_BOOLEAN:
        if (value == 0.0 || value == 1.0) return 0;
        shortest(value, v, sizeof v);
        return biso_est_fail(msg, msg_size, "%s.%s must be 0 (false) or 1 (true), got %s", kname, p->name, v);
    case BISO_EST_CHOICE:
        if (isfinite(value) && value == floor(value) && value >= 0.0 && value < p->n_choices) return 0;
        shortest(value, v, sizeof v);
        {
            char names[256] = "";
            int i;
            for (i = 0; i < p->n_choices; i++) {
                size_t n = strlen(names);
                snprintf(names + n, sizeof names - n, "%s%d '%s'", i ? ", " : "", i, p->choices[i]);
            }
            return biso_est_fail(msg, msg_size, "%s.%s must be one of %s, got %s", kname, p->name, names, v);
        }
    default:
        return biso_est_fail(msg, msg_size, "%s.%s has an unknown type", kname, p->name);
    }
}

/* the family's full parameter vector: the kind's values and the values its name fixes */
static void full_params(int kind, const double *params, double *full) {
    const biso_est_kind_info *info = &biso_est_kinds[kind];
    int i;
    for (i = 0; i < info->n_params; i++) full[info->family_index[i]] = params[i];
    for (i = 0; i < info->n_fixed; i++) full[info->fixed[i].family_index] = info->fixed[i].value;
}

/* every value on its own, then the family's checks and coefficients (into coef) */
static int derive(int kind, double fs_hz, const double *params, double *coef, char *msg, size_t msg_size) {
    double full[BISO_EST_MAX_PARAMS];
    int i;
    if (params == NULL) return biso_est_fail(msg, msg_size, "%s: no parameter values given", biso_est_kind_name(kind));
    for (i = 0; i < biso_est_kinds[kind].n_params; i++)
        if (biso_est_check_param(kind, i, params[i], msg, msg_size) != 0) return -1;
    full_params(kind, params, full);
    return family_of(kind)->coefficients(biso_est_kinds[kind].name, full, fs_hz, coef, msg, msg_size);
}

/* ---- life cycle ----------------------------------------------------------------------- */

int biso_est_init(biso_est *est, int kind, double fs_hz, const double *params, char *msg, size_t msg_size) {
    double coef[BISO_EST_MAX_COEF];
    double full[BISO_EST_MAX_PARAMS];
    int n;
    if (est == NULL) return biso_est_fail(msg, msg_size, "biso_est_init: no instance given");
    if (kind_info(kind) == NULL) {
        char names[256] = "";
        int k;
        for (k = 0; k < BISO_EST_N_KINDS; k++) {
            size_t len = strlen(names);
            snprintf(names + len, sizeof names - len, "%s%s", k ? ", " : "", biso_est_kinds[k].name);
        }
        return biso_est_fail(msg, msg_size, "unknown estimator kind %d; known: %s", kind, names);
    }
    if (!(isfinite(fs_hz) && fs_hz > 0.0)) {
        char v[32];
        return biso_est_fail(msg, msg_size, "fs_hz must be finite and > 0, got %s", shortest(fs_hz, v, sizeof v));
    }
    if (derive(kind, fs_hz, params, coef, msg, msg_size) != 0) return -1;
    memset(est, 0, sizeof *est);
    est->kind = kind;
    est->fs_hz = fs_hz;
    n = biso_est_kinds[kind].n_params;
    memcpy(est->params, params, (size_t)n * sizeof(double));
    memcpy(est->coef, coef, (size_t)family_of(kind)->coef_size * sizeof(double));
    full_params(kind, params, full);
    family_of(kind)->initial_state(full, NULL, est->state);
    if (msg != NULL && msg_size > 0) msg[0] = '\0';
    return 0;
}

int biso_est_set_params(biso_est *est, const double *params, char *msg, size_t msg_size) {
    double coef[BISO_EST_MAX_COEF];
    if (est == NULL || kind_info(est->kind) == NULL)
        return biso_est_fail(msg, msg_size, "biso_est_set_params: no initialised instance given");
    if (derive(est->kind, est->fs_hz, params, coef, msg, msg_size) != 0) return -1;
    memcpy(est->params, params, (size_t)biso_est_kinds[est->kind].n_params * sizeof(double));
    memcpy(est->coef, coef, (size_t)family_of(est->kind)->coef_size * sizeof(double));
    return 0;
}

int biso_est_reset(biso_est *est, const double *q0, char *msg, size_t msg_size) {
    double full[BISO_EST_MAX_PARAMS], q[4];
    if (est == NULL || kind_info(est->kind) == NULL)
        return biso_est_fail(msg, msg_size, "biso_est_reset: no initialised instance given");
    if (q0 != NULL) {
        /* as_quaternion: finite and non-zero, normalised */
        double n = sqrt(q0[0] * q0[0] + q0[1] * q0[1] + q0[2] * q0[2] + q0[3] * q0[3]);
        int i;
        if (!(isfinite(n) && n != 0.0))
            return biso_est_fail(msg, msg_size, "q0 must be finite and non-zero, got (%g, %g, %g, %g)", q0[0], q0[1],
                                 q0[2], q0[3]);
        for (i = 0; i < 4; i++) q[i] = q0[i] / n;
    }
    full_params(est->kind, est->params, full);
    family_of(est->kind)->initial_state(full, q0 != NULL ? q : NULL, est->state);
    return 0;
}

void biso_est_get_state(const biso_est *est, double *state) {
    memcpy(state, est->state, (size_t)family_of(est->kind)->state_size * sizeof(double));
}

void biso_est_set_state(biso_est *est, const double *state) {
    memcpy(est->state, state, (size_t)family_of(est->kind)->state_size * sizeof(double));
}

int biso_est_initialized(const biso_est *est) { return est->state[0] != 0.0; }

void biso_est_peek(const biso_est *est, biso_est_output *out) {
    const biso_est_family *f = family_of(est->kind);
    const double *lam = est->state + 1;  /* every family: (initialized, lam, ...) */
    double n = sqrt(lam[0] * lam[0] + lam[1] * lam[1] + lam[2] * lam[2] + lam[3] * lam[3]);
    int i;
    for (i = 0; i < 4; i++) out->q_wb[i] = lam[i] / n;
    out->flags = biso_est_initialized(est) ? 0 : BISO_EST_FLAG_UNINITIALIZED;
    for (i = 0; i < 3; i++)
        out->gyro_bias_b[i] = f->bias_offset < 0 ? 0.0 : f->bias_sign * est->state[f->bias_offset + i];
}

void biso_est_update(biso_est *est, const biso_est_input *in, biso_est_output *out) {
    family_of(est->kind)->update(est->coef, est->state, in, out);
}

void biso_est_run(biso_est *est, size_t n, const double *gyro_b, const double *accel_b, const double *mag_b,
                  const double *speed_mps, const double *velocity_enu_mps, const int64_t *imu_flags,
                  double *q_wb, int64_t *flags, double *gyro_bias_b) {
    const biso_est_family *f = family_of(est->kind);
    biso_est_input in;
    biso_est_output out;
    size_t i, j;
    in.speed_mps = NAN;
    in.has_velocity = velocity_enu_mps != NULL;
    in.velocity_enu_mps[0] = in.velocity_enu_mps[1] = in.velocity_enu_mps[2] = 0.0;
    in.imu_flags = 0;
    for (i = 0; i < n; i++) {
        for (j = 0; j < 3; j++) {
            in.gyro_b[j] = gyro_b[3 * i + j];
            in.accel_b[j] = accel_b[3 * i + j];
            in.mag_b[j] = mag_b[3 * i + j];
            if (velocity_enu_mps != NULL) in.velocity_enu_mps[j] = velocity_enu_mps[3 * i + j];
        }
        if (speed_mps != NULL) in.speed_mps = speed_mps[i];
        if (imu_flags != NULL) in.imu_flags = imu_flags[i];
        f->update(est->coef, est->state, &in, &out);
        if (q_wb != NULL)
            for (j = 0; j < 4; j++) q_wb[4 * i + j] = out.q_wb[j];
        if (flags != NULL) flags[i] = out.flags;
        if (gyro_bias_b != NULL)
            for (j = 0; j < 3; j++) gyro_bias_b[3 * i + j] = out.gyro_bias_b[j];
    }
}
