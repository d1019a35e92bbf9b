/* RCLadder4: four equal RC sections separated by voltage followers, Astrom & Hagglund's 1/(1+sT)^4.
 *   tau dv_k/dt = v_{k-1} - v_k,  v_0 = v_in,  v_out = v_4. */
#include "plant_model.h"

void model_initialize(ModelData *m) {
    int k;
    for (k = 0; k < 4; k++) m->x[k] = m->v[VR_v_in]; /* steady state at the start input */
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double tau = m->v[VR_R] * m->v[VR_C];
    (void)t;
    dx[0] = (m->v[VR_v_in] - x[0]) / tau;
    dx[1] = (x[0] - x[1]) / tau;
    dx[2] = (x[1] - x[2]) / tau;
    dx[3] = (x[2] - x[3]) / tau;
}

void model_outputs(ModelData *m) { m->v[VR_v_out] = m->x[3]; }

void model_constrain(double *x) { (void)x; }
