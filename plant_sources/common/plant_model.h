/* The interface between the shared FMI layer and one plant model.
 *
 * Every plant provides model.c implementing the four functions below. The
 * build generates variables.h from the plant's model.yaml: value references
 * (VR_<name>), N_VARIABLES, N_STATES, start values and causalities.
 * Value reference 0 is `time`, 1 is `fixed_step` (internal RK4 step, s);
 * the model's own variables follow.
 */
#ifndef PLANT_MODEL_H
#define PLANT_MODEL_H

#include "variables.h"

typedef struct {
    double time;              /* simulation time, s */
    double v[N_VARIABLES];    /* all real variables, indexed by value reference */
    double x[N_STATES];       /* continuous states */
} ModelData;

/* Set the states from the (initial-value) parameters in v. */
void model_initialize(ModelData *m);

/* dx = f(t, x, v): state derivatives at time t for states x (inputs and
 * parameters are read from m->v). Must not modify m. */
void model_derivatives(const ModelData *m, double t, const double *x, double *dx);

/* Write the outputs into m->v from m->time, m->x and m->v. */
void model_outputs(ModelData *m);

/* Project states back onto their physical domain after an integration
 * sub-step (e.g. a tank level cannot be negative). Most models do nothing. */
void model_constrain(double *x);

#endif
