/* Misbehaviour for tests, compiled in only by -D switches (the bundled plants' normal build defines none):
 *
 *   PRLPID_FAULT_NAN_AFTER_S=t       outputs are NaN after every step that ends at or after t [s]
 *   PRLPID_FAULT_DISCARD_AFTER_S=t   doStep returns discard from communication point t on
 *   PRLPID_FAULT_CRASH_AFTER_S=t     doStep dereferences NULL (a segmentation fault) from t on
 *   PRLPID_FAULT_ONCE_PER_PROCESS    a second live instance in the process is refused
 *   PRLPID_FAULT_NO_STATE            get/set FMU state fail (pair with canGetAndSetFMUstate="false")
 *   PRLPID_FAULT_NO_SERIALIZE        (de)serializing the FMU state fails (canSerializeFMUstate="false")
 *   PRLPID_FAULT_RESET_LEAK_BYTES=n  every reset allocates and touches n bytes, freed only with the instance
 *   PRLPID_FAULT_RESET_NOOP          a reset does not reset: from then on the outputs stay at their values at
 *                                    the reset whatever the inputs (a 20-sim 4.6 FMU after fmi2Reset)
 *   PRLPID_FAULT_CRASH_IN_RESET_BEFORE_INIT  a reset of an instance never initialised dereferences NULL
 *                                    (a 20-sim 4.7 FMU reset straight after instantiation)
 *   PRLPID_FAULT_CRASH_IN_RESET      every reset dereferences NULL
 *   PRLPID_FAULT_STOP_TIME=t         doStep past the stop time fails with an error log message; the stop
 *                                    time is the one setupExperiment defines, else t (the DefaultExperiment's)
 *   PRLPID_FAULT_HANG_AFTER_S=t      doStep from communication point t on never returns (sleeps in a loop)
 *   PRLPID_FAULT_CRASH_IN_PRIOR      doStep of an instance named "prior" dereferences NULL (a second instance
 *                                    that crashes where the first runs, as an FMU with global state may)
 *   PRLPID_FAULT_GATED               the hang and the crash act only while the file named by the environment
 *                                    variable PRLPID_FAULT_GATE exists (a test opens the gate when it wants)
 *   PRLPID_FAULT_BANNER              instantiation prints a banner on stdout (printf, as some exporters do)
 *   PRLPID_FAULT_DENORMAL_AFTER_S=t  outputs are 5.6e-322 (a denormal: garbage) after every step ending at or
 *                                    after t [s]
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

/* At the start of doStep from communication point t over h: STATUS_OK to go on, else the status to return. */
Status prlpid_fault_before_step(Instance *c, double t, double h);

/* After a successful doStep (outputs computed). */
void prlpid_fault_after_step(Instance *c);

/* At the start of a reset, before the start values are set again. */
void prlpid_fault_on_reset(Instance *c);

/* After a reset has set the start values again. */
void prlpid_fault_after_reset(Instance *c);

/* After a new instance got its start values. */
void prlpid_fault_on_new(Instance *c);

/* When the experiment is set up: whether a stop time is defined, and which [s]. */
void prlpid_fault_on_setup(Instance *c, int stop_time_defined, double stop_time);

/* When initialisation mode is left (outputs computed). */
void prlpid_fault_after_initialization(Instance *c);

/* When the instance is freed: releases what the faults allocated for it. */
void prlpid_fault_on_free(Instance *c);

/* STATUS_ERROR (logged) when the FMU state (what = 0) or its serialization (what = 1) is switched off. */
Status prlpid_fault_state_refused(Instance *c, int what);

#endif
