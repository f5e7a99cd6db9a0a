/* What the estimators' C files share: the kind table, the per-family operations and the
 * message helpers. Not part of the public API (biso_estimators.h). */
#ifndef BISO_EST_INTERNAL_H
#define BISO_EST_INTERNAL_H

#include <stddef.h>

#include "biso_estimators.h"

/* C implementations, one per Python estimator class */
#define BISO_EST_FAMILY_BISO 0
#define BISO_EST_FAMILY_DCM_PI 1
#define BISO_EST_FAMILY_BISO_PLUS 2

typedef struct {
    int family_index;  /* a parameter of the family that the kind's name fixes */
    double value;
} biso_est_fixed;

typedef struct {
    const char *name;
    const char *summary;
    int family;
    int inputs;          /* BISO_EST_INPUT_* */
    int estimates_bias;
    const biso_est_param *params;
    const int *family_index;  /* kind's parameter i -> index in the family's full vector */
    int n_params;
    const biso_est_fixed *fixed;
    int n_fixed;
} biso_est_kind_info;

extern const biso_est_kind_info biso_est_kinds[BISO_EST_N_KINDS];  /* generated tables */

/* Errors: a message of the form "<kind>.<param> ..." into (msg, size); always returns -1. */
int biso_est_fail(char *msg, size_t size, const char *format, ...);

/* A family: its parameters are the full vector `p` (indices BISO_EST_<FAMILY>_P_*);
 * `kind` names variables in messages. */
typedef struct {
    int (*coefficients)(const char *kind, const double *p, double fs_hz, double *coef, char *msg, size_t size);
    void (*initial_state)(const double *p, const double *q0, double *state);
    void (*update)(const double *coef, double *state, const biso_est_input *in, biso_est_output *out);
    int state_size;
    int coef_size;
    int bias_offset;  /* state offset of the gyro bias estimate, -1 if none */
    int bias_sign;    /* +1, or -1 where the state holds minus the bias (DCM's omega_I) */
} biso_est_family;

extern const biso_est_family biso_est_family_biso;
extern const biso_est_family biso_est_family_dcm_pi;
extern const biso_est_family biso_est_family_biso_plus;

/* Python's check_finite(name, value, low=lo, high=hi, low_open=open): 0, or -1 with the
 * message naming "<kind>.<name>" and the allowed range. */
int biso_est_check_real(const char *kind, const char *name, double value, double lo, double hi, int lo_open,
                        char *msg, size_t size);

/* 0 if a derived value is finite, else -1 with the message "<kind>: <names> give a
 * non-finite <what> ..." (names: the parameters it comes from, comma-separated, without
 * the kind): values the Python estimator refuses with an OverflowError or runs on. */
int biso_est_need_finite(const char *kind, double value, const char *what, const char *names, char *msg,
                         size_t size);

#endif /* BISO_EST_INTERNAL_H */
