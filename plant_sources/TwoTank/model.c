/* TwoTank (paper eq. 24):
 *   dh1/dt = (q_in + q_d - valve_factor k1 sqrt(max(h1 - h2, 0))) / A1
 *   dh2/dt = (valve_factor k1 sqrt(max(h1 - h2, 0)) - k2 sqrt(max(h2, 0))) / A2
 * An empty tank cannot drain: a level <= 0 with a negative derivative has derivative 0,
 * and a level that an integration sub-step pushed below 0 is set to 0. */
#include <math.h>
#include "plant_model.h"

void model_initialize(ModelData *m) {
    m->x[0] = m->v[VR_h1_0];
    m->x[1] = m->v[VR_h2_0];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double q12 = m->v[VR_valve_factor] * m->v[VR_k1] * sqrt(fmax(x[0] - x[1], 0.0));
    double q2 = m->v[VR_k2] * sqrt(fmax(x[1], 0.0));
    (void)t;
    dx[0] = (m->v[VR_q_in] + m->v[VR_q_d] - q12) / m->v[VR_A1];
    dx[1] = (q12 - q2) / m->v[VR_A2];
    if (x[0] <= 0.0 && dx[0] < 0.0) dx[0] = 0.0;
    if (x[1] <= 0.0 && dx[1] < 0.0) dx[1] = 0.0;
}

void model_outputs(ModelData *m) {
    m->v[VR_h1] = m->x[0];
    m->v[VR_h2] = m->x[1];
}

void model_constrain(double *x) {
    if (x[0] < 0.0) x[0] = 0.0;
    if (x[1] < 0.0) x[1] = 0.0;
}
