/* Bistable: tau dy/dt = y - y^3 + u, starting on the unstable middle branch at y = 0. */
#include "plant_model.h"

void model_initialize(ModelData *m) { m->x[0] = 0.0; }

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    (void)t;
    dx[0] = (x[0] - x[0] * x[0] * x[0] + m->v[VR_u]) / m->v[VR_tau];
}

void model_outputs(ModelData *m) { m->v[VR_y] = m->x[0]; }

void model_constrain(double *x) { (void)x; }
