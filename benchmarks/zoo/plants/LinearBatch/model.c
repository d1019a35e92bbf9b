/* LinearBatch: one parameterised linear plant for Astrom & Hagglund's PID test batch,
 *
 *   Y(s) = N(s) / D(s) * e^{-sL} U(s),   N(s) = num0 + num1 s + num2 s^2 + num3 s^3,
 *                                        D(s) = den0 + den1 s + ... + den8 s^8,
 *
 * (K. J. Astrom and T. Hagglund, "Benchmark systems for PID control", IFAC Workshop on Digital Control:
 * Past, Present and Future of PID Control, Terrassa, 2000; also Astrom & Hagglund, Advanced PID Control,
 * ISA 2006, section 7.x, the test batch). The order n is the highest power with den_n != 0 (1..8); the
 * numerator must be of lower order (strictly proper), else y is NaN.
 *
 * Realisation: controllable canonical form in x1..xn, x1 the "partial state" w with D(s) W = U:
 *   dx_i/dt = x_{i+1} (i < n),  dx_n/dt = (u(t - L) - sum_k den_k x_{k+1}) / den_n,  y = sum_k num_k x_{k+1}.
 * States above n stay at zero. Start: the steady state at the start input, x1 = u0 / den0 (x1 = 0 when
 * den0 = 0: an integrating plant is at rest at any output for u0 = 0; the start input must then be 0).
 *
 * Dead time: as benchmarks/plants/HeatExchanger, a ring of RING inputs at the internal step, filled between
 * RK4 sub-steps by model_constrain from two auxiliary integrals (the input held over the sub-step and the
 * sub-step's length); the ODE reads the input of d = round(L / fixed_step) sub-steps ago. L must be at most
 * RING * fixed_step, else y is NaN. Co-simulation only. */
#include <math.h>
#include <string.h>
#include "plant_model.h"

#define RING 256
#define NMAX 8
enum { S_X = 0, S_Z = NMAX, S_C = NMAX + 1, S_RING = NMAX + 2 };

static double den(const ModelData *m, int k) { return m->v[VR_den0 + k]; }
static double num(const ModelData *m, int k) { return m->v[VR_num0 + k]; }

/* Order of D(s), or -1 when D is zero or N is not of lower order. */
static int order(const ModelData *m) {
    int n = -1, k;
    for (k = NMAX; k >= 1; k--) if (den(m, k) != 0.0) { n = k; break; }
    if (n < 1) return -1;
    for (k = n; k <= 3; k++) if (num(m, k) != 0.0) return -1;
    return n;
}

static int delay_substeps(const ModelData *m) {
    double d = m->v[VR_L] / m->v[VR_fixed_step];
    if (!(d >= 0.0) || d > RING + 0.5) return -1;
    return (int)floor(d + 0.5);
}

void model_initialize(ModelData *m) {
    int j;
    memset(m->x, 0, sizeof(double) * N_STATES);
    if (den(m, 0) != 0.0) m->x[S_X] = m->v[VR_u] / den(m, 0);
    for (j = 0; j < RING; j++) m->x[S_RING + j] = m->v[VR_u];
}

void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    int n = order(m), d = delay_substeps(m), k;
    double u_delayed = d <= 0 ? m->v[VR_u] : x[S_RING + d - 1], acc;
    (void)t;
    memset(dx, 0, sizeof(double) * N_STATES);
    if (n > 0) {
        for (k = 0; k < n - 1; k++) dx[S_X + k] = x[S_X + k + 1];
        acc = u_delayed;
        for (k = 0; k < n; k++) acc -= den(m, k) * x[S_X + k];
        dx[S_X + n - 1] = acc / den(m, n);
    }
    dx[S_Z] = m->v[VR_u];
    dx[S_C] = 1.0;
}

void model_outputs(ModelData *m) {
    int n = order(m), k;
    double y = 0.0;
    if (n < 0 || delay_substeps(m) < 0) { m->v[VR_y] = NAN; return; }
    for (k = 0; k < n && k <= 3; k++) y += num(m, k) * m->x[S_X + k];
    m->v[VR_y] = y;
}

void model_constrain(double *x) {
    double held = x[S_C] > 0.0 ? x[S_Z] / x[S_C] : x[S_RING];
    memmove(&x[S_RING + 1], &x[S_RING], sizeof(double) * (RING - 1));
    x[S_RING] = held;
    x[S_Z] = 0.0;
    x[S_C] = 0.0;
}
