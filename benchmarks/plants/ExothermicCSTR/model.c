/* ExothermicCSTR: a jacketed, perfectly mixed reactor with a first-order irreversible exothermic reaction
 * A -> B, rate k(T) C_A with k(T) = k0 exp(-E/(R T)) (Seborg, Edgar, Mellichamp & Doyle's nonisothermal
 * CSTR). Constant volume and physical properties; the jacket temperature T_c is the manipulated input:
 *
 *   dC_A/dt = q/V (C_Af - C_A) - k(T) C_A
 *   dT/dt   = q/V (T_f - T) + (-dH)/(rho Cp) k(T) C_A + UA/(V rho Cp) (T_c - T)
 *
 * in the textbook's units (L, min, J, K, mol); the FMU's time is in s, so both derivatives are / 60.
 *
 * Start: a steady state at the start inputs. There can be three (the middle one unstable); the one
 * nearest the parameter T_0 is taken. Steady states are the roots in T of the energy balance with the
 * mass balance's C_A = q C_Af / (q + V k(T)) inserted,
 *   r(T) = q rho Cp (T_f - T) + (-dH) V k(T) C_A(T) + UA (T_c - T),
 * bracketed on a 0.1 K grid over [T_SCAN_LOW, T_SCAN_HIGH] and bisected to 1e-12 K. Without a root there
 * (inputs far outside the model's range) the states are NaN. */
#include <math.h>
#include "plant_model.h"

enum { S_CA = 0, S_T = 1 };

#define T_SCAN_LOW 200.0
#define T_SCAN_HIGH 800.0
#define T_SCAN_STEP 0.1

static double rate_constant(const ModelData *m, double temp) {
    return m->v[VR_k0] * exp(-m->v[VR_E_R] / temp);
}

static double steady_ca(const ModelData *m, double temp) {
    double q = m->v[VR_q], vol = m->v[VR_V];
    return q * m->v[VR_C_Af] / (q + vol * rate_constant(m, temp));
}

static double energy_residual(const ModelData *m, double temp) {
    double q = m->v[VR_q], vol = m->v[VR_V], rho_cp = m->v[VR_rho] * m->v[VR_Cp];
    return q * rho_cp * (m->v[VR_T_f] - temp) - m->v[VR_dH] * vol * rate_constant(m, temp) * steady_ca(m, temp)
           + m->v[VR_UA] * (m->v[VR_T_c] - temp);
}

static double bisect(const ModelData *m, double lo, double hi) {
    double r_lo = energy_residual(m, lo);
    int i;
    for (i = 0; i < 200 && hi - lo > 1e-12; i++) {
        double mid = 0.5 * (lo + hi), r_mid = energy_residual(m, mid);
        if ((r_mid > 0.0) == (r_lo > 0.0)) { lo = mid; r_lo = r_mid; } else hi = mid;
    }
    return 0.5 * (lo + hi);
}

void model_initialize(ModelData *m) {
    double best = NAN, target = m->v[VR_T_0], prev = energy_residual(m, T_SCAN_LOW);
    int j, n = (int)((T_SCAN_HIGH - T_SCAN_LOW) / T_SCAN_STEP + 0.5);
    for (j = 1; j <= n; j++) {
        double lo = T_SCAN_LOW + (j - 1) * T_SCAN_STEP, hi = T_SCAN_LOW + j * T_SCAN_STEP;
        double r = energy_residual(m, hi);
        if (r == 0.0 || (r > 0.0) != (prev > 0.0)) {
            double root = r == 0.0 ? hi : bisect(m, lo, hi);
            if (isnan(best) || fabs(root - target) < fabs(best - target)) best = root;
        }
        prev = r;
    }
    m->x[S_T] = best;
    m->x[S_CA] = isnan(best) ? NAN : steady_ca(m, best);
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    double q_v = m->v[VR_q] / m->v[VR_V], rho_cp = m->v[VR_rho] * m->v[VR_Cp];
    double r = rate_constant(m, x[S_T]) * x[S_CA];
    (void)t;
    dx[S_CA] = (q_v * (m->v[VR_C_Af] - x[S_CA]) - r) / 60.0;
    dx[S_T] = (q_v * (m->v[VR_T_f] - x[S_T]) - m->v[VR_dH] / rho_cp * r
               + m->v[VR_UA] / (m->v[VR_V] * rho_cp) * (m->v[VR_T_c] - x[S_T])) / 60.0;
}

void model_outputs(ModelData *m) {
    m->v[VR_T] = m->x[S_T];
    m->v[VR_C_A] = m->x[S_CA];
}

void model_constrain(double *x) {
    if (x[S_CA] < 0.0) x[S_CA] = 0.0;
}
