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

The mechanism (MECHANISMS: pure integrator, integrator with lag, double integrator, oscillator, lag, lag with
delay, delay, inverse response, unstable, static) comes from the model's poles at zero, the lags the grid
resolves, a lightly damped pair, Δy first moving against its final value (a right-half-plane zero) and the dead
time; the transfer function itself (`Model`) is the least-squares fit of Δy by the step response through the
ARX poles, so its zeros and high-frequency gain are read as well. A run that reaches a stop (the output pinned
at one value after moving: a ball on its magnet, an empty tank) is fitted up to the stop, so an unstable plant's
growth rate and gain are read before it. An integrating response is sampled on the grid that resolves its lag.

Beyond the dominant pole: a lightly damped complex pair gives the oscillation's period (2π/ω_d, the fit of
the oscillation itself, not of its decay envelope) and damping ratio; a stable response whose steady
change is below ZERO_GAIN_FRACTION of its peak is a zero-gain pulse (a rate of what the input moves, e.g. a
velocity under a spring), never a loop to close. `probe_outputs` records every output in each run (runs are
cached by grid and input values, so the trim run and the other outputs cost nothing more) and marks an
output whose response is the time derivative of another output's (`rate_of`: a velocity beside its
position). `sweep_input` holds an input at several levels across its limits until the outputs settle: the
range the plant can reach at steady state, and whether the input acts on/off (two output values, a jump
between two neighbouring levels).
"""
from __future__ import annotations

import dataclasses
import math
import os
import tempfile
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
ZERO_GAIN_FRACTION = 0.01      # steady |Δy| below this part of the peak |Δy|: a zero-gain pulse
INTEGRATING_GROWTH = 0.02      # a dominant pole with |Re p| x horizon below this is an integrator's (p ≈ 0)
OSCILLATORY_DAMPING = 0.7      # a complex pair damped less than this shows as an oscillation
RATE_TOLERANCE = 0.02          # relative residual of Δy_B ≈ c dΔy_A/dt that makes B the rate of A


def is_disturbance_like(name: str, description: str = "") -> bool:
    """True when an input's name or description marks it as a disturbance (ambient, outside, load, ...)."""
    text = f"{name} {description}".lower()
    return any(word in text for word in DISTURBANCE_WORDS)


MECHANISMS = ("pure integrator", "integrator with lag", "double integrator", "oscillator", "lag", "lag with delay",
              "delay", "inverse response", "unstable", "static", "none")
INVERSE_FRACTION = 0.01         # Δy first moving against its final value by more than this part of it: inverse response
STOP_INCREMENTS = 4             # a run pinned at one value after at least this many moving samples ran onto a stop


@dataclass(frozen=True)
class Model:
    """The identified linear model G(s) e^(-L s) = num(s)/den(s) e^(-L s) of a step response, per input unit:
    num and den are polynomial coefficients, highest power first (den monic); integrating poles are exactly 0."""

    num: tuple[float, ...]
    den: tuple[float, ...]
    dead_time_s: float = 0.0

    @property
    def poles(self) -> np.ndarray:
        return np.roots(self.den) if len(self.den) > 1 else np.zeros(0)

    @property
    def zeros(self) -> np.ndarray:
        return np.roots(self.num) if len(self.num) > 1 else np.zeros(0)

    @property
    def integrators(self) -> int:
        """How many poles are at s = 0."""
        k = 0
        for c in reversed(self.den):
            if c != 0.0:
                break
            k += 1
        return k

    @property
    def low_frequency_gain(self) -> float:
        """lim s->0 s^m G(s) for m integrators: the steady gain (m = 0), the rate (1), the curvature d²y/dt² (2)."""
        den = self.den[:len(self.den) - self.integrators]
        return float(self.num[-1] / den[-1]) if den[-1] else math.nan

    @property
    def high_frequency_gain(self) -> float:
        """lim s->inf s^r G(s), r the relative degree: the sign and size of the first move after a step."""
        return float(self.num[0] / self.den[0])

    def magnitude(self, w: np.ndarray) -> np.ndarray:
        """|G(jw)| (the delay does not change it), shape of w."""
        s = 1j * np.asarray(w, dtype=float)
        return np.abs(np.polyval(self.num, s) / np.polyval(self.den, s))

    def text(self) -> str:
        """G(s) as factors, e.g. '2 (1 - 5 s) / ((30 s + 1) (15 s + 1))' with e^(-L s) when delayed."""
        k = self.low_frequency_gain
        m = self.integrators
        factors = []
        for p in sorted(self.poles, key=lambda p: abs(p)):
            if abs(p) == 0 or p.imag < 0:
                continue
            if p.imag > 0:
                wn, zeta = abs(p), -p.real / abs(p)
                factors.append(f"(s²/{wn:.3g}² + 2·{zeta:.3g} s/{wn:.3g} + 1)")
            else:
                factors.append(f"({-1 / p.real:.4g} s + 1)" if p.real < 0 else f"({1 / p.real:.4g} s - 1)")
        zeros = [f"(1 - {1 / z.real:.4g} s)" if z.real > 0 else f"(1 + {-1 / z.real:.4g} s)"
                 for z in self.zeros if abs(z.imag) < 1e-9 and z.real != 0]
        unstable_sign = (-1) ** sum(1 for p in self.poles if p.real > 0 and abs(p.imag) < 1e-12)
        text = f"{k * unstable_sign:.4g}" + (" " + " ".join(zeros) if zeros else "")
        below = ("s" if m == 1 else f"s^{m}" if m else "") + (" " if m and factors else "") + " ".join(factors)
        text += f" / ({below})" if below else ""
        return text + (f" e^(-{self.dead_time_s:.3g} s)" if self.dead_time_s > 0 else "")


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
    period_s: Optional[float] = None         # oscillation period 2π/ω_d of the least damped complex pair
    damping_ratio: Optional[float] = None    # its damping ratio ζ
    rate_of: Optional[str] = None            # this output's response is the time derivative of that output's
    mechanism: str = ""                      # what the response shows (MECHANISMS), said in the probe's output
    model: Optional[Model] = None            # the identified linear model (None: static, none)
    stop_s: Optional[float] = None           # when a run reached a stop (the output pinned): fitted before it

    @property
    def peak(self) -> float:
        """max |Δy| over the run."""
        return float(np.max(np.abs(self.delta))) if len(self.delta) else 0.0

    @property
    def zero_gain(self) -> bool:
        """A stable response that returns to where it started (steady change < ZERO_GAIN_FRACTION of its peak):
        the output is a rate of what the input moves; no PID can hold it at a setpoint with this input."""
        return self.kind == "stable" and abs(self.gain * self.du) < ZERO_GAIN_FRACTION * self.peak

    @property
    def time_scale_s(self) -> Optional[float]:
        """The fastest time that matters to a loop on this response: the time constant, or the oscillation's
        period / 2π where that is shorter (stable); 1/λ (unstable); None (integrating, static, none)."""
        if self.kind == "stable":
            return min(self.time_constant_s, self.period_s / (2 * math.pi)) if self.period_s else self.time_constant_s
        if self.kind == "unstable":
            return self.time_constant_s
        return None

    @property
    def delta(self) -> np.ndarray:
        """Δy(t) = step run - trim run, shape (n,)."""
        return self.stepped - self.trim

    @property
    def output_change_per_unit(self) -> float:
        """How much one input unit moves the output: |gain| (stable, unstable), |rate| x 10 T_sample
        (integrating: the change over ten samples), 0 (none)."""
        if self.zero_gain:
            return 0.0
        if self.kind in ("stable", "unstable", "static"):
            return abs(self.gain)
        if self.kind == "integrating":
            return abs(self.rate) * 10 * self.sample_time_s
        return 0.0

    def summary(self) -> str:
        """One line for the probe table."""
        osc = (f", oscillates with period {self.period_s:.4g} s (damping ratio {self.damping_ratio:.3g})"
               if self.period_s else "")
        if self.kind == "stable" and self.zero_gain:
            what = (f"stable, ZERO GAIN: a pulse of {self.peak:.4g} that dies out (steady gain {self.gain:.3g}; "
                    f"this output is a rate of what {self.input} moves), time constant {self.time_constant_s:.4g} s{osc}")
        elif self.kind == "stable":
            what = f"stable, gain {self.gain:.4g}, time constant {self.time_constant_s:.4g} s{osc}"
        elif self.kind == "unstable":
            what = (f"UNSTABLE, grows as e^(λt) with λ = {self.growth_rate_per_s:.4g} 1/s "
                    f"(time constant {self.time_constant_s:.4g} s), formal steady-state gain {self.gain:.4g}{osc}")
        elif self.kind == "integrating" and self.mechanism == "double integrator":
            what = f"integrating twice, d²y/dt² = {self.model.low_frequency_gain:.4g} per s² per input unit"
        elif self.kind == "integrating":
            what = f"integrating, rate {self.rate:.4g} per s per input unit"
        elif self.kind == "static":
            what = f"static, gain {self.gain:.4g} (no dynamics at {self.sample_time_s:g} s steps)"
        else:
            return f"{self.input}: does not move {self.output}"
        dead = f", dead time {self.dead_time_s:.4g} s" if self.dead_time_s > 0 else ""
        if self.stop_s is not None:
            dead += f"; reached a stop after {self.stop_s:.4g} s (fitted before it)"
        if self.mechanism:
            dead += f"; {self.mechanism.upper()}" + (f": G(s) = {self.model.text()}" if self.model is not None else "")
        flag = "  (looks like a disturbance input)" if self.disturbance_like else ""
        if self.rate_of:
            flag += f"  (the rate of {self.rate_of})"
        return f"{self.input} (step {self.du:+.4g} from {self.u0:.4g}): {what}{dead}{flag}"


@dataclass(frozen=True)
class ProbeResult:
    """The probe of one output: its start value and every input's step response, and the operating point it
    was taken at (every input's start value, the parameters set) so that further runs can start there."""

    fmu: Path
    output: str
    y0: float
    responses: tuple[StepResponse, ...]
    inputs: tuple[str, ...] = ()
    u0: tuple[float, ...] = ()
    parameters: Mapping[str, float] = field(default_factory=dict)

    def response(self, name: str) -> StepResponse:
        return next(r for r in self.responses if r.input == name)


def snap_sample_time(dt: float) -> float:
    """dt rounded down to the 1-2-5 series, clipped to [MIN_DT_S, MAX_DT_S]."""
    dt = min(max(dt, MIN_DT_S), MAX_DT_S)
    decade = 10 ** math.floor(math.log10(dt))
    return max(m for m in (1, 2, 5, 10) if m * decade <= dt * (1 + 1e-9)) * decade


class _Runs:
    """Open-loop runs of one FMU from its start values, every output of interest recorded, cached by (grid,
    input values, samples): the trim run is shared by every input and every output costs one run."""

    def __init__(self, path, inputs: Sequence[str], outputs: Sequence[str], parameters: Mapping[str, float],
                 u0: Sequence[float] = ()):
        self.path, self.inputs, self.outputs, self.parameters = path, list(inputs), list(outputs), dict(parameters)
        self.u0 = tuple(float(v) for v in u0)  # the start values of every input (the trim run's)
        self._cache: dict = {}

    def run(self, u: Sequence[float], dt: float, samples: int = SAMPLES) -> np.ndarray:
        """Output samples, shape (n <= samples + 1, n_outputs), inputs held at u; stops at a rejected step or a
        non-finite output."""
        key = (float(dt), tuple(float(v) for v in u), int(samples))
        if key not in self._cache:
            self._cache[key] = self._simulate(u, dt, samples)
        return self._cache[key]

    def _simulate(self, u, dt, samples) -> np.ndarray:
        from prlpid_fmi.fmu.worker import crash_seen

        args = (self.path, self.inputs, self.outputs, self.parameters, tuple(float(v) for v in u), dt, samples)
        if crash_seen([self.path]):
            return _record_in_worker(*args)
        return record_run(*args)

    def column(self, u, dt, output: str, samples: int = SAMPLES) -> np.ndarray:
        return self.run(u, dt, samples)[:, self.outputs.index(output)]


def record_run(path, inputs: Sequence[str], outputs: Sequence[str], parameters: Mapping[str, float],
               u: Sequence[float], dt: float, samples: int, sink: Optional[str] = None) -> np.ndarray:
    """Output samples, shape (n <= samples + 1, n_outputs), of one open-loop run holding the inputs at u, with
    sample time dt [s]; stops at a rejected step or a non-finite output. sink: a file each sample is also appended
    to (float64 rows) as it is made, so the samples before a crash of this process can be read back."""
    from prlpid_fmi.fmu import FmuPlant
    from prlpid_fmi.fmu.plant import StepRejected

    fd = os.open(sink, os.O_WRONLY | os.O_APPEND) if sink else None
    try:
        with FmuPlant(path, inputs=list(inputs), outputs=list(outputs), sample_time_s=dt,
                      parameters=dict(parameters), instance_name="probe") as plant:
            y = [np.array(plant.read_outputs(), dtype=float)]
            if fd is not None:
                os.write(fd, y[0].tobytes())
            values = [float(v) for v in u]
            for _ in range(samples):
                try:
                    value = np.array(plant.step_values(values), dtype=float)
                except (StepRejected, PlantError):
                    break
                if not np.all(np.isfinite(value)) or np.any(np.abs(value) > 1e150):
                    break
                y.append(value)
                if fd is not None:
                    os.write(fd, value.tobytes())
    finally:
        if fd is not None:
            os.close(fd)
    return np.array(y)


def _record_in_worker(path, inputs, outputs, parameters, u, dt, samples) -> np.ndarray:
    """record_run in a worker process (for an FMU that crashed a worker before: fmu.worker.crash_seen). A run
    that crashes or hangs its worker ends at the sample before the call that failed, as a rejected step does;
    PlantError with the crash's line when it failed before its first output."""
    from prlpid_fmi.fmu.worker import WorkerCrashed, call_in_worker

    fd, sink = tempfile.mkstemp(prefix="prlpid-fmi-probe-run-")
    os.close(fd)
    try:
        try:
            return call_in_worker(record_run, path, list(inputs), list(outputs), dict(parameters), u, dt, samples,
                                  sink, fmus=[path], what="a probe run", check_outputs=True)
        except WorkerCrashed as exc:
            rows = np.fromfile(sink, dtype=float)
            y = rows[:len(rows) // len(outputs) * len(outputs)].reshape(-1, len(outputs))
            if not len(y):
                raise PlantError(str(exc)) from None
            return y
    finally:
        os.unlink(sink)


def _simulate(path, inputs, u, output, dt, parameters) -> np.ndarray:
    """Output samples (n <= SAMPLES + 1,) holding inputs u; stops at a rejected step or a non-finite output."""
    return _Runs(path, inputs, [output], parameters).column(u, dt, output)


MAX_ORDER = 4                   # ARX orders tried: the smallest that explains Δy to 1e-4 wins


def _arx(dy: np.ndarray, order: int):
    """Least-squares Δy_k = Σ a_i Δy_(k-i) + B for k >= order (a step input: the input terms are one
    constant). Returns (a, B, rms residual)."""
    rows = np.column_stack([dy[order - i - 1:len(dy) - i - 1] for i in range(order)] + [np.ones(len(dy) - order)])
    target = dy[order:]
    coef, *_ = np.linalg.lstsq(rows, target, rcond=None)
    residual = float(np.sqrt(np.mean((rows @ coef - target) ** 2)))
    return coef[:order], float(coef[order]), residual


@dataclass(frozen=True)
class _Fit:
    kind: str
    gain: Optional[float] = None
    tau: Optional[float] = None
    growth: Optional[float] = None
    rate: Optional[float] = None
    dead: float = 0.0
    period: Optional[float] = None
    damping: Optional[float] = None
    model: Optional[Model] = None
    mechanism: str = ""


def _oscillation(poles: np.ndarray, dominant: complex) -> tuple[Optional[float], Optional[float]]:
    """(period 2π/ω_d, damping ratio) of the least damped complex pair that decays no more than five times
    faster than the dominant pole (a relevant mode, not a fitting artefact); (None, None) when none oscillates."""
    pairs = [p for p in poles if p.imag > 1e-12 and p.real >= 5 * min(dominant.real, 0.0) - 1e-300]
    if not pairs:
        return None, None
    p = min(pairs, key=lambda p: -p.real / abs(p))
    zeta = float(-p.real / abs(p))
    if zeta >= OSCILLATORY_DAMPING:
        return None, None
    return float(2 * math.pi / p.imag), zeta


def _model(t: np.ndarray, y: np.ndarray, poles: np.ndarray, integrators: int, dead: float) -> Optional[Model]:
    """The transfer function whose step response through `poles` (plus `integrators` poles at 0) fits y(t) (per
    input unit, t from the end of the dead time) best: y = c0 + Σ c_j t^j + Σ a_i e^(p_i t) by least squares,
    then G(s) = s Y(s). The numerator is strictly proper; terms too small to matter at the fastest pole's
    frequency are dropped (fitting noise, not zeros)."""
    cols, kinds = [np.ones_like(t)], []
    for j in range(1, integrators + 1):
        cols.append(t ** j)
    for p in poles:
        if abs(p.imag) < 1e-12:
            cols.append(np.exp(np.clip(p.real * t, -700, 700)))
            kinds.append((complex(p.real, 0.0), False))
        elif p.imag > 0:
            e = np.exp(np.clip(p.real * t, -700, 700))
            cols += [e * np.cos(p.imag * t), e * np.sin(p.imag * t)]
            kinds.append((complex(p), True))
    rows = np.column_stack(cols)
    if rows.shape[0] <= rows.shape[1] + 2:
        return None
    coef, *_ = np.linalg.lstsq(rows, y, rcond=None)
    c0, ramp, rest = coef[0], coef[1:1 + integrators], coef[1 + integrators:]
    residues, k = [], 0
    for p, pair in kinds:
        if pair:
            a = (rest[k] - 1j * rest[k + 1]) / 2
            residues += [(p, a), (np.conj(p), np.conj(a))]
            k += 2
        else:
            residues.append((p, complex(rest[k])))
            k += 1
    nonzero = np.array([p for p, _ in residues], dtype=complex)
    base = np.poly(nonzero) if len(nonzero) else np.array([1.0 + 0j])
    den = np.polymul(base, np.r_[1.0, np.zeros(integrators)])          # s^m Π (s - p_i)
    num = c0 * den
    for j, c in enumerate(ramp, start=1):                                 # c_j j!/s^j
        num = np.polyadd(num, c * math.factorial(j) * np.polymul(base, np.r_[1.0, np.zeros(integrators - j)]))
    for i, (p, a) in enumerate(residues):                                 # a_i s / (s - p_i)
        others = np.poly(np.delete(nonzero, i)) if len(nonzero) > 1 else np.array([1.0 + 0j])
        num = np.polyadd(num, a * np.polymul(others, np.r_[1.0, np.zeros(integrators + 1)]))
    num, den = np.real(num), np.real(den)
    num = np.r_[np.zeros(max(len(den) - len(num), 0)), num][1:]          # strictly proper
    w0 = max([abs(p) for p in nonzero] + [1.0 / max(t[-1], 1e-300)])
    size = np.abs(num) * w0 ** np.arange(len(num) - 1, -1, -1)
    keep = np.nonzero(size > 1e-3 * np.max(size))[0] if np.max(size) > 0 else []
    if not len(keep):
        return None
    return Model(tuple(float(c) for c in num[keep[0]:]), tuple(float(c) for c in den), dead)


def _mechanism(kind: str, model: Optional[Model], dy: np.ndarray, dt: float, horizon: float, dead: float,
               period: Optional[float]) -> str:
    """The mechanism a response shows (one of MECHANISMS), from its kind, its model and Δy."""
    if kind in ("none", "static"):
        return "delay" if kind == "static" and dead > 0 else kind
    if kind == "unstable":
        return "unstable"
    if kind == "integrating":
        if model is not None and model.integrators >= 2:
            return "double integrator"
        lags = [-1 / p.real for p in (model.poles if model is not None else []) if p.real < 0]
        return "integrator with lag" if any(2 * dt <= T <= horizon / 3 for T in lags) else "pure integrator"
    if period:
        return "oscillator"
    final = dy[-1]
    if final != 0 and np.min(dy * np.sign(final)) < -INVERSE_FRACTION * abs(final):
        return "inverse response"
    slowest = max((-1 / p.real for p in model.poles if p.real < 0), default=0.0) if model is not None else 0.0
    if dead > 0:
        return "delay" if dead >= slowest else "lag with delay"
    return "lag"


def _fit(t: np.ndarray, dy: np.ndarray, dt: float, du: float, y_scale: float, max_order: int = MAX_ORDER) -> _Fit:
    """The kind and numbers of a step response Δy sampled at t (see the module docstring)."""
    n = min(len(dy), len(t))
    t, dy = t[:n], dy[:n]
    scale = float(np.max(np.abs(dy))) if n else 0.0
    if n < 8 or scale <= 1e-12 * (1.0 + y_scale):
        return _Fit("none", mechanism="none")
    nz = int(np.argmax(np.abs(dy) > 1e-6 * scale))           # a transport delay: Δy stays at zero
    dead = (nz - 1) * dt if nz - 1 >= 2 else 0.0
    if np.all(np.abs(dy[nz:] - dy[-1]) <= 1e-6 * scale):      # at its final value from the first step it moves
        return _Fit("static", gain=float(dy[-1] / du), dead=dead, mechanism="delay" if dead > 0 else "static")
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
    at_zero = near_one | (np.abs(poles) * horizon < INTEGRATING_GROWTH)
    resolved = ~at_zero & (np.abs(z) > 1e-3) & (np.abs(poles.imag) < 0.8 * math.pi / dt)  # not an artefact of the grid
    shift = dead if dead > 0 else 0.0
    since = t >= shift - 1e-12 * dt
    model = _model(t[since] - shift, dy[since] / du, poles[resolved], int(np.count_nonzero(at_zero)), dead)
    if abs(dominant.real) * horizon < INTEGRATING_GROWTH or near_one.any():
        rate = float(np.mean(np.diff(dy[-max(3, n // 10):])) / dt / du)
        if model is None or model.integrators == 0:
            model = None
        mechanism = _mechanism("integrating", model, dy, dt, horizon, dead, None)
        if mechanism == "integrator with lag":   # the final slope still carries the lag's tail: the model's rate
            rate = model.low_frequency_gain
        return _Fit("integrating", rate=rate, dead=dead, model=model, mechanism=mechanism)
    gain = float(b * scale / (1.0 - np.sum(a)) / du)           # G(0): the model's steady state (formal if unstable)
    period, damping = _oscillation(poles, dominant)
    kind = "unstable" if dominant.real > 0 else "stable"
    mech = _mechanism(kind, model, dy, dt, horizon, dead, period)
    if dominant.real > 0:
        return _Fit("unstable", gain, 1.0 / float(dominant.real), float(dominant.real), None, dead, period, damping,
                    model, mech)
    return _Fit("stable", gain, -1.0 / float(dominant.real), None, None, dead, period, damping, model, mech)


def _analyse(t: np.ndarray, dy: np.ndarray, dt: float, du: float, y_scale: float, max_order: int = MAX_ORDER):
    """(kind, gain, time constant, growth rate, rate, dead time) of a step response Δy sampled at t (`_fit`)."""
    f = _fit(t, dy, dt, du, y_scale, max_order)
    return f.kind, f.gain, f.tau, f.growth, f.rate, f.dead


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


def _lag_s(f: _Fit) -> Optional[float]:
    """The slowest lag time constant of an integrating response's model (None: no lag)."""
    lags = [-1 / p.real for p in (f.model.poles if f.model is not None else []) if p.real < 0]
    return max(lags) if lags else None


def _next_grid(f: _Fit, dt: float, n: int) -> float:
    """The grid the next run should use after a fit `f` on grid dt with n samples (before any stop)."""
    if f.kind == "stable":
        scale = min(f.tau, f.period / (2 * math.pi)) if f.period else f.tau
        target = snap_sample_time(scale / SAMPLES_PER_TIME_CONSTANT)
    elif f.kind == "unstable":
        target = snap_sample_time(f.tau / SAMPLES_PER_TIME_CONSTANT)
    elif f.kind == "integrating" and _lag_s(f) and 2 * dt <= _lag_s(f) <= n * dt / 3:
        return snap_sample_time(_lag_s(f) / SAMPLES_PER_TIME_CONSTANT)    # the lag resolved: sample it as a lag
    else:  # integrating, none: too short to see it settle, or too slow to see it move
        return snap_sample_time(dt * 10)
    if n < SAMPLES // 8:  # blew up or ran onto a stop early: finer grid
        target = snap_sample_time(dt / 10)
    return target


def _stop_index(y: np.ndarray) -> Optional[int]:
    """The sample from which a run stays pinned at one value after moving (STOP_INCREMENTS moving samples or
    more before it): the output ran onto a stop. None when it never does."""
    if len(y) < 8:
        return None
    tol = 1e-9 * (1.0 + float(np.ptp(y)))
    moving = np.abs(np.diff(y)) > tol
    if moving[-1] or not moving.any():
        return None
    k = int(len(moving) - np.argmax(moving[::-1]))        # first sample of the final flat run
    if k >= len(y) - 3 or np.count_nonzero(moving[:k]) < STOP_INCREMENTS:
        return None
    return k


def _response(runs: _Runs, i: int, du: float, output: str, dt0: float, y0: float, v) -> StepResponse:
    """The step response of input i on `output`, on a grid adapted to its time scale; a run that reaches a stop
    is fitted up to the stop."""
    u0 = [float(x) for x in runs.u0]
    stepped_u = list(u0)
    stepped_u[i] += du
    dt, tried, result, seen = snap_sample_time(dt0), set(), None, {}

    def measure(dt):
        trim, stepped = runs.column(u0, dt, output), runs.column(stepped_u, dt, output)
        n = min(len(trim), len(stepped))
        t = dt * np.arange(n)
        stops = [k for k in (_stop_index(trim[:n]), _stop_index(stepped[:n])) if k is not None]
        m = min(stops) if stops else n
        f = _fit(t[:m], stepped[:m] - trim[:m], dt, du, abs(y0))
        return dt, t, trim[:n], stepped[:n], f, (m * dt if stops else None), m

    for _ in range(8):
        tried.add(dt)
        result = measure(dt)
        seen[dt] = result
        f = result[4]
        if f.kind == "static":  # no time scale to resolve: a finer grid would show the same
            break
        target = _next_grid(f, dt, result[6])
        if target in tried or target == dt:
            break
        if f.kind in ("integrating", "none") and len(tried) >= 3 and f.mechanism != "integrator with lag":
            break
        dt = target
    if result[4].kind == "integrating":  # the grid that resolves a lag; else the finest that showed an integrator
        integrating = [r for r in seen.values() if r[4].kind == "integrating"]
        with_lag = [r for r in integrating if r[4].mechanism == "integrator with lag"]
        result = with_lag[-1] if with_lag else min(integrating, key=lambda r: r[0])
    dt, t, trim, stepped, f, stop, _ = result
    name = runs.inputs[i]
    return StepResponse(name, output, u0[i], du, dt, t, trim, stepped, f.kind, f.gain, f.tau, f.growth, f.rate,
                        f.dead, is_disturbance_like(name, v.description), f.period, f.damping,
                        mechanism=f.mechanism, model=f.model, stop_s=stop)


def probe_input(path, name: str, output: str, inputs: Sequence[str], u0: Sequence[float],
                parameters: Mapping[str, float], dt0: float, y0: float) -> StepResponse:
    """The step response of input `name` on `output`, on a grid adapted to its time scale."""
    from prlpid_fmi.fmu import describe_fmu

    v = describe_fmu(path).variable(name)
    runs = _Runs(path, inputs, [output], parameters, u0)
    i = list(inputs).index(name)
    return _response(runs, i, _step_size(v, u0[i]), output, dt0, y0, v)


def _is_rate(a: StepResponse, b_delta: np.ndarray) -> bool:
    """True when Δy_B ≈ c dΔy_A/dt on A's grid (c != 0): B is the rate of A (a velocity beside its position).
    Compared as ΔA_k - ΔA_(k-1) ≈ c dt (ΔB_(k-1) + ΔB_k)/2 from the third sample on."""
    da = np.diff(a.delta)[1:]
    mid = 0.5 * (b_delta[1:-1] + b_delta[2:])[:len(da)]
    da = da[:len(mid)]
    if len(mid) < 8 or not np.any(mid) or not np.any(da):
        return False
    c = float(mid @ da / (mid @ mid))
    return c != 0 and float(np.linalg.norm(da - c * mid)) <= RATE_TOLERANCE * float(np.linalg.norm(da))


def probe_outputs(fmu_path, outputs: Optional[Sequence[str]] = None, inputs: Optional[Sequence[str]] = None,
                  start_values: Optional[Mapping[str, float]] = None) -> dict[str, ProbeResult]:
    """Step and trim test of every real input (or `inputs`) on every output (or `outputs`): {output: ProbeResult}.

    Each run records every output (one run per input and grid, shared). An output whose response to an input
    is the time derivative of another output's response to it gets `rate_of` that output.
    start_values {parameter or input: value}: the operating point (parameters applied before each run,
    inputs held there). Raises PlantError for an FMU that cannot be a plant or an unknown variable."""
    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.fmu.archive import archive_problems

    path = Path(fmu_path)
    d = describe_fmu(path)
    problems = archive_problems(path) or d.plant_problems()  # the archive first: no binary, unsafe names, ...
    if problems:
        raise PlantError(f"{path}: cannot be probed as a plant: {'; '.join(problems)}")
    outputs = list(outputs) if outputs else list(d.output_names)
    for name in outputs:
        d.require(name, None, "the probed output")
    all_inputs = list(d.input_names)
    chosen = list(inputs) if inputs else all_inputs
    for name in chosen:
        d.require(name, ("input",), "a probed input")
    start_values = dict(start_values or {})
    for name in start_values:
        d.require(name, ("parameter", "input"), "a start value")
    u0 = tuple(float(start_values.get(n, _start(d.variable(n)))) for n in all_inputs)
    parameters = {k: v for k, v in start_values.items() if k not in all_inputs}
    dt0 = d.default_step_size_s or 0.1
    runs = _Runs(path, all_inputs, outputs, parameters, u0)
    y0s = runs.run(u0, snap_sample_time(dt0))[0]
    table = {o: [] for o in outputs}
    for name in chosen:
        i = all_inputs.index(name)
        v = d.variable(name)
        du = _step_size(v, u0[i])
        responses = {o: _response(runs, i, du, o, dt0, float(y0s[k]), v) for k, o in enumerate(outputs)}
        for o, r in responses.items():
            if r.kind == "none":
                continue
            stepped = list(u0)
            stepped[i] += du
            for a in responses.values():
                if a.output == o or a.kind == "none" or a.rate_of:
                    continue
                b_delta = runs.column(stepped, a.sample_time_s, o) - runs.column(u0, a.sample_time_s, o)
                if len(b_delta) >= len(a.delta) and _is_rate(a, b_delta[:len(a.delta)]):
                    r = dataclasses.replace(r, rate_of=a.output)
                    break
            responses[o] = r
        for o in outputs:
            table[o].append(responses[o])
    return {o: ProbeResult(path, o, float(y0s[k]), tuple(table[o]), tuple(all_inputs), u0, parameters)
            for k, o in enumerate(outputs)}


def probe(fmu_path, output: Optional[str] = None, inputs: Optional[Sequence[str]] = None,
          start_values: Optional[Mapping[str, float]] = None) -> ProbeResult:
    """Step and trim test of every real input (or `inputs`) on `output` (default: the first output).

    start_values {parameter or input: value}: the operating point (parameters applied before each run,
    inputs held there). Raises PlantError for an FMU that cannot be a plant or an unknown variable.
    """
    from prlpid_fmi.fmu import describe_fmu

    if output is None:
        outputs = describe_fmu(Path(fmu_path)).output_names
        output = outputs[0] if outputs else None
    if output is None:
        return next(iter(probe_outputs(fmu_path, None, inputs, start_values).values()))
    return probe_outputs(fmu_path, [output], inputs, start_values)[output]


@dataclass(frozen=True)
class Sweep:
    """An input held at several levels from the start point until the outputs settle (or as long as a run
    lasts): the output's end value at each level, whether it settled, and what follows."""

    input: str
    output: str
    levels: tuple[float, ...]
    values: tuple[float, ...]         # the output at the end of each run
    settled: tuple[bool, ...]         # the last tenth of the run moved less than 1e-3 of the values' spread
    slopes: tuple[float, ...]         # dy/dt over the run's last tenth (output units per s)
    duration_s: float

    @property
    def reach(self) -> tuple[float, float]:
        """(lowest, highest) output value at the levels."""
        return (min(self.values), max(self.values))

    @property
    def on_off(self) -> Optional[tuple[float, float]]:
        """(level below, level above) the threshold when the input acts on/off: the settled outputs take two
        values (equal to 1e-6 of the jump) and change between two neighbouring levels only; else None."""
        y = np.array(self.values)
        if len(y) < 4 or not all(self.settled):
            return None
        jumps = np.abs(np.diff(y))
        big = float(np.max(jumps))
        if big <= 1e-12 * (1 + float(np.max(np.abs(y)))):
            return None
        k = int(np.argmax(jumps))
        if np.all(np.delete(jumps, k) <= 1e-6 * big):
            return (self.levels[k], self.levels[k + 1])
        return None


def sweep_input(result: ProbeResult, r: StepResponse, levels: Sequence[float], samples: int = SAMPLES) -> Sweep:
    """Hold input r.input at each level (the other inputs at their start values) from the start point on r's
    grid, or a coarser one when the output has not settled after `samples` steps (up to two times x10 for a
    stable response, whose time constant grows at other levels of a nonlinear plant)."""
    runs = _Runs(result.fmu, result.inputs, [result.output], result.parameters)
    i = list(result.inputs).index(r.input)
    dt = r.sample_time_s
    if r.kind == "stable" and r.time_constant_s:  # about 10 time constants at the probe's point
        dt = max(dt, snap_sample_time(10 * r.time_constant_s / samples))
    tries = 3 if r.kind in ("stable", "static") else 1
    for attempt in range(tries):
        ends, movement, slopes = [], [], []
        for level in levels:
            u = list(result.u0)
            u[i] = float(level)
            y = runs.column(u, dt, result.output, samples)
            tail = y[-max(3, len(y) // 10):]
            ends.append(float(y[-1]))
            slopes.append(float((tail[-1] - tail[0]) / (dt * max(len(tail) - 1, 1))))
            movement.append(float(np.ptp(tail)) if len(y) == samples + 1 else math.inf)  # a run cut short: unsettled
        spread = max(float(np.ptp(ends)), 1e-12 * (1 + max(abs(e) for e in ends)))
        ok = tuple(m <= 1e-3 * spread for m in movement)
        if all(ok) or attempt == tries - 1:
            break
        dt = snap_sample_time(dt * 10)
    return Sweep(r.input, result.output, tuple(float(v) for v in levels), tuple(ends), ok, tuple(slopes), dt * samples)


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
    """The identified model's Δy(t) (else the first-order one of its kind; None for "none")."""
    t = np.maximum(r.time_s - r.dead_time_s, 0.0)
    if r.model is not None:
        from scipy import signal

        _, y = signal.step((r.model.num, r.model.den), T=t)
        return np.where(r.time_s >= r.dead_time_s, y * r.du, 0.0)
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
