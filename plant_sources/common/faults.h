/* Misbehaviour for tests, compiled in only by -D switches (the bundled plants' normal build defines none):
 *
 *   PRLPID_FAULT_NAN_AFTER_S=t       outputs are NaN after every step that ends at or after t [s]
 *   PRLPID_FAULT_DISCARD_AFTER_S=t   doStep returns discard from communication point t on
 *   PRLPID_FAULT_CRASH_AFTER_S=t     doStep dereferences NULL (a segmentation fault) from t on
 *   PRLPID_FAULT_ONCE_PER_PROCESS    a second live instance in the process is refused
 *   PRLPID_FAULT_NO_STATE            get/set FMU state fail (pair with canGetAndSetFMUstate="false")
 *   PRLPID_FAULT_NO_SERIALIZE        (de)serializing the FMU state fails (canSerializeFMUstate="false")
 *   PRLPID_FAULT_RESET_LEAK_BYTES=n  every reset allocates and touches n bytes, freed only with the instance
 *
 * Declarations only; faults.c defines the functions (compiled with the same switches as every other
 * source, so a switch must be given to the whole build). Without any switch every function is a no-op
 * that lets the call go on. Called by instance.c. */
#ifndef FAULTS_H
#define FAULTS_H

#include "instance.h"

/* 1 when another instance may be created now. */
int prlpid_fault_may_instantiate(void);

/* Count a live instance: +1 after instantiation, -1 when it is freed. */
void prlpid_fault_count_instance(int delta);

/* At the start of doStep from communication point t: STATUS_OK to go on. */
Status prlpid_fault_before_step(Instance *c, double t);

/* After a successful doStep (outputs computed). */
void prlpid_fault_after_step(Instance *c);

/* At the start of a reset, before the start values are set again. */
void prlpid_fault_on_reset(Instance *c);

/* When the instance is freed: releases what the faults allocated for it. */
void prlpid_fault_on_free(Instance *c);

/* STATUS_ERROR (logged) when the FMU state (what = 0) or its serialization (what = 1) is switched off. */
Status prlpid_fault_state_refused(Instance *c, int what);

#endif
