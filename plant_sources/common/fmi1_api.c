/* FMI 1.0 co-simulation (stand-alone) interface over the shared instance core.
 *
 * FMI 1.0 names every function <modelIdentifier>_fmi<Name>; MODEL_IDENTIFIER comes from the generated
 * variables.h. FMI 1.0 has no FMU state functions, so such an FMU cannot be its own predictive prior.
 */
#include <stdlib.h>
#include <string.h>

#include "fmi1Functions.h"
#include "instance.h"
#include "faults.h"

#define FMI1_CONCAT2(a, b) a##_fmi##b
#define FMI1_CONCAT(a, b) FMI1_CONCAT2(a, b)
#define FMI1(name) FMI1_CONCAT(MODEL_IDENTIFIER, name)

#if defined(_WIN32)
#define FMI1_EXPORT __declspec(dllexport)
#else
#define FMI1_EXPORT __attribute__((visibility("default")))
#endif

typedef struct {
    Instance *core;
    fmi1CallbackFunctions callbacks;
} Fmi1Instance;

#define CORE(c) (((Fmi1Instance *)(c))->core)

static void log_fmi1(void *env, const char *instance_name, Status status, const char *message) {
    Fmi1Instance *c = (Fmi1Instance *)env;
    if (c->callbacks.logger) {
        c->callbacks.logger(c, instance_name, (fmi1Status)status,
                            status >= STATUS_DISCARD ? "logStatusError" : "logAll", "%s", message);
    }
}

static fmi1Status to_fmi1(Status status) { return (fmi1Status)status; }

FMI1_EXPORT const char *FMI1(GetTypesPlatform)(void) { return "standard32"; }
FMI1_EXPORT const char *FMI1(GetVersion)(void) { return "1.0"; }

FMI1_EXPORT fmi1Status FMI1(SetDebugLogging)(fmi1Component c, fmi1Boolean loggingOn) {
    (void)c; (void)loggingOn;
    return fmi1OK;
}

FMI1_EXPORT fmi1Component FMI1(InstantiateSlave)(fmi1String instanceName, fmi1String fmuGUID, fmi1String fmuLocation,
                                                 fmi1String mimeType, fmi1Real timeout, fmi1Boolean visible,
                                                 fmi1Boolean interactive, fmi1CallbackFunctions functions,
                                                 fmi1Boolean loggingOn) {
    Fmi1Instance *c;
    (void)fmuLocation; (void)mimeType; (void)timeout; (void)visible; (void)interactive; (void)loggingOn;
    if (!fmuGUID || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        if (functions.logger) {
            functions.logger(NULL, instanceName, fmi1Error, "logStatusError", "only GUID %s is supported",
                             INSTANTIATION_TOKEN);
        }
        return NULL;
    }
    c = (Fmi1Instance *)calloc(1, sizeof(Fmi1Instance));
    if (!c) return NULL;
    c->callbacks = functions;
    c->core = instance_new(instanceName, log_fmi1, c);
    if (!c->core) { free(c); return NULL; }
    return c;
}

FMI1_EXPORT fmi1Status FMI1(InitializeSlave)(fmi1Component c, fmi1Real tStart, fmi1Boolean stopTimeDefined,
                                             fmi1Real tStop) {
    Status status;
    prlpid_fault_on_setup(CORE(c), stopTimeDefined, tStop);
    status = instance_enter_initialization(CORE(c), tStart);
    if (status != STATUS_OK) return to_fmi1(status);
    return to_fmi1(instance_exit_initialization(CORE(c)));
}

FMI1_EXPORT fmi1Status FMI1(TerminateSlave)(fmi1Component c) {
    CORE(c)->mode = MODE_TERMINATED;
    return fmi1OK;
}

FMI1_EXPORT fmi1Status FMI1(ResetSlave)(fmi1Component c) {
    instance_reset(CORE(c));
    return fmi1OK;
}

FMI1_EXPORT void FMI1(FreeSlaveInstance)(fmi1Component c) {
    if (!c) return;
    instance_free(CORE(c));
    free(c);
}

FMI1_EXPORT fmi1Status FMI1(GetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Real value[]) {
    return to_fmi1(instance_get_real(CORE(c), vr, nvr, value));
}

FMI1_EXPORT fmi1Status FMI1(SetReal)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, const fmi1Real value[]) {
    return to_fmi1(instance_set_real(CORE(c), vr, nvr, value));
}

/* This model has only real variables. */
static fmi1Status no_such_variable(fmi1Component c, size_t nvr) {
    if (nvr == 0) return fmi1OK;
    instance_log(CORE(c), STATUS_ERROR, "the model has no integer, boolean or string variables");
    return fmi1Error;
}

FMI1_EXPORT fmi1Status FMI1(GetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Integer value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
FMI1_EXPORT fmi1Status FMI1(GetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1Boolean value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
FMI1_EXPORT fmi1Status FMI1(GetString)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, fmi1String value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
FMI1_EXPORT fmi1Status FMI1(SetInteger)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, const fmi1Integer value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
FMI1_EXPORT fmi1Status FMI1(SetBoolean)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, const fmi1Boolean value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}
FMI1_EXPORT fmi1Status FMI1(SetString)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr, const fmi1String value[]) {
    (void)vr; (void)value; return no_such_variable(c, nvr);
}

FMI1_EXPORT fmi1Status FMI1(SetRealInputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                                     const fmi1Integer order[], const fmi1Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    instance_log(CORE(c), STATUS_ERROR, "input derivatives are not supported");
    return fmi1Error;
}

FMI1_EXPORT fmi1Status FMI1(GetRealOutputDerivatives)(fmi1Component c, const fmi1ValueReference vr[], size_t nvr,
                                                      const fmi1Integer order[], fmi1Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    instance_log(CORE(c), STATUS_ERROR, "output derivatives are not supported");
    return fmi1Error;
}

FMI1_EXPORT fmi1Status FMI1(DoStep)(fmi1Component c, fmi1Real currentCommunicationPoint, fmi1Real communicationStepSize,
                                    fmi1Boolean newStep) {
    (void)newStep;
    return to_fmi1(instance_do_step(CORE(c), currentCommunicationPoint, communicationStepSize));
}

FMI1_EXPORT fmi1Status FMI1(CancelStep)(fmi1Component c) { (void)c; return fmi1Error; }

FMI1_EXPORT fmi1Status FMI1(GetStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Status *value) {
    (void)c; (void)s; (void)value; return fmi1Discard;
}
FMI1_EXPORT fmi1Status FMI1(GetRealStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Real *value) {
    if (s == fmi1LastSuccessfulTime) {
        *value = CORE(c)->m.time;
        return fmi1OK;
    }
    return fmi1Discard;
}
FMI1_EXPORT fmi1Status FMI1(GetIntegerStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Integer *value) {
    (void)c; (void)s; (void)value; return fmi1Discard;
}
FMI1_EXPORT fmi1Status FMI1(GetBooleanStatus)(fmi1Component c, const fmi1StatusKind s, fmi1Boolean *value) {
    (void)c; (void)s; (void)value; return fmi1Discard;
}
FMI1_EXPORT fmi1Status FMI1(GetStringStatus)(fmi1Component c, const fmi1StatusKind s, fmi1String *value) {
    (void)c; (void)s; (void)value; return fmi1Discard;
}
