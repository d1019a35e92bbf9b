/* The test faults declared in faults.h, each behind its -D switch (documented there). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef PRLPID_FAULT_HANG_AFTER_S
#ifdef _WIN32
#include <windows.h>
#else
#include <unistd.h>
#endif
#endif

#include "faults.h"

#ifdef PRLPID_FAULT_ONCE_PER_PROCESS
static int fault_live_instances = 0;
#endif

int prlpid_fault_may_instantiate(void) {
#ifdef PRLPID_FAULT_ONCE_PER_PROCESS
    return fault_live_instances == 0;
#else
    return 1;
#endif
}

void prlpid_fault_count_instance(int delta) {
#ifdef PRLPID_FAULT_ONCE_PER_PROCESS
    fault_live_instances += delta;
#else
    (void)delta;
#endif
}

/* PRLPID_FAULT_GATED: 1 while the file $PRLPID_FAULT_GATE exists; always 1 without the switch. */
static int gate_open(void) {
#ifdef PRLPID_FAULT_GATED
    const char *name = getenv("PRLPID_FAULT_GATE");
    FILE *f = name ? fopen(name, "r") : NULL;
    if (!f) return 0;
    fclose(f);
#endif
    return 1;
}

Status prlpid_fault_before_step(Instance *c, double t, double h) {
#ifdef PRLPID_FAULT_STOP_TIME
    if (t + h > c->fault_stop_time + 1e-9 * (fabs(c->fault_stop_time) > 1.0 ? fabs(c->fault_stop_time) : 1.0)) {
        instance_log(c, STATUS_ERROR, "Exceeded model finish time: %.4g > %.4g", t + h, c->fault_stop_time);
        c->mode = MODE_ERROR;
        return STATUS_ERROR;
    }
#endif
#ifdef PRLPID_FAULT_HANG_AFTER_S
    if (t >= PRLPID_FAULT_HANG_AFTER_S && gate_open()) {
        for (;;) {
#ifdef _WIN32
            Sleep(100);
#else
            usleep(100000);
#endif
        }
    }
#endif
#ifdef PRLPID_FAULT_CRASH_AFTER_S
    if (t >= PRLPID_FAULT_CRASH_AFTER_S && gate_open()) {
        volatile int *nowhere = NULL;
        *nowhere = 1;
    }
#endif
#ifdef PRLPID_FAULT_CRASH_IN_PRIOR
    if (c->name && strcmp(c->name, "prior") == 0) {
        volatile int *nowhere = NULL;
        *nowhere = 1;
    }
#endif
#ifdef PRLPID_FAULT_DISCARD_AFTER_S
    if (t >= PRLPID_FAULT_DISCARD_AFTER_S) {
        instance_log(c, STATUS_DISCARD, "fault switch: discarding the step from t = %g", t);
        return STATUS_DISCARD;
    }
#endif
    (void)c; (void)t; (void)h; (void)gate_open;
    return STATUS_OK;
}

static void set_outputs(Instance *c, double value) {
    int vr;
    for (vr = 0; vr < N_VARIABLES; vr++) {
        if (CAUSALITY[vr] == CAUSALITY_OUTPUT) c->m.v[vr] = value;
    }
}

/* PRLPID_FAULT_RESET_NOOP: the outputs back at the values they had at the reset. */
static void hold_outputs(Instance *c) {
#ifdef PRLPID_FAULT_RESET_NOOP
    int vr;
    if (!c->fault_frozen) return;
    for (vr = 0; vr < N_VARIABLES; vr++) {
        if (CAUSALITY[vr] == CAUSALITY_OUTPUT) c->m.v[vr] = c->fault_held[vr];
    }
#else
    (void)c;
#endif
}

void prlpid_fault_after_step(Instance *c) {
#ifdef PRLPID_FAULT_NAN_AFTER_S
    if (c->m.time >= PRLPID_FAULT_NAN_AFTER_S) set_outputs(c, NAN);
#endif
#ifdef PRLPID_FAULT_DENORMAL_AFTER_S
    if (c->m.time >= PRLPID_FAULT_DENORMAL_AFTER_S) set_outputs(c, 5.6e-322);
#endif
    hold_outputs(c);
    (void)c; (void)set_outputs;
}

void prlpid_fault_on_new(Instance *c) {
#ifdef PRLPID_FAULT_STOP_TIME
    c->fault_stop_time = PRLPID_FAULT_STOP_TIME;
#endif
#ifdef PRLPID_FAULT_BANNER
    printf("*** fault switch banner: %s instantiated (printed on stdout by the FMU) ***\n", c->name);
    fflush(stdout);
#endif
    (void)c;
}

void prlpid_fault_on_setup(Instance *c, int stop_time_defined, double stop_time) {
#ifdef PRLPID_FAULT_STOP_TIME
    c->fault_stop_time = stop_time_defined ? stop_time : PRLPID_FAULT_STOP_TIME;
#endif
    (void)c; (void)stop_time_defined; (void)stop_time;
}

void prlpid_fault_after_initialization(Instance *c) {
#if defined(PRLPID_FAULT_RESET_NOOP) || defined(PRLPID_FAULT_CRASH_IN_RESET_BEFORE_INIT) || defined(PRLPID_FAULT_STOP_TIME)
    c->fault_initialized = 1;
#endif
    hold_outputs(c);
}

void prlpid_fault_after_reset(Instance *c) {
#ifdef PRLPID_FAULT_RESET_NOOP
    if (!c->fault_frozen) {
        memcpy(c->fault_held, c->m.v, sizeof(c->fault_held));
        c->fault_frozen = 1;
    }
    hold_outputs(c);
#endif
#ifdef PRLPID_FAULT_STOP_TIME
    c->fault_stop_time = PRLPID_FAULT_STOP_TIME;
#endif
    (void)c;
}

void prlpid_fault_on_reset(Instance *c) {
#ifdef PRLPID_FAULT_CRASH_IN_RESET
    {
        volatile int *nowhere = NULL;
        *nowhere = 1;
    }
#endif
#ifdef PRLPID_FAULT_CRASH_IN_RESET_BEFORE_INIT
    if (!c->fault_initialized) {
        volatile int *nowhere = NULL;
        *nowhere = 1;
    }
#endif
#ifdef PRLPID_FAULT_RESET_LEAK_BYTES
    void **block = (void **)malloc(sizeof(void *) + (size_t)(PRLPID_FAULT_RESET_LEAK_BYTES));
    if (block) {
        memset(block + 1, 0x5a, (size_t)(PRLPID_FAULT_RESET_LEAK_BYTES));
        *block = c->fault_leak;
        c->fault_leak = block;
    }
#else
    (void)c;
#endif
}

void prlpid_fault_on_free(Instance *c) {
#ifdef PRLPID_FAULT_RESET_LEAK_BYTES
    void **block = (void **)c->fault_leak;
    while (block) {
        void **next = (void **)*block;
        free(block);
        block = next;
    }
#else
    (void)c;
#endif
}

Status prlpid_fault_state_refused(Instance *c, int what) {
#ifdef PRLPID_FAULT_NO_STATE
    instance_log(c, STATUS_ERROR, "fault switch: this FMU cannot get or set its state");
    return STATUS_ERROR;
#endif
#ifdef PRLPID_FAULT_NO_SERIALIZE
    if (what == 1) {
        instance_log(c, STATUS_ERROR, "fault switch: this FMU cannot serialize its state");
        return STATUS_ERROR;
    }
#endif
    (void)c; (void)what;
    return STATUS_OK;
}
