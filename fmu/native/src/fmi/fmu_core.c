/* The FMI-independent part of the native FMUs: see fmu_core.h. */
#include "fmu_core.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "biso_estimators.h"
#include "biso_field.h"
#include "biso_sensor.h"

static const char *type_names[] = {"Real", "Integer", "Boolean", "String"};

void biso_log(biso_instance *inst, int status, const char *fmt, ...) {
    char msg[BISO_MSG];
    const char *category = status == BISO_OK ? "logEvents" : status == BISO_WARNING ? "logStatusWarning"
                                                                                    : "logStatusError";
    va_list args;
    if (!inst->log || (status == BISO_OK && !inst->logging_on)) return;
    va_start(args, fmt);
    vsnprintf(msg, sizeof msg, fmt, args);
    va_end(args);
    inst->log(inst, status, category, msg);
}

void biso_start_values(biso_instance *inst) {
    biso_core *c = &inst->core;
    int i;
    memset(c, 0, sizeof *c);
    for (i = 0; i < BISO_N_VARS; i++) {
        const biso_var_info *v = &biso_vars[i];
        switch (v->type) {
        case BISO_REAL: c->real[v->slot] = v->start_real; break;
        case BISO_INTEGER: c->integer[v->slot] = v->start_int; break;
        case BISO_BOOLEAN: c->boolean[v->slot] = v->start_int; break;
        default: snprintf(c->string[v->slot], BISO_STRING_LENGTH, "%s", v->start_string); break;
        }
    }
    c->phase = BISO_INSTANTIATED;
    model_start(inst);
}

const biso_var_info *biso_var(biso_instance *inst, unsigned vr, int type, const char *function) {
    if (vr < 1 || vr > BISO_N_VARS || biso_vars[vr - 1].type != type) {
        biso_log(inst, BISO_ERROR, "%s: %s has no %s variable with value reference %u", function, BISO_FMU_NAME,
                 type_names[type], vr);
        return NULL;
    }
    return &biso_vars[vr - 1];
}

/* ---- life cycle ----------------------------------------------------------------------- */

int biso_enter_initialization(biso_instance *inst, double start_time) {
    if (inst->core.phase != BISO_INSTANTIATED) {
        biso_log(inst, BISO_ERROR, "EnterInitializationMode: only allowed after instantiation or reset");
        return BISO_ERROR;
    }
    inst->core.phase = BISO_INITIALIZATION;
    inst->core.time = start_time;
    return BISO_OK;
}

int biso_exit_initialization(biso_instance *inst) {
    char msg[BISO_MSG];
    if (inst->core.phase != BISO_INITIALIZATION) {
        biso_log(inst, BISO_ERROR, "ExitInitializationMode: not in initialization mode");
        return BISO_ERROR;
    }
    msg[0] = 0;
    if (model_configure(inst, msg, sizeof msg) != 0) {
        biso_log(inst, BISO_ERROR, "ExitInitializationMode: invalid parameters: %s", msg);
        return BISO_ERROR; /* stays in initialization mode: correct the parameters and exit again */
    }
    inst->core.phase = BISO_STEP;
    return BISO_OK;
}

int biso_do_step(biso_instance *inst, double t, double h) {
    char msg[BISO_MSG];
    int status;
    if (inst->core.phase != BISO_STEP) {
        biso_log(inst, BISO_ERROR, "DoStep at t = %.17g s refused: %s", t,
                 inst->core.phase == BISO_TERMINATED ? "the instance is terminated"
                                                     : "not initialized (call ExitInitializationMode first)");
        return BISO_ERROR;
    }
    if (!(isfinite(h) && h > 0.0) || !isfinite(t)) {
        biso_log(inst, BISO_ERROR, "DoStep at t = %.17g s refused: the step size must be positive and finite, got "
                 "%.17g", t, h);
        return BISO_ERROR;
    }
    msg[0] = 0;
    status = model_step(inst, t, h, msg, sizeof msg);
    if (status != BISO_OK) {
        biso_log(inst, status, "DoStep at t = %.17g s refused: %s (nothing was computed)", t, msg);
        return status;
    }
    inst->core.time = t + h;
    return BISO_OK;
}

int biso_terminate(biso_instance *inst) {
    if (inst->core.phase != BISO_STEP) {
        biso_log(inst, BISO_ERROR, "Terminate: not in step mode");
        return BISO_ERROR;
    }
    inst->core.phase = BISO_TERMINATED;
    return BISO_OK;
}

int biso_reset(biso_instance *inst) {
    biso_start_values(inst);
    return BISO_OK;
}

/* ---- setters -------------------------------------------------------------------------- */

int biso_begin_set(biso_instance *inst, const char *function) {
    inst->function = function;
    inst->undo.n = 0;
    inst->core.tunable_changed = 0;
    return BISO_OK;
}

/* may a variable be set now? (logs why not) */
static int settable(biso_instance *inst, const biso_var_info *v) {
    int phase = inst->core.phase;
    if (v->causality == BISO_OUTPUT) {
        biso_log(inst, BISO_ERROR, "%s: %s is an output and cannot be set", inst->function, v->name);
        return 0;
    }
    if (phase == BISO_TERMINATED) {
        biso_log(inst, BISO_ERROR, "%s: %s cannot be set after Terminate (Reset first)", inst->function, v->name);
        return 0;
    }
    if (v->causality == BISO_PARAMETER && v->variability == BISO_FIXED && phase == BISO_STEP) {
        biso_log(inst, BISO_ERROR, "%s: %s is a fixed parameter: it cannot change after initialization",
                 inst->function, v->name);
        return 0;
    }
    return 1;
}

static int tunable_now(biso_instance *inst, const biso_var_info *v) {
    return v->causality == BISO_PARAMETER && v->variability == BISO_TUNABLE && inst->core.phase == BISO_STEP;
}

static void remember(biso_instance *inst, const biso_var_info *v) {
    biso_undo *u = &inst->undo;
    int i;
    for (i = 0; i < u->n; i++)
        if (u->type[i] == v->type && u->slot[i] == v->slot) return;
    if (u->n >= BISO_MAX_UNDO) return;
    u->type[u->n] = v->type;
    u->slot[u->n] = v->slot;
    switch (v->type) {
    case BISO_REAL: u->real[u->n] = inst->core.real[v->slot]; break;
    case BISO_INTEGER: u->integer[u->n] = inst->core.integer[v->slot]; break;
    case BISO_BOOLEAN: u->integer[u->n] = inst->core.boolean[v->slot]; break;
    default: memcpy(u->string[u->n], inst->core.string[v->slot], BISO_STRING_LENGTH); break;
    }
    u->n++;
    inst->core.tunable_changed = 1;
}

static int refuse(biso_instance *inst, const biso_var_info *v, const char *msg) {
    biso_log(inst, BISO_ERROR, "%s: %s not set: %s", inst->function, v->name, msg);
    return BISO_ERROR;
}

static int check_number(biso_instance *inst, const biso_var_info *v, double x) {
    char msg[BISO_MSG];
    if (v->causality == BISO_PARAMETER && !isfinite(x)) {
        snprintf(msg, sizeof msg, "a parameter must be finite, got %.17g", x);
        return refuse(inst, v, msg);
    }
    if ((v->has_min && x < v->min) || (v->has_max && x > v->max)) {
        if (v->has_min && v->has_max)
            snprintf(msg, sizeof msg, "allowed [%.17g, %.17g], got %.17g", v->min, v->max, x);
        else if (v->has_min)
            snprintf(msg, sizeof msg, "allowed >= %.17g, got %.17g", v->min, x);
        else
            snprintf(msg, sizeof msg, "allowed <= %.17g, got %.17g", v->max, x);
        return refuse(inst, v, msg);
    }
    msg[0] = 0;
    if (v->role == BISO_ROLE_PARAM && v->given_slot < 0) { /* an optional one is checked once given */
        int kind = biso_est_kind(v->param_kind), index = biso_est_param_find(kind, v->param_name);
        if (index < 0 || biso_est_check_param(kind, index, x, msg, sizeof msg) != 0) return refuse(inst, v, msg);
    } else if (v->role == BISO_ROLE_REGISTER) {
        if (biso_register_check(v->register_field, (int)x, msg, sizeof msg)) return refuse(inst, v, msg);
    }
    return BISO_OK;
}

int biso_set_real(biso_instance *inst, unsigned vr, double value) {
    const biso_var_info *v = biso_var(inst, vr, BISO_REAL, inst->function);
    char msg[BISO_MSG];
    if (!v || !settable(inst, v)) return BISO_ERROR;
    if (v->causality == BISO_PARAMETER) {
        if (check_number(inst, v, value) != BISO_OK) return BISO_ERROR;
        msg[0] = 0;
        if (model_check_real(inst, v, value, msg, sizeof msg)) return refuse(inst, v, msg);
    }
    if (tunable_now(inst, v)) remember(inst, v);
    inst->core.real[v->slot] = value;
    return BISO_OK;
}

int biso_set_integer(biso_instance *inst, unsigned vr, int32_t value) {
    const biso_var_info *v = biso_var(inst, vr, BISO_INTEGER, inst->function);
    if (!v || !settable(inst, v)) return BISO_ERROR;
    if (check_number(inst, v, (double)value) != BISO_OK) return BISO_ERROR;
    if (tunable_now(inst, v)) remember(inst, v);
    inst->core.integer[v->slot] = value;
    return BISO_OK;
}

int biso_set_boolean(biso_instance *inst, unsigned vr, int value) {
    const biso_var_info *v = biso_var(inst, vr, BISO_BOOLEAN, inst->function);
    if (!v || !settable(inst, v)) return BISO_ERROR;
    if (v->role == BISO_ROLE_REGISTER) {
        char msg[BISO_MSG];
        if (biso_register_check(v->register_field, value != 0, msg, sizeof msg)) return refuse(inst, v, msg);
    }
    if (tunable_now(inst, v)) remember(inst, v);
    inst->core.boolean[v->slot] = value != 0;
    return BISO_OK;
}

int biso_set_string(biso_instance *inst, unsigned vr, const char *value) {
    const biso_var_info *v = biso_var(inst, vr, BISO_STRING, inst->function);
    char msg[BISO_MSG];
    if (!v || !settable(inst, v)) return BISO_ERROR;
    if (!value) value = "";
    if (strlen(value) >= BISO_STRING_LENGTH) {
        snprintf(msg, sizeof msg, "at most %d bytes", BISO_STRING_LENGTH - 1);
        return refuse(inst, v, msg);
    }
    if (v->role == BISO_ROLE_ESTIMATOR) {
        int kind = biso_est_kind(value), k, n;
        if (kind < 0) {
            n = snprintf(msg, sizeof msg, "must be one of ");
            for (k = 0; biso_est_kind_name(k) && n > 0 && (size_t)n < sizeof msg; k++)
                n += snprintf(msg + n, sizeof msg - n, "%s%s", k ? ", " : "", biso_est_kind_name(k));
            if (n > 0 && (size_t)n < sizeof msg) snprintf(msg + n, sizeof msg - n, ", got '%s'", value);
            return refuse(inst, v, msg);
        }
    } else if (v->role == BISO_ROLE_PARAM) {
        int kind = biso_est_kind(v->param_kind), index = biso_est_param_find(kind, v->param_name);
        const biso_est_param *p = biso_est_param_at(kind, index);
        if (!p || biso_est_choice_find(p, value) < 0) {
            int k, n = snprintf(msg, sizeof msg, "must be one of ");
            for (k = 0; p && k < p->n_choices && n > 0 && (size_t)n < sizeof msg; k++)
                n += snprintf(msg + n, sizeof msg - n, "%s%s", k ? ", " : "", p->choices[k]);
            if (n > 0 && (size_t)n < sizeof msg) snprintf(msg + n, sizeof msg - n, ", got '%s'", value);
            return refuse(inst, v, msg);
        }
    }
    msg[0] = 0;
    if (v->causality == BISO_PARAMETER && model_check_string(inst, v, value, msg, sizeof msg)) return refuse(inst, v, msg);
    if (tunable_now(inst, v)) remember(inst, v);
    snprintf(inst->core.string[v->slot], BISO_STRING_LENGTH, "%s", value);
    return BISO_OK;
}

int biso_end_set(biso_instance *inst, int status) {
    char msg[BISO_MSG];
    biso_undo *u = &inst->undo;
    int i;
    if (!inst->core.tunable_changed) return status;
    inst->core.tunable_changed = 0;
    msg[0] = 0;
    if (status == BISO_OK && model_apply_tunables(inst, msg, sizeof msg) == 0) {
        biso_log(inst, BISO_OK, "%s: tunable parameters changed", inst->function);
        return status;
    }
    /* refused (or another value of the call was): every tunable value of this call goes back */
    for (i = 0; i < u->n; i++) {
        switch (u->type[i]) {
        case BISO_REAL: inst->core.real[u->slot[i]] = u->real[i]; break;
        case BISO_INTEGER: inst->core.integer[u->slot[i]] = u->integer[i]; break;
        case BISO_BOOLEAN: inst->core.boolean[u->slot[i]] = u->integer[i]; break;
        default: memcpy(inst->core.string[u->slot[i]], u->string[i], BISO_STRING_LENGTH); break;
        }
    }
    u->n = 0;
    if (msg[0]) biso_log(inst, BISO_ERROR, "%s: parameter change refused, parameters kept: %s", inst->function, msg);
    return BISO_ERROR;
}

/* ---- getters -------------------------------------------------------------------------- */

int biso_get_real(biso_instance *inst, unsigned vr, double *value) {
    const biso_var_info *v = biso_var(inst, vr, BISO_REAL, inst->function);
    if (!v) return BISO_ERROR;
    if (v->role == BISO_ROLE_DERIVED && inst->core.derived_stale) {
        model_derive_outputs(inst);
        inst->core.derived_stale = 0;
    }
    *value = inst->core.real[v->slot];
    return BISO_OK;
}

int biso_get_integer(biso_instance *inst, unsigned vr, int32_t *value) {
    const biso_var_info *v = biso_var(inst, vr, BISO_INTEGER, inst->function);
    if (!v) return BISO_ERROR;
    *value = inst->core.integer[v->slot];
    return BISO_OK;
}

int biso_get_boolean(biso_instance *inst, unsigned vr, int *value) {
    const biso_var_info *v = biso_var(inst, vr, BISO_BOOLEAN, inst->function);
    if (!v) return BISO_ERROR;
    *value = inst->core.boolean[v->slot];
    return BISO_OK;
}

int biso_get_string(biso_instance *inst, unsigned vr, const char **value) {
    const biso_var_info *v = biso_var(inst, vr, BISO_STRING, inst->function);
    if (!v) return BISO_ERROR;
    *value = inst->core.string[v->slot];
    return BISO_OK;
}

/* ---- serialization -------------------------------------------------------------------- */

#define MAGIC "biso_cosim FMU state\n"
#define HEADER_SIZE 64 /* magic (24), fingerprint (24), core size (16), as text */

size_t biso_serialized_size(void) { return HEADER_SIZE + sizeof(biso_core); }

static void header(char out[HEADER_SIZE]) {
    memset(out, 0, HEADER_SIZE);
    snprintf(out, 24, "%s", MAGIC);
    snprintf(out + 24, 24, "%s", BISO_FMU_FINGERPRINT);
    snprintf(out + 48, 16, "%lu", (unsigned long)sizeof(biso_core));
}

void biso_serialize(const biso_core *core, unsigned char *out) {
    header((char *)out);
    memcpy(out + HEADER_SIZE, core, sizeof *core);
}

int biso_deserialize(biso_instance *inst, const unsigned char *data, size_t size, biso_core *out) {
    char expected[HEADER_SIZE];
    header(expected);
    if (!data || size != biso_serialized_size() || memcmp(data, expected, HEADER_SIZE) != 0) {
        biso_log(inst, BISO_ERROR, "DeSerializeFMUstate: not a serialized state of this %s (built with the same "
                 "variables, on the same platform): nothing changed", BISO_FMU_NAME);
        return BISO_ERROR;
    }
    memcpy(out, data + HEADER_SIZE, sizeof *out);
    return BISO_OK;
}
