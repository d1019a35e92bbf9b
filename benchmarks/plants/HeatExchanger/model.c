/* HeatExchanger: first-order lag with dead time (FOPDT), Astrom & Hagglund's family K e^{-sL}/(1+sT).
 *
 *   T dT_out/dt = T_in + K * valve(t - L) - T_out
 *
 * The dead time is a ring buffer of the valve position at the internal step: RING states hold the
 * valve of the last RING sub-steps (x[S_RING] the most recent). The shared RK4 layer cannot hand the
 * model its input between sub-steps, so two auxiliary states integrate, over each sub-step, the valve
 * (z' = valve) and the time (c' = 1); model_constrain, called after every sub-step, pushes z / c (the
 * valve held during that sub-step, exact to rounding) into the ring and zeroes both. The lag then reads
 * the valve of d = round(L / fixed_step) sub-steps ago: L exactly when the sample time is a multiple
 * of fixed_step. A dead time longer than RING sub-steps cannot be represented: T_out is NaN then. */
#include <math.h>
#include <string.h>
#include "plant_model.h"

#define RING 256
enum { S_T = 0, S_Z = 1, S_C = 2, S_RING = 3 };

/* Dead time in sub-steps, or -1 when it does not fit the ring (or is negative / not finite). */
static int delay_substeps(const ModelData *m) {
    double d = m->v[VR_L] / m->v[VR_fixed_step];
    if (!(d >= 0.0) || d > RING + 0.5) return -1;
    return (int)floor(d + 0.5);
}

void model_initialize(ModelData *m) {
    int j;
    m->x[S_T] = m->v[VR_T_in] + m->v[VR_K] * m->v[VR_valve]; /* steady state at the start inputs */
    m->x[S_Z] = 0.0;
    m->x[S_C] = 0.0;
    for (j = 0; j < RING; j++) m->x[S_RING + j] = m->v[VR_valve];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    int d = delay_substeps(m);
    double valve_delayed = d <= 0 ? m->v[VR_valve] : x[S_RING + d - 1];
    (void)t;
    memset(dx, 0, sizeof(double) * N_STATES);
    dx[S_T] = (m->v[VR_T_in] + m->v[VR_K] * valve_delayed - x[S_T]) / m->v[VR_T];
    dx[S_Z] = m->v[VR_valve];
    dx[S_C] = 1.0;
}

void model_outputs(ModelData *m) { m->v[VR_T_out] = delay_substeps(m) < 0 ? NAN : m->x[S_T]; }

void model_constrain(double *x) {
    double held = x[S_C] > 0.0 ? x[S_Z] / x[S_C] : x[S_RING];
    memmove(&x[S_RING + 1], &x[S_RING], sizeof(double) * (RING - 1));
    x[S_RING] = held;
    x[S_Z] = 0.0;
    x[S_C] = 0.0;
}
