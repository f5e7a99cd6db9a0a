/* What the FMI 2.0 and FMI 3.0 shells of a native FMU share: the values of the variables,
 * the FMI state machine, the checks every setter makes, logging, FMU state, and the calls
 * into the model (model_*.c).
 *
 * biso_core is plain data (no pointers): it is the FMU state. fmi*GetFMUstate copies it,
 * fmi*SetFMUstate copies it back, serialization writes its bytes after a header. */
#ifndef BISO_FMU_CORE_H
#define BISO_FMU_CORE_H

#include <stddef.h>
#include <stdint.h>

#include "biso_variables.h"

enum { BISO_OK = 0, BISO_WARNING = 1, BISO_DISCARD = 2, BISO_ERROR = 3, BISO_FATAL = 4 };
enum { BISO_INSTANTIATED, BISO_INITIALIZATION, BISO_STEP, BISO_TERMINATED };

#define BISO_MSG 1024

typedef struct {
    double real[BISO_N_REAL + 1];
    int32_t integer[BISO_N_INTEGER + 1];
    int32_t boolean[BISO_N_BOOLEAN + 1];
    char string[BISO_N_STRING + 1][BISO_STRING_LENGTH];
    int phase;
    double time;
    int tunable_changed; /* a tunable parameter was set in step mode: apply after the setter */
    int derived_stale;   /* the derived outputs (BISO_ROLE_DERIVED) lag the others: compute them when read */
    biso_model model;
} biso_core;

struct biso_instance;
typedef void (*biso_log_function)(struct biso_instance *inst, int status, const char *category, const char *message);

#define BISO_MAX_UNDO 256

typedef struct {
    int n;
    int type[BISO_MAX_UNDO], slot[BISO_MAX_UNDO];
    double real[BISO_MAX_UNDO];
    int32_t integer[BISO_MAX_UNDO];
    char string[BISO_MAX_UNDO][BISO_STRING_LENGTH];
} biso_undo;

typedef struct biso_instance {
    biso_core core;
    biso_undo undo;  /* tunable parameters' old values during a setter call in step mode */
    const char *function; /* the FMI function being called (for messages) */
    char name[BISO_STRING_LENGTH];
    int logging_on;
    biso_log_function log;
    void *shell; /* the shell's own callbacks and environment */
} biso_instance;

/* the core ------------------------------------------------------------------------------ */

void biso_start_values(biso_instance *inst);
void biso_log(biso_instance *inst, int status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
/* the variable of a value reference of a type; NULL (an error logged) when there is none */
const biso_var_info *biso_var(biso_instance *inst, unsigned vr, int type, const char *function);

int biso_enter_initialization(biso_instance *inst, double start_time);
int biso_exit_initialization(biso_instance *inst);
int biso_do_step(biso_instance *inst, double t, double h);
int biso_terminate(biso_instance *inst);
int biso_reset(biso_instance *inst);

/* setters: each checks and stores one value (status); biso_end_set after a batch */
int biso_begin_set(biso_instance *inst, const char *function);
int biso_set_real(biso_instance *inst, unsigned vr, double value);
int biso_set_integer(biso_instance *inst, unsigned vr, int32_t value);
int biso_set_boolean(biso_instance *inst, unsigned vr, int value);
int biso_set_string(biso_instance *inst, unsigned vr, const char *value);
int biso_end_set(biso_instance *inst, int status);

int biso_get_real(biso_instance *inst, unsigned vr, double *value);
int biso_get_integer(biso_instance *inst, unsigned vr, int32_t *value);
int biso_get_boolean(biso_instance *inst, unsigned vr, int *value);
int biso_get_string(biso_instance *inst, unsigned vr, const char **value);

/* FMU state serialization: the header + biso_core */
size_t biso_serialized_size(void);
void biso_serialize(const biso_core *core, unsigned char *out);
int biso_deserialize(biso_instance *inst, const unsigned char *data, size_t size, biso_core *out);

/* the model (model_*.c) ------------------------------------------------------------------ */

/* start values of the model's own data (called with the core's) */
void model_start(biso_instance *inst);
/* a model-specific check of a value before it is stored (0: allowed, else msg) */
int model_check_real(biso_instance *inst, const biso_var_info *v, double value, char *msg, size_t len);
int model_check_string(biso_instance *inst, const biso_var_info *v, const char *value, char *msg, size_t len);
/* exit initialization: build the model from the parameters, write the initial outputs */
int model_configure(biso_instance *inst, char *msg, size_t len);
/* tunable parameters changed in step mode: apply them (0), or refuse all (msg) */
int model_apply_tunables(biso_instance *inst, char *msg, size_t len);
/* one communication step from t of size h: BISO_OK, or BISO_ERROR with msg (nothing changed) */
int model_step(biso_instance *inst, double t, double h, char *msg, size_t len);
/* write the derived outputs (BISO_ROLE_DERIVED) from the others; the core calls it when one is
 * read while core.derived_stale is set (a model sets it when it changes what they derive from) */
void model_derive_outputs(biso_instance *inst);

#endif
