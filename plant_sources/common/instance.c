/* Shared co-simulation core: modes, fixed-step RK4, real variables, FMU states and their serialization. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "instance.h"
#include "faults.h"

#define SERIAL_MAGIC 0x534c5250u /* "PRLS" */
#define SERIAL_VERSION 1u

typedef struct {
    unsigned int magic;
    unsigned int version;
    unsigned int n_variables;
    unsigned int n_states;
    unsigned long long payload_size;
} SerialHeader;

void instance_log(const Instance *c, Status status, const char *fmt, ...) {
    char message[512];
    va_list args;
    if (!c || !c->log) return;
    va_start(args, fmt);
    vsnprintf(message, sizeof(message), fmt, args);
    va_end(args);
    c->log(c->log_env, c->name, status, message);
}

static void set_start_values(Instance *c) {
    memcpy(c->m.v, START_VALUES, sizeof(START_VALUES));
    memset(c->m.x, 0, sizeof(c->m.x));
    c->m.time = 0.0;
    model_initialize(&c->m);
    model_outputs(&c->m);
}

Instance *instance_new(const char *name, LogFunction log, void *log_env) {
    Instance *c;
    if (!prlpid_fault_may_instantiate()) {
        if (log) log(log_env, name, STATUS_ERROR, "only one instance of this FMU per process");
        return NULL;
    }
    c = (Instance *)calloc(1, sizeof(Instance));
    if (!c) return NULL;
    c->name = (char *)malloc(strlen(name ? name : "") + 1);
    if (!c->name) { free(c); return NULL; }
    strcpy(c->name, name ? name : "");
    c->log = log;
    c->log_env = log_env;
    c->mode = MODE_INSTANTIATED;
    set_start_values(c);
    prlpid_fault_count_instance(1);
    prlpid_fault_on_new(c);
    return c;
}

void instance_free(Instance *c) {
    if (!c) return;
    prlpid_fault_on_free(c);
    prlpid_fault_count_instance(-1);
    free(c->name);
    free(c);
}

void instance_reset(Instance *c) {
    prlpid_fault_on_reset(c);
    set_start_values(c);
    c->mode = MODE_INSTANTIATED;
    prlpid_fault_after_reset(c);
}

Status instance_enter_initialization(Instance *c, double start_time) {
    if (c->mode != MODE_INSTANTIATED) {
        instance_log(c, STATUS_ERROR, "enter initialization mode is only allowed after instantiation or reset");
        return STATUS_ERROR;
    }
    c->m.time = start_time;
    c->mode = MODE_INITIALIZATION;
    return STATUS_OK;
}

Status instance_exit_initialization(Instance *c) {
    if (c->mode != MODE_INITIALIZATION) {
        instance_log(c, STATUS_ERROR, "exit initialization mode is only allowed in initialization mode");
        return STATUS_ERROR;
    }
    if (!(c->m.v[VR_fixed_step] > 0.0) || !isfinite(c->m.v[VR_fixed_step])) {
        instance_log(c, STATUS_ERROR, "fixed_step must be a positive finite number, got %g", c->m.v[VR_fixed_step]);
        return STATUS_ERROR;
    }
    model_initialize(&c->m);
    model_outputs(&c->m);
    c->mode = MODE_STEP;
    prlpid_fault_after_initialization(c);
    return STATUS_OK;
}

static int states_finite(const double *x) {
    int i;
    for (i = 0; i < N_STATES; i++) {
        if (!isfinite(x[i])) return 0;
    }
    return 1;
}

/* One classical Runge-Kutta step of size dt from (t, x) in place. */
static void rk4(const ModelData *m, double t, double dt, double *x) {
    double k1[N_STATES], k2[N_STATES], k3[N_STATES], k4[N_STATES], tmp[N_STATES];
    int i;
    model_derivatives(m, t, x, k1);
    for (i = 0; i < N_STATES; i++) tmp[i] = x[i] + 0.5 * dt * k1[i];
    model_derivatives(m, t + 0.5 * dt, tmp, k2);
    for (i = 0; i < N_STATES; i++) tmp[i] = x[i] + 0.5 * dt * k2[i];
    model_derivatives(m, t + 0.5 * dt, tmp, k3);
    for (i = 0; i < N_STATES; i++) tmp[i] = x[i] + dt * k3[i];
    model_derivatives(m, t + dt, tmp, k4);
    for (i = 0; i < N_STATES; i++) x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

Status instance_do_step(Instance *c, double t, double h) {
    double x[N_STATES];
    double dt, tol;
    long n, k;
    if (c->mode != MODE_STEP) {
        instance_log(c, STATUS_ERROR, "doStep is only allowed in step mode");
        return STATUS_ERROR;
    }
    tol = 1e-9 * (fabs(t) > 1.0 ? fabs(t) : 1.0);
    if (fabs(t - c->m.time) > tol) {
        instance_log(c, STATUS_ERROR, "currentCommunicationPoint %.17g differs from the instance time %.17g", t, c->m.time);
        return STATUS_ERROR;
    }
    if (!(h > 0.0) || !isfinite(h)) {
        instance_log(c, STATUS_ERROR, "communicationStepSize must be positive and finite, got %g", h);
        return STATUS_ERROR;
    }
    {
        Status fault = prlpid_fault_before_step(c, t, h);
        if (fault != STATUS_OK) return fault;
    }
    n = (long)ceil(h / c->m.v[VR_fixed_step] - 1e-9);
    if (n < 1) n = 1;
    dt = h / (double)n;
    memcpy(x, c->m.x, sizeof(x));
    for (k = 0; k < n; k++) {
        rk4(&c->m, t + (double)k * dt, dt, x);
        model_constrain(x);
        if (!states_finite(x)) {
            instance_log(c, STATUS_DISCARD, "non-finite state at t = %g; the last good state is kept", t + (double)(k + 1) * dt);
            return STATUS_DISCARD;
        }
    }
    memcpy(c->m.x, x, sizeof(x));
    c->m.time = t + h;
    model_outputs(&c->m);
    prlpid_fault_after_step(c);
    return STATUS_OK;
}

Status instance_get_real(Instance *c, const unsigned int vr[], size_t nvr, double value[]) {
    size_t i;
    if (c->mode == MODE_INITIALIZATION) {
        /* parameters may have changed since instantiation: derive states and outputs again */
        model_initialize(&c->m);
        model_outputs(&c->m);
    }
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= N_VARIABLES) {
            instance_log(c, STATUS_ERROR, "unknown value reference %u", vr[i]);
            return STATUS_ERROR;
        }
        value[i] = vr[i] == VR_time ? c->m.time : c->m.v[vr[i]];
    }
    return STATUS_OK;
}

Status instance_set_real(Instance *c, const unsigned int vr[], size_t nvr, const double value[]) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        unsigned int r = vr[i];
        int causality;
        if (r >= N_VARIABLES) {
            instance_log(c, STATUS_ERROR, "unknown value reference %u", r);
            return STATUS_ERROR;
        }
        causality = CAUSALITY[r];
        if (causality == CAUSALITY_INPUT ||
            (causality == CAUSALITY_TUNABLE_PARAMETER && c->mode != MODE_TERMINATED) ||
            (causality == CAUSALITY_FIXED_PARAMETER && (c->mode == MODE_INSTANTIATED || c->mode == MODE_INITIALIZATION))) {
            c->m.v[r] = value[i];
        } else {
            instance_log(c, STATUS_ERROR, "variable with value reference %u cannot be set in the current mode", r);
            return STATUS_ERROR;
        }
    }
    return STATUS_OK;
}

/* Snapshot of everything that defines the simulation: what get/set FMU state copies. */
typedef struct {
    ModelData m;
    Mode mode;
} Snapshot;

void instance_copy_state(const Instance *from, Instance *to) {
    to->m = from->m;
    to->mode = from->mode;
}

Status instance_get_state(Instance *c, void **state) {
    Snapshot *s = (Snapshot *)*state;
    if (prlpid_fault_state_refused(c, 0) != STATUS_OK) return STATUS_ERROR;
    if (!s) { /* otherwise overwrite a state returned earlier */
        s = (Snapshot *)malloc(sizeof(Snapshot));
        if (!s) {
            instance_log(c, STATUS_ERROR, "out of memory for the FMU state");
            return STATUS_ERROR;
        }
        *state = s;
    }
    s->m = c->m;
    s->mode = c->mode;
    return STATUS_OK;
}

Status instance_set_state(Instance *c, const void *state) {
    const Snapshot *s = (const Snapshot *)state;
    if (prlpid_fault_state_refused(c, 0) != STATUS_OK) return STATUS_ERROR;
    if (!s) {
        instance_log(c, STATUS_ERROR, "the FMU state is NULL");
        return STATUS_ERROR;
    }
    c->m = s->m;
    c->mode = s->mode;
    return STATUS_OK;
}

void instance_free_state(void **state) {
    if (state && *state) {
        free(*state);
        *state = NULL;
    }
}

size_t instance_serialized_state_size(void) {
    return sizeof(SerialHeader) + sizeof(Snapshot);
}

Status instance_serialize_state(Instance *c, const void *state, unsigned char *buffer, size_t size) {
    SerialHeader header;
    if (prlpid_fault_state_refused(c, 1) != STATUS_OK) return STATUS_ERROR;
    if (!state || size < instance_serialized_state_size()) {
        instance_log(c, STATUS_ERROR, "buffer too small for the serialized state");
        return STATUS_ERROR;
    }
    header.magic = SERIAL_MAGIC;
    header.version = SERIAL_VERSION;
    header.n_variables = N_VARIABLES;
    header.n_states = N_STATES;
    header.payload_size = sizeof(Snapshot);
    memcpy(buffer, &header, sizeof(header));
    memcpy(buffer + sizeof(header), state, sizeof(Snapshot));
    return STATUS_OK;
}

Status instance_deserialize_state(Instance *c, const unsigned char *buffer, size_t size, void **state) {
    SerialHeader header;
    if (prlpid_fault_state_refused(c, 1) != STATUS_OK) return STATUS_ERROR;
    if (size != instance_serialized_state_size()) {
        instance_log(c, STATUS_ERROR, "serialized state has %lu bytes, expected %lu",
                     (unsigned long)size, (unsigned long)instance_serialized_state_size());
        return STATUS_ERROR;
    }
    memcpy(&header, buffer, sizeof(header));
    if (header.magic != SERIAL_MAGIC || header.version != SERIAL_VERSION ||
        header.n_variables != N_VARIABLES || header.n_states != N_STATES ||
        header.payload_size != sizeof(Snapshot)) {
        instance_log(c, STATUS_ERROR, "serialized state is not from this model or has another format version");
        return STATUS_ERROR;
    }
    if (*state == NULL) {
        *state = malloc(sizeof(Snapshot));
        if (!*state) {
            instance_log(c, STATUS_ERROR, "out of memory for the FMU state");
            return STATUS_ERROR;
        }
    }
    memcpy(*state, buffer + sizeof(header), sizeof(Snapshot));
    return STATUS_OK;
}
