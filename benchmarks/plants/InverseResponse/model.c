/* InverseResponse: Astrom & Hagglund's non-minimum-phase benchmark (1 - alpha s)/(1 + tau s)^3 with gain K.
 * Three equal lags x1..x3 driven by the steam flow; T = T_base + K ((1 + a) x3 - a x2) with a = alpha / tau
 * (since x2 = (1 + tau s) x3, this is K (1 - alpha s) x3: the zero at s = +1/alpha). */
#include "plant_model.h"

void model_initialize(ModelData *m) {
    int k;
    for (k = 0; k < 3; k++) m->x[k] = m->v[VR_Q_steam]; /* steady state at the start input */
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double tau = m->v[VR_tau];
    (void)t;
    dx[0] = (m->v[VR_Q_steam] - x[0]) / tau;
    dx[1] = (x[0] - x[1]) / tau;
    dx[2] = (x[1] - x[2]) / tau;
}

void model_outputs(ModelData *m) {
    double a = m->v[VR_alpha] / m->v[VR_tau];
    m->v[VR_T_tray] = m->v[VR_T_base] + m->v[VR_K] * ((1.0 + a) * m->x[2] - a * m->x[1]);
}

void model_constrain(double *x) { (void)x; }
