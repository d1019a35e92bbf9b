/* SecondOrderUnstable: controllable canonical form of K(1 - Tn s)/(a2 s^2 + a1 s + a0). */
#include "plant_model.h"

void model_initialize(ModelData *m) {
    m->x[0] = m->v[VR_x1_0];
    m->x[1] = m->v[VR_x2_0];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    (void)t;
    dx[0] = x[1];
    dx[1] = (m->v[VR_u] - m->v[VR_a1] * x[1] - m->v[VR_a0] * x[0]) / m->v[VR_a2];
}

void model_outputs(ModelData *m) { m->v[VR_y] = m->v[VR_K] * (m->x[0] - m->v[VR_Tn] * m->x[1]); }

void model_constrain(double *x) { (void)x; }
