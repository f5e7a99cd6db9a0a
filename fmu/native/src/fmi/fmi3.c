/* The FMI 3.0 co-simulation interface of a native FMU: fmi3* calls into fmu_core. Scalar
 * variables only (the variables are the FMI 2.0 ones); Model Exchange and Scheduled
 * Execution are not provided, nor clocks, event mode or intermediate updates. */
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmu_core.h"

typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log_message;
} shell3;

#define INST ((biso_instance *)instance)
#define CHECK_INSTANCE(name)       \
    if (!instance) return fmi3Error; \
    INST->function = name

static void log3(biso_instance *inst, int status, const char *category, const char *message) {
    shell3 *s = (shell3 *)inst->shell;
    if (s->log_message) s->log_message(s->env, (fmi3Status)status, category, message);
}

static fmi3Status unsupported(fmi3Instance instance, const char *function, const char *why) {
    if (!instance) return fmi3Error;
    biso_log(INST, BISO_ERROR, "%s: not supported by %s (%s)", function, BISO_FMU_NAME, why);
    return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    (void)nCategories;
    (void)categories;
    CHECK_INSTANCE("fmi3SetDebugLogging");
    INST->logging_on = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    biso_instance *inst;
    shell3 *s;
    (void)resourcePath;
    (void)visible;
    (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables;
    (void)intermediateUpdate;
    if (!instantiationToken || strcmp(instantiationToken, BISO_FMU_TOKEN) != 0 || eventModeUsed) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       eventModeUsed ? "fmi3InstantiateCoSimulation: " BISO_FMU_NAME " has no event mode "
                                       "(hasEventMode=false)"
                                     : "fmi3InstantiateCoSimulation: the instantiation token is not " BISO_FMU_NAME
                                       "'s " BISO_FMU_TOKEN " (a modelDescription.xml of another build?)");
        return NULL;
    }
    inst = (biso_instance *)calloc(1, sizeof *inst);
    s = (shell3 *)calloc(1, sizeof *s);
    if (!inst || !s) {
        free(inst);
        free(s);
        return NULL;
    }
    s->env = instanceEnvironment;
    s->log_message = logMessage;
    inst->shell = s;
    inst->log = log3;
    inst->logging_on = loggingOn;
    strncpy(inst->name, instanceName ? instanceName : "", sizeof inst->name - 1);
    biso_start_values(inst);
    return inst;
}

void fmi3FreeInstance(fmi3Instance instance) {
    if (!instance) return;
    free(INST->shell);
    free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined;
    (void)tolerance;
    (void)stopTimeDefined;
    (void)stopTime;
    CHECK_INSTANCE("fmi3EnterInitializationMode");
    return (fmi3Status)biso_enter_initialization(INST, startTime);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    CHECK_INSTANCE("fmi3ExitInitializationMode");
    return (fmi3Status)biso_exit_initialization(INST);
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterEventMode", "hasEventMode=false");
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    CHECK_INSTANCE("fmi3Terminate");
    return (fmi3Status)biso_terminate(INST);
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    CHECK_INSTANCE("fmi3Reset");
    return (fmi3Status)biso_reset(INST);
}

/* ---- values --------------------------------------------------------------------------- */

/* time (value reference 0, the independent variable) reads as the current time */
static int get_float64(biso_instance *inst, fmi3ValueReference vr, fmi3Float64 *value) {
    if (vr == 0) {
        *value = inst->core.time;
        return BISO_OK;
    }
    return biso_get_real(inst, vr, value);
}

static int get_boolean(biso_instance *inst, fmi3ValueReference vr, fmi3Boolean *value) {
    int v = 0, s = biso_get_boolean(inst, vr, &v);
    *value = v != 0;
    return s;
}

#define GETTER(Name, ctype, call)                                                                          \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[],               \
                             size_t nValueReferences, ctype values[], size_t nValues) {                    \
        size_t i;                                                                                          \
        int status = fmi3OK;                                                                               \
        CHECK_INSTANCE("fmi3Get" #Name);                                                                   \
        if (nValues != nValueReferences) {                                                                 \
            biso_log(INST, BISO_ERROR, "fmi3Get" #Name ": every variable is a scalar: nValues must equal " \
                     "nValueReferences");                                                                  \
            return fmi3Error;                                                                              \
        }                                                                                                  \
        for (i = 0; i < nValueReferences; i++) {                                                           \
            int s = call;                                                                                  \
            if (s > status) status = s;                                                                    \
        }                                                                                                  \
        return (fmi3Status)status;                                                                         \
    }

GETTER(Float64, fmi3Float64, get_float64(INST, valueReferences[i], &values[i]))
GETTER(Int32, fmi3Int32, biso_get_integer(INST, valueReferences[i], &values[i]))
GETTER(Boolean, fmi3Boolean, get_boolean(INST, valueReferences[i], &values[i]))
GETTER(String, fmi3String, biso_get_string(INST, valueReferences[i], &values[i]))

#define SETTER(Name, ctype, call)                                                                          \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[],               \
                             size_t nValueReferences, const ctype values[], size_t nValues) {              \
        size_t i;                                                                                          \
        int status = fmi3OK;                                                                               \
        CHECK_INSTANCE("fmi3Set" #Name);                                                                   \
        if (nValues != nValueReferences) {                                                                 \
            biso_log(INST, BISO_ERROR, "fmi3Set" #Name ": every variable is a scalar: nValues must equal " \
                     "nValueReferences");                                                                  \
            return fmi3Error;                                                                              \
        }                                                                                                  \
        biso_begin_set(INST, "fmi3Set" #Name);                                                             \
        for (i = 0; i < nValueReferences; i++) {                                                           \
            int s = call;                                                                                  \
            if (s > status) status = s;                                                                    \
        }                                                                                                  \
        return (fmi3Status)biso_end_set(INST, status);                                                     \
    }

SETTER(Float64, fmi3Float64, biso_set_real(INST, valueReferences[i], values[i]))
SETTER(Int32, fmi3Int32, biso_set_integer(INST, valueReferences[i], values[i]))
SETTER(Boolean, fmi3Boolean, biso_set_boolean(INST, valueReferences[i], values[i]))
SETTER(String, fmi3String, biso_set_string(INST, valueReferences[i], values[i]))

/* ---- FMU state ------------------------------------------------------------------------ */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    biso_core *copy;
    CHECK_INSTANCE("fmi3GetFMUState");
    if (!FMUState) return fmi3Error;
    copy = (biso_core *)*FMUState;
    if (!copy) copy = (biso_core *)malloc(sizeof *copy);
    if (!copy) {
        biso_log(INST, BISO_ERROR, "fmi3GetFMUState: out of memory");
        return fmi3Error;
    }
    memcpy(copy, &INST->core, sizeof *copy);
    *FMUState = copy;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    CHECK_INSTANCE("fmi3SetFMUState");
    if (!FMUState) {
        biso_log(INST, BISO_ERROR, "fmi3SetFMUState: no state given");
        return fmi3Error;
    }
    memcpy(&INST->core, FMUState, sizeof INST->core);
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    CHECK_INSTANCE("fmi3FreeFMUState");
    if (FMUState) {
        free(*FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    (void)FMUState;
    CHECK_INSTANCE("fmi3SerializedFMUStateSize");
    if (!size) return fmi3Error;
    *size = biso_serialized_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    CHECK_INSTANCE("fmi3SerializeFMUState");
    if (!FMUState || !serializedState || size < biso_serialized_size()) {
        biso_log(INST, BISO_ERROR, "fmi3SerializeFMUState: needs a state and %lu bytes",
                 (unsigned long)biso_serialized_size());
        return fmi3Error;
    }
    biso_serialize((const biso_core *)FMUState, (unsigned char *)serializedState);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    biso_core *copy;
    CHECK_INSTANCE("fmi3DeserializeFMUState");
    if (!FMUState) return fmi3Error;
    copy = (biso_core *)malloc(sizeof *copy);
    if (!copy) return fmi3Error;
    if (biso_deserialize(INST, (const unsigned char *)serializedState, size, copy) != BISO_OK) {
        free(copy);
        return fmi3Error;
    }
    free(*FMUState);
    *FMUState = copy;
    return fmi3OK;
}

/* ---- what this FMU does not provide --------------------------------------------------- */
#include "fmi3_unsupported.h"

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    int status;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK_INSTANCE("fmi3DoStep");
    status = biso_do_step(INST, currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = INST->core.time;
    return (fmi3Status)status;
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference;
    (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition", "co-simulation only");
}
