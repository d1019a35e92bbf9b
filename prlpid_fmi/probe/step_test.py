"""Open-loop step and trim test of an FMU: how each input moves an output (`prlpid-fmi probe`).

For every real input, two runs from the FMU's start values (inputs held at their start values, or the
values given): the *trim* run with nothing changed, and the *step* run with that input stepped by du at
t = 0. Their difference Δy(t) is the input's step response around the start point, drift removed.

The response is fitted by a discrete ARX model, Δy_k = Σ a_i Δy_(k-i) + B, of the smallest order (1 to 4)
that explains it: exact for a linear plant of that order. Its poles s = ln(z)/T_sample give the
dominant pole p (largest real part). p < 0: stable, time constant T = -1/p, gain K = B/(1 - Σa)/du;
p > 0: unstable, growth rate λ = p, and the formal steady-state gain G(0) of the same model;
p ≈ 0: integrating, rate = dΔy/dt / du (output units per second per input unit). Dead time: the time Δy stays at zero (below 1e-6 of its scale), when it is at least two
samples (a lag's slow start is not a dead time). The sampling grid adapts: 400 samples of T/40 (or 1/(40λ)), so a 2 ms motor and a room with an
hour-long time constant are both resolved.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Optional, Sequence

import numpy as np

from prlpid_fmi.errors import PlantError

SAMPLES = 400                   # samples per run
SAMPLES_PER_TIME_CONSTANT = 40  # the grid aims at T/40 (1/(40 λ) when unstable)
DISTURBANCE_WORDS = ("ambient", "outside", "outdoor", "load", "disturbance", "disturb", "weather", "environment")
STEP_FRACTION = 0.01            # du: 1 % of the input's start value, nominal value or declared range
MIN_DT_S, MAX_DT_S = 1e-6, 1e5


def is_disturbance_like(name: str, description: str = "") -> bool:
    """True when an input's name or description marks it as a disturbance (ambient, outside, load, ...)."""
    text = f"{name} {description}".lower()
    return any(word in text for word in DISTURBANCE_WORDS)


@dataclass(frozen=True)
class StepResponse:
    """One input's open-loop step response on one output, around the start values.

    kind: "stable" | "unstable" | "integrating" | "static" (the output follows the input within one step: no
    dynamics on the probe's grid) | "none" (the input does not move the output).
    gain: Δy/Δu at steady state [output units per input unit] (stable, static), the formal G(0) (unstable).
    time_constant_s: the slowest time constant (stable) or 1/growth rate (unstable), s.
    growth_rate_per_s: λ of an unstable response (1/s); rate: dy/dt per input unit of an integrating one.
    """

    input: str
    output: str
    u0: float
    du: float
    sample_time_s: float
    time_s: np.ndarray = field(repr=False)
    trim: np.ndarray = field(repr=False)
    stepped: np.ndarray = field(repr=False)
    kind: str
    gain: Optional[float]
    time_constant_s: Optional[float]
    growth_rate_per_s: Optional[float]
    rate: Optional[float]
    dead_time_s: float
    disturbance_like: bool

    @property
    def delta(self) -> np.ndarray:
        """Δy(t) = step run - trim run, shape (n,)."""
        return self.stepped - self.trim

    @property
    def output_change_per_unit(self) -> float:
        """How much one input unit moves the output: |gain| (stable, unstable), |rate| x 10 T_sample
        (integrating: the change over ten samples), 0 (none)."""
        if self.kind in ("stable", "unstable", "static"):
            return abs(self.gain)
        if self.kind == "integrating":
            return abs(self.rate) * 10 * self.sample_time_s
        return 0.0

    def summary(self) -> str:
        """One line for the probe table."""
        if self.kind == "stable":
            what = f"stable, gain {self.gain:.4g}, time constant {self.time_constant_s:.4g} s"
        elif self.kind == "unstable":
            what = (f"UNSTABLE, grows as e^(λt) with λ = {self.growth_rate_per_s:.4g} 1/s "
                    f"(time constant {self.time_constant_s:.4g} s), formal steady-state gain {self.gain:.4g}")
        elif self.kind == "integrating":
            what = f"integrating, rate {self.rate:.4g} per s per input unit"
        elif self.kind == "static":
            what = f"static, gain {self.gain:.4g} (no dynamics at {self.sample_time_s:g} s steps)"
        else:
            return f"{self.input}: does not move {self.output}"
        dead = f", dead time {self.dead_time_s:.4g} s" if self.dead_time_s > 0 else ""
        flag = "  (looks like a disturbance input)" if self.disturbance_like else ""
        return f"{self.input} (step {self.du:+.4g} from {self.u0:.4g}): {what}{dead}{flag}"


@dataclass(frozen=True)
class ProbeResult:
    """The probe of one output: its start value and every input's step response."""

    fmu: Path
    output: str
    y0: float
    responses: tuple[StepResponse, ...]

    def response(self, name: str) -> StepResponse:
        return next(r for r in self.responses if r.input == name)


def snap_sample_time(dt: float) -> float:
    """dt rounded down to the 1-2-5 series, clipped to [MIN_DT_S, MAX_DT_S]."""
    dt = min(max(dt, MIN_DT_S), MAX_DT_S)
    decade = 10 ** math.floor(math.log10(dt))
    return max(m for m in (1, 2, 5, 10) if m * decade <= dt * (1 + 1e-9)) * decade


def _simulate(path, inputs, u, output, dt, parameters) -> np.ndarray:
    """Output samples (n <= SAMPLES + 1,) holding inputs u; stops at a rejected step or a non-finite output."""
    from prlpid_fmi.fmu import FmuPlant
    from prlpid_fmi.fmu.plant import StepRejected

    with FmuPlant(path, inputs=inputs, outputs=[output], sample_time_s=dt, parameters=parameters,
                  instance_name="probe") as plant:
        y = [float(plant.read_outputs()[0])]
        values = [float(v) for v in u]
        for _ in range(SAMPLES):
            try:
                value = plant.step_values(values)[0]
            except (StepRejected, PlantError):
                break
            if not math.isfinite(value) or abs(value) > 1e150:
                break
            y.append(value)
    return np.array(y)


MAX_ORDER = 4                   # ARX orders tried: the smallest that explains Δy to 1e-4 wins


def _arx(dy: np.ndarray, order: int):
    """Least-squares Δy_k = Σ a_i Δy_(k-i) + B for k >= order (a step input: the input terms are one
    constant). Returns (a, B, rms residual)."""
    rows = np.column_stack([dy[order - i - 1:len(dy) - i - 1] for i in range(order)] + [np.ones(len(dy) - order)])
    target = dy[order:]
    coef, *_ = np.linalg.lstsq(rows, target, rcond=None)
    residual = float(np.sqrt(np.mean((rows @ coef - target) ** 2)))
    return coef[:order], float(coef[order]), residual


def _analyse(t: np.ndarray, dy: np.ndarray, dt: float, du: float, y_scale: float, max_order: int = MAX_ORDER):
    """(kind, gain, time constant, growth rate, rate, dead time) of a step response Δy sampled at t.

    A discrete ARX model of the smallest order (<= max_order) that fits Δy gives the poles
    s = ln(z)/dt; the dominant one (largest real part) decides the kind and the time scale."""
    n = min(len(dy), len(t))
    t, dy = t[:n], dy[:n]
    scale = float(np.max(np.abs(dy))) if n else 0.0
    if n < 8 or scale <= 1e-12 * (1.0 + y_scale):
        return "none", None, None, None, None, 0.0
    nz = int(np.argmax(np.abs(dy) > 1e-6 * scale))           # a transport delay: Δy stays at zero
    dead = (nz - 1) * dt if nz - 1 >= 2 else 0.0
    if np.all(np.abs(dy[nz:] - dy[-1]) <= 1e-6 * scale):      # at its final value from the first step it moves
        return "static", float(dy[-1] / du), None, None, None, dead
    data = dy[max(nz - 1, 0):] / scale
    best = None
    for order in range(1, min(max_order, (len(data) - 2) // 3) + 1):
        a, b, residual = _arx(data, order)
        if best is None or residual < 0.5 * best[2]:
            best = (a, b, residual)
        if residual <= 1e-4:
            break
    a, b, _ = best
    z = np.roots(np.concatenate(([1.0], -a)))
    poles = np.log(z.astype(complex)) / dt
    dominant = poles[np.argmax(poles.real)]
    near_one = np.abs(z - 1.0) < 1e-6
    horizon = max(t[-1], dt)
    if abs(dominant.real) * horizon < 1e-3 or near_one.any():
        rate = float(np.mean(np.diff(dy[-max(3, n // 10):])) / dt / du)
        return "integrating", None, None, None, rate, dead
    gain = float(b * scale / (1.0 - np.sum(a)) / du)           # G(0): the model's steady state (formal if unstable)
    if dominant.real > 0:
        return "unstable", gain, 1.0 / float(dominant.real), float(dominant.real), None, dead
    return "stable", gain, -1.0 / float(dominant.real), None, None, dead


def _step_size(v, u0: float) -> float:
    """du: STEP_FRACTION of the start value, else of the nominal value, else of the declared range, else 1."""
    for basis in (u0, v.nominal, (v.max - v.min) if v.min is not None and v.max is not None else None):
        if basis is not None and math.isfinite(basis) and basis != 0:
            du = STEP_FRACTION * abs(basis)
            break
    else:
        du = 1.0
    if v.max is not None and u0 + du > v.max:  # step down where the declared maximum leaves no room
        du = -du
    return du


def probe_input(path, name: str, output: str, inputs: Sequence[str], u0: Sequence[float],
                parameters: Mapping[str, float], dt0: float, y0: float) -> StepResponse:
    """The step response of input `name` on `output`, on a grid adapted to its time scale."""
    from prlpid_fmi.fmu import describe_fmu

    d = describe_fmu(path)
    v = d.variable(name)
    i = list(inputs).index(name)
    du = _step_size(v, u0[i])
    stepped_u = list(u0)
    stepped_u[i] += du
    dt, tried, result = snap_sample_time(dt0), set(), None
    for _ in range(8):
        tried.add(dt)
        trim = _simulate(path, inputs, u0, output, dt, parameters)
        stepped = _simulate(path, inputs, stepped_u, output, dt, parameters)
        n = min(len(trim), len(stepped))
        t = dt * np.arange(n)
        kind, gain, tau, growth, rate, dead = _analyse(t, stepped[:n] - trim[:n], dt, du, abs(y0))
        result = (dt, t, trim[:n], stepped[:n], kind, gain, tau, growth, rate, dead)
        if kind == "static":  # no time scale to resolve: a finer grid would show the same
            break
        if kind in ("stable", "unstable"):
            target = snap_sample_time(tau / SAMPLES_PER_TIME_CONSTANT)
            if n < SAMPLES // 2:  # blew up early: finer grid
                target = snap_sample_time(dt / 10)
        elif kind in ("integrating", "none"):  # too short to see it settle, or too slow to see it move
            target = snap_sample_time(dt * 10)
        if target in tried or target == dt:
            break
        if kind in ("integrating", "none") and len(tried) >= 3:
            break
        dt = target
    dt, t, trim, stepped, kind, gain, tau, growth, rate, dead = result
    if kind == "integrating":  # report an integrator on the finest grid that showed it
        dt = min(tried)
        trim = _simulate(path, inputs, u0, output, dt, parameters)
        stepped = _simulate(path, inputs, stepped_u, output, dt, parameters)
        n = min(len(trim), len(stepped))
        t = dt * np.arange(n)
        kind, gain, tau, growth, rate, dead = _analyse(t, stepped[:n] - trim[:n], dt, du, abs(y0))
        trim, stepped = trim[:n], stepped[:n]
    return StepResponse(name, output, float(u0[i]), du, dt, t, trim, stepped, kind, gain, tau, growth, rate, dead,
                        is_disturbance_like(name, v.description))


def probe(fmu_path, output: Optional[str] = None, inputs: Optional[Sequence[str]] = None,
          start_values: Optional[Mapping[str, float]] = None) -> ProbeResult:
    """Step and trim test of every real input (or `inputs`) on `output` (default: the first output).

    start_values {parameter or input: value}: the operating point (parameters applied before each run,
    inputs held there). Raises PlantError for an FMU that cannot be a plant or an unknown variable.
    """
    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.fmu.archive import archive_problems

    path = Path(fmu_path)
    d = describe_fmu(path)
    problems = archive_problems(path) or d.plant_problems()  # the archive first: no binary, unsafe names, ...
    if problems:
        raise PlantError(f"{path}: cannot be probed as a plant: {'; '.join(problems)}")
    output = output or d.output_names[0]
    d.require(output, None, "the probed output")
    all_inputs = list(d.input_names)
    chosen = list(inputs) if inputs else all_inputs
    for name in chosen:
        d.require(name, ("input",), "a probed input")
    start_values = dict(start_values or {})
    for name in start_values:
        d.require(name, ("parameter", "input"), "a start value")
    u0 = [float(start_values.get(n, _start(d.variable(n)))) for n in all_inputs]
    parameters = {k: v for k, v in start_values.items() if k not in all_inputs}
    dt0 = d.default_step_size_s or 0.1
    y0 = float(_simulate(path, all_inputs, u0, output, dt0, parameters)[0])
    responses = tuple(probe_input(path, n, output, all_inputs, u0, parameters, dt0, y0) for n in chosen)
    return ProbeResult(path, output, y0, responses)


def _start(v) -> float:
    try:
        return float(v.start) if v.start is not None else 0.0
    except (TypeError, ValueError):
        return 0.0


def format_probe(result: ProbeResult) -> str:
    """The probe as text: one line per input."""
    lines = [f"{result.fmu.name}: output {result.output} starts at {result.y0:.6g}"]
    lines += ["  " + r.summary() for r in result.responses]
    return "\n".join(lines)


def plot_probe(result: ProbeResult, path) -> Path:
    """One panel per input: the step response Δy (step run minus trim run) with the fitted model, and the
    trim run on the right axis, annotated. Returns path."""

    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.report.plots import new_figure, save_figure

    d = describe_fmu(result.fmu)
    unit = d.unit_of(result.output)
    n = len(result.responses)
    fig, axes = new_figure(n, 1, figsize=(8, 0.8 + 2.8 * n), squeeze=False)
    for ax, r in zip(axes[:, 0], result.responses):
        scale, tunit = _time_unit(r.time_s[-1] if len(r.time_s) else 1.0)
        t = r.time_s / scale
        ax.plot(t, r.delta, color="C0", lw=1.8, label=f"step response: {r.input} stepped by {r.du:+.3g} at t = 0")
        model = _model_response(r)
        if model is not None:
            ax.plot(t, model, color="C3", lw=1.2, ls="--", label="fitted model")
        if r.dead_time_s > 0:
            ax.axvline(r.dead_time_s / scale, color="C2", lw=0.8, label=f"dead time {r.dead_time_s:.3g} s")
        ax.set_ylabel(f"Δ{result.output} [{unit}]" if unit else f"Δ{result.output}")
        trim_ax = ax.twinx()
        trim_ax.plot(t, r.trim, color="0.55", lw=1.0, ls=":", label="trim run: all inputs at start values (right axis)")
        trim_ax.set_ylabel(f"{result.output} [{unit}] (trim)" if unit else f"{result.output} (trim)", color="0.4")
        trim_ax.tick_params(axis="y", colors="0.4")
        ax.set_title(r.summary(), fontsize=8.5, loc="left")
        ax.set_xlabel(f"time [{tunit}] (sample {r.sample_time_s:g} s)")
        ax.grid(alpha=0.3)
        handles = ax.get_legend_handles_labels()[0] + trim_ax.get_legend_handles_labels()[0]
        ax.legend(handles=handles, fontsize=8, loc="best")
    fig.suptitle(f"Open-loop step and trim test of {d.model_name}", fontsize=11)
    fig.tight_layout()
    return save_figure(fig, path)


def _time_unit(span_s: float) -> tuple[float, str]:
    for scale, name in ((3600.0, "h"), (60.0, "min"), (1.0, "s"), (1e-3, "ms")):
        if span_s >= 3 * scale:
            return scale, name
    return 1e-3, "ms"


def _model_response(r: StepResponse) -> Optional[np.ndarray]:
    """The fitted first-order model's Δy(t) (None for "none")."""
    t = np.maximum(r.time_s - r.dead_time_s, 0.0)
    if r.kind == "stable":
        return r.gain * r.du * (1 - np.exp(-t / r.time_constant_s))
    if r.kind == "unstable":
        return -r.gain * r.du * np.expm1(np.minimum(r.growth_rate_per_s * t, 700))
    if r.kind == "integrating":
        return r.rate * r.du * t
    if r.kind == "static":
        return np.where(r.time_s >= r.dead_time_s, r.gain * r.du, 0.0)
    return None


# ---------------------------------------------------------------------------------------------
# what init proposes from a probe
