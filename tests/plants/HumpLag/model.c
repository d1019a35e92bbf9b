/* HumpLag: tau dy/dt = 4 ymax u (1 - u) - y. */
#include "plant_model.h"

void model_initialize(ModelData *m) { m->x[0] = 0.75; }

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    (void)t;
    double u = m->v[VR_u];
    dx[0] = (4.0 * m->v[VR_ymax] * u * (1.0 - u) - x[0]) / m->v[VR_tau];
}

void model_outputs(ModelData *m) { m->v[VR_y] = m->x[0]; }

void model_constrain(double *x) { (void)x; }
