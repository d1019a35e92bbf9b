/* RoomHeating: C dT/dt = P_heat - (T - T_outside) / R. */
#include "plant_model.h"

void model_initialize(ModelData *m) { m->x[0] = m->v[VR_T0]; }

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    (void)t;
    dx[0] = (m->v[VR_P_heat] - (x[0] - m->v[VR_T_outside]) / m->v[VR_R]) / m->v[VR_C];
}

void model_outputs(ModelData *m) { m->v[VR_T_room] = m->x[0]; }

void model_constrain(double *x) { (void)x; }
