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
} Instance;

/* Snapshot of everything that defines the simulation: what get/set FMU state copies. */
typedef struct {
    ModelData m;
    Mode mode;
} Snapshot;

Instance *instance_new(const char *name, LogFunction log, void *log_env);
void instance_free(Instance *c);
void instance_reset(Instance *c);
Status instance_enter_initialization(Instance *c, double start_time);
Status instance_exit_initialization(Instance *c);
Status instance_do_step(Instance *c, double t, double h);
Status instance_get_real(Instance *c, const unsigned int vr[], size_t nvr, double value[]);
Status instance_set_real(Instance *c, const unsigned int vr[], size_t nvr, const double value[]);
void instance_log(const Instance *c, Status status, const char *fmt, ...);

Snapshot *snapshot_new(const Instance *c);
void snapshot_capture(const Instance *c, Snapshot *s);
void snapshot_restore(Instance *c, const Snapshot *s);
size_t snapshot_serialized_size(void);
void snapshot_serialize(const Snapshot *s, unsigned char *buffer);
Status snapshot_deserialize(Instance *c, const unsigned char *buffer, size_t size, Snapshot **s);

#endif
