/* FMI 3.0 co-simulation API over the boat model (model.h): translation, checks, logging. */
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "model.h"

typedef struct {
    BoatModel *model;
    fmi3LogMessageCallback log_message;
    fmi3InstanceEnvironment environment;
} Instance;

static fmi3Status to_fmi3(BoatStatus s) {
    return s == BOAT_OK ? fmi3OK : s == BOAT_WARNING ? fmi3Warning : fmi3Error;
}

static void deliver(void *wrapper, BoatStatus status, const char *category, const char *msg) {
    Instance *inst = (Instance *)wrapper;
    if (inst->log_message) inst->log_message(inst->environment, to_fmi3(status), category, msg);
}

#define MODEL(i) (((Instance *)(i))->model)
#define CHECK(i)                         \
    do {                                 \
        if (!(i)) return fmi3Error;      \
    } while (0)

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn,
                               size_t nCategories, const fmi3String categories[]) {
    CHECK(instance);
    return to_fmi3(boat_set_debug_logging(MODEL(instance), loggingOn, nCategories, categories));
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    Instance *inst;
    (void)instanceName; (void)resourcePath; (void)visible; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)intermediateUpdate;
    if (!instantiationToken || strcmp(instantiationToken, BOAT_TOKEN) != 0) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "the instantiation token does not match this FMU's modelDescription.xml");
        return NULL;
    }
    if (eventModeUsed || nRequiredIntermediateVariables > 0) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "event mode and intermediate variables are not supported");
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    inst->log_message = logMessage;
    inst->environment = instanceEnvironment;
    inst->model = boat_new(deliver, inst, loggingOn);
    if (!inst->model) {
        free(inst);
        return NULL;
    }
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "this FMU supports co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn; (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "this FMU supports co-simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    if (!instance) return;
    boat_free(MODEL(instance));
    free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined; (void)tolerance;
    CHECK(instance);
    return to_fmi3(boat_enter_initialization(MODEL(instance), startTime, stopTimeDefined,
                                             stopTime));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    CHECK(instance);
    return to_fmi3(boat_exit_initialization(MODEL(instance)));
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    CHECK(instance);
    boat_log(MODEL(instance), BOAT_ERROR, BOAT_LOG_ERROR, "this FMU has no event mode");
    return fmi3Error;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    CHECK(instance);
    return to_fmi3(boat_terminate(MODEL(instance)));
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    CHECK(instance);
    boat_reset(MODEL(instance));
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    CHECK(instance);
    if (nValues != nValueReferences) {
        boat_log(MODEL(instance), BOAT_ERROR, BOAT_LOG_ERROR,
                 "fmi3GetFloat64: %lu values for %lu scalar value references",
                 (unsigned long)nValues, (unsigned long)nValueReferences);
        return fmi3Error;
    }
    return to_fmi3(boat_get(MODEL(instance), valueReferences, nValueReferences, values));
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    CHECK(instance);
    boat_log(MODEL(instance), BOAT_OK, BOAT_LOG_CALLS, "fmi3SetFloat64");
    if (!boat_phase_ok(MODEL(instance), PHASE_INSTANTIATED | PHASE_INITIALIZATION | PHASE_STEP,
                       "fmi3SetFloat64"))
        return fmi3Error;
    if (nValues != nValueReferences) {
        boat_log(MODEL(instance), BOAT_ERROR, BOAT_LOG_ERROR,
                 "fmi3SetFloat64: %lu values for %lu scalar value references",
                 (unsigned long)nValues, (unsigned long)nValueReferences);
        return fmi3Error;
    }
    return to_fmi3(boat_set(MODEL(instance), valueReferences, nValueReferences, values));
}

/* Every other type: this FMU has none. */
#define NO_SUCH_TYPE(Name, T, CONST)                                                          \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,  \
                             T values[], size_t nValues) {                                    \
        (void)values; (void)nValues;                                                          \
        CHECK(instance);                                                                      \
        return to_fmi3(boat_no_such_type(MODEL(instance), #Name, vr, nvr));                  \
    }                                                                                         \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,  \
                             CONST T values[], size_t nValues) {                              \
        (void)values; (void)nValues;                                                          \
        CHECK(instance);                                                                      \
        return to_fmi3(boat_no_such_type(MODEL(instance), #Name, vr, nvr));                  \
    }

NO_SUCH_TYPE(Float32, fmi3Float32, const)
NO_SUCH_TYPE(Int8, fmi3Int8, const)
NO_SUCH_TYPE(UInt8, fmi3UInt8, const)
NO_SUCH_TYPE(Int16, fmi3Int16, const)
NO_SUCH_TYPE(UInt16, fmi3UInt16, const)
NO_SUCH_TYPE(Int32, fmi3Int32, const)
NO_SUCH_TYPE(UInt32, fmi3UInt32, const)
NO_SUCH_TYPE(Int64, fmi3Int64, const)
NO_SUCH_TYPE(UInt64, fmi3UInt64, const)
NO_SUCH_TYPE(Boolean, fmi3Boolean, const)
NO_SUCH_TYPE(String, fmi3String, const)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    (void)valueSizes; (void)values; (void)nValues;
    CHECK(instance);
    return to_fmi3(boat_no_such_type(MODEL(instance), "Binary", vr, nvr));
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    (void)valueSizes; (void)values; (void)nValues;
    CHECK(instance);
    return to_fmi3(boat_no_such_type(MODEL(instance), "Binary", vr, nvr));
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        fmi3Clock values[]) {
    (void)values;
    CHECK(instance);
    return to_fmi3(boat_no_such_type(MODEL(instance), "Clock", vr, nvr));
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                        const fmi3Clock values[]) {
    (void)values;
    CHECK(instance);
    return to_fmi3(boat_no_such_type(MODEL(instance), "Clock", vr, nvr));
}

/* -- dependencies: as declared in the modelDescription (outputs: no direct feedthrough) -- */

static int is_output(fmi3ValueReference vr) {
    return vr >= BOAT_GROUP_X && vr < BOAT_GROUP_ACT + 2;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    CHECK(instance);
    if (!nDependencies || !is_output(valueReference)) {
        boat_log(MODEL(instance), BOAT_ERROR, BOAT_LOG_ERROR,
                 "dependencies: value reference %u is not an output", valueReference);
        return fmi3Error;
    }
    *nDependencies = 0;
    return fmi3OK;
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds;
    CHECK(instance);
    if (!is_output(dependent) || nDependencies != 0) {
        boat_log(MODEL(instance), BOAT_ERROR, BOAT_LOG_ERROR,
                 "dependencies: value reference %u has no direct dependencies", dependent);
        return fmi3Error;
    }
    return fmi3OK;
}

/* -- FMU state ----------------------------------------------------------------------- */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    BoatState *snapshot;
    CHECK(instance);
    if (!FMUState) return fmi3Error;
    if (*FMUState) {
        memcpy(*FMUState, &MODEL(instance)->s, sizeof(BoatState));
        return fmi3OK;
    }
    snapshot = boat_state_new(MODEL(instance));
    if (!snapshot) {
        boat_log(MODEL(instance), BOAT_ERROR, BOAT_LOG_ERROR, "get FMU state: out of memory");
        return fmi3Error;
    }
    *FMUState = snapshot;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    CHECK(instance);
    return to_fmi3(boat_state_restore(MODEL(instance), (const BoatState *)FMUState));
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    CHECK(instance);
    if (FMUState) {
        free(*FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    (void)FMUState;
    CHECK(instance);
    if (!size) return fmi3Error;
    *size = boat_serialized_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    CHECK(instance);
    if (!FMUState || !serializedState) return fmi3Error;
    if (size < boat_serialized_size()) {
        boat_log(MODEL(instance), BOAT_ERROR, BOAT_LOG_ERROR,
                 "serialize FMU state: buffer of %lu bytes is too small (need %lu)",
                 (unsigned long)size, (unsigned long)boat_serialized_size());
        return fmi3Error;
    }
    boat_serialize((const BoatState *)FMUState, (unsigned char *)serializedState);
    return fmi3OK;
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    BoatState *target;
    CHECK(instance);
    if (!FMUState) return fmi3Error;
    target = *FMUState ? (BoatState *)*FMUState : (BoatState *)malloc(sizeof(BoatState));
    if (!target) return fmi3Error;
    if (boat_deserialize(MODEL(instance), (const unsigned char *)serializedState, size,
                         target) != BOAT_OK) {
        if (!*FMUState) free(target);
        return fmi3Error;
    }
    *FMUState = target;
    return fmi3OK;
}

/* -- not provided ---------------------------------------------------------------------- */

#define UNSUPPORTED(instance, what)                                                     \
    do {                                                                                \
        CHECK(instance);                                                                \
        boat_log(MODEL(instance), BOAT_ERROR, BOAT_LOG_ERROR, "%s is not supported",    \
                 what);                                                                 \
        return fmi3Error;                                                               \
    } while (0)

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance,
                                        const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    UNSUPPORTED(instance, "fmi3GetDirectionalDerivative");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    UNSUPPORTED(instance, "fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    UNSUPPORTED(instance, "configuration mode");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    UNSUPPORTED(instance, "configuration mode");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)intervals; (void)qualifiers;
    UNSUPPORTED(instance, "clocks");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t nvr, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers;
    UNSUPPORTED(instance, "clocks");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts;
    UNSUPPORTED(instance, "clocks");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                size_t nvr, fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    UNSUPPORTED(instance, "clocks");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, const fmi3Float64 intervals[]) {
    (void)vr; (void)nvr; (void)intervals;
    UNSUPPORTED(instance, "clocks");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                   size_t nvr, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    UNSUPPORTED(instance, "clocks");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                               const fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts;
    UNSUPPORTED(instance, "clocks");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[],
                                size_t nvr, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    UNSUPPORTED(instance, "clocks");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    UNSUPPORTED(instance, "event mode");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate; (void)terminateSimulation;
    (void)nominalsOfContinuousStatesChanged; (void)valuesOfContinuousStatesChanged;
    (void)nextEventTimeDefined; (void)nextEventTime;
    UNSUPPORTED(instance, "event mode");
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    UNSUPPORTED(instance, "model exchange");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    UNSUPPORTED(instance, "model exchange");
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    UNSUPPORTED(instance, "model exchange");
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    UNSUPPORTED(instance, "model exchange");
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    (void)derivatives; (void)nContinuousStates;
    UNSUPPORTED(instance, "model exchange");
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    (void)eventIndicators; (void)nEventIndicators;
    UNSUPPORTED(instance, "model exchange");
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    UNSUPPORTED(instance, "model exchange");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    (void)nominals; (void)nContinuousStates;
    UNSUPPORTED(instance, "model exchange");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    CHECK(instance);
    if (!nEventIndicators) return fmi3Error;
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    CHECK(instance);
    if (!nContinuousStates) return fmi3Error;
    *nContinuousStates = 0;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    UNSUPPORTED(instance, "event mode (the FMU is always in step mode after initialization)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[],
                                    size_t nvr, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    UNSUPPORTED(instance, "output derivatives");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    BoatStatus status;
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK(instance);
    status = boat_do_step(MODEL(instance), currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = MODEL(instance)->s.time;
    return to_fmi3(status);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    UNSUPPORTED(instance, "scheduled execution");
}
