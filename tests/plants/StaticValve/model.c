/* StaticValve: q = Kv * opening, no states. */
#include "plant_model.h"

void model_initialize(ModelData *m) { (void)m; }

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    (void)m; (void)t; (void)x; (void)dx;
}

void model_outputs(ModelData *m) { m->v[VR_q] = m->v[VR_Kv] * m->v[VR_opening]; }

void model_constrain(double *x) { (void)x; }
