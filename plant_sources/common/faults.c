/* The test faults declared in faults.h, each behind its -D switch (documented there). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

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

Status prlpid_fault_before_step(Instance *c, double t) {
#ifdef PRLPID_FAULT_CRASH_AFTER_S
    if (t >= PRLPID_FAULT_CRASH_AFTER_S) {
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
    (void)c; (void)t;
    return STATUS_OK;
}

void prlpid_fault_after_step(Instance *c) {
#ifdef PRLPID_FAULT_NAN_AFTER_S
    if (c->m.time >= PRLPID_FAULT_NAN_AFTER_S) {
        int vr;
        for (vr = 0; vr < N_VARIABLES; vr++) {
            if (CAUSALITY[vr] == CAUSALITY_OUTPUT) c->m.v[vr] = NAN;
        }
    }
#else
    (void)c;
#endif
}

void prlpid_fault_on_reset(Instance *c) {
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
