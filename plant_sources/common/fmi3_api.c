/* FMI 3.0 co-simulation interface over the shared instance core. */
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "forecast.h"
#include "instance.h"
#include "faults.h"

typedef struct {
    Instance *core;
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log_message;
} Fmi3Instance;

#define CORE(c) (((Fmi3Instance *)(c))->core)

static void log_fmi3(void *env, const char *instance_name, Status status, const char *message) {
    Fmi3Instance *c = (Fmi3Instance *)env;
    (void)instance_name;
    if (c->log_message) {
        c->log_message(c->environment, (fmi3Status)status, status >= STATUS_DISCARD ? "logStatusError" : "logAll", message);
    }
}

static fmi3Status to_fmi3(Status status) { return (fmi3Status)status; }

static fmi3Status unsupported(fmi3Instance c, const char *what) {
    instance_log(CORE(c), STATUS_ERROR, "%s is not supported by this FMU", what);
    return fmi3Error;
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean loggingOn, size_t nCategories, const fmi3String categories[]) {
    (void)c; (void)loggingOn; (void)nCategories; (void)categories;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                          fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "model exchange is not supported");
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                         fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    Fmi3Instance *c;
    (void)resourcePath; (void)visible; (void)loggingOn; (void)eventModeUsed; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (!instantiationToken || strcmp(instantiationToken, INSTANTIATION_TOKEN) != 0) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "wrong instantiation token");
        return NULL;
    }
    c = (Fmi3Instance *)calloc(1, sizeof(Fmi3Instance));
    if (!c) return NULL;
    c->environment = instanceEnvironment;
    c->log_message = logMessage;
    c->core = instance_new(instanceName, log_fmi3, c);
    if (!c->core) { free(c); return NULL; }
    return c;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                               fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "scheduled execution is not supported");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance c) {
    if (!c) return;
    instance_free(CORE(c));
    free(c);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined; (void)tolerance;
    prlpid_fault_on_setup(CORE(c), stopTimeDefined, stopTime);
    return to_fmi3(instance_enter_initialization(CORE(c), startTime));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { return to_fmi3(instance_exit_initialization(CORE(c))); }

fmi3Status fmi3EnterEventMode(fmi3Instance c) { return unsupported(c, "event mode"); }

fmi3Status fmi3Terminate(fmi3Instance c) {
    CORE(c)->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance c) {
    instance_reset(CORE(c));
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[], size_t nValues) {
    if (nValues != nvr) return unsupported(c, "array variables");
    return to_fmi3(instance_get_real(CORE(c), vr, nvr, values));
}

fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[], size_t nValues) {
    if (nValues != nvr) return unsupported(c, "array variables");
    return to_fmi3(instance_set_real(CORE(c), vr, nvr, values));
}

/* The model has only Float64 variables: every other type is an error unless nothing is asked for. */
#define NO_VARIABLES_OF_TYPE(fn, type)                                                                       \
    fmi3Status fn(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, type values[], size_t nValues) { \
        (void)vr; (void)values; (void)nValues;                                                              \
        return nvr == 0 ? fmi3OK : unsupported(c, "variables of this type");                                \
    }

NO_VARIABLES_OF_TYPE(fmi3GetFloat32, fmi3Float32)
NO_VARIABLES_OF_TYPE(fmi3GetInt8, fmi3Int8)
NO_VARIABLES_OF_TYPE(fmi3GetUInt8, fmi3UInt8)
NO_VARIABLES_OF_TYPE(fmi3GetInt16, fmi3Int16)
NO_VARIABLES_OF_TYPE(fmi3GetUInt16, fmi3UInt16)
NO_VARIABLES_OF_TYPE(fmi3GetInt32, fmi3Int32)
NO_VARIABLES_OF_TYPE(fmi3GetUInt32, fmi3UInt32)
NO_VARIABLES_OF_TYPE(fmi3GetInt64, fmi3Int64)
NO_VARIABLES_OF_TYPE(fmi3GetUInt64, fmi3UInt64)
NO_VARIABLES_OF_TYPE(fmi3GetBoolean, fmi3Boolean)
NO_VARIABLES_OF_TYPE(fmi3GetString, fmi3String)
NO_VARIABLES_OF_TYPE(fmi3SetFloat32, const fmi3Float32)
NO_VARIABLES_OF_TYPE(fmi3SetInt8, const fmi3Int8)
NO_VARIABLES_OF_TYPE(fmi3SetUInt8, const fmi3UInt8)
NO_VARIABLES_OF_TYPE(fmi3SetInt16, const fmi3Int16)
NO_VARIABLES_OF_TYPE(fmi3SetUInt16, const fmi3UInt16)
NO_VARIABLES_OF_TYPE(fmi3SetInt32, const fmi3Int32)
NO_VARIABLES_OF_TYPE(fmi3SetUInt32, const fmi3UInt32)
NO_VARIABLES_OF_TYPE(fmi3SetInt64, const fmi3Int64)
NO_VARIABLES_OF_TYPE(fmi3SetUInt64, const fmi3UInt64)
NO_VARIABLES_OF_TYPE(fmi3SetBoolean, const fmi3Boolean)
NO_VARIABLES_OF_TYPE(fmi3SetString, const fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    return nvr == 0 ? fmi3OK : unsupported(c, "binary variables");
}
fmi3Status fmi3SetBinary(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    return nvr == 0 ? fmi3OK : unsupported(c, "binary variables");
}
fmi3Status fmi3GetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)vr; (void)values;
    return nvr == 0 ? fmi3OK : unsupported(c, "clocks");
}
fmi3Status fmi3SetClock(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    (void)vr; (void)values;
    return nvr == 0 ? fmi3OK : unsupported(c, "clocks");
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance c, fmi3ValueReference vr, size_t *nDependencies) {
    (void)vr; (void)nDependencies;
    return unsupported(c, "variable dependency queries");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance c, fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    return unsupported(c, "variable dependency queries");
}

/* FMU state: version-neutral in instance.c. */
fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *state) { return to_fmi3(instance_get_state(CORE(c), state)); }

fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState state) { return to_fmi3(instance_set_state(CORE(c), state)); }

fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *state) {
    (void)c;
    instance_free_state(state);
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance c, fmi3FMUState state, size_t *size) {
    (void)c; (void)state;
    *size = instance_serialized_state_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance c, fmi3FMUState state, fmi3Byte serializedState[], size_t size) {
    return to_fmi3(instance_serialize_state(CORE(c), state, (unsigned char *)serializedState, size));
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance c, const fmi3Byte serializedState[], size_t size, fmi3FMUState *state) {
    return to_fmi3(instance_deserialize_state(CORE(c), (const unsigned char *)serializedState, size, state));
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity; (void)nSensitivity;
    return unsupported(c, "directional derivatives");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity; (void)nSensitivity;
    return unsupported(c, "adjoint derivatives");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance c) { return unsupported(c, "configuration mode"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance c) { return unsupported(c, "configuration mode"); }

fmi3Status fmi3GetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)intervals; (void)qualifiers; return unsupported(c, "clocks");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers; return unsupported(c, "clocks");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts; return unsupported(c, "clocks");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; return unsupported(c, "clocks");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 intervals[]) {
    (void)vr; (void)nvr; (void)intervals; return unsupported(c, "clocks");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; return unsupported(c, "clocks");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts; return unsupported(c, "clocks");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; return unsupported(c, "clocks");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance c) { return unsupported(c, "discrete states"); }
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance c, fmi3Boolean *discreteStatesNeedUpdate, fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged, fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate; (void)terminateSimulation; (void)nominalsOfContinuousStatesChanged;
    (void)valuesOfContinuousStatesChanged; (void)nextEventTimeDefined; (void)nextEventTime;
    return unsupported(c, "discrete states");
}

/* Model exchange: not provided. */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance c) { return unsupported(c, "model exchange"); }
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance c, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return unsupported(c, "model exchange");
}
fmi3Status fmi3SetTime(fmi3Instance c, fmi3Float64 time) { (void)time; return unsupported(c, "model exchange"); }
fmi3Status fmi3SetContinuousStates(fmi3Instance c, const fmi3Float64 x[], size_t nx) { (void)x; (void)nx; return unsupported(c, "model exchange"); }
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance c, fmi3Float64 dx[], size_t nx) { (void)dx; (void)nx; return unsupported(c, "model exchange"); }
fmi3Status fmi3GetEventIndicators(fmi3Instance c, fmi3Float64 z[], size_t nz) { (void)z; (void)nz; return unsupported(c, "model exchange"); }
fmi3Status fmi3GetContinuousStates(fmi3Instance c, fmi3Float64 x[], size_t nx) { (void)x; (void)nx; return unsupported(c, "model exchange"); }
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance c, fmi3Float64 n[], size_t nx) { (void)n; (void)nx; return unsupported(c, "model exchange"); }
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance c, size_t *nz) { (void)nz; return unsupported(c, "model exchange"); }
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance c, size_t *nx) { (void)nx; return unsupported(c, "model exchange"); }

fmi3Status fmi3EnterStepMode(fmi3Instance c) { return unsupported(c, "event mode"); }

fmi3Status fmi3GetOutputDerivatives(fmi3Instance c, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    (void)vr; (void)nvr; (void)orders; (void)values; (void)nValues;
    return unsupported(c, "output derivatives");
}

fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Status status;
    (void)noSetFMUStatePriorToCurrentPoint;
    status = instance_do_step(CORE(c), currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = CORE(c)->m.time;
    return to_fmi3(status);
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance c, fmi3ValueReference clockReference, fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    return unsupported(c, "scheduled execution");
}

/* The reward forecast beside the FMI API (forecast.h): unwrap both instances to the shared core. */
int prlpid_forecast(void *plant, void *prior, const PrlpidForecastSetup *setup, const PrlpidForecastInput *input,
                    PrlpidForecastResult *result) {
    if (!plant || !prior) return PRLPID_EINVAL;
    return prlpid_forecast_core(CORE(plant), CORE(prior), setup, input, result);
}
