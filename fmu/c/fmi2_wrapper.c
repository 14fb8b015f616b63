/* FMI 2.0 co-simulation API over the boat model (model.h): translation, checks, logging. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "model.h"

typedef struct {
    BoatModel *model;
    char *name;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment environment;
} Instance;

static fmi2Status to_fmi2(BoatStatus s) {
    return s == BOAT_OK ? fmi2OK : s == BOAT_WARNING ? fmi2Warning : fmi2Error;
}

/* FMI 2.0 loggers treat the message as a printf format. Pass it as the format with every
   '%' doubled and no arguments: a logger that formats prints it as is, and one that cannot
   read C varargs (Python through ctypes) needs no proxy, only to undo the doubling. */
static void deliver(void *wrapper, BoatStatus status, const char *category, const char *msg) {
    Instance *inst = (Instance *)wrapper;
    char escaped[2048];
    size_t i = 0;
    if (!inst->logger) return;
    for (; *msg && i + 2 < sizeof escaped; msg++) {
        if (*msg == '%') escaped[i++] = '%';
        escaped[i++] = *msg;
    }
    escaped[i] = '\0';
    inst->logger(inst->environment, inst->name, to_fmi2(status), category, escaped);
}

#define MODEL(c) (((Instance *)(c))->model)
#define GUARD(c, allowed, fname)                                             \
    do {                                                                     \
        if (!(c)) return fmi2Error;                                          \
        boat_log(MODEL(c), BOAT_OK, BOAT_LOG_CALLS, "%s", fname);            \
        if (!boat_phase_ok(MODEL(c), (allowed), fname)) return fmi2Error;    \
    } while (0)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n,
                               const fmi2String categories[]) {
    if (!c) return fmi2Error;
    return to_fmi2(boat_set_debug_logging(MODEL(c), loggingOn, n, categories));
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid,
                              fmi2String resourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Instance *inst;
    fmi2CallbackLogger logger = functions ? functions->logger : NULL;
    void *env = functions ? functions->componentEnvironment : NULL;
    const char *name = instanceName && instanceName[0] ? instanceName : "canalnav_boat";
    (void)resourceLocation;
    (void)visible;
    if (fmuType != fmi2CoSimulation) {
        if (logger) logger(env, name, fmi2Error, "logStatusError",
                           "this FMU supports co-simulation only");
        return NULL;
    }
    if (!guid || strcmp(guid, BOAT_TOKEN) != 0) {
        if (logger) logger(env, name, fmi2Error, "logStatusError",
                           "the GUID does not match this FMU's modelDescription.xml");
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    inst->name = (char *)malloc(strlen(name) + 1);
    if (inst->name) strcpy(inst->name, name);
    inst->logger = logger;
    inst->environment = env;
    inst->model = boat_new(deliver, inst, loggingOn);
    if (!inst->name || !inst->model) {
        free(inst->name);
        boat_free(inst->model);
        free(inst);
        return NULL;
    }
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *inst = (Instance *)c;
    if (!inst) return;
    boat_free(inst->model);
    free(inst->name);
    free(inst);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BoatState *s;
    GUARD(c, PHASE_INSTANTIATED, "fmi2SetupExperiment");
    (void)toleranceDefined;
    (void)tolerance;
    s = &MODEL(c)->s;
    s->start_time = startTime;
    s->stop_time_defined = stopTimeDefined;
    s->stop_time = stopTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    BoatState *s;
    if (!c) return fmi2Error;
    s = &MODEL(c)->s;
    return to_fmi2(boat_enter_initialization(MODEL(c), s->start_time, s->stop_time_defined,
                                             s->stop_time));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    if (!c) return fmi2Error;
    return to_fmi2(boat_exit_initialization(MODEL(c)));
}

fmi2Status fmi2Terminate(fmi2Component c) {
    if (!c) return fmi2Error;
    return to_fmi2(boat_terminate(MODEL(c)));
}

fmi2Status fmi2Reset(fmi2Component c) {
    if (!c) return fmi2Error;
    boat_reset(MODEL(c));
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    if (!c) return fmi2Error;
    return to_fmi2(boat_get(MODEL(c), vr, nvr, value));
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    GUARD(c, PHASE_INSTANTIATED | PHASE_INITIALIZATION | PHASE_STEP, "fmi2SetReal");
    return to_fmi2(boat_set(MODEL(c), vr, nvr, value));
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    (void)value;
    if (!c) return fmi2Error;
    return to_fmi2(boat_no_such_type(MODEL(c), "Integer", vr, nvr));
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    (void)value;
    if (!c) return fmi2Error;
    return to_fmi2(boat_no_such_type(MODEL(c), "Boolean", vr, nvr));
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    (void)value;
    if (!c) return fmi2Error;
    return to_fmi2(boat_no_such_type(MODEL(c), "String", vr, nvr));
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    (void)value;
    if (!c) return fmi2Error;
    return to_fmi2(boat_no_such_type(MODEL(c), "Integer", vr, nvr));
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    (void)value;
    if (!c) return fmi2Error;
    return to_fmi2(boat_no_such_type(MODEL(c), "Boolean", vr, nvr));
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    (void)value;
    if (!c) return fmi2Error;
    return to_fmi2(boat_no_such_type(MODEL(c), "String", vr, nvr));
}

/* -- FMU state ----------------------------------------------------------------------- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    BoatState *snapshot;
    GUARD(c, PHASE_ANY, "fmi2GetFMUstate");
    if (!state) return fmi2Error;
    if (*state) { /* reuse the caller's earlier snapshot */
        memcpy(*state, &MODEL(c)->s, sizeof(BoatState));
        return fmi2OK;
    }
    snapshot = boat_state_new(MODEL(c));
    if (!snapshot) {
        boat_log(MODEL(c), BOAT_ERROR, BOAT_LOG_ERROR, "get FMU state: out of memory");
        return fmi2Error;
    }
    *state = snapshot;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    GUARD(c, PHASE_ANY, "fmi2SetFMUstate");
    return to_fmi2(boat_state_restore(MODEL(c), (const BoatState *)state));
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    if (!c) return fmi2Error;
    if (state) {
        free(*state);
        *state = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    (void)state;
    if (!c || !size) return fmi2Error;
    *size = boat_serialized_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[],
                                 size_t size) {
    if (!c || !state || !bytes) return fmi2Error;
    if (size < boat_serialized_size()) {
        boat_log(MODEL(c), BOAT_ERROR, BOAT_LOG_ERROR,
                 "serialize FMU state: buffer of %lu bytes is too small (need %lu)",
                 (unsigned long)size, (unsigned long)boat_serialized_size());
        return fmi2Error;
    }
    boat_serialize((const BoatState *)state, (unsigned char *)bytes);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state) {
    BoatState *target;
    if (!c || !state) return fmi2Error;
    target = *state ? (BoatState *)*state : (BoatState *)malloc(sizeof(BoatState));
    if (!target) return fmi2Error;
    if (boat_deserialize(MODEL(c), (const unsigned char *)bytes, size, target) != BOAT_OK) {
        if (!*state) free(target);
        return fmi2Error;
    }
    *state = target;
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                        size_t nUnknown, const fmi2ValueReference vKnown[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown; (void)nUnknown; (void)vKnown; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    if (!c) return fmi2Error;
    boat_log(MODEL(c), BOAT_ERROR, BOAT_LOG_ERROR, "directional derivatives are not provided");
    return fmi2Error;
}

/* -- co-simulation ------------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    boat_log(MODEL(c), BOAT_ERROR, BOAT_LOG_ERROR,
             "input derivatives are not supported (canInterpolateInputs is false)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    boat_log(MODEL(c), BOAT_ERROR, BOAT_LOG_ERROR, "output derivatives are not provided");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!c) return fmi2Error;
    return to_fmi2(boat_do_step(MODEL(c), currentCommunicationPoint, communicationStepSize));
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    if (!c) return fmi2Error;
    boat_log(MODEL(c), BOAT_ERROR, BOAT_LOG_ERROR, "doStep never runs asynchronously");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    if (!c) return fmi2Error;
    boat_log(MODEL(c), BOAT_ERROR, BOAT_LOG_ERROR, "fmi2GetStatus: doStep is synchronous");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    if (!c || !value) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = MODEL(c)->s.time;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    return c ? fmi2Discard : fmi2Error;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    if (!c || !value) return fmi2Error;
    if (s == fmi2Terminated) {
        *value = fmi2False;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    return c ? fmi2Discard : fmi2Error;
}

/* -- model exchange: not provided; present because tools bind every fmi2 symbol --------- */

#define NOT_MODEL_EXCHANGE(c)                                                          \
    do {                                                                               \
        if (c) boat_log(MODEL(c), BOAT_ERROR, BOAT_LOG_ERROR,                          \
                        "this FMU supports co-simulation only");                       \
        return fmi2Error;                                                              \
    } while (0)

fmi2Status fmi2EnterEventMode(fmi2Component c) { NOT_MODEL_EXCHANGE(c); }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    (void)info;
    NOT_MODEL_EXCHANGE(c);
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { NOT_MODEL_EXCHANGE(c); }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode,
                                       fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    NOT_MODEL_EXCHANGE(c);
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    (void)time;
    NOT_MODEL_EXCHANGE(c);
}
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    (void)x; (void)nx;
    NOT_MODEL_EXCHANGE(c);
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    (void)derivatives; (void)nx;
    NOT_MODEL_EXCHANGE(c);
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators; (void)ni;
    NOT_MODEL_EXCHANGE(c);
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    (void)x; (void)nx;
    NOT_MODEL_EXCHANGE(c);
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    (void)x_nominal; (void)nx;
    NOT_MODEL_EXCHANGE(c);
}
