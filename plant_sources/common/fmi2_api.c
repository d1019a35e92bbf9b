/* FMI 2.0 co-simulation interface over the shared instance core. */
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "forecast.h"
#include "instance.h"
#include "faults.h"

typedef struct {
    Instance *core;
    fmi2CallbackFunctions callbacks;
    int model_exchange;  /* instantiated as fmi2ModelExchange: the importer integrates m.x */
} Fmi2Instance;

/* Model exchange exposes the states and their derivatives after the model's variables:
 * value reference N_VARIABLES + i is state i, N_VARIABLES + N_STATES + i its derivative. */
#define VR_FIRST_STATE N_VARIABLES
#define VR_FIRST_DERIVATIVE (N_VARIABLES + N_STATES)

static void log_fmi2(void *env, const char *instance_name, Status status, const char *message) {
    Fmi2Instance *c = (Fmi2Instance *)env;
    if (c->callbacks.logger) {
        c->callbacks.logger(c->callbacks.componentEnvironment, instance_name, (fmi2Status)status,
                            status >= STATUS_DISCARD ? "logStatusError" : "logAll", "%s", message);
    }
}

static fmi2Status to_fmi2(Status status) {
    if (status == STATUS_ERROR) return fmi2Error;
    return (fmi2Status)status;
}

#define CORE(c) (((Fmi2Instance *)(c))->core)

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[]) {
    (void)c; (void)loggingOn; (void)nCategories; (void)categories;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Fmi2Instance *c;
    (void)fmuResourceLocation; (void)visible; (void)loggingOn;
    if (!functions || (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) || !fmuGUID ||
        strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        if (functions && functions->logger) {
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                              "only GUID %s is supported", INSTANTIATION_TOKEN);
        }
        return NULL;
    }
    c = (Fmi2Instance *)calloc(1, sizeof(Fmi2Instance));
    if (!c) return NULL;
    c->callbacks = *functions;
    c->model_exchange = fmuType == fmi2ModelExchange;
    c->core = instance_new(instanceName, log_fmi2, c);
    if (!c->core) { free(c); return NULL; }
    return c;
}

void fmi2FreeInstance(fmi2Component c) {
    if (!c) return;
    instance_free(CORE(c));
    free(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined; (void)tolerance;
    if (CORE(c)->mode != MODE_INSTANTIATED) return fmi2Error;
    CORE(c)->m.time = startTime;
    prlpid_fault_on_setup(CORE(c), stopTimeDefined, stopTime);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    return to_fmi2(instance_enter_initialization(CORE(c), CORE(c)->m.time));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) { return to_fmi2(instance_exit_initialization(CORE(c))); }

fmi2Status fmi2Terminate(fmi2Component c) {
    CORE(c)->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    instance_reset(CORE(c));
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *core = CORE(c);
    double dx[N_STATES + 1];
    size_t i;
    if (!((Fmi2Instance *)c)->model_exchange) return to_fmi2(instance_get_real(core, vr, nvr, value));
    /* model exchange: outputs follow the states, time and inputs the importer set last */
    if (core->mode != MODE_INITIALIZATION) model_outputs(&core->m);
    model_derivatives(&core->m, core->m.time, core->m.x, dx);
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= VR_FIRST_DERIVATIVE && vr[i] < VR_FIRST_DERIVATIVE + N_STATES) {
            value[i] = dx[vr[i] - VR_FIRST_DERIVATIVE];
        } else if (vr[i] >= VR_FIRST_STATE && vr[i] < VR_FIRST_DERIVATIVE) {
            value[i] = core->m.x[vr[i] - VR_FIRST_STATE];
        } else if (instance_get_real(core, &vr[i], 1, &value[i]) != STATUS_OK) {
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    return to_fmi2(instance_set_real(CORE(c), vr, nvr, value));
}

/* This model has only real variables. */
static fmi2Status no_such_variable(fmi2Component c, size_t nvr) {
    if (nvr == 0) return fmi2OK;
    instance_log(CORE(c), STATUS_ERROR, "the model has no integer, boolean or string variables");
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}

/* FMU state: version-neutral in instance.c. */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) { return to_fmi2(instance_get_state(CORE(c), state)); }

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) { return to_fmi2(instance_set_state(CORE(c), state)); }

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    (void)c;
    instance_free_state(state);
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    (void)c; (void)state;
    *size = instance_serialized_state_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[], size_t size) {
    return to_fmi2(instance_serialize_state(CORE(c), state, (unsigned char *)serializedState, size));
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *state) {
    return to_fmi2(instance_deserialize_state(CORE(c), (const unsigned char *)serializedState, size, state));
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    instance_log(CORE(c), STATUS_ERROR, "directional derivatives are not provided");
    return fmi2Error;
}

/* Model exchange: the importer's solver integrates the core's states; no events, no event indicators. */
fmi2Status fmi2EnterEventMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    (void)c;
    memset(info, 0, sizeof(*info));
    return fmi2OK;
}
fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    model_constrain(CORE(c)->m.x);  /* e.g. a tank level never goes negative */
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}
fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) { CORE(c)->m.time = time; return fmi2OK; }
static fmi2Status state_count(fmi2Component c, size_t nx) {
    if (nx == N_STATES) return fmi2OK;
    instance_log(CORE(c), STATUS_ERROR, "the model has %d continuous states, got nx = %lu", N_STATES, (unsigned long)nx);
    return fmi2Error;
}
fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    if (state_count(c, nx) != fmi2OK) return fmi2Error;
    memcpy(CORE(c)->m.x, x, nx * sizeof(double));
    return fmi2OK;
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    if (state_count(c, nx) != fmi2OK) return fmi2Error;
    model_derivatives(&CORE(c)->m, CORE(c)->m.time, CORE(c)->m.x, derivatives);
    return fmi2OK;
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators;
    if (ni == 0) return fmi2OK;
    instance_log(CORE(c), STATUS_ERROR, "the model has no event indicators, got ni = %lu", (unsigned long)ni);
    return fmi2Error;
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    if (state_count(c, nx) != fmi2OK) return fmi2Error;
    memcpy(x, CORE(c)->m.x, nx * sizeof(double));
    return fmi2OK;
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    size_t i;
    if (state_count(c, nx) != fmi2OK) return fmi2Error;
    for (i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    instance_log(CORE(c), STATUS_ERROR, "input derivatives are not supported");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    instance_log(CORE(c), STATUS_ERROR, "output derivatives are not supported");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    return to_fmi2(instance_do_step(CORE(c), currentCommunicationPoint, communicationStepSize));
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value; (void)c; return fmi2Discard;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    if (s == fmi2LastSuccessfulTime) {
        *value = CORE(c)->m.time;
        return fmi2OK;
    }
    return fmi2Discard;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    if (s == fmi2Terminated) {
        *value = fmi2False;
        return fmi2OK;
    }
    (void)c; return fmi2Discard;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)c; (void)s; (void)value; return fmi2Discard;
}

/* The reward forecast beside the FMI API (forecast.h): unwrap both instances to the shared core. */
int prlpid_forecast(void *plant, void *prior, const PrlpidForecastSetup *setup, const PrlpidForecastInput *input,
                    PrlpidForecastResult *result) {
    if (!plant || !prior) return PRLPID_EINVAL;
    return prlpid_forecast_core(CORE(plant), CORE(prior), setup, input, result);
}
