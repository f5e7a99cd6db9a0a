/*
 * biso_estimators.h: the attitude estimators of biso_cosim in C99 (the FMU path).
 *
 * The estimators biso, positional, poisson, dcm_pi and biso_plus of the Python package
 * (biso_cosim/estimators), ported operation by operation from their numba kernels: the
 * same inputs, parameters and state give the same outputs, bit for bit where the
 * arithmetic is the same (tests/test_native_estimators.py). Compile with
 * -std=c99 -O2 -ffp-contract=off -fno-fast-math (no fused multiply-add: numba has none).
 * Dependencies: the C library and libm only; no allocation, no global state, no I/O.
 *
 * Conventions (the package's): samples in body axes (x forward, y left, z up); gyro in
 * rad/s, accelerometer = specific force in m/s^2 (+g up at rest), magnetometer in uT;
 * attitude q_wb = (w, x, y, z), Hamilton, body -> ENU.
 *
 * Use:
 *     double p[BISO_EST_MAX_PARAMS];
 *     char msg[256];
 *     biso_est est;
 *     int kind = biso_est_kind("biso_plus");
 *     biso_est_params_default(kind, p);
 *     p[biso_est_param_find(kind, "k_tilt")] = 5.0;
 *     if (biso_est_init(&est, kind, 200.0, p, msg, sizeof msg) != 0) { log(msg); ... }
 *     for each sample: biso_est_update(&est, &in, &out);
 *
 * Parameters are a flat array of doubles, one per entry of the estimator's parameter
 * table (biso_est_param_at): a Real as itself, a Boolean as 0 or 1, an Integer as its
 * value, a Choice (a Python string) as the index of its name in `choices`; an optional
 * parameter (Python None) as NaN; a 3-vector as three entries "name[1]", "name[2]",
 * "name[3]". The tables, defaults, ranges and documentation are generated from the
 * Python parameter records (python -m biso_cosim.fmu.native.gen; biso_estimators_gen.h).
 *
 * The instance is plain data (no pointers): copy it with = or memcpy to save and restore
 * everything (FMU get/set state). The state alone, biso_est_get_state/set_state, is the
 * flat array of the Python estimator's State.values, with the same layout: a state moves
 * between C and Python.
 */
#ifndef BISO_ESTIMATORS_H
#define BISO_ESTIMATORS_H

#include <stddef.h>
#include <stdint.h>

#include "biso_estimators_gen.h"

#ifdef __cplusplus
extern "C" {
#endif

#define BISO_EST_API_VERSION 1

/* ---- parameter metadata ------------------------------------------------------------ */

typedef enum {
    BISO_EST_REAL = 0,    /* double */
    BISO_EST_INTEGER = 1, /* a whole number */
    BISO_EST_BOOLEAN = 2, /* 0 or 1 */
    BISO_EST_CHOICE = 3   /* index into choices (the Python parameter is a string) */
} biso_est_type;

typedef struct {
    const char *name;      /* as the FMU variable suffix: "k_tilt", "speed_point_b_m[1]" */
    const char *symbol;    /* the equation's symbol, UTF-8 ("" if none) */
    const char *unit;      /* the Python record's unit, UTF-8 ("1/s²", "µT", "" if none) */
    const char *fmi_unit;  /* the FMI unit name ("1/s2", "uT", "" if none) */
    const char *doc;       /* one-line meaning (the Python record's doc) */
    const char *source;    /* paper / equation / "measured" ("" if none) */
    int type;              /* biso_est_type */
    int optional;          /* 1: NaN stands for Python's None (meaning in doc) */
    int tunable;           /* 1: may change in mid-run (biso_est_set_params, no jump) */
    double default_value;  /* NaN where the Python default is None */
    double min, max;       /* allowed range, -HUGE_VAL/HUGE_VAL where unbounded */
    int min_open;          /* 1: value must be > min (else >= min) */
    const char *const *choices; /* BISO_EST_CHOICE: the names, NULL otherwise */
    int n_choices;
} biso_est_param;

/* ---- instance ------------------------------------------------------------------------ */

typedef struct {
    int kind;                              /* BISO_EST_KIND_* */
    double fs_hz;                          /* sample rate, Hz */
    double params[BISO_EST_MAX_PARAMS];    /* the kind's parameter values (see above) */
    double coef[BISO_EST_MAX_COEF];        /* derived coefficients (the Python `coefficients`) */
    double state[BISO_EST_MAX_STATE];      /* the state (the Python State.values) */
} biso_est;

/* One sample in. Optional inputs: speed_mps (biso_plus; NaN = unknown, exactly as not
 * given), velocity_enu_mps (biso/positional/poisson with latitude_rad set: transport
 * rate; used only when has_velocity), imu_flags (the sensor's flag bits
 * BISO_EST_IMU_*, 0 = none). Estimators ignore inputs they do not take
 * (biso_est_inputs says which they take). */
typedef struct {
    double gyro_b[3];          /* rad/s */
    double accel_b[3];         /* m/s^2, specific force */
    double mag_b[3];           /* uT */
    double speed_mps;          /* forward speed at speed_point_b_m; NaN = unknown */
    double velocity_enu_mps[3];
    int has_velocity;
    int64_t imu_flags;
} biso_est_input;

/* One sample out: never NaN (non-finite or saturated inputs are flagged, see flags). */
typedef struct {
    double q_wb[4];            /* attitude after this sample, unit, (w, x, y, z) */
    int64_t flags;             /* BISO_EST_FLAG_* bitmask */
    double gyro_bias_b[3];     /* estimated gyro bias, rad/s (0 where not estimated) */
} biso_est_output;

/* Optional inputs a kind takes (biso_est_inputs). */
#define BISO_EST_INPUT_IMU_FLAGS 1
#define BISO_EST_INPUT_SPEED_MPS 2
#define BISO_EST_INPUT_VELOCITY_ENU_MPS 4

/* ---- kinds and parameter tables ------------------------------------------------------ */

int biso_est_kind(const char *name);          /* BISO_EST_KIND_*, -1 if unknown */
const char *biso_est_kind_name(int kind);     /* "biso", ...; NULL if unknown */
const char *biso_est_kind_summary(int kind);  /* one line; NULL if unknown */
int biso_est_inputs(int kind);                /* BISO_EST_INPUT_* bits */
int biso_est_estimates_bias(int kind);        /* 1: gyro_bias_b is an estimate */
int biso_est_param_count(int kind);           /* -1 if unknown */
const biso_est_param *biso_est_param_at(int kind, int index);   /* NULL if out of range */
int biso_est_param_find(int kind, const char *name);           /* index, -1 if none */
int biso_est_choice_find(const biso_est_param *param, const char *choice); /* -1 if none */
void biso_est_params_default(int kind, double *params);        /* param_count values */
int biso_est_state_size(int kind);            /* doubles in the state, -1 if unknown */
int biso_est_coef_size(int kind);             /* doubles in coef, -1 if unknown */

/* Write into msg (at most msg_size bytes, NUL-terminated; msg may be NULL) why `value`
 * is not allowed for parameter `index` of `kind`, naming the variable "<kind>.<name>"
 * and its allowed range, and return -1; return 0 if it is allowed on its own (some
 * combinations are refused by biso_est_init / set_params). */
int biso_est_check_param(int kind, int index, double value, char *msg, size_t msg_size);

/* ---- life cycle (each returns 0, or -1 with the reason in msg and nothing changed) ---- */

/* Validate the parameters (each, and their combinations, as the Python estimator does),
 * derive the coefficients and start from the initial state: as make_estimator(kind,
 * fs_hz, **params). fs_hz must be finite and > 0. */
int biso_est_init(biso_est *est, int kind, double fs_hz, const double *params, char *msg, size_t msg_size);

/* Retune in mid-run: all param_count values at once (set_params of the Python estimator:
 * the coefficients are derived again, the state is kept, so the attitude does not jump).
 * Refused as a whole if any value or combination is invalid. */
int biso_est_set_params(biso_est *est, const double *params, char *msg, size_t msg_size);

/* Start again (Python reset): q0 NULL: the first valid sample initialises the attitude;
 * else q0 (w, x, y, z), finite and non-zero, normalised, is the attitude at the first
 * sample of the next update. */
int biso_est_reset(biso_est *est, const double *q0, char *msg, size_t msg_size);

/* The whole state (biso_est_state_size doubles), as Python's get_state().values. */
void biso_est_get_state(const biso_est *est, double *state);
void biso_est_set_state(biso_est *est, const double *state);

/* 1 if an attitude is set (by reset with q0 or by a valid sample). */
int biso_est_initialized(const biso_est *est);

/* The output as the state holds it, before the next sample: q_wb = lam/|lam| (the
 * identity before initialisation), flags BISO_EST_FLAG_UNINITIALIZED while there is no
 * attitude (else 0), the bias estimate. What an FMU shows after initialisation. */
void biso_est_peek(const biso_est *est, biso_est_output *out);

/* Process one sample: the numba kernel's per-sample update. Never fails. */
void biso_est_update(biso_est *est, const biso_est_input *in, biso_est_output *out);

/* n samples from row-major arrays ((n, 3) gyro/accel/mag, (n, 3) velocity, (n,) speed
 * and flags; NULL = not given), outputs (n, 4) q, (n,) flags, (n, 3) bias (NULL = not
 * wanted): biso_est_update in a loop (the Python estimator's update of a block). */
void biso_est_run(biso_est *est, size_t n, const double *gyro_b, const double *accel_b, const double *mag_b,
                  const double *speed_mps, const double *velocity_enu_mps, const int64_t *imu_flags,
                  double *q_wb, int64_t *flags, double *gyro_bias_b);

#ifdef __cplusplus
}
#endif

#endif /* BISO_ESTIMATORS_H */
