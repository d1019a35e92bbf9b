/* FirstOrderUnstable: dx/dt = a*x + b*u, y = x. */
#include "plant_model.h"

void model_initialize(ModelData *m) { m->x[0] = m->v[VR_x0]; }

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    (void)t;
    dx[0] = m->v[VR_a] * x[0] + m->v[VR_b] * m->v[VR_u];
}

void model_outputs(ModelData *m) { m->v[VR_y] = m->x[0]; }

void model_constrain(double *x) { (void)x; }
