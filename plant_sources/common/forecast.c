/* The PRL-PID reward forecast in one call (see forecast.h). Every expression mirrors the Python
 * reference in prlpid_fmi/control (pid.py, reward.py, forecast.py) operation by operation: keep it
 * so, and build without floating-point contraction (the builder passes -ffp-contract=off). */
#include <math.h>
#include <string.h>

#include "forecast.h"

typedef struct {
    double integral[PRLPID_MAX_LOOPS], last_error[PRLPID_MAX_LOOPS], derivative[PRLPID_MAX_LOOPS];
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

/* One sample of eq. 2 on the given errors (pid.py PID.step_values); writes saturated u. */
static int pid_step(const PrlpidForecastSetup *s, const PrlpidForecastInput *in, PidState *st,
                    const double *errors, double *u_out) {
    const double dt = s->pid_sample_time;
    int i;
    if (!st->initialized) {
        for (i = 0; i < s->n_loops; i++) st->last_error[i] = errors[i];
        st->initialized = 1;
    }
    for (i = 0; i < s->n_loops; i++) {
        double e = errors[i], kp = in->Kp[i], ti = in->Ti[i], td = in->Td[i];
        double d = (e - st->last_error[i]) / dt;
        double ki, integral, u_unsat, lo, hi, u;
        if (s->has_derivative_filter) {
            double tf = td / s->derivative_filter_N;
            if (tf + dt == 0.0) return PRLPID_EZERODIV;
            d = (tf * st->derivative[i] + dt * d) / (tf + dt);
        }
        if (ti == 0.0) return PRLPID_EZERODIV;
        ki = kp / ti;
        integral = st->integral[i] + e * dt;
        u_unsat = kp * (e + td * d) + ki * integral;
        lo = s->u_min[i];
        hi = s->u_max[i];
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
        st->last_error[i] = e;
        st->derivative[i] = d;
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

/* PID errors: setpoint - measurement, or eq. 27's coupled error (pid.py _coupled_errors). */
static void pid_errors(const PrlpidForecastSetup *s, const PrlpidForecastInput *in, const double *y, double *errors) {
    int i;
    if (s->coupled) {
        const double *c = in->coupling;
        const double C[3][3] = {{0.0, c[0], c[1]}, {c[2], 0.0, c[3]}, {c[4], c[5], 0.0}};
        for (i = 0; i < 3; i++)
            errors[i] = in->setpoint[i] - y[i] + C[i][0] * y[0] + C[i][1] * y[1] + C[i][2] * y[2];
    } else {
        for (i = 0; i < s->n_loops; i++) errors[i] = in->setpoint[i] - y[i];
    }
}

int prlpid_forecast_core(Instance *plant, Instance *prior, const PrlpidForecastSetup *s,
                         const PrlpidForecastInput *in, PrlpidForecastResult *out) {
    double y[PRLPID_MAX_LOOPS], u[PRLPID_MAX_LOOPS], u_prev[PRLPID_MAX_LOOPS];
    double errors[PRLPID_MAX_LOOPS], error[PRLPID_MAX_LOOPS], previous_error[PRLPID_MAX_LOOPS];
    double total = 0.0;
    PidState st;
    int n, i, k, rc, count = 0;

    if (!plant || !prior || plant == prior || !s || !in || !out) return PRLPID_EINVAL;
    n = s->n_loops;
    if (n < 1 || n > PRLPID_MAX_LOOPS || s->horizon < 1 || (s->coupled && n != 3) || s->n_overrides < 0 ||
        (s->n_overrides > 0 && (!s->override_vr || !s->override_value)) || !s->measurements || !s->rewards) {
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
        pid_errors(s, in, y, errors);
        rc = pid_step(s, in, &st, errors, u);
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
