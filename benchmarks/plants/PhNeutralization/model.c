/* PhNeutralization: a weak acid (acetic acid, HAc) neutralised by a strong base (NaOH) in a stirred tank
 * (McAvoy, Hsu & Lowenthal 1972). Reaction invariants as states: the total acetate concentration
 * xa = [HAc] + [Ac-] and the sodium concentration xb = [Na+], both mol/L, perfectly mixed, constant volume:
 *
 *   V dxa/dt = F_a C_a - (F_a + F_b) xa
 *   V dxb/dt = F_b C_b - (F_a + F_b) xb          (flows in mL/min, V in mL; the FMU's time in s: / 60)
 *
 * pH from the charge balance [Na+] + [H+] = [OH-] + [Ac-], with [Ac-] = xa Ka / (Ka + [H+]) and
 * [OH-] = Kw / [H+]: with h = 10^-pH,
 *
 *   f(pH) = xb + h - Kw / h - xa Ka / (Ka + h) = 0,
 *
 * f strictly decreasing in pH (df/dh = 1 + Kw/h^2 + xa Ka/(Ka + h)^2 > 0), so one root, found by
 * bisection on [-2, 16] until the bracket is below 1e-13 pH (f(-2) > 0 > f(16) for concentrations below
 * 100 mol/L). The pH enters no derivative: it is computed for the output only. */
#include <math.h>
#include "plant_model.h"

enum { S_XA = 0, S_XB = 1 };

#define PH_LOW (-2.0)
#define PH_HIGH 16.0
#define PH_TOL 1e-13

static double charge_residual(double ph, double xa, double xb, double ka, double kw) {
    double h = pow(10.0, -ph);
    return xb + h - kw / h - xa * ka / (ka + h);
}

static double solve_ph(double xa, double xb, double ka, double kw) {
    double lo = PH_LOW, hi = PH_HIGH;
    int i;
    if (!(isfinite(xa) && isfinite(xb))) return NAN;
    for (i = 0; i < 200 && hi - lo > PH_TOL; i++) {
        double mid = 0.5 * (lo + hi);
        if (charge_residual(mid, xa, xb, ka, kw) > 0.0) lo = mid; else hi = mid;
    }
    return 0.5 * (lo + hi);
}

void model_initialize(ModelData *m) {
    /* steady state at the start inputs: the tank holds the feed mix */
    double fa = m->v[VR_F_a], fb = m->v[VR_F_b], total = fa + fb;
    m->x[S_XA] = total > 0.0 ? fa * m->v[VR_C_a] / total : 0.0;
    m->x[S_XB] = total > 0.0 ? fb * m->v[VR_C_b] / total : 0.0;
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double fa = m->v[VR_F_a], fb = m->v[VR_F_b], total = fa + fb, v = m->v[VR_V] * 60.0;
    (void)t;
    dx[S_XA] = (fa * m->v[VR_C_a] - total * x[S_XA]) / v;
    dx[S_XB] = (fb * m->v[VR_C_b] - total * x[S_XB]) / v;
}

void model_outputs(ModelData *m) {
    m->v[VR_pH] = solve_ph(m->x[S_XA], m->x[S_XB], m->v[VR_Ka], m->v[VR_Kw]);
    m->v[VR_acetate] = m->x[S_XA];
    m->v[VR_sodium] = m->x[S_XB];
}

void model_constrain(double *x) {
    if (x[S_XA] < 0.0) x[S_XA] = 0.0;
    if (x[S_XB] < 0.0) x[S_XB] = 0.0;
}
