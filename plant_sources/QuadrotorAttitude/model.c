/* QuadrotorAttitude (paper eq. 25), states (phi, theta, psi, p, q, r). */
#include "plant_model.h"

void model_initialize(ModelData *m) {
    m->x[0] = m->v[VR_phi0];
    m->x[1] = m->v[VR_theta0];
    m->x[2] = m->v[VR_psi0];
    m->x[3] = m->v[VR_p0];
    m->x[4] = m->v[VR_q0];
    m->x[5] = m->v[VR_r0];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double Ix = m->v[VR_Ix], Iy = m->v[VR_Iy], Iz = m->v[VR_Iz];
    double p = x[3], q = x[4], r = x[5];
    (void)t;
    dx[0] = p;
    dx[1] = q;
    dx[2] = r;
    dx[3] = (Iy - Iz) / Ix * q * r + m->v[VR_U_phi] / Ix;
    dx[4] = (Iz - Ix) / Iy * p * r + m->v[VR_U_theta] / Iy;
    dx[5] = (Ix - Iy) / Iz * p * q + m->v[VR_U_psi] / Iz;
}

void model_outputs(ModelData *m) {
    m->v[VR_phi] = m->x[0];
    m->v[VR_theta] = m->x[1];
    m->v[VR_psi] = m->x[2];
    m->v[VR_p] = m->x[3];
    m->v[VR_q] = m->x[4];
    m->v[VR_r] = m->x[5];
}

void model_constrain(double *x) { (void)x; }
