/* TwoMassDrive: motor and load inertias joined by an elastic, lightly damped shaft, viscous friction on both.
 *   J_m dw_m/dt = tau_motor - c phi - d (w_m - w_l) - b_m w_m
 *   J_l dw_l/dt = c phi + d (w_m - w_l) - b_l w_l - tau_load
 *   dphi/dt     = w_m - w_l                      (phi: shaft twist, rad) */
#include "plant_model.h"

enum { S_WM = 0, S_WL = 1, S_PHI = 2 };

void model_initialize(ModelData *m) {
    /* steady state at the start inputs: equal speeds, friction carries the net torque, the shaft the load's */
    double w = (m->v[VR_tau_motor] - m->v[VR_tau_load]) / (m->v[VR_b_m] + m->v[VR_b_l]);
    m->x[S_WM] = w;
    m->x[S_WL] = w;
    m->x[S_PHI] = (m->v[VR_b_l] * w + m->v[VR_tau_load]) / m->v[VR_c];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double shaft = m->v[VR_c] * x[S_PHI] + m->v[VR_d] * (x[S_WM] - x[S_WL]);
    (void)t;
    dx[S_WM] = (m->v[VR_tau_motor] - shaft - m->v[VR_b_m] * x[S_WM]) / m->v[VR_J_m];
    dx[S_WL] = (shaft - m->v[VR_b_l] * x[S_WL] - m->v[VR_tau_load]) / m->v[VR_J_l];
    dx[S_PHI] = x[S_WM] - x[S_WL];
}

void model_outputs(ModelData *m) {
    m->v[VR_w_load] = m->x[S_WL];
    m->v[VR_w_motor] = m->x[S_WM];
}

void model_constrain(double *x) { (void)x; }
