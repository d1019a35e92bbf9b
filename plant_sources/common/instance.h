/* Version-neutral co-simulation instance shared by the FMI 2.0 and 3.0 layers. */
#ifndef INSTANCE_H
#define INSTANCE_H

#include <stddef.h>
#include "plant_model.h"

typedef enum { MODE_INSTANTIATED, MODE_INITIALIZATION, MODE_STEP, MODE_TERMINATED, MODE_ERROR } Mode;

typedef enum { STATUS_OK = 0, STATUS_WARNING, STATUS_DISCARD, STATUS_ERROR } Status;

typedef void (*LogFunction)(void *env, const char *instance_name, Status status, const char *message);

typedef struct {
    ModelData m;
    Mode mode;
    char *name;
    LogFunction log;
    void *log_env;
#ifdef PRLPID_FAULT_RESET_LEAK_BYTES
    void *fault_leak; /* test builds only: blocks the leaking reset allocated (faults.c) */
#endif
#if defined(PRLPID_FAULT_RESET_NOOP) || defined(PRLPID_FAULT_CRASH_IN_RESET_BEFORE_INIT) || defined(PRLPID_FAULT_STOP_TIME)
    /* test builds only (faults.c) */
    int fault_initialized;          /* initialisation mode was left at least once */
    int fault_frozen;               /* PRLPID_FAULT_RESET_NOOP: outputs held at fault_held since a reset */
    double fault_held[N_VARIABLES];
    double fault_stop_time;         /* PRLPID_FAULT_STOP_TIME: the stop time in force [s] */
#endif
} Instance;

Instance *instance_new(const char *name, LogFunction log, void *log_env);
void instance_free(Instance *c);
void instance_reset(Instance *c);
Status instance_enter_initialization(Instance *c, double start_time);
Status instance_exit_initialization(Instance *c);
Status instance_do_step(Instance *c, double t, double h);
Status instance_get_real(Instance *c, const unsigned int vr[], size_t nvr, double value[]);
Status instance_set_real(Instance *c, const unsigned int vr[], size_t nvr, const double value[]);
void instance_log(const Instance *c, Status status, const char *fmt, ...);

/* The FMU-state functions of FMI 2.0 and 3.0, version-neutral: a state handle is an opaque
 * pointer to a snapshot of the model data (time included) and the mode. The API files only convert
 * types. */
Status instance_get_state(Instance *c, void **state);          /* new handle, or overwrite *state */
Status instance_set_state(Instance *c, const void *state);
void instance_free_state(void **state);                        /* frees *state and sets it to NULL */
size_t instance_serialized_state_size(void);
Status instance_serialize_state(Instance *c, const void *state, unsigned char *buffer, size_t size);
Status instance_deserialize_state(Instance *c, const unsigned char *buffer, size_t size, void **state);

/* What get/set FMU state would move from `from` to `to` (same model), without a handle. */
void instance_copy_state(const Instance *from, Instance *to);

#endif
