/* The PRL-PID reward forecast (paper eq. 12-14) in one call: a plain C function exported beside the
 * FMI API (not an FMI extension), for a plant and a prior that are two instances of this FMU.
 *
 * prlpid_forecast(plant, prior, setup, input, result) copies the plant instance's full state into the
 * prior, sets the overrides on the prior, and rolls the prior `horizon` samples ahead with a copy of
 * the PID state and fixed gains: u = PID (the 2-DOF law of pid.py: setpoint weights b, c, the
 * measurement filter Tf, the output rate limit R and the bumpless gain change, which at the first step rescales
 * the error sum from the previous sample's gains in the state to the call's; eq. 2 when b = c = 1, Tf = 0,
 * R = inf and gain_change positional; optionally the coupled errors of eq. 27) on the last measurement, prior inputs := u, doStep, measurement := prior
 * outputs, reward (eq. 10-11 plus the control-variation term) on the normalised error. A discarded step or an error beyond the divergence
 * bound adds the divergence penalty and ends the roll-out. The result is the mean reward. The roll-out starts
 * from the PID state copied in (the bumpless preset, if any, happened before the call; none happens here).
 *
 * The arithmetic is that of prlpid_fmi (control/pid.py PID.filter_measurement, PID.weighted_errors,
 * PID.step_weighted and CoupledPID.step_values; control/reward.py _loop_reward; loop/forecast/fmi.py
 * FmiForecast) in the same operation order, so that, compiled without floating-point contraction, both
 * give bit-identical results. Change them together.
 *
 * `plant` and `prior` are the FMI instance pointers (fmi2Component / fmi3Instance); each FMI layer
 * exports prlpid_forecast and unwraps them. prlpid_forecast_abi() returns PRLPID_FORECAST_ABI and
 * prlpid_forecast_struct_size(k) sizeof the setup (k = 0), input (1) and result (2) structs, so a
 * caller can refuse a binary whose layout it does not know.
 */
#ifndef FORECAST_H
#define FORECAST_H

#include <stddef.h>
#include "instance.h"

#define PRLPID_FORECAST_ABI 4 /* 4: the bumpless gain change (gain_change, the previous gains and ep) */
#define PRLPID_MAX_LOOPS 3

#if defined(_WIN32)
#define PRLPID_EXPORT __declspec(dllexport)
#else
#define PRLPID_EXPORT __attribute__((visibility("default")))
#endif

enum { PRLPID_CLAMPING = 0, PRLPID_BACK_CALCULATION = 1, PRLPID_NO_ANTI_WINDUP = 2 };
enum { PRLPID_POSITIONAL = 0, PRLPID_BUMPLESS = 1 }; /* what a gain change does to the error sum (pid.py) */

/* Return codes: 0 = done (possibly stopped by divergence); negative = nothing meaningful in result. */
enum {
    PRLPID_OK = 0,
    PRLPID_EINVAL = -1,      /* bad setup (n_loops, horizon, NULL pointers, plant == prior) */
    PRLPID_EFMU = -2,        /* the prior returned error on set/doStep/get (message in its log) */
    PRLPID_EZERODIV = -3,    /* a division by zero where Python raises ZeroDivisionError (Ti = 0, Td/N + dt = 0,
                                Tt + dt = 0) */
    PRLPID_EDOMAIN = -4      /* sqrt of a negative Ti*Td, where Python raises ValueError */
};

/* Fixed for a forecast object, except the PID structure (setpoint_weight, derivative_weight,
 * measurement_filter), which the caller refreshes before a call whenever the PID's changes; arrays are
 * per loop (first n_loops entries used). */
typedef struct {
    int n_loops;                    /* 1..3 */
    int horizon;                    /* N >= 1 */
    int anti_windup;                /* PRLPID_CLAMPING | PRLPID_BACK_CALCULATION | PRLPID_NO_ANTI_WINDUP */
    int coupled;                    /* 1: eq. 27 coupled error (n_loops = 3) */
    int has_derivative_filter;      /* 1: first-order derivative filter Td/N */
    int has_Tt;                     /* 1: Tt below; 0: sqrt(Ti*Td), or Ti when Td = 0 */
    int n_overrides;                /* entries in override_vr / override_value */
    int measurement_filter_order;   /* 1 | 2: sections of the measurement filter */
    int gain_change;                /* PRLPID_POSITIONAL | PRLPID_BUMPLESS */
    unsigned int input_vr[PRLPID_MAX_LOOPS];   /* prior inputs the PID drives */
    unsigned int output_vr[PRLPID_MAX_LOOPS];  /* prior outputs it measures */
    double pid_sample_time;         /* PID dt, s */
    double step_size;               /* prior communication step, s */
    double derivative_filter_N;
    double Tt[PRLPID_MAX_LOOPS];    /* back-calculation tracking time constants, s */
    double setpoint_weight[PRLPID_MAX_LOOPS];     /* b: ep = b*r - yf */
    double derivative_weight[PRLPID_MAX_LOOPS];   /* c: ed = c*r - yf */
    double measurement_filter[PRLPID_MAX_LOOPS];  /* Tf, s (0: yf = y) */
    double u_rate_limit[PRLPID_MAX_LOOPS];  /* R [u units / s] (HUGE_VAL: none): u moves at most R*dt from
                                               last_output per sample, and the anti-windup treats that band as the
                                               limits */
    double u_min[PRLPID_MAX_LOOPS], u_max[PRLPID_MAX_LOOPS];
    double scale[PRLPID_MAX_LOOPS];   /* measurement scale: error = (setpoint - y) / scale */
    double bound[PRLPID_MAX_LOOPS];   /* divergence bound on |error| */
    double u_scale[PRLPID_MAX_LOOPS]; /* control span of the control-variation term */
    double penalty;                 /* divergence penalty */
    double alpha, beta, v_clip, e_clip, bonus_threshold, bonus_numerator, bonus_offset, control_variation_weight;
    const unsigned int *override_vr;  /* set on the prior after the state copy */
    const double *override_value;
    double *measurements;           /* horizon x n_loops, row-major: the prior's outputs after each step */
    double *rewards;                /* horizon: each step's reward (the penalty included) */
} PrlpidForecastSetup;

/* Per call. */
typedef struct {
    double setpoint[PRLPID_MAX_LOOPS], measurement[PRLPID_MAX_LOOPS];
    double Kp[PRLPID_MAX_LOOPS], Ti[PRLPID_MAX_LOOPS], Td[PRLPID_MAX_LOOPS];
    double coupling[6];             /* c_rp, c_ry, c_pr, c_py, c_yr, c_yp (coupled only) */
    double u_prev[PRLPID_MAX_LOOPS];  /* control signal of the previous sample */
    double integral[PRLPID_MAX_LOOPS], last_error[PRLPID_MAX_LOOPS], derivative[PRLPID_MAX_LOOPS];  /* PID state */
    double filtered[PRLPID_MAX_LOOPS], filter_stage[PRLPID_MAX_LOOPS];  /* PID state: measurement filter */
    double last_output[PRLPID_MAX_LOOPS];  /* PID state: its previous output u(k-1), the rate limit's origin
                                              (NaN: none yet, no rate limit at that sample) */
    double last_p_error[PRLPID_MAX_LOOPS];  /* PID state: ep(k-1), the proportional error of its last sample */
    double last_Kp[PRLPID_MAX_LOOPS], last_Ti[PRLPID_MAX_LOOPS], last_Td[PRLPID_MAX_LOOPS];  /* PID state: the
                                              gains of its last sample (NaN: none yet, no rescale) */
    int initialized;                /* PID state: 0 until its first step after reset */
} PrlpidForecastInput;

typedef struct {
    double mean_reward;
    double prior_time;              /* the prior's time after the roll-out, s */
    int steps;                      /* rewards averaged and written to setup->rewards, the penalty included */
    int n_measurements;             /* rows written to setup->measurements */
    int stopped;                    /* 0: all N steps; 1: error beyond the bound; 2: the prior discarded a step */
} PrlpidForecastResult;

int prlpid_forecast_core(Instance *plant, Instance *prior, const PrlpidForecastSetup *setup,
                         const PrlpidForecastInput *input, PrlpidForecastResult *result);

PRLPID_EXPORT int prlpid_forecast_abi(void);
PRLPID_EXPORT size_t prlpid_forecast_struct_size(int which);
PRLPID_EXPORT int prlpid_forecast(void *plant, void *prior, const PrlpidForecastSetup *setup,
                                  const PrlpidForecastInput *input, PrlpidForecastResult *result);

#endif
