"""Closed-loop frequency response of an FMU plant: multisine at the plant input, the PID in the loop.

The plant FMU runs with the scenario's PID (gains fixed) at an operating point (one setpoint per
loop); the loop is never opened, so open-loop unstable plants can be measured. A periodic multisine
d is added to one loop's controller output, u = C(r - y) + d, and the plant response at each excited
frequency is the ratio of the discrete Fourier transforms of the measured y and u over whole periods
of the periodic steady state:

    P(e^{j w Ts}) = Y(w) / U(w)

Timing (the env's): u_k is computed from y_k, held over [k Ts, (k+1) Ts) and y_{k+1} is measured
after the step, so the ratio of y_k to u_k is the ZOH discretisation of the plant (one sample of
delay included). No measurement noise and no scenario disturbances: the experiment is deterministic.

With several loops ("loop-at-a-time"), the other loops stay closed; the response reported for loop i
is the *effective* plant its PID sees, (Y_i - sum_j c_ij Y_j) / U_i (the coupled error of eq. 27;
c = 0 without coupling), so that L_i = C_i * P_i is loop i's loop transfer broken at its plant input; its own
measurement's response Y_i / U_i is reported beside it (the plant's diagonal element where the plant's inputs act on
their own outputs, whatever the PID's coupling).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.control.pid import coupling_matrix
from prlpid_fmi.fmu import FmuPlant, StepRejected
from prlpid_fmi.fmu.resolve import resolve_fmu
from prlpid_fmi.loop.core import make_pid

SETPOINT_RAMP_STEPS = 100  # samples over which the setpoint ramps from the initial measurement to the operating point
SETTLE_WINDOW = 50          # samples over which the closed loop must be still to count as settled
SETTLE_TOLERANCE = 1e-7     # per-sample change of y [measurement_scale] and u [amplitude scale] counted as still
MAX_SETTLE_STEPS = 20_000   # give up settling after this many samples (the experiment still checks convergence)
CONVERGENCE_TOLERANCE = 1e-3  # max |L_p - L_{p-1}| / |1 + L_p| between the last two periods
MAX_PERIODS = 6             # measured periods at most (after the transient wait) of PERIODS_OF samples or more;
PERIODS_OF = 4096           # a shorter period measures as many as fill MAX_PERIODS x PERIODS_OF samples
MIN_WAIT = 200              # samples waited after the multisine starts, at least (at most one period)
AMPLITUDE_FRACTION = 0.02   # default multisine peak: 2 % of the u range (or of Kp * measurement_scale)
DECAY_RATIO = 0.5            # PlantResponse.decaying: last change between periods / first change at most this
GROWTH_RATIO = 2.0           # PlantResponse.growth: the loop's measurement swung this x more late than early
AMPLITUDE_RETRIES = 4       # halvings of the amplitude when the control signal hits a limit


_FMU_FILES: dict = {}  # (fmu, fmi_version) -> the FMU file resolve_fmu named (a bundled plant's check reads its
# sources: milliseconds per call, and the margins code asks for every measurement)


def fmu_file(config: TuningConfig):
    """resolve_fmu(config.fmu, config.fmi_version), remembered for the process while the file exists (a rebuilt
    bundled FMU keeps its path; its size and time tell a changed file)."""
    key = (config.fmu, config.fmi_version)
    path = _FMU_FILES.get(key)
    if path is None or not path.is_file():
        path = _FMU_FILES[key] = resolve_fmu(config.fmu, config.fmi_version)
    return path


def multisine(bins: Sequence[int], period: int, amplitude: float, iterations: int = 20) -> np.ndarray:
    """One period (shape (period,)) of a sum of cosines at DFT bins `bins` (1 <= bin <= period/2).

    Equal amplitudes, Schroeder phases, then a few clip-and-restore iterations to lower the crest
    factor; scaled so that max |d| = amplitude. A Nyquist bin keeps a real (0 or pi) phase.
    """
    bins = np.asarray(bins, dtype=int)
    K = len(bins)
    k = np.arange(1, K + 1)
    spectrum = np.zeros(period // 2 + 1, complex)
    spectrum[bins] = np.exp(-1j * np.pi * k * (k - 1) / K)
    nyquist = period % 2 == 0 and bins[-1] == period // 2
    if nyquist:
        spectrum[period // 2] = 1.0
    x = np.fft.irfft(spectrum, n=period)
    for _ in range(iterations):
        peak = np.max(np.abs(x))
        X = np.fft.rfft(np.clip(x, -0.8 * peak, 0.8 * peak))
        spectrum[bins] = np.exp(1j * np.angle(X[bins]))
        if nyquist:
            spectrum[period // 2] = 1.0 if X[period // 2].real >= 0 else -1.0
        x = np.fft.irfft(spectrum, n=period)
    return x * (amplitude / np.max(np.abs(x)))


@dataclass(frozen=True, eq=False)
class Settling:
    """How the closed loop reached the operating point.

    steps: samples run from t = 0; settled: still within SETTLE_TOLERANCE over SETTLE_WINDOW samples;
    diverged: left the divergence bound, non-finite, or the FMU rejected a step; saturated: a control
    signal sits at a limit at the end; measurement, control_signal (n_loops,): the final values.
    """

    steps: int
    settled: bool
    diverged: bool
    saturated: bool
    measurement: np.ndarray
    control_signal: np.ndarray


@dataclass(frozen=True, eq=False)
class PlantResponse:
    """Estimated effective plant response of one loop at the excited frequencies.

    frequencies_rad_s (K,), response (K,) complex P(e^{j w Ts}); period: samples per multisine period;
    periods: measured periods; change: max |L_p - L_{p-1}| / |1 + L_p| between the last two;
    distortion: RMS |Y| per non-excited bin / RMS |Y| per excited bin (0 for a linear plant in steady
    state; nonlinearity, time variation and leftover transients raise it); amplitude: multisine peak
    [u units] finally used; saturated / diverged: a control signal hit a limit / the loop diverged.
    """

    frequencies_rad_s: np.ndarray
    response: np.ndarray
    period: int
    periods: int
    change: float
    distortion: float
    amplitude: float
    saturated: bool
    diverged: bool
    changes: tuple = ()  # the change between each pair of consecutive periods, in order
    own_response: np.ndarray | None = None  # (K,) Y_i / U_i, the loop's own measurement (None: equal to response)
    levels: tuple = ()  # std of the loop's measurement over each measured period [plant units], in order

    @property
    def decaying(self) -> bool:
        """The changes between periods fall, period after period, to at most DECAY_RATIO x the first (3 changes
        or more): a transient dying out, as in a lightly damped linear loop; a time-varying plant's go up and down."""
        c = self.changes
        return len(c) >= 3 and all(b <= a for a, b in zip(c, c[1:])) and c[-1] <= DECAY_RATIO * c[0]

    @property
    def growth(self) -> float | None:
        """How many times more the measurement swung over the last third of the measured periods than over the first
        (3 periods or more) when at least GROWTH_RATIO, else None: an oscillation growing (beating, where it is slow),
        as in an unstable loop not yet out of its divergence bound; a time-varying plant's swing stays level."""
        v, k = self.levels, max(1, len(self.levels) // 3)
        if len(v) < 3 or not np.mean(v[:k]) > 0:
            return None
        ratio = float(np.mean(v[-k:]) / np.mean(v[:k]))
        return ratio if ratio >= GROWTH_RATIO else None


class ClosedLoopRig:
    """The scenario's plant FMU in closed loop with its PID (fixed gains) at an operating point.

    Args:
        config: the tuning problem (plant, loops, limits, anti-windup, derivative filter, coupling).
        Kp, Ti, Td: gains per loop (n_loops,); coupling: (6,) for the coupled PID, else None.
        setpoint: the operating point, one setpoint per loop (plant units).
        snapshots: return to the settled state through an FMU state snapshot where the FMU can
            serialize its state; otherwise (or False) by replaying the settling from t = 0.
    """

    def __init__(self, config: TuningConfig, Kp: Sequence[float], Ti: Sequence[float], Td: Sequence[float],
                 setpoint: Sequence[float], coupling: Sequence[float] | None = None, snapshots: bool = True):
        c = config
        n = c.n_loops
        for name, values in (("Kp", Kp), ("Ti", Ti), ("Td", Td), ("operating_point", setpoint)):
            if len(values) != n:
                raise ValueError(f"{name} needs one value per loop ({n}), got {list(values)!r}")
        self.config = c
        self.n_loops = n
        self.Kp, self.Ti, self.Td = [float(v) for v in Kp], [float(v) for v in Ti], [float(v) for v in Td]
        self.setpoint = np.array(setpoint, float)
        self._target = self.setpoint.tolist()
        self.u_min = np.array([l.u_min for l in c.loops], float)
        self.u_max = np.array([l.u_max for l in c.loops], float)
        self.scale = np.array([l.measurement_scale for l in c.loops], float)
        self.bound = np.array([l.divergence_bound for l in c.loops], float)
        if c.coupled:
            if coupling is None or len(coupling) != 6:
                raise ValueError(f"the coupled PID needs 6 coupling coefficients, got {coupling!r}")
            self.coupling = [float(v) for v in coupling]
            self.coupling_matrix = coupling_matrix(self.coupling)
        else:
            self.coupling = None
            self.coupling_matrix = np.zeros((n, n))
        self.pid = make_pid(c)
        path = fmu_file(c)
        self.plant = FmuPlant(path, [l.input for l in c.loops], [l.output for l in c.loops], c.sample_time_s,
                              c.plant_parameters, "margins")
        self._snapshots = snapshots
        self._snapshot = None
        self._settle_steps = 0  # replayed by restore() when the FMU cannot serialize its state
        self.y = self.plant.read_outputs()

    def close(self) -> None:
        self.plant.close()

    def _start(self) -> tuple[np.ndarray, np.ndarray]:
        """Plant and PID at t = 0, started bumplessly (the integral term holds the plant's input start
        values, clipped to the limits, as the env does); returns (y0, u0)."""
        y0 = self.plant.reset()
        self.pid.reset()
        u0 = np.clip(self.plant.get(list(self.plant.inputs)), self.u_min, self.u_max)
        self.pid.preset_output(u0.tolist(), y0.tolist(), list(self.Kp), list(self.Ti))
        return y0, u0

    def _ramp(self, start: list, k: int) -> list:
        """Setpoint while settling (plain floats): a ramp from the initial measurement to the operating point."""
        f = min(1.0, (k + 1) / SETPOINT_RAMP_STEPS)
        target = self._target
        return [start[i] + (target[i] - start[i]) * f for i in range(self.n_loops)]

    def _gains(self) -> tuple:
        """The PID's gain arguments after (setpoint, measurement) for step_values (the coupling too where coupled)."""
        return (self.Kp, self.Ti, self.Td) if self.coupling is None else (self.Kp, self.Ti, self.Td, self.coupling)

    def settle(self) -> Settling:
        """From t = 0, ramp the setpoint to the operating point over SETPOINT_RAMP_STEPS samples and run
        the closed loop until it is still (or MAX_SETTLE_STEPS); remember that state."""
        y0, u = self._start()
        n = self.n_loops
        # PID.step, FmuPlant.step and the divergence bound on plain floats, element by element (this loop runs up to
        # MAX_SETTLE_STEPS times per experiment, where numpy's per-call overhead would dominate)
        start, gains = y0.tolist(), self._gains()
        pid_step, plant_step = self.pid.step_values, self.plant.step_values
        scale, bound = self.scale.tolist(), self.bound.tolist()
        y_tolerance = [SETTLE_TOLERANCE * s for s in scale]
        u_scale = np.where(np.isfinite(self.u_max - self.u_min), self.u_max - self.u_min, 1.0).tolist()
        y = start
        still, u_prev, y_prev = 0, None, y
        diverged = settled = False
        k = 0
        while k < MAX_SETTLE_STEPS:
            r = self._ramp(start, k)
            u = pid_step(r, y, *gains)
            try:
                y = plant_step(u)
            except StepRejected:
                diverged = True
                break
            k += 1
            if not all(math.isfinite(y[i]) and abs(y[i] - r[i]) / scale[i] <= bound[i] for i in range(n)):
                diverged = True
                break
            # max(a, |u|) is a where |u| is NaN (np.maximum: NaN), but then |u - u_prev| is NaN and the test fails alike
            if k > SETPOINT_RAMP_STEPS and all(abs(y[i] - y_prev[i]) <= y_tolerance[i] for i in range(n)) and \
                    all(abs(u[i] - u_prev[i]) <= SETTLE_TOLERANCE * max(u_scale[i], abs(u[i])) for i in range(n)):
                still += 1
                if still >= SETTLE_WINDOW:
                    settled = True
                    break
            else:
                still = 0
            u_prev, y_prev = u, y
        y, u = np.array(y, float), np.array(u, float)
        self._settle_steps = k
        self.y = y
        saturated = bool(np.any((u <= self.u_min) | (u >= self.u_max)))
        if not diverged and self._snapshots and self.plant.description.can_serialize_state:
            self._snapshot = (self.plant.get_state(), self.pid.get_state(), y.copy())
        return Settling(k, settled, diverged, saturated, y.copy(), u)

    def restore(self) -> None:
        """Back to the settled state (state snapshot, or a deterministic replay from t = 0)."""
        if self._snapshot is not None:
            state, pid_state, y = self._snapshot
            self.plant.set_state(state)
            self.pid.set_state(pid_state)
            self.y = y.copy()
            return
        y0, _ = self._start()
        start, gains = y0.tolist(), self._gains()
        y = start
        for k in range(self._settle_steps):  # settle's arithmetic, on plain floats
            y = self.plant.step_values(self.pid.step_values(self._ramp(start, k), y, *gains))
        self.y = np.array(y, float)

    def simulate(self, loop: int, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool, bool]:
        """Continue the closed loop for len(d) samples with d added to loop `loop`'s control signal.

        Returns (u, y, saturated, diverged): u (n_loops, len(d)) the applied control signals and
        y (n_loops, len(d)) the measurements they were computed from (u_k from y_k); saturated: some
        u reached a limit (then it is clipped there); diverged: the loop left the divergence bound.
        """
        n = self.n_loops
        us, ys = [], []
        lo, hi = self.u_min.tolist(), self.u_max.tolist()
        r, scale, bound = self.setpoint.tolist(), self.scale.tolist(), self.bound.tolist()
        Kp, Ti, Td = [float(x) for x in self.Kp], [float(x) for x in self.Ti], [float(x) for x in self.Td]
        coupling = None if self.coupling is None else [float(x) for x in self.coupling]
        pid, plant = self.pid, self.plant
        y = [float(x) for x in self.y]
        saturated = diverged = False
        # the same arithmetic as PID.step / FmuPlant.step, on plain floats (this loop runs ~1e5 times)
        for dk in (d.tolist() if hasattr(d, "tolist") else list(d)):
            if coupling is not None:
                u = pid.step_values(r, y, Kp, Ti, Td, coupling)
            else:
                u = pid.step_values(r, y, Kp, Ti, Td)
            u[loop] += dk
            for i in range(n):
                if not lo[i] < u[i] < hi[i]:
                    saturated = True
                    u[i] = min(max(u[i], lo[i]), hi[i])
            us.append(u)
            ys.append(y)
            try:
                y = plant.step_values(u)
            except StepRejected:
                diverged = True
                break
            if not all(abs(y[i] - r[i]) <= bound[i] * scale[i] for i in range(n)):  # NaN fails too
                diverged = True
                break
        k = len(us)
        us, ys = np.array(us, float).reshape(k, n), np.array(ys, float).reshape(k, n)
        self.y = np.array(y, float)
        return us.T, ys.T, saturated, diverged


def default_amplitude(config: TuningConfig, Kp: Sequence[float]) -> list[float]:
    """Multisine peak per loop [u units]: AMPLITUDE_FRACTION of the u range, or of |Kp| * measurement_scale
    where the range is unbounded (the u a proportional action gives for that fraction of the scale)."""
    out = []
    for loop, kp in zip(config.loops, Kp):
        span = loop.u_max - loop.u_min
        out.append(AMPLITUDE_FRACTION * (span if math.isfinite(span) else abs(kp) * loop.measurement_scale))
    return out


def measure_response(rig: ClosedLoopRig, loop: int, bins: Sequence[int], period: int, amplitude: float,
                     controller: Callable[[np.ndarray], np.ndarray], wait: int) -> PlantResponse:
    """Effective plant response of loop `loop` at DFT bins `bins` of a `period`-sample multisine.

    Starts from the settled state (rig.restore()), waits `wait` samples (at least MIN_WAIT, at most one
    period), then measures whole periods until the loop transfer L = C * P changes by at most
    CONVERGENCE_TOLERANCE * |1 + L| between consecutive periods (MAX_PERIODS at most, more when short).
    When a control signal hits a limit or the loop diverges, the attempt ends there, the amplitude is halved and
    the experiment repeated (AMPLITUDE_RETRIES times; the last attempt runs to the end, flagged).
    `controller(w)` gives the loop's PID response C(e^{j w Ts}) at w [rad/s].
    """
    bins = np.unique(np.asarray(bins, dtype=int))
    Ts = rig.config.sample_time_s
    omega = 2 * np.pi * bins / (period * Ts)
    C = controller(omega)
    coupling_row = rig.coupling_matrix[loop]
    excited = np.zeros(period // 2 + 1, bool)
    excited[bins] = True
    excited[0] = False
    others = ~excited
    others[0] = False
    wait = int(min(period, max(MIN_WAIT, wait)))
    for attempt in range(AMPLITUDE_RETRIES + 1):
        rig.restore()
        d = multisine(bins, period, amplitude)
        last = attempt == AMPLITUDE_RETRIES
        _, _, saturated, diverged = rig.simulate(loop, d[:wait])
        estimates, own, change, changes, periods, distortion, levels = [], [], math.inf, [], 0, math.nan, []
        start = wait
        while not diverged and (last or not saturated):  # a saturated attempt before the last is repeated anyway
            uu, yy, sat, diverged = rig.simulate(loop, np.roll(d, -(start % period)))
            saturated |= sat
            if diverged or (saturated and not last):
                break
            U = np.fft.rfft(uu[loop])
            Y = np.fft.rfft(yy, axis=1)
            Y_eff = Y[loop] - coupling_row @ Y
            estimates.append(Y_eff[bins] / U[bins])
            levels.append(float(np.std(yy[loop])))
            own.append(Y[loop][bins] / U[bins])
            periods += 1
            start += period
            excited_rms = np.sqrt(np.mean(np.abs(Y_eff[excited]) ** 2))
            distortion = float(np.sqrt(np.mean(np.abs(Y_eff[others]) ** 2)) / excited_rms) if others.any() else 0.0
            if len(estimates) >= 2:
                L1, L0 = C * estimates[-1], C * estimates[-2]
                change = float(np.max(np.abs(L1 - L0) / np.abs(1 + L1)))
                changes.append(change)
                if change <= CONVERGENCE_TOLERANCE or periods >= MAX_PERIODS * max(1, PERIODS_OF // period):
                    break
        if not (saturated or diverged) or last:
            break
        amplitude /= 2  # a saturated unstable plant can escape: smaller is the cure for both
    response = estimates[-1] if estimates else np.full(len(bins), np.nan + 0j)
    own_response = own[-1] if own else np.full(len(bins), np.nan + 0j)
    if period % 2 == 0 and bins[-1] == period // 2:
        response[-1] = response[-1].real  # exactly real at Nyquist for a real system
        own_response[-1] = own_response[-1].real
    return PlantResponse(omega, response, period, periods, change, distortion, amplitude, saturated, diverged,
                         tuple(changes), own_response, tuple(levels))
