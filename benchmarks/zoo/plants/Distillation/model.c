/* Distillation: top composition of a binary column driven by the reflux, as a slow lag with a long dead
 * time on the logarithmic composition X = ln(x_D / (1 - x_D)),
 *
 *   T dX/dt = a + b R(t - L) - X,   x_D = 100 / (1 + e^{-X})  [mol %],
 *
 * S. Skogestad, "Dynamics and control of distillation columns: a tutorial introduction", Trans. IChemE 75A
 * (1997), and Skogestad & Morari, Ind. Eng. Chem. Res. 27 (1988) (logarithmic compositions are nearly linear
 * in the flows, the compositions themselves are not: the gain falls with x_D (1 - x_D)); time constant and
 * dead time of the order of R. K. Wood and M. W. Berry's column (Chem. Eng. Sci. 28, 1973: 16.7 min, 1 to
 * 3 min). Dead time: as benchmarks/plants/HeatExchanger, a ring of RING reflux values at the internal step,
 * L = round(L / fixed_step) sub-steps, at most RING; beyond that x_D is NaN. Co-simulation only. Start: the
 * steady state at the start reflux. */
#include <math.h>
#include <string.h>
#include "plant_model.h"

#define RING 256
enum { S_X = 0, S_Z = 1, S_C = 2, S_RING = 3 };

static int delay_substeps(const ModelData *m) {
    double d = m->v[VR_L] / m->v[VR_fixed_step];
    if (!(d >= 0.0) || d > RING + 0.5) return -1;
    return (int)floor(d + 0.5);
}

void model_initialize(ModelData *m) {
    int j;
    m->x[S_X] = m->v[VR_a] + m->v[VR_b] * m->v[VR_R];
    m->x[S_Z] = 0.0;
    m->x[S_C] = 0.0;
    for (j = 0; j < RING; j++) m->x[S_RING + j] = m->v[VR_R];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    int d = delay_substeps(m);
    double r = d <= 0 ? m->v[VR_R] : x[S_RING + d - 1];
    (void)t;
    memset(dx, 0, sizeof(double) * N_STATES);
    dx[S_X] = (m->v[VR_a] + m->v[VR_b] * r - x[S_X]) / m->v[VR_T];
    dx[S_Z] = m->v[VR_R];
    dx[S_C] = 1.0;
}

void model_outputs(ModelData *m) {
    m->v[VR_x_D] = delay_substeps(m) < 0 ? NAN : 100.0 / (1.0 + exp(-m->x[S_X]));
}

void model_constrain(double *x) {
    double held = x[S_C] > 0.0 ? x[S_Z] / x[S_C] : x[S_RING];
    memmove(&x[S_RING + 1], &x[S_RING], sizeof(double) * (RING - 1));
    x[S_RING] = held;
    x[S_Z] = 0.0;
    x[S_C] = 0.0;
}
