/* TimeVaryingFirstOrder: dx/dt = a(t) x + u with a(t) = offset + amplitude (sin(2 pi f t) + 1). */
#include <math.h>
#include "plant_model.h"

#define PI 3.14159265358979323846

static double pole(const ModelData *m, double t) {
    return m->v[VR_a_offset] + m->v[VR_a_amplitude] * (sin(2.0 * PI * m->v[VR_a_frequency] * t) + 1.0);
}

void model_initialize(ModelData *m) { m->x[0] = m->v[VR_x0]; }

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    dx[0] = pole(m, t) * x[0] + m->v[VR_u];
}

void model_outputs(ModelData *m) {
    m->v[VR_y] = m->x[0];
    m->v[VR_a_t] = pole(m, m->time);
}

void model_constrain(double *x) { (void)x; }
