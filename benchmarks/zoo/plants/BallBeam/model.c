/* BallBeam: a ball rolling on a beam whose angle follows the command through a servo lag,
 *
 *   d theta/dt = (theta_c - theta) / tau_s,
 *   (J_b / r_b^2 + m) d^2 p/dt^2 = m p (d theta/dt)^2 + m g sin(theta)
 *     i.e. d^2 p/dt^2 = B (p (d theta/dt)^2 + g sin(theta)),  B = m / (J_b / r_b^2 + m) = 5/7 (solid ball),
 *
 * J. Hauser, S. Sastry and P. Kokotovic, "Nonlinear control via approximate input-output linearization:
 * the ball and beam example", IEEE Trans. Automatic Control 37(3), 1992 (the ball's equation; theta here
 * positive where the beam tilts down towards +p, so the input-output gain is positive); the servo lag as
 * in the Quanser ball-and-beam experiment. Open-loop unstable (a double integrator from the angle, with
 * the servo lag: B g / (s^2 (tau_s s + 1)) linearised). Start: at rest at p = p0 with the beam level.
 * The beam is +-L_beam long; the model does not stop the ball at the ends (the loop's divergence bound). */
#include <math.h>
#include "plant_model.h"

enum { S_P = 0, S_V = 1, S_TH = 2 };

void model_initialize(ModelData *m) {
    m->x[S_P] = m->v[VR_p0];
    m->x[S_V] = 0.0;
    m->x[S_TH] = m->v[VR_theta_c];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double w = (m->v[VR_theta_c] - x[S_TH]) / m->v[VR_tau_s];
    (void)t;
    dx[S_P] = x[S_V];
    dx[S_V] = m->v[VR_B] * (x[S_P] * w * w + m->v[VR_g] * sin(x[S_TH]));
    dx[S_TH] = w;
}

void model_outputs(ModelData *m) { m->v[VR_p] = m->x[S_P]; }

void model_constrain(double *x) { (void)x; }
