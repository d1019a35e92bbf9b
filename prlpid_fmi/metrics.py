"""Closed-loop performance metrics of one evaluation run, from sampled signals.

Inputs (n samples; row k holds the values at time_s[k]): setpoint r and measurement y of shape (n,)
or (n, n_loops), control signal u of the same number of loops, and the sample time Ts [s]. The
tracking error is e = r - y. All sums are rectangular (left Riemann) sums over the samples of a
window [a, b) (half-open sample indices, like the paper's Table 2 rows "0<=k<=200", "200<=k<=400")::

    ISE  = sum e_k**2 * Ts               [y-unit^2 * s]
    IAE  = sum |e_k| * Ts                [y-unit * s]
    ITAE = sum t_k * |e_k| * Ts          [y-unit * s^2], t_k = time_s[k] - time_s[a] (from the window start)
    ControlEffort  = sum u_k**2 * Ts     [u-unit^2 * s]
    TotalVariation = sum |u_k - u_{k-1}| over k = max(a, 1) .. b-1   [u-unit]

Each difference u_k - u_{k-1} belongs to the window of its later sample, so ISE, IAE, ControlEffort
and TotalVariation of intervals that tile [0, n) add up to the overall values (ITAE does not: its
clock restarts at every window start).

Chatter [dimensionless, 0..1] (``chatter_fraction``): the fraction of the samples k = max(a, 2) .. b-1
of the window at which the controller's command u (``command``, default the control signal; the
evaluation passes the PID output before actuator noise, which would otherwise count as chatter the
controller did not make) reverses direction, i.e. du_k = u_k - u_{k-1} and du_{k-1}
have opposite signs and both |du| exceed ``CHATTER_THRESHOLD`` (1 %) of the loop's actuator range
u_max - u_min (``u_range``; when it is not finite or not given: of max |u| over the whole run). A
two-sample limit cycle (u swinging every sample) gives 1 (at the window's k), a smooth or monotone
response 0, and moves smaller than 1 % of the range (noise passed through the PID) do not count. NaN
when the window has no such k (fewer than 3 samples) or u is not finite in it.

Step metrics (names as in python-control's ``step_info``), per loop and per setpoint *segment*: a
segment starts at sample 0 and at every sample where the loop's setpoint changes, and ends before
the next change (or at the end of the run). The step of a segment starting at s > 0 is
delta = r[s] - r[s-1] with base value r[s-1]; the first segment is the step from the initial
measurement, delta = r[0] - y[0], base y[0]. Times are measured from time_s[s]; level crossings are
linearly interpolated between samples.

- Overshoot [%]: 100 * max over the segment of sign(delta)*(y - r[s]) / |delta|, 0 if the response
  never passes the new setpoint (for a step down: how far it goes below the new setpoint).
- RiseTime [s]: from the first time the response covers 10 % of the step (from the base value) to
  the first time it covers 90 %.
- SettlingTime [s]: from the step until |e| <= band for the rest of the segment (0 if it always is),
  band = max(2 % of |delta|, 5 * noise), where noise is the measurement noise's std when the caller
  knows it (``noise_std``: a simulation, 0 without noise), else std(diff(y)) / sqrt(2) over the
  segment's last 10 % (white measurement noise of std s gives std(diff) = s*sqrt(2); a smooth response
  gives almost 0): measurement noise cannot keep a settled loop "unsettled". Give noise_std whenever it
  is known: the estimate cannot tell noise from a controller that chatters, and widens the band for it.
- SteadyStateError [y-unit]: mean |e| over the last 10 % of the segment's samples (at least one).

Regulation segments: a segment that does not start with a setpoint step (zero step size, e.g. a
plant that starts at its setpoint; for the first segment, a step from the initial measurement no
larger than 5x the measured noise) or that starts at an *event* (``events``: sample indices where a
disturbance begins; a disturbance inside a setpoint segment splits it) reports, instead of the step
metrics above (which are NaN there):

- PeakDeviation [y-unit]: max |e| over the segment.
- RecoveryTime [s]: from the segment's start until |e| <= max(10 % of PeakDeviation, 5 * noise) for
  the rest of the segment (inf if never; 0 if always).

Undefined and failed values (plain floats; ``json.dumps`` writes them as NaN / Infinity):

- NaN = not defined: zero-size step (|delta| <= 1e-9 * max(1, |r[s]|, |base|)) -> Overshoot,
  RiseTime and SettlingTime are NaN (SteadyStateError is still computed); segment shorter than
  ``MIN_SEGMENT_STEPS`` samples -> all four are NaN.
- inf = failed: the response never settles within its segment -> SettlingTime inf; it never covers
  90 % of the step within its segment -> RiseTime inf. A non-finite measurement (diverged run) makes
  the window's ISE/IAE/ITAE inf and the segment's SteadyStateError and defined step metrics inf; a
  non-finite control signal makes ControlEffort and TotalVariation inf.

Aggregates over segments ("overall", and per interval over the segments that *start* inside the
interval; a segment is always measured to its own end): Overshoot, RiseTime and SettlingTime are
the worst (max) segment value, SteadyStateError is the mean; NaN segments are ignored, inf
propagates, NaN if no segment defines the value.

Result of ``compute_metrics``::

    {"loops": [names],
     "overall":   {metric keys},
     "intervals": [{"start_step": a, "end_step": b, metric keys}, ...],
     "segments":  [{"loop": name, "start_step": s, "end_step": e, "start_time_s": t,
                    "StepSize": delta, "Overshoot": .., "RiseTime": .., "SettlingTime": ..,
                    "SteadyStateError": ..}, ...]}

Metric keys are the names in ``METRIC_NAMES``: plain ("ISE") for one loop, "ISE[name]" for each
loop when there are several (flat, so one dict is one CSV row). Default loop names are "0", "1", ...
Segment metrics use plain names, the loop is in "loop". For ramps or other continuously varying
setpoints the segments are single samples and the step metrics are NaN; use the integral metrics.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

INTEGRAL_METRICS = ("ISE", "IAE", "ITAE", "ControlEffort", "TotalVariation")
CONTROL_METRICS = ("Chatter",)  # per window like the integral metrics, but a fraction: windows do not add up
STEP_METRICS = ("Overshoot", "RiseTime", "SettlingTime", "SteadyStateError", "PeakDeviation", "RecoveryTime")
RECOVERY_FRACTION = 0.1  # recovery band: this fraction of the peak deviation (or 3 x noise, if larger)
NOISE_BAND = 5.0  # bands are at least this many noise standard deviations wide (|noise| > 5 sigma: p = 6e-7)
METRIC_NAMES = INTEGRAL_METRICS + CONTROL_METRICS + STEP_METRICS
MIN_SEGMENT_STEPS = 2
_REL_TOL = 1e-9
CHATTER_THRESHOLD = 0.01  # a move counts towards Chatter when it exceeds this fraction of the actuator range
SPIKE_RATIO = 0.5  # a one-sample pulse of the command is a spike when the moves around it are below this x its own

__all__ = ["compute_metrics", "chatter_fraction", "fast_reversals", "metric_key", "METRIC_NAMES", "INTEGRAL_METRICS",
           "CONTROL_METRICS", "STEP_METRICS", "MIN_SEGMENT_STEPS", "overall_metric"]


def metric_key(name: str, loop: str, n_loops: int) -> str:
    """Key of metric ``name`` for ``loop`` in the result: "ISE" for one loop, "ISE[loop]" otherwise."""
    return name if n_loops == 1 else f"{name}[{loop}]"


def _as_2d(x, n: int, what: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 1:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] != n:
        raise ValueError(f"{what} must have shape (n,) or (n, n_loops) with n = {n}, got {np.shape(x)}")
    return a


def _zero_step(delta: float, *values: float) -> bool:
    return abs(delta) <= _REL_TOL * max(1.0, *(abs(v) for v in values))


def _crossing_time(t: np.ndarray, s: np.ndarray, level: float) -> float:
    """First time s (1-D) reaches >= level, interpolated linearly; inf if never; t[0] if already at start."""
    idx = np.flatnonzero(s >= level)
    if idx.size == 0:
        return math.inf
    j = int(idx[0])
    if j == 0:
        return float(t[0])
    frac = (level - s[j - 1]) / (s[j] - s[j - 1])
    return float(t[j - 1] + frac * (t[j] - t[j - 1]))


def _time_in_band(t: np.ndarray, abs_e: np.ndarray, band: float) -> float:
    """Time from t[0] until abs_e stays <= band (interpolated); 0 if always, inf if not at the end."""
    m = abs_e.size
    outside = np.flatnonzero(abs_e > band)
    if outside.size == 0:
        return 0.0
    if outside[-1] == m - 1:
        return math.inf
    j = int(outside[-1])
    frac = (abs_e[j] - band) / (abs_e[j] - abs_e[j + 1])
    return float(t[j] + frac * (t[j + 1] - t[j]) - t[0])


def _noise(y_tail: np.ndarray) -> float:
    """Measurement-noise estimate std(diff(y)) / sqrt(2) on a segment's tail (0 for fewer than 3 samples)."""
    return float(np.std(np.diff(y_tail)) / math.sqrt(2.0)) if y_tail.size >= 3 else 0.0


def _segment_metrics(t: np.ndarray, r_new: float, base: float, y: np.ndarray, settling_threshold: float,
                     rise_time_limits: tuple[float, float], steady_state_fraction: float,
                     regulation: bool = False, first: bool = False, noise_std: float | None = None) -> dict:
    """Step (or regulation) metrics of one segment: t, y (m,) from its first sample on; step from base to r_new;
    noise_std: the measurement noise's known std [y-unit] (None: estimated from the segment's tail)."""
    m = y.size

    def noise(y_tail: np.ndarray) -> float:
        return _noise(y_tail) if noise_std is None else noise_std

    nan = math.nan
    delta = r_new - base
    zero = regulation or _zero_step(delta, r_new, base)
    if not zero and first and m >= 3 and np.all(np.isfinite(y)):
        # the first segment steps from the initial *measurement*: a step no larger than the noise
        # (a plant that starts at its setpoint, measured with noise) is regulation, not a step
        zero = abs(delta) <= NOISE_BAND * noise(y[-max(math.ceil(steady_state_fraction * m), 3):])
    if m < MIN_SEGMENT_STEPS:
        return dict(Overshoot=nan, RiseTime=nan, SettlingTime=nan, SteadyStateError=nan, PeakDeviation=nan,
                    RecoveryTime=nan)
    if not np.all(np.isfinite(y)):
        step_value = nan if zero else math.inf
        return dict(Overshoot=step_value, RiseTime=step_value, SettlingTime=step_value,
                    SteadyStateError=math.inf, PeakDeviation=math.inf if zero else nan,
                    RecoveryTime=math.inf if zero else nan)
    abs_e = np.abs(r_new - y)
    n_tail = max(1, math.ceil(steady_state_fraction * m))
    sse = float(np.mean(abs_e[-n_tail:]))
    noise_band = NOISE_BAND * noise(y[-max(n_tail, 3):])
    if zero:
        peak = float(np.max(abs_e))
        recovery = _time_in_band(t, abs_e, max(RECOVERY_FRACTION * peak, noise_band))
        return dict(Overshoot=nan, RiseTime=nan, SettlingTime=nan, SteadyStateError=sse, PeakDeviation=peak,
                    RecoveryTime=recovery)
    size = abs(delta)
    sign = 1.0 if delta > 0 else -1.0
    overshoot = max(0.0, float(np.max(sign * (y - r_new)))) / size * 100.0
    progress = sign * (y - base)  # distance covered towards the new setpoint
    t_low = _crossing_time(t, progress, rise_time_limits[0] * size)
    t_high = _crossing_time(t, progress, rise_time_limits[1] * size)
    rise = t_high - t_low if math.isfinite(t_high) else math.inf
    settling = _time_in_band(t, abs_e, max(settling_threshold * size, noise_band))
    return dict(Overshoot=float(overshoot), RiseTime=float(rise), SettlingTime=float(settling),
                SteadyStateError=sse, PeakDeviation=nan, RecoveryTime=nan)


def _chatter_threshold(u: np.ndarray, u_range: float | None) -> float:
    """CHATTER_THRESHOLD of u_range, or of max |u| (finite samples) when the range is not finite or None."""
    if u_range is not None and math.isfinite(u_range) and u_range > 0:
        return CHATTER_THRESHOLD * float(u_range)
    finite = np.abs(u[np.isfinite(u)])
    return CHATTER_THRESHOLD * float(np.max(finite)) if finite.size else 0.0


def _reversal_fraction(u: np.ndarray, threshold: float, first: int = 2) -> float:
    """Fraction of k = first .. len(u)-1 (first >= 2) where u reverses by moves both > threshold."""
    k_count = u.size - first
    if k_count <= 0 or not np.all(np.isfinite(u[first - 2:])):
        return math.nan
    du = np.diff(u[first - 2:])  # du[j] = u[first-1+j] - u[first-2+j]
    big = np.abs(du) > threshold
    reversals = (du[1:] * du[:-1] < 0) & big[1:] & big[:-1]
    return float(np.count_nonzero(reversals)) / k_count


def chatter_fraction(u, u_range: float | None = None) -> float:
    """Chatter of one loop's control signal u (n,) [input units] over the whole run: the fraction of
    samples k = 2 .. n-1 where u reverses direction with both moves > 1 % of u_range = u_max - u_min
    [input units] (None or infinite: of max |u|). Dimensionless, 0..1; NaN for fewer than 3 samples or a
    non-finite u (see the module docstring)."""
    a = np.asarray(u, dtype=float)
    if a.ndim != 1:
        raise ValueError(f"u must be a 1-D array of one loop's control signal, got shape {np.shape(u)}")
    return _reversal_fraction(a, _chatter_threshold(a, None if u_range is None else float(u_range)))


def fast_reversals(u, span: float | None) -> float:
    """The fraction of the samples k = 3 .. n-1 of a command u (n,) at which it moves at the sample rate: its moves
    du_k, du_(k-1), du_(k-2) alternate in sign and each exceeds CHATTER_THRESHOLD x span (an oscillation at the
    sample rate), or it spikes: a pulse one sample wide (two moves of opposite sign above the threshold) between
    moves less than SPIKE_RATIO of the pulse's (a command leaving a limit or a level for one sample; the peak of a
    swing at the loop's bandwidth is flanked by larger moves). span: the loop's u_max - u_min [input units] (None or
    not finite: max |u|, as Chatter's). The acceptance check's chatter (deliver.acceptance). NaN for fewer than 4
    samples, a u that is not finite or a zero span."""
    u = np.asarray(u, float)
    if u.size < 4 or not np.all(np.isfinite(u)):
        return math.nan
    threshold = _chatter_threshold(u, None if span is None else float(span))
    if not threshold > 0:
        return math.nan
    du = np.diff(u)
    size = np.abs(du)
    big = size > threshold
    turn = (du[1:] * du[:-1] < 0) & big[1:] & big[:-1]  # turn[j]: moves j and j + 1
    pulse = SPIKE_RATIO * np.minimum(size[1:-2], size[2:-1])  # the pulses of turn[1:-1]
    spikes = turn[1:-1] & (size[:-3] < pulse) & (size[3:] < pulse)
    return float(np.count_nonzero(turn[1:] & turn[:-1]) + np.count_nonzero(spikes)) / (u.size - 3)


def _integral_metrics(t: np.ndarray, e: np.ndarray, u: np.ndarray, u_prev: float | None, ts: float) -> dict:
    """ISE, IAE, ITAE of e (m,) and effort and TV of u (m,) on one window; u_prev = u before the window."""
    with np.errstate(over="ignore", invalid="ignore"):
        if np.all(np.isfinite(e)):
            abs_e = np.abs(e)
            ise = float(np.sum(e * e) * ts)
            iae = float(np.sum(abs_e) * ts)
            itae = float(np.sum((t - t[0]) * abs_e) * ts)
        else:
            ise = iae = itae = math.inf
        if np.all(np.isfinite(u)) and (u_prev is None or math.isfinite(u_prev)):
            effort = float(np.sum(u * u) * ts)
            uu = u if u_prev is None else np.concatenate(([u_prev], u))
            tv = float(np.sum(np.abs(np.diff(uu))))
        else:
            effort = tv = math.inf
    return dict(ISE=ise, IAE=iae, ITAE=itae, ControlEffort=effort, TotalVariation=tv)


def _aggregate(segments: list[dict]) -> dict:
    """Worst Overshoot/RiseTime/SettlingTime and mean SteadyStateError over segments, NaN ignored."""
    out = {}
    for name in STEP_METRICS:
        values = [s[name] for s in segments if not math.isnan(s[name])]
        if not values:
            out[name] = math.nan
        elif name == "SteadyStateError":
            out[name] = float(math.inf if math.inf in values else sum(values) / len(values))
        else:
            out[name] = float(max(values))
    return out


def compute_metrics(time_s, setpoint, measurement, control_signal, sample_time_s: float,
                    intervals: Sequence[tuple[int, int]] | None = None,
                    loop_names: Sequence[str] | None = None, events: Sequence[int] | None = None, *,
                    u_range: Sequence[float] | float | None = None, command=None,
                    noise_std: Sequence[float] | float | None = None, settling_threshold: float = 0.02,
                    rise_time_limits: tuple[float, float] = (0.1, 0.9), steady_state_fraction: float = 0.1) -> dict:
    """Closed-loop metrics of one run (see the module docstring for definitions and the result layout).

    time_s: (n,) sample times [s], increasing. setpoint, measurement: (n,) or (n, n_loops).
    control_signal: (n,) or (n, n_loops). sample_time_s: Ts [s] > 0 for the rectangular sums.
    intervals: optional (start_step, end_step) half-open index ranges, 0 <= start < end <= n.
    loop_names: optional names (n_loops,) used in the keys; default "0", "1", ...
    events: sample indices where disturbances begin (they start regulation segments).
    u_range: actuator range u_max - u_min per loop [input units] (scalar or (n_loops,)) for Chatter;
    None or infinite: 1 % of max |u| over the run is the threshold instead.
    command: the controller's command (n,) or (n, n_loops) [input units] that Chatter is measured on
    (default: control_signal).
    noise_std: the measurement noise's std per loop [y-unit] (scalar or (n_loops,); 0: none) when known,
    as in a simulation; None: estimated from each segment's tail (see the module docstring).
    settling_threshold, rise_time_limits, steady_state_fraction: 2 % band, 10 %/90 % levels, last
    10 % of a segment (fractions of the step size / segment length).
    Returns a dict of plain Python floats/ints/strings/lists, serialisable with json.dumps.
    """
    t, r, y, u, cmd, names = _signals(time_s, setpoint, measurement, control_signal, command, loop_names)
    n, n_loops = t.size, r.shape[1]
    ts = float(sample_time_s)
    if not (math.isfinite(ts) and ts > 0):
        raise ValueError(f"sample_time_s must be a positive finite number, got {sample_time_s!r}")
    if not (0.0 <= settling_threshold and 0.0 <= rise_time_limits[0] < rise_time_limits[1] <= 1.0
            and 0.0 < steady_state_fraction <= 1.0):
        raise ValueError("settling_threshold >= 0, 0 <= rise_time_limits[0] < [1] <= 1 and "
                         "0 < steady_state_fraction <= 1 are required")
    windows = _windows(intervals, n)
    ranges = _per_loop(u_range, n_loops, lambda v: not (math.isnan(v) or v <= 0),
                       "u_range must be > 0 (or inf) per loop, got {}")
    noise_stds = _per_loop(noise_std, n_loops, lambda v: math.isfinite(v) and v >= 0,
                           "noise_std must be finite and >= 0 per loop, got {}")
    chatter_thresholds = [_chatter_threshold(cmd[:, i], ranges[i]) for i in range(n_loops)]

    e = r - y
    per_loop_segments = [_loop_segments(t, r[:, i], y[:, i], name, events, settling_threshold, rise_time_limits,
                                        steady_state_fraction, noise_stds[i]) for i, name in enumerate(names)]
    segments = [s for loop_segments in per_loop_segments for s in loop_segments]

    def window(a: int, b: int) -> dict:
        out = {}
        for i, name in enumerate(names):
            u_prev = float(u[a - 1, i]) if a > 0 else None
            values = _integral_metrics(t[a:b], e[a:b, i], u[a:b, i], u_prev, ts)
            first = max(a, 2)  # reversals at k in [first, b) need u[k-2 .. k]
            values["Chatter"] = _reversal_fraction(cmd[first - 2:b, i], chatter_thresholds[i]) if b > first else math.nan
            values.update(_aggregate([s for s in per_loop_segments[i] if a <= s["start_step"] < b]))
            for metric in METRIC_NAMES:
                out[metric_key(metric, name, n_loops)] = float(values[metric])
        return out

    return {
        "loops": names,
        "overall": window(0, n),
        "intervals": [{"start_step": a, "end_step": b, **window(a, b)} for a, b in windows],
        "segments": segments,
    }


def overall_metric(overall: dict, key: str) -> float:
    """`key` from compute_metrics' overall dict: plain for one loop; "key[loop]" summed (INTEGRAL_METRICS) or
    maximised (the others: the worst loop) over loops for several; NaN when the dict has no such key."""
    if key in overall:
        return float(overall[key])
    values = [float(v) for k, v in overall.items() if k.startswith(key + "[")]
    if not values:
        return math.nan
    return sum(values) if key in INTEGRAL_METRICS else max(values)


def _signals(time_s, setpoint, measurement, control_signal, command, loop_names):
    """The checked inputs of compute_metrics: t (n,); r, y, u, cmd (n, n_loops); the loop names."""
    t = np.asarray(time_s, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise ValueError(f"time_s must be a non-empty 1-D array, got shape {np.shape(time_s)}")
    n = t.size
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ValueError("time_s must be finite and strictly increasing")
    r = _as_2d(setpoint, n, "setpoint")
    y = _as_2d(measurement, n, "measurement")
    u = _as_2d(control_signal, n, "control_signal")
    n_loops = r.shape[1]
    if y.shape[1] != n_loops or u.shape[1] != n_loops:
        raise ValueError(f"setpoint, measurement and control_signal must have the same number of loops, "
                         f"got {r.shape[1]}, {y.shape[1]}, {u.shape[1]}")
    if not np.all(np.isfinite(r)):
        raise ValueError("setpoint must be finite")
    if loop_names is None:
        names = [str(i) for i in range(n_loops)]
    else:
        names = [str(x) for x in loop_names]
        if len(names) != n_loops or len(set(names)) != n_loops:
            raise ValueError(f"loop_names must be {n_loops} distinct names, got {list(loop_names)!r}")
    cmd = u if command is None else _as_2d(command, n, "command")
    if cmd.shape[1] != n_loops:
        raise ValueError(f"command must have {n_loops} loop(s), got {cmd.shape[1]}")
    return t, r, y, u, cmd, names


def _windows(intervals, n: int) -> list[tuple[int, int]]:
    """The (start_step, end_step) intervals as int pairs with 0 <= start < end <= n."""
    windows = []
    for iv in intervals or []:
        try:
            a, b = (int(v) for v in iv)
        except (TypeError, ValueError):
            raise ValueError(f"an interval must be a pair (start_step, end_step), got {iv!r}") from None
        if not 0 <= a < b <= n:
            raise ValueError(f"interval {iv!r} must satisfy 0 <= start_step < end_step <= {n}")
        windows.append((a, b))
    return windows


def _per_loop(value, n_loops: int, valid, message: str) -> list:
    """A scalar or (n_loops,) value as n_loops floats checked by `valid` (ValueError: message.format(values));
    None: n_loops Nones."""
    if value is None:
        return [None] * n_loops
    values = [float(v) for v in np.broadcast_to(np.asarray(value, dtype=float), (n_loops,))]
    if not all(valid(v) for v in values):
        raise ValueError(message.format(values))
    return values


def _loop_segments(t: np.ndarray, r: np.ndarray, y: np.ndarray, name: str, events, settling_threshold: float,
                   rise_time_limits, steady_state_fraction: float, noise_std: float | None) -> list[dict]:
    """One loop's segments (module docstring): split at setpoint changes and disturbance events, each measured
    by _segment_metrics. r, y: (n,) of this loop."""
    n = t.size
    tol = _REL_TOL * np.maximum(1.0, np.maximum(np.abs(r[1:]), np.abs(r[:-1])))
    changes = [int(k) + 1 for k in np.flatnonzero(np.abs(np.diff(r)) > tol)]
    event_starts = sorted({int(k) for k in (events or ()) if 0 < int(k) < n} - set(changes))
    starts = sorted({0, *changes, *event_starts})
    out = []
    for s, end in zip(starts, starts[1:] + [n]):
        base = y[0] if s == 0 else r[s - 1]
        m = _segment_metrics(t[s:end], float(r[s]), float(base), y[s:end], settling_threshold,
                             tuple(rise_time_limits), steady_state_fraction, regulation=s in event_starts,
                             first=s == 0, noise_std=noise_std)
        out.append({"loop": name, "start_step": int(s), "end_step": int(end), "start_time_s": float(t[s]),
                    "StepSize": float(r[s] - base) if math.isfinite(base) else math.nan, **m})
    return out
