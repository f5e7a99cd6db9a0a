/* The FMI 2.0 co-simulation interface of a native FMU: fmi2* calls into fmu_core. */
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_core.h"

typedef struct {
    fmi2CallbackFunctions callbacks;
} shell2;

#define INST ((biso_instance *)c)
#define CALLBACKS (((shell2 *)INST->shell)->callbacks)
#define CHECK_INSTANCE(name)   \
    if (!c) return fmi2Error;  \
    INST->function = name

static void log2(biso_instance *inst, int status, const char *category, const char *message) {
    /* an FMI 2.0 message is a printf format; ours has no arguments: "%" is written "%%" (a host
     * that does not format, e.g. through ctypes, still reads the whole message) */
    char format[2 * BISO_MSG];
    size_t i, j = 0;
    shell2 *s = (shell2 *)inst->shell;
    for (i = 0; message[i] && j + 2 < sizeof format; i++) {
        if (message[i] == '%') format[j++] = '%';
        format[j++] = message[i];
    }
    format[j] = 0;
    if (s->callbacks.logger)
        s->callbacks.logger(s->callbacks.componentEnvironment, inst->name, (fmi2Status)status, category, format);
}

static fmi2Status unsupported(fmi2Component c, const char *function, const char *why) {
    if (!c) return fmi2Error;
    INST->function = function;
    biso_log(INST, BISO_ERROR, "%s: not supported by %s (%s)", function, BISO_FMU_NAME, why);
    return fmi2Error;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    (void)nCategories;
    (void)categories;
    CHECK_INSTANCE("fmi2SetDebugLogging");
    INST->logging_on = loggingOn != 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    biso_instance *inst;
    shell2 *s;
    (void)fmuResourceLocation;
    (void)visible;
    if (!functions || !functions->logger) return NULL;
    if (fmuType != fmi2CoSimulation || !fmuGUID || strcmp(fmuGUID, BISO_FMU_TOKEN) != 0) {
        functions->logger(functions->componentEnvironment, instanceName ? instanceName : "", fmi2Error,
                          "logStatusError", "%s",
                          fmuType != fmi2CoSimulation ? "fmi2Instantiate: " BISO_FMU_NAME " is a co-simulation FMU "
                                                        "only (fmi2CoSimulation)"
                                                      : "fmi2Instantiate: the GUID is not " BISO_FMU_NAME "'s "
                                                        BISO_FMU_TOKEN " (a modelDescription.xml of another build?)");
        return NULL;
    }
    inst = functions->allocateMemory ? (biso_instance *)functions->allocateMemory(1, sizeof *inst)
                                     : (biso_instance *)calloc(1, sizeof *inst);
    s = functions->allocateMemory ? (shell2 *)functions->allocateMemory(1, sizeof *s) : (shell2 *)calloc(1, sizeof *s);
    if (!inst || !s) {
        if (functions->freeMemory) {
            if (inst) functions->freeMemory(inst);
            if (s) functions->freeMemory(s);
        }
        return NULL;
    }
    s->callbacks = *functions;
    inst->shell = s;
    inst->log = log2;
    inst->logging_on = loggingOn != 0;
    strncpy(inst->name, instanceName ? instanceName : "", sizeof inst->name - 1);
    biso_start_values(inst);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    fmi2CallbackFreeMemory release;
    shell2 *s;
    if (!c) return;
    s = (shell2 *)INST->shell;
    release = s->callbacks.freeMemory ? s->callbacks.freeMemory : free;
    release(c);
    release(s);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    CHECK_INSTANCE("fmi2SetupExperiment");
    if (INST->core.phase != BISO_INSTANTIATED) {
        biso_log(INST, BISO_ERROR, "fmi2SetupExperiment: only allowed after instantiation or reset");
        return fmi2Error;
    }
    INST->core.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    CHECK_INSTANCE("fmi2EnterInitializationMode");
    return (fmi2Status)biso_enter_initialization(INST, INST->core.time);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    CHECK_INSTANCE("fmi2ExitInitializationMode");
    return (fmi2Status)biso_exit_initialization(INST);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    CHECK_INSTANCE("fmi2Terminate");
    return (fmi2Status)biso_terminate(INST);
}

fmi2Status fmi2Reset(fmi2Component c) {
    CHECK_INSTANCE("fmi2Reset");
    return (fmi2Status)biso_reset(INST);
}

/* ---- values --------------------------------------------------------------------------- */

#define GETTER(Name, ctype, core_get, type_enum)                                                    \
    fmi2Status fmi2Get##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, ctype value[]) { \
        size_t i;                                                                                   \
        int status = fmi2OK;                                                                        \
        CHECK_INSTANCE("fmi2Get" #Name);                                                            \
        if (nvr && (!vr || !value)) return fmi2Error;                                               \
        for (i = 0; i < nvr; i++) {                                                                 \
            int s = core_get;                                                                       \
            if (s > status) status = s;                                                             \
        }                                                                                           \
        return (fmi2Status)status;                                                                  \
    }

GETTER(Real, fmi2Real, biso_get_real(INST, vr[i], &value[i]), BISO_REAL)
GETTER(Integer, fmi2Integer, biso_get_integer(INST, vr[i], (int32_t *)&value[i]), BISO_INTEGER)
GETTER(Boolean, fmi2Boolean, biso_get_boolean(INST, vr[i], &value[i]), BISO_BOOLEAN)
GETTER(String, fmi2String, biso_get_string(INST, vr[i], &value[i]), BISO_STRING)

#define SETTER(Name, ctype, core_set)                                                                      \
    fmi2Status fmi2Set##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const ctype value[]) { \
        size_t i;                                                                                          \
        int status = fmi2OK;                                                                               \
        CHECK_INSTANCE("fmi2Set" #Name);                                                                   \
        if (nvr && (!vr || !value)) return fmi2Error;                                                      \
        biso_begin_set(INST, "fmi2Set" #Name);                                                             \
        for (i = 0; i < nvr; i++) {                                                                        \
            int s = core_set;                                                                              \
            if (s > status) status = s;                                                                    \
        }                                                                                                  \
        return (fmi2Status)biso_end_set(INST, status);                                                     \
    }

SETTER(Real, fmi2Real, biso_set_real(INST, vr[i], value[i]))
SETTER(Integer, fmi2Integer, biso_set_integer(INST, vr[i], (int32_t)value[i]))
SETTER(Boolean, fmi2Boolean, biso_set_boolean(INST, vr[i], value[i]))
SETTER(String, fmi2String, biso_set_string(INST, vr[i], value[i]))

/* ---- FMU state ------------------------------------------------------------------------ */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    biso_core *copy;
    CHECK_INSTANCE("fmi2GetFMUstate");
    if (!state) return fmi2Error;
    copy = (biso_core *)*state;
    if (!copy) {
        copy = CALLBACKS.allocateMemory ? (biso_core *)CALLBACKS.allocateMemory(1, sizeof *copy)
                                        : (biso_core *)calloc(1, sizeof *copy);
        if (!copy) {
            biso_log(INST, BISO_ERROR, "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(copy, &INST->core, sizeof *copy);
    *state = copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    CHECK_INSTANCE("fmi2SetFMUstate");
    if (!state) {
        biso_log(INST, BISO_ERROR, "fmi2SetFMUstate: no state given");
        return fmi2Error;
    }
    memcpy(&INST->core, state, sizeof INST->core);
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    CHECK_INSTANCE("fmi2FreeFMUstate");
    if (state && *state) {
        if (CALLBACKS.freeMemory)
            CALLBACKS.freeMemory(*state);
        else
            free(*state);
        *state = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    (void)state;
    CHECK_INSTANCE("fmi2SerializedFMUstateSize");
    if (!size) return fmi2Error;
    *size = biso_serialized_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[], size_t size) {
    CHECK_INSTANCE("fmi2SerializeFMUstate");
    if (!state || !serializedState || size < biso_serialized_size()) {
        biso_log(INST, BISO_ERROR, "fmi2SerializeFMUstate: needs a state and %lu bytes",
                 (unsigned long)biso_serialized_size());
        return fmi2Error;
    }
    biso_serialize((const biso_core *)state, (unsigned char *)serializedState);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *state) {
    biso_core *copy;
    CHECK_INSTANCE("fmi2DeSerializeFMUstate");
    if (!state) return fmi2Error;
    copy = CALLBACKS.allocateMemory ? (biso_core *)CALLBACKS.allocateMemory(1, sizeof *copy)
                                    : (biso_core *)calloc(1, sizeof *copy);
    if (!copy) return fmi2Error;
    if (biso_deserialize(INST, (const unsigned char *)serializedState, size, copy) != BISO_OK) {
        if (CALLBACKS.freeMemory) CALLBACKS.freeMemory(copy); else free(copy);
        return fmi2Error;
    }
    if (*state) fmi2FreeFMUstate(c, state);
    *state = copy;
    return fmi2OK;
}

/* ---- co-simulation -------------------------------------------------------------------- */

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK_INSTANCE("fmi2DoStep");
    return (fmi2Status)biso_do_step(INST, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    CHECK_INSTANCE("fmi2GetRealStatus");
    if (s == fmi2LastSuccessfulTime && value) {
        *value = INST->core.time;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    CHECK_INSTANCE("fmi2GetBooleanStatus");
    if (s == fmi2Terminated && value) {
        *value = fmi2False;
        return fmi2OK;
    }
    return fmi2Discard;
}

#include "fmi2_unsupported.h"
