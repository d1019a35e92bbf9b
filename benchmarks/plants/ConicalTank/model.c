/* ConicalTank: level in an inverted (apex-down) conical tank, truncated at the outlet, draining through an
 * orifice at the bottom (Torricelli), filled by a pump:
 *
 *   A(h) dh/dt = q_in + q_d - k sqrt(h),   A(h) = pi (r0 + (R - r0) h / H)^2,   k = Cd pi d^2/4 sqrt(2 g)
 *
 * Units cm, cm2, cm3/s. An empty tank cannot drain (derivative clipped at h = 0, a sub-step that undershoots
 * is projected back to 0); a full one overflows (h capped at H, inflow beyond the outflow spills). */
#include <math.h>
#include "plant_model.h"

#define PI 3.14159265358979323846
#define GRAVITY 981.0   /* cm/s2 */

static double outlet_coefficient(const ModelData *m) {
    double d = m->v[VR_d_out];
    return m->v[VR_Cd] * PI * d * d / 4.0 * sqrt(2.0 * GRAVITY);
}

static double area(const ModelData *m, double h) {
    double r = m->v[VR_r0] + (m->v[VR_R] - m->v[VR_r0]) * h / m->v[VR_H];
    return PI * r * r;
}

void model_initialize(ModelData *m) {
    /* steady state at the start inputs: outflow = inflow */
    double k = outlet_coefficient(m), q = m->v[VR_q_in] + m->v[VR_q_d], h = q > 0.0 ? (q / k) * (q / k) : 0.0;
    m->x[0] = h < m->v[VR_H] ? h : m->v[VR_H];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double h = fmin(fmax(x[0], 0.0), m->v[VR_H]);
    (void)t;
    dx[0] = (m->v[VR_q_in] + m->v[VR_q_d] - outlet_coefficient(m) * sqrt(h)) / area(m, h);
    if (x[0] <= 0.0 && dx[0] < 0.0) dx[0] = 0.0;
    if (x[0] >= m->v[VR_H] && dx[0] > 0.0) dx[0] = 0.0;
}

void model_outputs(ModelData *m) { m->v[VR_h] = m->x[0]; }

void model_constrain(double *x) {
    if (x[0] < 0.0) x[0] = 0.0;
}
