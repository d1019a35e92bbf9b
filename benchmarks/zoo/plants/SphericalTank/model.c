/* SphericalTank: level h in a spherical tank of radius R with gravity outflow through a valve,
 *
 *   A(h) dh/dt = q_in - k sqrt(h),   A(h) = pi h (2R - h)   (cross-section at height h),
 *
 * q in L/s (/ 1000 for m^3/s). The area vanishes at the bottom and the top, so the gain 2 sqrt(h)/k and the
 * time constant 2 A(h) sqrt(h)/k change across the range: a standard nonlinear level benchmark (e.g.
 * S. Nithya, N. Sivakumaran, T. Balasubramanian, N. Anantharaman, "Model based controller design for a
 * spherical tank process in real time", Int. J. Simulation: Systems, Science & Technology 9(4), 2008).
 * The area is floored at A_min (the inlet and outlet necks), h is kept >= 0, and a full tank (h >= 2R)
 * overflows: the level stops rising.
 * Start: the steady state h = (q_in / k)^2 at the start inflow. */
#include <math.h>
#include "plant_model.h"

static double area(const ModelData *m, double h) {
    double R = m->v[VR_R], a = M_PI * h * (2.0 * R - h);
    return a > m->v[VR_A_min] ? a : m->v[VR_A_min];
}

void model_initialize(ModelData *m) {
    double h = m->v[VR_q_in] / m->v[VR_k];
    m->x[0] = h * h;
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double h = x[0] > 0.0 ? x[0] : 0.0, net = m->v[VR_q_in] - m->v[VR_k] * sqrt(h);
    (void)t;
    dx[0] = (h >= 2.0 * m->v[VR_R] && net > 0.0) ? 0.0 : net / 1000.0 / area(m, h);  /* full: overflow */
}

void model_outputs(ModelData *m) { m->v[VR_h] = m->x[0]; }

void model_constrain(double *x) {
    if (x[0] < 0.0) x[0] = 0.0;
}
