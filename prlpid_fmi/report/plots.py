"""Report figures (matplotlib, Agg backend: no display needed), each written to a PNG atomically.

Trajectories are loop.evaluation.Trajectory: time_s (n+1,), setpoint, measurement, control_signal (n+1,
n_loops), gains {Kp, Ti, Td: (n, n_loops), coupling: (n, 6)}. Signal names and units come from the
config's loops (the FMU variable names). Every figure names its controllers the same way: "adaptive
policy" (the trained policy), "fixed PID" (the baseline with constant gains) and "gain schedule" (a
schedule replay); the disturbances of the config are marked where they act.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Optional

import matplotlib
import numpy as np
from matplotlib import ticker
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.transforms import blended_transform_factory

from prlpid_fmi.config import Disturbance, TuningConfig
from prlpid_fmi.control import COUPLING_NAMES
from prlpid_fmi.fmu.resolve import loop_units
from prlpid_fmi.rundir import write_atomic

DPI = 110
POLICY, FIXED, SCHEDULE = "adaptive policy", "fixed PID", "gain schedule"  # the legends' controller names
CLASSICAL = "classical gain schedule"
COLORS = {POLICY: "tab:blue", FIXED: "tab:orange", SCHEDULE: "tab:green", CLASSICAL: "tab:purple"}
LINESTYLES = {SCHEDULE: (0, (4, 2))}  # signals of the controllers; "-" for those not named here
DISTURBANCE_COLOR = "tab:red"
# A gain axis shows at least this share of the gain's range (in decades on a log range) ...
MIN_SPAN_OF_RANGE = 0.1
# ... and at least this share of the gain's magnitude (a factor 1 + this on a log range), so that a
# nearly constant gain draws as a nearly flat line instead of noise blown up to full height.
MIN_SPAN_OF_VALUE = 0.2
LOG_AXIS_MIN_RATIO = 10.0  # a log-scale gain gets a log axis only when the axis spans this factor

__all__ = ["plot_response", "plot_control_signal", "plot_gains", "plot_learning_curve", "load_monitor_csvs",
           "new_figure", "save_figure", "response_figure", "control_signal_figure", "gains_figure", "gain_axis_limits",
           "disturbance_label", "transient_span", "events", "step_response_figure", "load_step_figure",
           "schedule_gains_figure", "LoadResponse"]


def new_figure(nrows: int = 1, ncols: int = 1, figsize=None, **kwargs):
    """(figure, axes) as pyplot's subplots returns them, outside pyplot: drawn by Agg, so no GUI backend is
    chosen or needed and importing this module changes no matplotlib setting."""
    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def save_figure(fig, path) -> Path:
    """Save fig as PNG atomically (rundir.write_atomic)."""
    return write_atomic(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI))


def _label(name: str, unit: str) -> str:
    return f"{name} [{unit}]" if unit else name


def _axes(n: int, height: float = 2.6):
    fig, axes = new_figure(n, 1, figsize=(10, 0.8 + height * n), sharex=True, squeeze=False)
    return fig, axes[:, 0]


# -- gain axes ---------------------------------------------------------------------------------------
def gain_axis_limits(values, low: float, high: float, scale: str = "linear") -> tuple[float, float, bool]:
    """Y-axis limits for a gain: (bottom, top, log axis?).

    values: every value drawn on the axis (the policy's gains, the fixed PID's); low, high: the gain's
    range in the scenario; scale: its "log" or "linear" range. The axis spans the values, but at least
    MIN_SPAN_OF_RANGE of the range and MIN_SPAN_OF_VALUE of the gain's magnitude (both in log10 on a
    log range), centred on the values and moved inside the range where the values allow; a range limit
    within a quarter span of the axis is brought on scale. A log axis only when top/bottom >=
    LOG_AXIS_MIN_RATIO (on a narrower one, log ticks would repeat one label).
    """
    v = np.asarray(values, float).ravel()
    v = v[np.isfinite(v)]
    log = scale == "log" and low > 0 and v.size > 0 and bool(np.all(v > 0))
    f = np.log10 if log else (lambda x: x)
    if v.size == 0:
        v = np.array([low, high], float)
    lo_v, hi_v = float(f(v.min())), float(f(v.max()))
    lo_r, hi_r = (float(f(low)), float(f(high))) if np.isfinite([low, high]).all() else (-np.inf, np.inf)
    if log:
        floor = max(MIN_SPAN_OF_RANGE * (hi_r - lo_r), math.log10(1 + MIN_SPAN_OF_VALUE))
    else:
        magnitude = max(abs(lo_v), abs(hi_v))
        width = hi_r - lo_r if np.isfinite(hi_r - lo_r) else 0.0
        floor = max(MIN_SPAN_OF_RANGE * width, MIN_SPAN_OF_VALUE * magnitude) or 1.0
    span = max(hi_v - lo_v, floor)
    bottom = (lo_v + hi_v - span) / 2
    bottom = max(bottom, min(lo_r, lo_v))  # move inside the range (never cutting a value off)
    bottom = min(bottom, max(hi_r, hi_v) - span)
    top = bottom + span
    for limit in (lo_r, hi_r):  # a limit just off the axis: bring it on
        if np.isfinite(limit) and bottom - span / 4 <= limit < bottom:
            bottom = limit
        elif np.isfinite(limit) and top < limit <= top + span / 4:
            top = limit
    pad = 0.06 * (top - bottom)
    bottom, top = bottom - pad, top + pad
    if log:
        bottom, top = 10 ** bottom, 10 ** top
    return bottom, top, bool(log and top / bottom >= LOG_AXIS_MIN_RATIO)


def _format_gain_axis(ax, log: bool) -> None:
    """Tick labels that differ from each other: plain numbers, no offset, log ticks at 1-2-5 steps."""
    if log:
        ax.set_yscale("log")
        ax.yaxis.set_major_locator(ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(ticker.FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(ticker.NullFormatter())
    else:
        ax.yaxis.set_major_locator(ticker.MaxNLocator(nbins=5))
        ax.yaxis.set_major_formatter(ticker.ScalarFormatter(useOffset=False))


def _shade_outside(ax, low: float, high: float) -> None:
    """Grey bands beyond a gain range's limits where a limit is on scale; the legend gives the range
    either way ("off scale" when neither limit is)."""
    bottom, top = ax.get_ylim()
    text = f"{low:g} … {high:g}"
    label = f"outside the gain range {text}"
    if np.isfinite(high) and high < top:
        ax.axhspan(high, top, color="0.5", alpha=0.18, lw=0, label=label, gid="gain range")
        label = None
    if np.isfinite(low) and low > bottom:
        ax.axhspan(bottom, low, color="0.5", alpha=0.18, lw=0, label=label, gid="gain range")
        label = None
    if label is not None:  # both limits off scale: name the range in the legend without drawing it
        ax.plot([], [], ls="none", label=f"gain range {text} (off scale)", gid="gain range")
    ax.set_ylim(bottom, top)


# -- disturbances and early ends ----------------------------------------------------------------------
def disturbance_label(d: Disturbance, config: TuningConfig) -> str:
    """Short text for a disturbance: what changes by how much, e.g. "q_d = -20" (an FMU input or
    parameter set to a value), "q_in +5 (actuator offset)" (added to the loop's control signal),
    "h2 +0.1 (measurement offset)"."""
    if d.kind == "fmu":
        return f"{d.target} = {d.value:g}"
    loop = next((l for l in config.loops if l.output == d.target), None)
    name = loop.input if (loop is not None and d.kind == "actuator") else d.target
    return f"{name} {d.value:+g} ({d.kind} offset)"


def _mark_disturbances(axes, config: TuningConfig, t_end: float, loop_panels: bool = True) -> None:
    """A vertical line at each disturbance's start, a band over a pulse's duration, a label in the
    panel of the loop it acts on when the panels are the loops (loop_panels), else in the top panel."""
    ts = config.sample_time_s
    for j, d in enumerate(config.disturbances):
        t0 = d.start_step * ts
        if t0 > t_end:
            continue
        t1 = None if d.end_step is None else min(d.end_step * ts, t_end)
        panel = next((i for i, l in enumerate(config.loops) if loop_panels and d.kind != "fmu"
                      and l.output == d.target), 0)
        for i, ax in enumerate(axes):
            ax.axvline(t0, color=DISTURBANCE_COLOR, ls="-.", lw=1.0, alpha=0.8, gid="disturbance",
                       label="disturbance" if j == 0 else None)
            if t1 is not None:
                ax.axvspan(t0, t1, color=DISTURBANCE_COLOR, alpha=0.12, lw=0, gid="disturbance")
            if i == panel:
                text = disturbance_label(d, config) + ("" if t1 is None else f" for {t1 - t0:g} s")
                ax.text(t0, 0.98, " " + text, transform=blended_transform_factory(ax.transData, ax.transAxes),
                        ha="left", va="top", fontsize=7, color=DISTURBANCE_COLOR, gid="disturbance",
                        bbox=dict(boxstyle="square,pad=0.1", fc="white", ec="none", alpha=0.7))


def _mark_end(axes, traj, name: str) -> None:
    """A vertical line where an episode ended early, labelled with why."""
    t = traj.termination
    if t is None:
        return
    for ax in axes:
        ax.axvline(t.time_s, color=COLORS.get(name, "k"), ls=":", lw=1.5, label=f"{name} ended: {t.kind}")


def _controllers(traj, baseline_traj, baseline_label: str, schedule_traj, label: str) -> list:
    """(name, trajectory) in drawing order: the fixed PID, the main trajectory over it, then the gain
    schedule, dashed (LINESTYLES): it replays the policy's gains and often lies right on the policy's line."""
    out = [(baseline_label, baseline_traj), (label, traj), (SCHEDULE, schedule_traj)]
    return [(name, t) for name, t in out if t is not None]


def _ended_note(pairs) -> str:
    """The title's note on early ends, e.g. " (adaptive policy ended early (nan, t = 3 s))"; controllers
    that ended alike are named together; "" when none did."""
    ended: dict[tuple, list[str]] = {}
    for name, t in pairs:
        if t.termination is not None:
            ended.setdefault((t.termination.kind, t.termination.time_s), []).append(name)
    parts = [f"{' and '.join(names)} ended early ({kind}, t = {time_s:g} s)" for (kind, time_s), names in ended.items()]
    return f" ({'; '.join(parts)})" if parts else ""


def _legend(ax, **kw) -> None:
    """The axes' legend with the adaptive policy first and the disturbances and limits last."""
    handles, labels = ax.get_legend_handles_labels()
    first = ("setpoint", POLICY, FIXED, SCHEDULE)
    rank = {name: i for i, name in enumerate(first)}
    order = sorted(range(len(labels)), key=lambda i: (rank.get(labels[i], len(first)), i))
    ax.legend([handles[i] for i in order], [labels[i] for i in order], loc="upper left", bbox_to_anchor=(1.01, 1.0),
              borderaxespad=0.0, fontsize=8, **kw)  # beside the axes: it never hides a signal or a label


# -- figures -------------------------------------------------------------------------------------------
def plot_response(traj, config: TuningConfig, path, title: str = "Closed-loop response", **kw) -> Path:
    """response_figure written to `path` (PNG)."""
    return save_figure(response_figure(traj, config, title, **kw), path)


def response_figure(traj, config: TuningConfig, title: str = "Closed-loop response", baseline_traj=None,
                    baseline_label: str = FIXED, schedule_traj=None, label: str = POLICY):
    """Measurement and setpoint against time, one panel per loop, for the adaptive policy and, when
    given, the fixed PID (baseline_traj) and a gain-schedule replay (schedule_traj); disturbances marked."""
    y_units, _ = loop_units(config)
    fig, axes = _axes(config.n_loops)
    pairs = _controllers(traj, baseline_traj, baseline_label, schedule_traj, label)
    for i, (ax, loop) in enumerate(zip(axes, config.loops)):
        ax.plot(traj.time_s, traj.setpoint[:, i], "k--", lw=1.2, label="setpoint")
        for name, t in pairs:
            ax.plot(t.time_s, t.measurement[:, i], color=COLORS.get(name), ls=LINESTYLES.get(name, "-"),
                    lw=1.5 if t is traj else 1.2, label=name)
        ax.set_ylabel(_label(loop.output, y_units[i]))
        ax.grid(True, alpha=0.3)
    return _finish(fig, axes, config, traj, pairs, title)


def _finish(fig, axes, config: TuningConfig, traj, pairs, title: str):
    """A time-series figure's common end: disturbances and early ends marked, legends, the time axis, the
    title (with any early end said), tight layout. Returns fig."""
    _mark_disturbances(axes, config, float(traj.time_s[-1]))
    for name, t in pairs:
        _mark_end(axes, t, name)
    for ax in axes:
        _legend(ax)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(title + _ended_note(pairs), fontsize=11)
    fig.tight_layout()
    return fig


def plot_control_signal(traj, config: TuningConfig, path, title: str = "Control signal", **kw) -> Path:
    """control_signal_figure written to `path` (PNG)."""
    return save_figure(control_signal_figure(traj, config, title, **kw), path)


def control_signal_figure(traj, config: TuningConfig, title: str = "Control signal", baseline_traj=None,
                          baseline_label: str = FIXED, schedule_traj=None, label: str = POLICY):
    """Control signal (after saturation) per loop as a zero-order hold, with the output limits, for the
    same controllers as response_figure; disturbances marked."""
    _, u_units = loop_units(config)
    fig, axes = _axes(config.n_loops)
    pairs = _controllers(traj, baseline_traj, baseline_label, schedule_traj, label)
    for i, (ax, loop) in enumerate(zip(axes, config.loops)):
        for name, t in pairs:
            ax.step(t.time_s, t.control_signal[:, i], where="post", color=COLORS.get(name),
                    ls=LINESTYLES.get(name, "-"), lw=1.3 if t is traj else 1.1, label=name)
        limits = [v for v in (loop.u_min, loop.u_max) if np.isfinite(v)]
        for k, limit in enumerate(limits):
            ax.axhline(limit, color="gray", ls=":", lw=1, label="actuator limits" if k == 0 else None)
        ax.set_ylabel(_label(loop.input, u_units[i]))
        ax.grid(True, alpha=0.3)
    return _finish(fig, axes, config, traj, pairs, title)


def plot_gains(traj, config: TuningConfig, path, title: str = "PID parameters set by the adaptive policy",
               baseline_gains: Optional[dict] = None, schedule_traj=None) -> Path:
    """gains_figure written to `path` (PNG)."""
    return save_figure(gains_figure(traj, config, title, baseline_gains, schedule_traj), path)


def _held(traj, key: str) -> tuple[np.ndarray, np.ndarray]:
    """(t (n+1,), gains (n+1, m)): a gain trajectory as a zero-order hold (step k's gains from k·Ts to
    (k+1)·Ts; the last row repeats)."""
    v = np.asarray(traj.gains[key], float)
    return np.asarray(traj.time_s[: len(v) + 1]), (np.vstack([v, v[-1:]]) if len(v) else v)


def gains_figure(traj, config: TuningConfig, title: str = "PID parameters set by the adaptive policy",
                 baseline_gains: Optional[dict] = None, schedule_traj=None):
    """Kp, Ti, Td against time (one panel each, one line per loop), plus the coupling coefficients if present.

    Gains of step k apply from t = k*Ts to (k+1)*Ts, drawn as a zero-order hold. baseline_gains: the
    fixed PID's {Kp, Ti, Td: (n_loops,), coupling: (6,)} (fixed_pid.json), drawn dashed; schedule_traj:
    a gain-schedule replay, whose table gains are drawn dotted. Each axis follows gain_axis_limits; what
    lies outside a loop's gain range (loop.Kp.low/high, ...) is shaded.
    """
    y_units, u_units = loop_units(config)
    panels = [("Kp", None), ("Ti", "s"), ("Td", "s")] + ([("coupling", "1")] if "coupling" in traj.gains else [])
    fig, axes = _axes(len(panels), height=2.0)
    base = baseline_gains or {}
    multi = config.n_loops > 1
    colors = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]

    for ax, (key, unit) in zip(axes, panels):
        t, values = _held(traj, key)
        fixed = None if base.get(key) is None else np.atleast_1d(np.asarray(base[key], float))
        t_s, scheduled = _held(schedule_traj, key) if schedule_traj is not None else (None, None)
        names = COUPLING_NAMES if key == "coupling" else [l.output for l in config.loops]
        # several lines: a colour per loop (coefficient), solid = adaptive policy, dashed = fixed PID;
        # one line: the controllers' colours of the other figures
        per_line = multi or key == "coupling"
        for j, name in enumerate(names):
            color = colors[j % len(colors)] if per_line else COLORS[POLICY]
            ax.step(t, values[:, j], where="post", lw=1.3, color=color, label=name if per_line else POLICY)
            if fixed is not None and j < fixed.size:
                ax.axhline(fixed[j], color=color if per_line else COLORS[FIXED], ls="--", lw=1.2,
                           label=None if per_line else FIXED)
            if scheduled is not None:
                ax.step(t_s, scheduled[:, j], where="post", ls=":", lw=1.6,
                        color=color if per_line else COLORS[SCHEDULE], label=None if per_line else SCHEDULE)
        if per_line:  # the line styles' meaning, once
            ax.plot([], [], color="k", lw=1.3, label=POLICY)
            if fixed is not None:
                ax.plot([], [], color="k", ls="--", lw=1.2, label=FIXED)
            if scheduled is not None:
                ax.plot([], [], color="k", ls=":", lw=1.6, label=SCHEDULE)
        if key == "coupling":
            c = float(config.coupling_range)
            ranges, scale = [(-c, c)], "linear"
            ax.set_ylabel("coupling [1]")
        else:
            rng = [getattr(l, key) for l in config.loops]
            ranges = sorted({(r.low, r.high) for r in rng})
            scale = "log" if all(r.scale == "log" for r in rng) else "linear"
            if key == "Kp":
                units = {f"{u or 'u'}/{y or 'y'}" for u, y in zip(u_units, y_units)}
                unit = units.pop() if len(units) == 1 else "u/y"
            ax.set_ylabel(f"{key} [{unit}]")
        drawn = np.concatenate([v.ravel() for v in (values, fixed, scheduled) if v is not None])
        bottom, top, log = gain_axis_limits(drawn, min(r[0] for r in ranges), max(r[1] for r in ranges), scale)
        _format_gain_axis(ax, log)
        ax.set_ylim(bottom, top)
        for low, high in ranges:
            _shade_outside(ax, low, high)
        ax.grid(True, alpha=0.3, which="major")
    _mark_disturbances(axes, config, float(traj.time_s[-1]), loop_panels=False)
    for ax, (key, _) in zip(axes, panels):
        _legend(ax, ncol=2 if key == "coupling" else 1)
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(title, fontsize=11)
    fig.tight_layout()
    return fig


def load_monitor_csvs(monitor_dir) -> tuple[np.ndarray, np.ndarray]:
    """Episodes from SB3 Monitor files ``*.monitor.csv`` (a JSON comment line, then columns r, l, t).

    Returns (timesteps, rewards), ordered by wall time t across files; timesteps is the cumulative
    episode length (l) at the end of each episode, summed over all environments.
    """
    rows = []
    for f in sorted(Path(monitor_dir).glob("*.monitor.csv")):
        with open(f, newline="") as fh:
            lines = [line for line in fh if not line.startswith("#")]
        offset = last = 0.0  # a resumed training appends with its clock restarted at 0: continue it
        for rec in csv.DictReader(lines):
            try:
                t = float(rec["t"])
                row = (t + offset if t + offset >= last else t + last, float(rec["r"]), int(float(rec["l"])))
            except (KeyError, TypeError, ValueError):
                continue  # a line being written by a still-running training
            if row[0] != t + offset:
                offset = last
            last = row[0]
            rows.append(row)
    rows.sort(key=lambda r: r[0])
    rewards = np.array([r[1] for r in rows], float)
    steps = np.cumsum([r[2] for r in rows]).astype(float)
    return steps, rewards


def plot_learning_curve(monitor_dir, path, window: int = 20, title: str = "Learning curve") -> Path:
    """Episode reward against training timesteps from Monitor CSVs, with a rolling mean over `window` episodes."""
    steps, rewards = load_monitor_csvs(monitor_dir)
    fig, ax = new_figure(figsize=(8, 4))
    if rewards.size:
        ax.plot(steps, rewards, ".", color="tab:blue", alpha=0.35, ms=4, label="episode reward")
        w = max(1, min(window, rewards.size // 5))  # keep a visible curve for short runs
        mean = np.convolve(rewards, np.ones(w) / w, mode="valid")
        ax.plot(steps[w - 1:], mean, color="tab:red", lw=2, label=f"rolling mean ({w} episodes)")
        ax.legend(loc="best", fontsize=8)
    else:
        ax.text(0.5, 0.5, f"no finished episodes in {monitor_dir}", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("training timesteps [samples]")
    ax.set_ylabel("episode reward [1]")
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    return save_figure(fig, path)


# -- transients, zoomed ------------------------------------------------------------------------------------------
SETTLING_BAND = 0.02  # a transient is over once its deviation stays within this share of its size ...
NOISE_BAND = 3.0  # ... and within this many standard deviations of the measurement's noise
SMOOTHING_SAMPLES = 5  # moving average of the deviation before that test
MIN_WINDOW_SAMPLES = 10  # a zoomed panel spans at least this many samples
ZOOM_MARGIN = 0.3  # a panel shows this share of the transient's duration after its end, a tenth before its start
MAX_EVENT_PANELS = 6  # step_response_figure's panels at most (the first events)


def transient_span(t, deviation, t0: float, t1: float, size: float | None = None) -> float:
    """How long [s] a transient starting at t0 lasts within [t0, t1): until the deviation (e.g. y - r; (n+1,) over
    t [s]), smoothed over SMOOTHING_SAMPLES, stays within max(SETTLING_BAND x size, NOISE_BAND x its noise) of the
    value it settles at (the median over the last fifth of the interval; the noise from the sample-to-sample
    differences there, divided by sqrt(SMOOTHING_SAMPLES) for the smoothing). size: the transient's size (default: its largest smoothed deviation). t1 - t0 when it
    never settles; non-finite samples (an early end) are left out."""
    t, e = np.asarray(t, float), np.asarray(deviation, float)
    sel = (t >= t0) & (t < t1) & np.isfinite(e)
    t, e = t[sel], e[sel]
    if len(e) < 4:
        return float(t1 - t0)
    tail = e[-max(len(e) // 5, 3):]
    noise = float(np.std(np.diff(tail)) / math.sqrt(2.0))
    k = min(SMOOTHING_SAMPLES, len(e))
    d = np.abs(np.convolve(e - float(np.median(tail)), np.ones(k) / k, mode="same"))
    d[0] = abs(e[0] - float(np.median(tail)))  # the step itself, not averaged away
    size = float(np.max(d)) if size is None else abs(float(size))
    band = max(SETTLING_BAND * size, NOISE_BAND * noise / math.sqrt(k), 1e-12)  # the noise left after smoothing
    outside = np.nonzero(d > band)[0]
    if len(outside) == 0:
        return 0.0
    last = outside[-1] + 1
    return float((t[last] if last < len(t) else t1) - t0)


def events(traj, config: TuningConfig) -> list[tuple[float, str]]:
    """(time [s], what) of the evaluation's transients in time order: setpoint changes (the trajectory's setpoint
    rows; at t = 0 where the setpoint differs from the first measurement by more than 1 % of the setpoint range)
    and the disturbances' starts (disturbance_label). Events at the same time are joined, a line each."""
    ts = config.sample_time_s
    found: dict[float, list[str]] = {}
    r, y = np.asarray(traj.setpoint, float), np.asarray(traj.measurement, float)
    for i, loop in enumerate(config.loops):
        width = abs(loop.setpoint_range[1] - loop.setpoint_range[0]) or 1.0
        if abs(r[0, i] - y[0, i]) > 0.01 * width:
            found.setdefault(0.0, []).append(f"setpoint {loop.output} {y[0, i]:.4g} → {r[0, i]:.4g}")
        for k in np.nonzero(np.abs(np.diff(r[:, i])) > 1e-12 * max(1.0, width))[0] + 1:
            found.setdefault(round(float(traj.time_s[k]), 9), []).append(
                f"setpoint {loop.output} {r[k - 1, i]:.4g} → {r[k, i]:.4g}")
    for d in config.disturbances:
        t0 = round(d.start_step * ts, 9)
        if t0 <= float(traj.time_s[-1]):
            pulse = "" if d.end_step is None else f" for {(d.end_step - d.start_step) * ts:g} s"
            found.setdefault(t0, []).append(disturbance_label(d, config) + pulse)
    return [(t, "\n".join(what)) for t, what in sorted(found.items())]


def _window(t0: float, t1: float, span: float, ts: float) -> tuple[float, float]:
    """A zoomed panel's time range around a transient of `span` s starting at t0, ending by t1."""
    end = min(t0 + max(span * (1 + ZOOM_MARGIN), MIN_WINDOW_SAMPLES * ts), t1)
    return max(t0 - 0.1 * (end - t0), 0.0), end


def _sliced(traj, a: float, b: float) -> slice:
    """The rows of traj within [a, b] [s]."""
    k0 = int(np.searchsorted(traj.time_s, a - 1e-9))
    k1 = int(np.searchsorted(traj.time_s, b + 1e-9, side="right"))
    return slice(k0, max(k1, k0 + 2))


def _limits_on_scale(ax, loop) -> None:
    """The loop's actuator limits as dotted lines where they lie within the axis (the axis kept)."""
    bottom, top = ax.get_ylim()
    for limit in (loop.u_min, loop.u_max):
        if np.isfinite(limit) and bottom <= limit <= top:
            ax.axhline(limit, color="gray", ls=":", lw=1, label="actuator limits")
    ax.set_ylim(bottom, top)


def _named(name: str, deployed: str | None) -> str:
    return f"{name} (deployed)" if deployed is not None and name == deployed else name


def _unique_legend(ax) -> None:
    handles, labels = ax.get_legend_handles_labels()
    seen = dict(zip(labels, handles))
    ax.legend(list(seen.values()), list(seen.keys()), loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
              fontsize=8)


def step_response_figure(pairs, config: TuningConfig, title: str = "Transients", deployed: str | None = None):
    """The evaluation zoomed to its transients: one column per event (setpoint change or disturbance, `events`; the
    first MAX_EVENT_PANELS), the measurement and the control signal of every loop in rows, for each controller in
    pairs [(name, Trajectory), ...]; each column spans its transient (`transient_span` of the slowest controller,
    ZOOM_MARGIN past it), at most up to the next event. deployed: the name to mark "(deployed)"."""
    y_units, u_units = loop_units(config)
    ts, n = config.sample_time_s, config.n_loops
    first = pairs[0][1]
    t_end = float(first.time_s[-1])
    found = events(first, config) or [(0.0, "the evaluation (no setpoint change or disturbance)")]
    shown = found[:MAX_EVENT_PANELS]
    m = len(shown)
    fig, axes = new_figure(2 * n, m, figsize=(1.9 + 3.7 * m, 0.9 + 2.1 * 2 * n), squeeze=False)
    fig.set_layout_engine("constrained")
    for j, (t0, what) in enumerate(shown):
        t1 = found[j + 1][0] if j + 1 < len(found) else t_end
        span = 0.0
        for _, traj in pairs:
            for i in range(n):
                size = None
                k = int(np.searchsorted(traj.time_s, t0 - 1e-9))
                if "setpoint" in what and k < len(traj.time_s):
                    before = traj.measurement[0, i] if k == 0 else traj.setpoint[max(k - 1, 0), i]
                    size = abs(traj.setpoint[k, i] - before) or None
                span = max(span, transient_span(traj.time_s, traj.measurement[:, i] - traj.setpoint[:, i], t0, t1, size))
        a, b = _window(t0, t1, span, ts)
        drawn_to = b - 0.5 * ts if j + 1 < len(found) and b >= t1 - 1e-9 else b  # not the next event's first sample
        for i, loop in enumerate(config.loops):
            ax_y, ax_u = axes[2 * i, j], axes[2 * i + 1, j]
            sl = _sliced(first, a, drawn_to)
            ax_y.plot(first.time_s[sl], first.setpoint[sl, i], "k--", lw=1.2, label="setpoint")
            for name, traj in pairs:
                sl = _sliced(traj, a, drawn_to)
                style = dict(color=COLORS.get(name), ls=LINESTYLES.get(name, "-"), label=_named(name, deployed),
                             lw=1.6 if name == deployed else 1.2)
                ax_y.plot(traj.time_s[sl], traj.measurement[sl, i], **style)
                ax_u.step(traj.time_s[sl], traj.control_signal[sl, i], where="post", **style)
            _limits_on_scale(ax_u, loop)
            for ax in (ax_y, ax_u):
                ax.set_xlim(a, b)
                ax.grid(True, alpha=0.3)
                if t0 > a:
                    ax.axvline(t0, color=DISTURBANCE_COLOR, ls="-.", lw=1.0, alpha=0.8)
            if j == 0:
                ax_y.set_ylabel(_label(loop.output, y_units[i]))
                ax_u.set_ylabel(_label(loop.input, u_units[i]))
        axes[0, j].set_title(f"t = {t0:g} s: {what}", fontsize=9 if "\n" not in what else 8)
        axes[-1, j].set_xlabel("time [s]")
    _unique_legend(axes[0, -1])
    if len(axes) > 1:
        _unique_legend(axes[1, -1])
    more = f" (the first {m} of {len(found)} events)" if len(found) > m else ""
    fig.suptitle(title + more, fontsize=11)
    return fig


# -- load steps -------------------------------------------------------------------------------------------------
class LoadResponse:
    """One operating point of the load experiment (tuning.load_experiment.load_experiment) with one controller:
    point: setpoints per loop; loads: the load per loop [input units], loop i's from hold_steps x (i + 1) samples on;
    loaded: the Trajectory with the loads, unloaded: the same controller's run without them."""

    def __init__(self, point, loads, loaded, unloaded, hold_steps: int):
        self.point, self.loads, self.loaded, self.unloaded = list(point), list(loads), loaded, unloaded
        self.hold_steps = int(hold_steps)


def load_step_figure(runs: dict, config: TuningConfig, title: str = "Load steps at the plant input",
                     deployed: str | None = None):
    """The load experiment's responses: runs {controller name: [LoadResponse per operating point]}; one column per
    operating point, the measurement (dotted: the same controller's run without the load, from which the load IAE
    counts y's deviation) and the control signal of every loop in rows, against the time since that loop's load step,
    zoomed to the slowest controller's recovery (`transient_span` of y - y_unloaded)."""
    y_units, u_units = loop_units(config)
    ts, n = config.sample_time_s, config.n_loops
    names = list(runs)
    points = len(runs[names[0]]) if names else 0
    fig, axes = new_figure(2 * n, max(points, 1), figsize=(1.9 + 3.7 * max(points, 1), 0.9 + 2.1 * 2 * n),
                           squeeze=False)
    fig.set_layout_engine("constrained")
    for j in range(points):
        reference = runs[names[0]][j]
        for i, loop in enumerate(config.loops):
            t_load = reference.hold_steps * (i + 1) * ts
            t1 = t_load + reference.hold_steps * ts
            span = 0.0
            for name in names:
                r = runs[name][j]
                dev = r.loaded.measurement[:, i] - r.unloaded.measurement[:, i]
                span = max(span, transient_span(r.loaded.time_s, dev, t_load, t1))
            a, b = _window(t_load, t1, span, ts)
            ax_y, ax_u = axes[2 * i, j], axes[2 * i + 1, j]
            sl = _sliced(reference.loaded, a, b)
            t = reference.loaded.time_s[sl] - t_load
            ax_y.plot(t, reference.loaded.setpoint[sl, i], "k--", lw=1.2, label="setpoint")
            for name in names:
                r = runs[name][j]
                sl = _sliced(r.loaded, a, b)
                style = dict(color=COLORS.get(name), ls=LINESTYLES.get(name, "-"), label=_named(name, deployed),
                             lw=1.6 if name == deployed else 1.2)
                ax_y.plot(r.loaded.time_s[sl] - t_load, r.loaded.measurement[sl, i], **style)
                su = _sliced(r.unloaded, a, b)
                ax_y.plot(r.unloaded.time_s[su] - t_load, r.unloaded.measurement[su, i], color=COLORS.get(name), ls=":",
                          lw=0.9)
                ax_u.step(r.loaded.time_s[sl] - t_load, r.loaded.control_signal[sl, i], where="post", **style)
            ax_y.plot([], [], color="0.3", ls=":", lw=0.9, label="the same without the load")
            _limits_on_scale(ax_u, loop)
            for ax in (ax_y, ax_u):
                ax.set_xlim(a - t_load, b - t_load)
                ax.axvline(0.0, color=DISTURBANCE_COLOR, ls="-.", lw=1.0, alpha=0.8, label="load step")
                ax.grid(True, alpha=0.3)
            if j == 0:
                ax_y.set_ylabel(_label(loop.output, y_units[i]))
                ax_u.set_ylabel(_label(loop.input, u_units[i]))
        point = ", ".join(f"{l.output} = {v:.4g}" for l, v in zip(config.loops, reference.point))
        loads = "\n".join(f"load {d:+.3g} {u}".rstrip() + f" on {l.input}"
                          for l, d, u in zip(config.loops, reference.loads, u_units))
        axes[0, j].set_title(f"setpoint {point}\n{loads}", fontsize=9 if n == 1 else 8)
        axes[-1, j].set_xlabel("time since the load step [s]")
    if names:
        _unique_legend(axes[0, -1])
        if len(axes) > 1:
            _unique_legend(axes[1, -1])
    fig.suptitle(title, fontsize=11)
    return fig


# -- gains over the scheduling variable --------------------------------------------------------------------------
def schedule_gains_figure(tables, config: TuningConfig, fixed=None, deployed: str | None = None,
                          title: str = "PID gains over the scheduling variable"):
    """Kp, Ti, Td (rows) of each gain table in tables [(name, tuning.schedule.table.GainSchedule), ...] against its
    scheduling variable (one column per variable), marked at the breakpoints and linear between them as the PID
    interpolates (held constant outside: not drawn); fixed: the fixed PID's loop.gains.Gains, dashed; each loop's
    gain range shaded where on scale."""
    y_units, u_units = loop_units(config)
    variables = list(dict.fromkeys((t.variable, t.unit) for _, t in tables))
    fig, axes = new_figure(3, max(len(variables), 1), figsize=(2.2 + 5.0 * max(len(variables), 1), 7.4),
                           squeeze=False)
    fig.set_layout_engine("constrained")
    multi = config.n_loops > 1
    loop_styles = ("-", "--", ":", "-.")
    for c, (variable, unit) in enumerate(variables):
        for r, key in enumerate(("Kp", "Ti", "Td")):
            ax = axes[r, c]
            drawn = []
            for name, table in tables:
                if (table.variable, table.unit) != (variable, unit):
                    continue
                values = np.asarray(getattr(table, key), float)
                for i, loop in enumerate(config.loops):
                    label = _named(name, deployed) + (f", {loop.output}" if multi else "")
                    ax.plot(table.breakpoints, values[:, i], marker="o", ms=4, color=COLORS.get(name),
                            ls=loop_styles[i % len(loop_styles)], lw=1.4, label=label)
                    drawn.append(values[:, i])
            if fixed is not None:
                for i, loop in enumerate(config.loops):
                    v = float(np.asarray(getattr(fixed, key), float)[i])
                    ax.axhline(v, color=COLORS[FIXED], ls=loop_styles[i % len(loop_styles)] if multi else "--", lw=1.2,
                               label=_named(FIXED, deployed) + (f", {loop.output}" if multi else ""))
                    drawn.append(np.array([v]))
            rng = [getattr(l, key) for l in config.loops]
            low, high = min(g.low for g in rng), max(g.high for g in rng)
            scale = "log" if all(g.scale == "log" for g in rng) else "linear"
            bottom, top, log = gain_axis_limits(np.concatenate(drawn) if drawn else [], low, high, scale)
            _format_gain_axis(ax, log)
            ax.set_ylim(bottom, top)
            _shade_outside(ax, low, high)
            if key == "Kp":
                units = {f"{u or 'u'}/{y or 'y'}" for u, y in zip(u_units, y_units)}
                ax.set_ylabel(f"Kp [{units.pop() if len(units) == 1 else 'u/y'}]")
            else:
                ax.set_ylabel(f"{key} [s]")
            ax.grid(True, alpha=0.3)
        axes[-1, c].set_xlabel(_label(variable, unit))
        for ax in axes[:, c]:
            ax.xaxis.set_major_locator(ticker.MaxNLocator(nbins=6))
        _unique_legend(axes[0, c])
    fig.suptitle(title, fontsize=11)
    return fig
