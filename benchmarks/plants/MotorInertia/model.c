/* MotorInertia: J dw/dt = tau - b w - tau_load (a motor's rotor and load on one stiff shaft). */
#include "plant_model.h"

void model_initialize(ModelData *m) { m->x[0] = (m->v[VR_tau] - m->v[VR_tau_load]) / m->v[VR_b]; }

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    (void)t;
    dx[0] = (m->v[VR_tau] - m->v[VR_b] * x[0] - m->v[VR_tau_load]) / m->v[VR_J];
}

void model_outputs(ModelData *m) { m->v[VR_w] = m->x[0]; }

void model_constrain(double *x) { (void)x; }
