/* The PRL-PID reward forecast in one call (see forecast.h). Every expression mirrors the Python
 * reference (prlpid_fmi/control/pid.py, control/reward.py, loop/forecast/fmi.py) operation by operation: keep it
 * so, and build without floating-point contraction (the builder passes -ffp-contract=off). */
#include <math.h>
#include <string.h>

#include "forecast.h"

typedef struct {
    double integral[PRLPID_MAX_LOOPS], last_error[PRLPID_MAX_LOOPS], derivative[PRLPID_MAX_LOOPS];
    double filtered[PRLPID_MAX_LOOPS], stage[PRLPID_MAX_LOOPS];
    double last_output[PRLPID_MAX_LOOPS];
    double last_p[PRLPID_MAX_LOOPS], last_kp[PRLPID_MAX_LOOPS], last_ti[PRLPID_MAX_LOOPS], last_td[PRLPID_MAX_LOOPS];
    int initialized;
} PidState;

int prlpid_forecast_abi(void) { return PRLPID_FORECAST_ABI; }

size_t prlpid_forecast_struct_size(int which) {
    switch (which) {
        case 0: return sizeof(PrlpidForecastSetup);
        case 1: return sizeof(PrlpidForecastInput);
        case 2: return sizeof(PrlpidForecastResult);
        default: return 0;
    }
}

/* One sample on the integral, proportional and derivative errors e, ep, ed (pid.py PID.step_weighted),
 * clipped to the limits, or to the rate limit's band within them; writes saturated u. Bumpless: when the gains
 * differ from the last sample's, the error sum is first rescaled so that the new gains give the old output on
 * the last sample's ep, D and sum. */
static int pid_step(const PrlpidForecastSetup *s, const PrlpidForecastInput *in, PidState *st,
                    const double *errors, const double *p_errors, const double *d_errors, double *u_out) {
    const double dt = s->pid_sample_time;
    int i;
    if (!st->initialized) {
        for (i = 0; i < s->n_loops; i++) st->last_error[i] = d_errors[i];
        st->initialized = 1;
    }
    for (i = 0; i < s->n_loops; i++) {
        double e = errors[i], kp = in->Kp[i], ti = in->Ti[i], td = in->Td[i];
        double ed = d_errors[i];
        double d = (ed - st->last_error[i]) / dt;
        double ki, integral, u_unsat, lo, hi, u;
        if (s->has_derivative_filter) {
            double tf = td / s->derivative_filter_N;
            if (tf + dt == 0.0) return PRLPID_EZERODIV;
            d = (tf * st->derivative[i] + dt * d) / (tf + dt);
        }
        if (ti == 0.0) return PRLPID_EZERODIV;
        ki = kp / ti;
        if (s->gain_change == PRLPID_BUMPLESS && (kp != st->last_kp[i] || ti != st->last_ti[i] || td != st->last_td[i])
            && st->last_kp[i] == st->last_kp[i] && ki != 0) {
            double kp0 = st->last_kp[i], d0 = st->derivative[i], p0 = st->last_p[i];
            double v = kp0 * (p0 + st->last_td[i] * d0) + kp0 / st->last_ti[i] * st->integral[i];
            st->integral[i] = (v - kp * (p0 + td * d0)) / ki;
        }
        st->last_p[i] = p_errors[i];
        st->last_kp[i] = kp;
        st->last_ti[i] = ti;
        st->last_td[i] = td;
        integral = st->integral[i] + e * dt;
        u_unsat = kp * (p_errors[i] + td * d) + ki * integral;
        lo = s->u_min[i];
        hi = s->u_max[i];
        if (s->u_rate_limit[i] != HUGE_VAL && st->last_output[i] == st->last_output[i]) {
            /* the rate limit: a band around the previous output; max(lo, down) and min(hi, up) as Python's
             * max and min (the first argument unless the second is strictly beyond it) */
            double step = s->u_rate_limit[i] * dt;
            double down = st->last_output[i] - step, up = st->last_output[i] + step;
            lo = down > lo ? down : lo;
            hi = up < hi ? up : hi;
        }
        u = u_unsat < lo ? lo : (u_unsat > hi ? hi : u_unsat); /* NaN passes through */
        if (u != u_unsat) { /* saturated */
            if (s->anti_windup == PRLPID_CLAMPING) {
                if ((u_unsat - u) * (kp * e) > 0) integral = st->integral[i];
            } else if (s->anti_windup == PRLPID_BACK_CALCULATION && ki != 0) {
                double Tt, tracked;
                if (s->has_Tt) {
                    Tt = s->Tt[i];
                } else if (td > 0) {
                    if (ti * td < 0) return PRLPID_EDOMAIN;
                    Tt = sqrt(ti * td);
                } else {
                    Tt = ti;
                }
                if (Tt + dt == 0.0) return PRLPID_EZERODIV;
                tracked = dt / (Tt + dt) * (u - u_unsat);
                integral += tracked / ki;
            }
        }
        st->integral[i] = integral;
        st->last_error[i] = ed;
        st->derivative[i] = d;
        st->last_output[i] = u; /* Python keeps it only when a loop is rate limited; it is read only then */
        u_out[i] = u;
    }
    return PRLPID_OK;
}

/* Eq. 10-11 plus the control-variation term for one loop (reward.py _loop_reward). */
static double loop_reward(const PrlpidForecastSetup *s, double e, double e_prev, double u, double u_prev,
                          double u_scale) {
    double abs_e = e >= 0 ? e : -e;
    double v = 0.5 * e * e;
    double v_growth = v - 0.5 * e_prev * e_prev;
    double r = -(v_growth <= 0 ? 0.0 : v_growth)
               - s->alpha * (v >= s->v_clip ? s->v_clip : v)
               - s->beta * (abs_e >= s->e_clip ? s->e_clip : abs_e);
    if (abs_e < s->bonus_threshold) r += s->bonus_numerator / (abs_e + s->bonus_offset);
    if (s->control_variation_weight != 0.0) {
        double variation = fabs(u - u_prev) / u_scale;
        r -= s->control_variation_weight * (variation >= 1.0 ? 1.0 : variation);
    }
    return r;
}

/* Eq. 27 (pid.py _coupled_errors): e_i = (r_i - y_i) + sum_j C[i][j] * y_j, left to right, C's zero
 * diagonal kept in the sum. */
static void coupled_errors(const double *c, const double *r, const double *y, double *errors) {
    const double C[3][3] = {{0.0, c[0], c[1]}, {c[2], 0.0, c[3]}, {c[4], c[5], 0.0}};
    int i;
    for (i = 0; i < 3; i++) errors[i] = r[i] - y[i] + C[i][0] * y[0] + C[i][1] * y[1] + C[i][2] * y[2];
}

/* yf from y, advancing the measurement filter once per sample (pid.py PID.filter_measurement). */
static void filter_measurement(const PrlpidForecastSetup *s, PidState *st, const double *y, double *yf) {
    const double dt = s->pid_sample_time;
    int i, filtered = 0;
    for (i = 0; i < s->n_loops; i++) {
        yf[i] = y[i];
        if (s->measurement_filter[i] != 0.0) filtered = 1;
    }
    if (!filtered) return;
    if (!st->initialized) {
        for (i = 0; i < s->n_loops; i++) st->filtered[i] = st->stage[i] = y[i];
        return;
    }
    for (i = 0; i < s->n_loops; i++) {
        double T = s->measurement_filter[i] / (double)s->measurement_filter_order, x;
        if (T == 0.0) continue;
        x = (T * st->stage[i] + dt * y[i]) / (T + dt);
        st->stage[i] = x;
        if (s->measurement_filter_order == 2) x = (T * st->filtered[i] + dt * x) / (T + dt);
        st->filtered[i] = x;
        yf[i] = x;
    }
}

/* The PID's errors e, ep, ed of one sample (pid.py PID.weighted_errors, CoupledPID.step_values): e from
 * (r, y), ep from (b*r, yf), ed from (c*r, yf), each through eq. 27 when coupled; advances the filter. */
static void pid_errors(const PrlpidForecastSetup *s, const PrlpidForecastInput *in, PidState *st, const double *y,
                       double *errors, double *p_errors, double *d_errors) {
    const double *r = in->setpoint;
    double yf[PRLPID_MAX_LOOPS], br[PRLPID_MAX_LOOPS], cr[PRLPID_MAX_LOOPS];
    int i, n = s->n_loops, weighted = 0;
    if (s->coupled) coupled_errors(in->coupling, r, y, errors);
    else for (i = 0; i < n; i++) errors[i] = r[i] - y[i];
    for (i = 0; i < n; i++) {
        if (s->setpoint_weight[i] != 1.0 || s->derivative_weight[i] != 1.0 || s->measurement_filter[i] != 0.0)
            weighted = 1;
    }
    if (!weighted) {
        memcpy(p_errors, errors, (size_t)n * sizeof(double));
        memcpy(d_errors, errors, (size_t)n * sizeof(double));
        return;
    }
    filter_measurement(s, st, y, yf);
    if (s->coupled) {
        for (i = 0; i < 3; i++) {
            br[i] = s->setpoint_weight[i] * r[i];
            cr[i] = s->derivative_weight[i] * r[i];
        }
        coupled_errors(in->coupling, br, yf, p_errors);
        coupled_errors(in->coupling, cr, yf, d_errors);
    } else {
        for (i = 0; i < n; i++) {
            p_errors[i] = s->setpoint_weight[i] * r[i] - yf[i];
            d_errors[i] = s->derivative_weight[i] * r[i] - yf[i];
        }
    }
}

int prlpid_forecast_core(Instance *plant, Instance *prior, const PrlpidForecastSetup *s,
                         const PrlpidForecastInput *in, PrlpidForecastResult *out) {
    double y[PRLPID_MAX_LOOPS], u[PRLPID_MAX_LOOPS], u_prev[PRLPID_MAX_LOOPS];
    double errors[PRLPID_MAX_LOOPS], p_errors[PRLPID_MAX_LOOPS], d_errors[PRLPID_MAX_LOOPS];
    double error[PRLPID_MAX_LOOPS], previous_error[PRLPID_MAX_LOOPS];
    double total = 0.0;
    PidState st;
    int n, i, k, rc, count = 0;

    if (!plant || !prior || plant == prior || !s || !in || !out) return PRLPID_EINVAL;
    n = s->n_loops;
    if (n < 1 || n > PRLPID_MAX_LOOPS || s->horizon < 1 || (s->coupled && n != 3) || s->n_overrides < 0 ||
        (s->n_overrides > 0 && (!s->override_vr || !s->override_value)) || !s->measurements || !s->rewards ||
        (s->measurement_filter_order != 1 && s->measurement_filter_order != 2) ||
        (s->gain_change != PRLPID_POSITIONAL && s->gain_change != PRLPID_BUMPLESS)) {
        return PRLPID_EINVAL;
    }
    out->steps = out->n_measurements = out->stopped = 0;

    instance_copy_state(plant, prior);
    if (s->n_overrides > 0 &&
        instance_set_real(prior, s->override_vr, (size_t)s->n_overrides, s->override_value) != STATUS_OK) {
        return PRLPID_EFMU;
    }
    memcpy(st.integral, in->integral, sizeof(st.integral));
    memcpy(st.last_error, in->last_error, sizeof(st.last_error));
    memcpy(st.derivative, in->derivative, sizeof(st.derivative));
    memcpy(st.filtered, in->filtered, sizeof(st.filtered));
    memcpy(st.stage, in->filter_stage, sizeof(st.stage));
    memcpy(st.last_output, in->last_output, sizeof(st.last_output));
    memcpy(st.last_p, in->last_p_error, sizeof(st.last_p));
    memcpy(st.last_kp, in->last_Kp, sizeof(st.last_kp));
    memcpy(st.last_ti, in->last_Ti, sizeof(st.last_ti));
    memcpy(st.last_td, in->last_Td, sizeof(st.last_td));
    st.initialized = in->initialized;
    for (i = 0; i < n; i++) {
        previous_error[i] = (in->setpoint[i] - in->measurement[i]) / s->scale[i];
        y[i] = in->measurement[i];
        u_prev[i] = in->u_prev[i];
    }

    for (k = 0; k < s->horizon; k++) {
        Status status;
        double r = 0.0;
        int diverged = 0;
        pid_errors(s, in, &st, y, errors, p_errors, d_errors);
        rc = pid_step(s, in, &st, errors, p_errors, d_errors, u);
        if (rc != PRLPID_OK) return rc;
        if (instance_set_real(prior, s->input_vr, (size_t)n, u) != STATUS_OK) return PRLPID_EFMU;
        status = instance_do_step(prior, prior->m.time, s->step_size);
        if (status == STATUS_DISCARD) {
            s->rewards[count] = s->penalty;
            total += s->penalty;
            count++;
            out->stopped = 2;
            break;
        }
        if (status != STATUS_OK) return PRLPID_EFMU;
        if (instance_get_real(prior, s->output_vr, (size_t)n, y) != STATUS_OK) return PRLPID_EFMU;
        memcpy(s->measurements + (size_t)k * (size_t)n, y, (size_t)n * sizeof(double));
        out->n_measurements = k + 1;
        for (i = 0; i < n; i++) {
            error[i] = (in->setpoint[i] - y[i]) / s->scale[i];
            if (!(fabs(error[i]) <= s->bound[i])) diverged = 1; /* also NaN */
        }
        if (diverged) {
            s->rewards[count] = s->penalty;
            total += s->penalty;
            count++;
            out->stopped = 1;
            break;
        }
        for (i = 0; i < n; i++) r += loop_reward(s, error[i], previous_error[i], u[i], u_prev[i], s->u_scale[i]);
        r /= (double)n;
        s->rewards[count] = r;
        total += r;
        count++;
        for (i = 0; i < n; i++) {
            previous_error[i] = error[i];
            u_prev[i] = u[i];
        }
    }
    out->mean_reward = total / (double)count;
    out->steps = count;
    out->prior_time = prior->m.time;
    return PRLPID_OK;
}
