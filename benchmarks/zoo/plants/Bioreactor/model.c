/* Bioreactor: continuous culture with substrate-inhibited (Haldane) growth; the dilution rate D drives the
 * biomass concentration X. B. W. Bequette, Process Dynamics: Modeling, Analysis and Simulation (Prentice
 * Hall 1998), module 9 / section 6.x; M. A. Henson and D. E. Seborg (eds.), Nonlinear Process Control
 * (Prentice Hall 1997), ch. 4 (the same model and parameters):
 *
 *   dX/dt = (mu(S) - D) X,   dS/dt = D (S_f - S) - mu(S) X / Y,   mu(S) = mu_max S / (k_m + S + k_1 S^2)
 *
 * rates in 1/h, the FMU's time in s (/ 3600). mu has its maximum at S* = sqrt(k_m / k_1): a steady state
 * with D < mu(S*) has a stable branch S < S* (X > Y (S_f - S*), dX/dD < 0), an unstable branch S > S*
 * (saddle, dX/dD > 0) and washout X = 0 (stable for D > mu(S_f)). Start: the stable steady state at the
 * start dilution rate. X and S are kept >= 0. */
#include <math.h>
#include "plant_model.h"

enum { S_X = 0, S_S = 1 };

static double mu(const ModelData *m, double S) {
    return m->v[VR_mu_max] * S / (m->v[VR_k_m] + S + m->v[VR_k_1] * S * S);
}

void model_initialize(ModelData *m) {
    double D = m->v[VR_D], k1 = m->v[VR_k_1], km = m->v[VR_k_m], mm = m->v[VR_mu_max];
    /* D k1 S^2 + (D - mu_max) S + D km = 0: the smaller root is the stable branch */
    double disc = (mm - D) * (mm - D) - 4.0 * D * D * k1 * km;
    double S = (D > 0.0 && disc >= 0.0 && mm > D) ? ((mm - D) - sqrt(disc)) / (2.0 * D * k1) : m->v[VR_S_f];
    if (D <= 0.0) S = 0.0;
    m->x[S_S] = S;
    m->x[S_X] = (S < m->v[VR_S_f]) ? m->v[VR_Y] * (m->v[VR_S_f] - S) : 0.0;
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double D = m->v[VR_D] / 3600.0, r = mu(m, x[S_S]) / 3600.0;
    (void)t;
    dx[S_X] = (r - D) * x[S_X];
    dx[S_S] = D * (m->v[VR_S_f] - x[S_S]) - r * x[S_X] / m->v[VR_Y];
}

void model_outputs(ModelData *m) { m->v[VR_X_out] = m->x[S_X]; m->v[VR_S_out] = m->x[S_S]; }

void model_constrain(double *x) {
    if (x[S_X] < 0.0) x[S_X] = 0.0;
    if (x[S_S] < 0.0) x[S_S] = 0.0;
}
