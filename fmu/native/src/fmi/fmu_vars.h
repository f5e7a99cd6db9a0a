/* The variable table of a native FMU (generated into biso_variables.c from fmu/variables.py). */
#ifndef BISO_FMU_VARS_H
#define BISO_FMU_VARS_H

enum { BISO_REAL, BISO_INTEGER, BISO_BOOLEAN, BISO_STRING };
enum { BISO_PARAMETER, BISO_INPUT, BISO_OUTPUT };
enum { BISO_FIXED, BISO_TUNABLE, BISO_DISCRETE, BISO_CONTINUOUS };
/* what a variable is to the generic core; BISO_ROLE_MODEL: only the model knows;
 * BISO_ROLE_DERIVED: an output the model computes from its others when it is read */
enum { BISO_ROLE_MODEL, BISO_ROLE_PARAM, BISO_ROLE_GIVEN, BISO_ROLE_REGISTER, BISO_ROLE_ESTIMATOR, BISO_ROLE_DERIVED };

typedef struct {
    const char *name;
    int type, causality, variability, role;
    int slot;                   /* index into the value array of its type */
    double start_real;          /* Real */
    int start_int;              /* Integer, Boolean */
    const char *start_string;   /* String */
    int has_min;
    double min;
    int has_max;
    double max;
    const char *param_kind;     /* BISO_ROLE_PARAM / GIVEN: the estimator ("biso_plus") */
    const char *param_name;     /* ... and its C parameter entry ("k_tilt", "speed_point_b_m[1]") */
    int given_slot;             /* BISO_ROLE_PARAM of an optional parameter: its has_ flag's Boolean slot */
    int register_field;         /* BISO_ROLE_REGISTER: BISO_REG_* */
} biso_var_info;

extern const biso_var_info biso_vars[];

#endif
