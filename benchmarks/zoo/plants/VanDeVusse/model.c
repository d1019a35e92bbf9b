/* VanDeVusse: isothermal CSTR with the Van de Vusse reactions A -> B -> C, 2A -> D; the dilution rate
 * D = F/V drives the concentration of the product B. S. Engell and K.-U. Klatt, "Nonlinear control of a
 * non-minimum-phase CSTR", American Control Conference 1993; P. B. Sistu and B. W. Bequette, Chem. Eng.
 * Sci. 50 (1995); B. W. Bequette, Process Control: Modeling, Design and Simulation (Prentice Hall 2003),
 * the isothermal Van de Vusse reactor example:
 *
 *   dCa/dt = D (Caf - Ca) - k1 Ca - k3 Ca^2,   dCb/dt = -D Cb + k1 Ca - k2 Cb,
 *
 * rates per minute, the FMU's time in s (/ 60). The steady-state Cb(D) has a maximum (about 1.266 mol/L
 * at D = 1.29 1/min): the static gain changes sign there, both branches stable (an input multiplicity;
 * right of the maximum the response has an inverse response). Start: the steady state at the start D. */
#include <math.h>
#include "plant_model.h"

enum { S_A = 0, S_B = 1 };

void model_initialize(ModelData *m) {
    double D = m->v[VR_D], k1 = m->v[VR_k1], k2 = m->v[VR_k2], k3 = m->v[VR_k3], caf = m->v[VR_Caf];
    /* k3 Ca^2 + (k1 + D) Ca - D Caf = 0, the positive root */
    double b = k1 + D, ca = (-b + sqrt(b * b + 4.0 * k3 * D * caf)) / (2.0 * k3);
    m->x[S_A] = ca;
    m->x[S_B] = k1 * ca / (D + k2);
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double D = m->v[VR_D] / 60.0, k1 = m->v[VR_k1] / 60.0, k2 = m->v[VR_k2] / 60.0, k3 = m->v[VR_k3] / 60.0;
    (void)t;
    dx[S_A] = D * (m->v[VR_Caf] - x[S_A]) - k1 * x[S_A] - k3 * x[S_A] * x[S_A];
    dx[S_B] = -D * x[S_B] + k1 * x[S_A] - k2 * x[S_B];
}

void model_outputs(ModelData *m) { m->v[VR_Cb] = m->x[S_B]; m->v[VR_Ca] = m->x[S_A]; }

void model_constrain(double *x) { (void)x; }
