"""Robustness margins of a deployable PID, measured on the FMU at an operating point.

``loop_margins`` estimates the plant's frequency response on the FMU with the loop closed by the PID
(prlpid_fmi.robustness.identification: a small multisine at the plant input), forms the loop transfer
L = C * P at the sample time Ts with C the discrete PID of eq. 2 exactly as prlpid_fmi/control/pid.py
computes it, and reads through python-control (``frd``, ``stability_margins``):

- Ms = max |1 / (1 + L)| over the frequency grid (and between grid points by python-control's
  interpolation), the peak sensitivity; 1/Ms is the smallest distance from L to -1.
- gain margin (ratio and dB) at the phase crossover, phase margin (deg) at the gain crossover. With
  several crossings python-control keeps the gain margin closest to 1 (0 dB) and the smallest phase
  margin. A gain margin below 1 (negative dB) is a *lower* margin: an open-loop unstable plant loses
  stability when the gain drops by that factor.

The PID's transfer function (positional form, e = r - y)::

    u_k = Kp * (e_k + (Ts/Ti) * sum_{i<=k} e_i + Td * Df_k),  Df = backward-Euler low pass (Td/N) of (e_k - e_{k-1})/Ts
    C(z) = Kp * (1 + (Ts/Ti) * z/(z - 1) + Td * (z - 1) / ((Tdf + Ts) z - Tdf)),   Tdf = Td/N (0 without a filter)

Frequency grid: the DFT bins of a multisine period of N samples, log-spaced from 2 pi/(N Ts) up to
the Nyquist frequency pi/Ts, then every bin of that period around the |S| peak and the crossovers.
N starts at the loop's settling time at the operating point (a power of 2 from SHORTEST_PERIOD to
DEFAULT_PERIOD: a slow loop's transient contaminates a short period's estimate) and grows (up to
MAX_PERIOD) while a point of interest lies below bin MIN_RESOLUTION_BIN, so the grid is fine enough near
the peak for Ms to 1 %, or, below DEFAULT_PERIOD, while |L| < CROSSING_RANGE at the lowest frequency.

Several loops: loop-at-a-time margins. Each loop is broken at its plant input in turn with the other
loops closed; the returned Margins is the loop with the largest Ms, and ``per_loop`` holds every
loop's own Margins.
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from typing import Sequence

import control
import numpy as np

from prlpid_fmi import runcontext
from prlpid_fmi.config import LoopConfig, TuningConfig
from prlpid_fmi.loop.core import pid_structure
from prlpid_fmi.loop.gains import GainValues
from prlpid_fmi.robustness.plant_response import MeasuredPlant
from prlpid_fmi.robustness.identification import (
    CONVERGENCE_TOLERANCE,
    ClosedLoopRig,
    PlantResponse,
    default_amplitude,
    fmu_file,
    measure_response,
)

SHORTEST_PERIOD = 1024       # samples per multisine period at least (lowest frequency 2 pi/(N Ts))
DEFAULT_PERIOD = 4096        # and at least this while the loop settles slower or |L| < CROSSING_RANGE at the lowest
MAX_PERIOD = 32768           # longest period the grid refinement may choose
GRID_POINTS = 120            # log-spaced bins of the first multisine (fewer after rounding to distinct bins)
MIN_RESOLUTION_BIN = 32      # a peak or crossover below this bin gets a longer period (finer grid)
REFINE_POINTS = 24           # bins added around each peak or crossover, at most
CROSSING_RANGE = 20.0        # phase crossings with 1/20 < |L| < 20 count as points of interest
DC_PEAK_GAP = 0.003          # an |S| peak at the lowest grid point may sit this far (relative) below |S(0)|
DISTORTION_LIMIT = 0.02      # relative response at non-excited bins above which the estimate is flagged


def pid_transfer_function(Kp: float, Ti: float, Td: float, sample_time_s: float,
                          derivative_filter_N: float | None = None, measurement_filter_s: float = 0.0,
                          measurement_filter_order: int = 1) -> control.TransferFunction:
    """C(z), the feedback part of the PID of control.pid (u = -C y + setpoint terms), dt = sample_time_s::

        C(z) = Kp * (F(z) + (Ts/Ti) z/(z - 1) + Td (z - 1)/((Tdf + Ts) z - Tdf) F(z)),   Tdf = Td/N (0 without)
        F(z) = (Ts z / ((T + Ts) z - T))^order,   T = Tf / order (F = 1 when Tf = 0)

    the measurement filter F acting on P and D, not on the integral. The setpoint weights b, c do not enter
    (they act on the setpoint only), so Ms, the margins and the load response do not depend on them.
    Ti = inf drops the integral term, Td = 0 the derivative term.
    """
    Ts = float(sample_time_s)
    F = (np.array([1.0]), np.array([1.0]))
    if measurement_filter_s > 0:
        T = measurement_filter_s / measurement_filter_order
        for _ in range(measurement_filter_order):
            F = (np.polymul(F[0], [Ts, 0.0]), np.polymul(F[1], [T + Ts, -T]))
    terms = [F]
    if math.isfinite(Ti):
        terms.append((np.array([Ts / Ti, 0.0]), np.array([1.0, -1.0])))
    if Td != 0:
        Tdf = Td / derivative_filter_N if derivative_filter_N else 0.0  # the derivative filter; Tf is the measurement's
        terms.append((np.polymul([Td, -Td], F[0]), np.polymul([Tdf + Ts, -Tdf], F[1])))
    num, den = np.array([0.0]), np.array([1.0])
    for n, d in terms:
        num, den = np.polyadd(np.polymul(num, d), np.polymul(n, den)), np.polymul(den, d)
    return control.tf(Kp * num, den, Ts)


def pid_frequency_response(Kp: float, Ti: float, Td: float, sample_time_s: float, omega,
                           derivative_filter_N: float | None = None, measurement_filter_s: float = 0.0,
                           measurement_filter_order: int = 1) -> np.ndarray:
    """C(e^{j w Ts}) at w = omega [rad/s], complex array of omega's shape (exactly real at Nyquist, w = pi/Ts):
    the terms of `pid_transfer_function` evaluated at z directly (the search calls this for every candidate)."""
    Ts = float(sample_time_s)
    wT = np.asarray(omega, float) * Ts
    z = np.where(np.abs(wT - np.pi) <= 1e-12 * np.pi, -1.0 + 0j, np.exp(1j * wT))  # np.isclose's test, 10x cheaper
    F = np.ones_like(z)
    if measurement_filter_s > 0:
        T = measurement_filter_s / measurement_filter_order
        F = (Ts * z / ((T + Ts) * z - T)) ** measurement_filter_order
    C = F.copy()
    if math.isfinite(Ti):
        C = C + (Ts / Ti) * z / (z - 1)
    if Td != 0:
        Tdf = Td / derivative_filter_N if derivative_filter_N else 0.0
        C = C + Td * (z - 1) / ((Tdf + Ts) * z - Tdf) * F
    return Kp * C


@dataclass(frozen=True, eq=False)
class Margins:
    """Robustness margins of one loop (or the worst loop) at one operating point.

    Ms: peak sensitivity max |1/(1 + L)| (inf: the loop cannot be held at the operating point);
    Ms_frequency_rad_s: where it peaks. gain_margin: ratio (inf: no phase crossover; < 1: a lower
    margin) at phase_crossover_rad_s; phase_margin_deg at gain_crossover_rad_s (inf: no gain crossover).
    frequencies_rad_s (K,): the grid; plant_response (K,) complex: the estimated P(e^{j w Ts}) (with
    several loops, the effective plant the loop's PID sees with the other loops closed);
    controller_response (K,): C(e^{j w Ts}). amplitude: multisine peak [u units] used.
    reliable: False when the estimate or the margins should not be trusted, with the reason in note and
    its kinds in problems (PROBLEM_KINDS). loop: the loop's measured output name; per_loop: every loop's
    Margins (several loops only); own_response (K,): the loop's own measurement over its plant input, y_i / u_i
    with the other loops closed (None: equal to plant_response, as without coupling).
    """

    Ms: float
    Ms_frequency_rad_s: float
    gain_margin: float
    phase_crossover_rad_s: float
    phase_margin_deg: float
    gain_crossover_rad_s: float
    frequencies_rad_s: np.ndarray
    plant_response: np.ndarray
    controller_response: np.ndarray
    amplitude: float
    reliable: bool
    note: str
    loop: str
    per_loop: tuple = ()
    problems: tuple = ()  # kinds of the flags behind reliable = False: PROBLEM_KINDS
    own_response: np.ndarray | None = None

    @property
    def gain_margin_db(self) -> float:
        """20 log10(gain_margin) [dB]; NaN when there is no margin to speak of (Ms = inf)."""
        if math.isnan(self.gain_margin):
            return math.nan
        return 20 * math.log10(self.gain_margin) if self.gain_margin > 0 else -math.inf

    @property
    def Mt(self) -> float:
        """Peak complementary sensitivity max |L / (1 + L)| over the grid (inf when Ms is)."""
        if not math.isfinite(self.Ms) or len(self.frequencies_rad_s) == 0:
            return math.inf
        L = self.loop_response
        return float(np.max(np.abs(L / (1 + L))))

    @property
    def delay_margin_s(self) -> float:
        """The extra loop delay [s] that the loop tolerates: phase margin [rad] / gain crossover [rad/s]; inf
        without a gain crossover, 0 for a non-positive phase margin, NaN when there are no margins (Ms inf)."""
        if not math.isfinite(self.Ms):
            return math.nan
        if not math.isfinite(self.phase_margin_deg) or not self.gain_crossover_rad_s > 0:
            return math.inf
        return max(0.0, math.radians(self.phase_margin_deg) / self.gain_crossover_rad_s)

    @property
    def loop_response(self) -> np.ndarray:
        """L = C * P at frequencies_rad_s."""
        return self.controller_response * self.plant_response

    @property
    def sensitivity(self) -> np.ndarray:
        """S = 1 / (1 + L) at frequencies_rad_s."""
        return 1 / (1 + self.loop_response)


def margins_from_loop_response(omega: np.ndarray, L: np.ndarray, finite_dc_gain: bool = False
                               ) -> tuple[float, float, float, float, float, float]:
    """(Ms, w_Ms, gain margin, w_pc, phase margin [deg], w_gc) of a loop response L at omega [rad/s].

    Ms is the larger of the grid maximum of |1/(1+L)| and python-control's interpolated stability
    margin 1/sm (which only finds interior minima of |1 + L|). Of several crossings, the gain margin
    closest to 1 and the smallest |phase margin| are kept (python-control's rule). finite_dc_gain:
    L has no pole at z = 1 (no integral action and a plant with a finite DC gain), so its DC value,
    extrapolated from the two lowest grid points, is a phase crossover when it is negative.
    """
    S = np.abs(1 / (1 + L))
    i = int(np.argmax(S))
    Ms, w_ms = float(S[i]), float(omega[i])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gm, pm, sm, wpc, wgc, wms = control.stability_margins(control.frd(L, omega), returnall=True)
    gm, wpc = list(np.atleast_1d(gm)), list(np.atleast_1d(wpc))
    if finite_dc_gain and len(L) > 1:
        L_dc = L[0].real - (L[1].real - L[0].real) * omega[0] ** 2 / (omega[1] ** 2 - omega[0] ** 2)
        if L_dc < 0:
            gm.append(1 / abs(L_dc))
            wpc.append(0.0)
    if len(sm) and np.min(sm) > 0 and 1 / np.min(sm) > Ms:
        Ms, w_ms = 1 / float(np.min(sm)), float(np.asarray(wms)[np.argmin(sm)])
    g = int(np.argmin(np.abs(np.log(gm)))) if gm else 0
    p = int(np.argmin(np.abs(pm))) if len(pm) else 0
    return (Ms, w_ms, float(gm[g]) if gm else math.inf, float(wpc[g]) if gm else math.nan,
            float(pm[p]) if len(pm) else math.inf, float(np.asarray(wgc)[p]) if len(pm) else math.nan)


def _log_bins(period: int, points: int) -> np.ndarray:
    """Distinct integer bins, log-spaced from 1 to period/2 (Nyquist included)."""
    return np.unique(np.round(np.geomspace(1, period // 2, points)).astype(int))


def _bins_for(frequencies, period: int, Ts: float) -> np.ndarray:
    bins = np.round(np.asarray(frequencies, float) * period * Ts / (2 * np.pi)).astype(int)
    return np.unique(np.clip(bins, 1, period // 2))


def _points_of_interest(L: np.ndarray) -> list[int]:
    """Indices of the |S| peak and of the grid intervals where |L| crosses 1 or L crosses the negative real axis."""
    points = {int(np.argmax(np.abs(1 / (1 + L))))}
    mag = np.abs(L)
    for i in range(len(L) - 1):
        if (mag[i] - 1) * (mag[i + 1] - 1) <= 0:
            points.update((i, i + 1))
        if L[i].imag * L[i + 1].imag <= 0 and min(L[i].real, L[i + 1].real) < 0 and \
                1 / CROSSING_RANGE < mag[i] < CROSSING_RANGE:
            points.update((i, i + 1))
    return sorted(points)


def _period_factor(omega: np.ndarray, bins: np.ndarray, L: np.ndarray, points: list[int], period: int) -> int:
    """How many times longer the multisine period must be for a fine enough grid at the points of interest.

    A point below bin MIN_RESOLUTION_BIN needs that bin. An |S| peak at the lowest grid point (a peak
    at DC, e.g. P control of an unstable plant) needs |S| flat there: |S| is even in w, so
    |S(0)| - |S(w0)| ~ (|S(w0)| - |S(w1)|) w0^2 / (w1^2 - w0^2), which must be below DC_PEAK_GAP * |S(w0)|.
    A period shorter than DEFAULT_PERIOD grows to it while |L| < CROSSING_RANGE at the lowest frequency: the loop
    gain has not risen to where |S| is small and no crossing is left below, so the grid must reach lower.
    """
    S = np.abs(1 / (1 + L))
    factor = 1
    if period < DEFAULT_PERIOD and abs(L[0]) < CROSSING_RANGE:
        factor = DEFAULT_PERIOD // period
    for j in points:
        if j == 0 and int(np.argmax(S)) == 0 and len(S) > 1:
            gap = (S[0] - S[1]) / S[0] * omega[0] ** 2 / (omega[1] ** 2 - omega[0] ** 2)
            if gap > DC_PEAK_GAP:
                factor = max(factor, 2 ** math.ceil(0.5 * math.log2(gap / DC_PEAK_GAP)))
        elif bins[j] < MIN_RESOLUTION_BIN:
            factor = max(factor, 2 ** math.ceil(math.log2(MIN_RESOLUTION_BIN / bins[j])))
    return factor


def _refinement_bins(bins: np.ndarray, points: list[int]) -> np.ndarray:
    """Bins strictly between the grid neighbours of each point of interest (REFINE_POINTS per point at most)."""
    extra = set()
    for j in points:
        lo, hi = bins[max(j - 1, 0)], bins[min(j + 1, len(bins) - 1)]
        inside = np.arange(lo + 1, hi)
        if len(inside) > REFINE_POINTS:
            inside = np.unique(np.round(np.geomspace(lo + 1, hi - 1, REFINE_POINTS)).astype(int))
        extra.update(int(b) for b in inside)
    return np.array(sorted(extra - set(int(b) for b in bins)), dtype=int)


def _no_margins(loop: str, amplitude: float, note: str) -> Margins:
    empty = np.zeros(0)
    return Margins(math.inf, math.nan, math.nan, math.nan, math.nan, math.nan, empty, empty.astype(complex),
                   empty.astype(complex), amplitude, False, note, loop)


def _controller(rig: ClosedLoopRig, loop: int):
    """w [rad/s] -> C(e^{j w Ts}) of loop `loop`'s PID as the rig runs it (feedback part, filter included)."""
    c = rig.config
    tf = pid_structure(c)[2][loop]
    return lambda w: pid_frequency_response(rig.Kp[loop], rig.Ti[loop], rig.Td[loop], c.sample_time_s, w,
                                            c.derivative_filter_N, tf, c.measurement_filter_order)


def _measure_loop(rig: ClosedLoopRig, loop: int, frequencies, amplitude: float, wait: int) -> list[PlantResponse]:
    """The multisine experiments of one loop: a log grid (period grown while too coarse), then refinement.

    wait: samples to let the transient of a new multisine die out (the settling time is a fair guess).
    """
    Ts = rig.config.sample_time_s
    controller = _controller(rig, loop)
    if frequencies is None:  # a period the loop's settling time fits in (its transients die out within one)
        period = int(2 ** math.ceil(math.log2(min(max(wait, SHORTEST_PERIOD), DEFAULT_PERIOD))))
    else:
        w_min = float(np.min(frequencies))
        if not 0 < w_min or np.max(frequencies) > np.pi / Ts * (1 + 1e-9):
            raise ValueError(f"frequencies must lie in (0, pi/Ts = {np.pi / Ts:g}] rad/s, got {frequencies!r}")
        period = int(2 ** math.ceil(math.log2(max(2 * np.pi * MIN_RESOLUTION_BIN / (w_min * Ts), 16))))
    bins = _log_bins(period, GRID_POINTS) if frequencies is None else _bins_for(frequencies, period, Ts)
    responses = [measure_response(rig, loop, bins, period, amplitude, controller, wait)]
    grown = False
    while not responses[-1].diverged and not _problems(responses):  # refining cannot make a flagged estimate good
        omega, P = _merged(responses)
        L = controller(omega) * P
        points = _points_of_interest(L)
        grid = np.round(omega * period * Ts / (2 * np.pi)).astype(int)
        factor = 1 if frequencies is not None else _period_factor(omega, grid, L, points, period)
        if grown and factor == 1:
            break  # the longer period's experiment refined around the points of interest already
        grown = min(MAX_PERIOD, period * factor) > period
        if grown:  # every measured frequency is also a bin of the longer period
            period = min(MAX_PERIOD, period * factor)
            grid = np.round(omega * period * Ts / (2 * np.pi)).astype(int)
        extra = _refinement_bins(grid, points)
        if grown:
            extra = np.union1d(extra, [b for b in _log_bins(period, GRID_POINTS) if b < grid[0]])
        if len(extra) == 0:
            break
        responses.append(measure_response(rig, loop, extra, period, responses[-1].amplitude, controller, wait))
        if not grown:
            break
    return responses


def _merged(responses: list[PlantResponse], own: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """All measured (frequencies [rad/s], responses), sorted by frequency; own: the loop's own measurement's
    responses (PlantResponse.own_response) instead."""
    omega = np.concatenate([r.frequencies_rad_s for r in responses])
    P = np.concatenate([r.own_response if own and r.own_response is not None else r.response for r in responses])
    order = np.argsort(omega)
    return omega[order], P[order]


def _loop_result(rig: ClosedLoopRig, loop: int, responses: list[PlantResponse]) -> Margins:
    name = rig.config.loops[loop].output
    amplitude = min(r.amplitude for r in responses)
    if any(r.diverged for r in responses):
        return _no_margins(name, amplitude, "the closed loop diverged during the frequency-response experiment "
                                            f"(multisine peak {amplitude:.3g})")
    omega, P = _merged(responses)
    C = _controller(rig, loop)(omega)
    L = C * P
    # no integral action and |L| flat at the lowest frequencies: a finite DC loop gain
    no_integrator = not math.isfinite(rig.Ti[loop]) and len(L) > 1 and abs(abs(L[1]) / abs(L[0]) - 1) < 0.1
    Ms, w_ms, gm, wpc, pm, wgc = margins_from_loop_response(omega, L, finite_dc_gain=no_integrator)
    problems = _problems(responses)
    own = _merged(responses, own=True)[1] if rig.coupling is not None else None
    return Margins(Ms, w_ms, gm, wpc, pm, wgc, omega, P, C, amplitude, not problems,
                   "; ".join(text for _, text in problems), name, problems=tuple(kind for kind, _ in problems),
                   own_response=own)


PROBLEM_KINDS = ("saturated", "lightly_damped", "growing", "varying", "distorted", "not_settled")  # Margins.problems


def _problems(responses: list[PlantResponse]) -> list[tuple[str, str]]:
    """Why estimates from these experiments cannot be trusted, as (kind, sentence) (empty: reliable). Each test is
    on the worst experiment, so a flag raised by one experiment stays whatever further experiments measure."""
    problems = []
    if any(r.saturated for r in responses):
        amplitude = min(r.amplitude for r in responses)
        problems.append(("saturated", f"the control signal reached a limit even with a multisine peak of "
                                      f"{amplitude:.3g}"))
    worst = max(responses, key=lambda r: r.change)
    if worst.change > 10 * CONVERGENCE_TOLERANCE:
        growing = next((r for r in responses if r.growth is not None), None)
        if worst.decaying:
            problems.append(("lightly_damped", f"the response did not reach a periodic steady state (change "
                                               f"{worst.change:.2g} between periods, falling: a loop too lightly "
                                               "damped to settle)"))
        elif growing is not None:
            problems.append(("growing", f"the response did not reach a periodic steady state: the measurement swung "
                                        f"{growing.growth:.3g}x more over the last third of {len(growing.levels)} "
                                        "periods than over the first (an oscillation growing: the loop is unstable "
                                        "at this operating point)"))
        else:
            problems.append(("varying", f"the response did not reach a periodic steady state (change "
                                        f"{worst.change:.2g} between periods, not falling: a time-varying plant)"))
    distortion = max(r.distortion for r in responses)
    if distortion > DISTORTION_LIMIT:
        problems.append(("distorted", f"the plant does not respond linearly around this operating point "
                                      f"(distortion {distortion:.1%}: nonlinear or time-varying)"))
    return problems


def loop_margins(config: TuningConfig, Kp: Sequence[float], Ti: Sequence[float], Td: Sequence[float],
                 operating_point: Sequence[float], coupling: Sequence[float] | None = None,
                 frequencies: Sequence[float] | None = None,
                 amplitude: Sequence[float] | None = None) -> Margins:
    """Robustness margins of the PID (Kp, Ti, Td per loop [, coupling (6,)]) on config's FMU plant.

    operating_point: one setpoint per loop (plant units); the closed loop settles there before the
    experiment. frequencies: grid [rad/s] in (0, pi/Ts] (rounded to DFT bins; refined around the peak
    and the crossovers), None for the automatic grid. amplitude: multisine peak per loop [u units]
    (halved while the control signal hits a limit), None for identification.default_amplitude.
    Several loops: loop-at-a-time, the loop with the largest Ms is returned (per_loop: all loops).
    """
    c = config
    n = c.n_loops
    amplitudes = list(default_amplitude(c, Kp) if amplitude is None else amplitude)
    if len(amplitudes) != n or not all(a > 0 for a in amplitudes):
        raise ValueError(f"amplitude needs one positive value per loop ({n}), got {amplitude!r}")
    # in a worker process when the FMU runs isolated (a crash: no margins, not a dead tool) or may be
    # instantiated only once per process (the caller may hold an instance, e.g. the fixed-PID search)
    from prlpid_fmi.fmu import describe_fmu

    path = fmu_file(c)
    from prlpid_fmi.fmu.worker import WorkerCrashed, call_in_worker, in_worker

    from prlpid_fmi.loop.isolated import runs_isolated

    if not in_worker() and (runs_isolated(c) or describe_fmu(path).once_per_process):
        try:
            return call_in_worker(loop_margins, dataclasses.replace(c, isolation="none", fmu=str(path)), Kp, Ti, Td,
                                  operating_point, coupling, frequencies, amplitude, fmus=[path],
                                  what="the robustness margins' measurement")
        except WorkerCrashed as exc:
            return _no_margins(c.loops[0].output, amplitudes[0], str(exc))
    rig = ClosedLoopRig(c, Kp, Ti, Td, operating_point, coupling)
    try:
        settling = rig.settle()
        results = []
        for i in range(n):
            name = c.loops[i].output
            if settling.diverged:
                results.append(_no_margins(name, amplitudes[i], "the closed loop diverges at this operating point"))
            elif settling.saturated:
                results.append(_no_margins(name, amplitudes[i], "the control signal is at a limit at this operating "
                                           f"point (u = {np.array2string(settling.control_signal, precision=4)})"))
            else:
                responses = _measure_loop(rig, i, frequencies, amplitudes[i], settling.steps)
                results.append(_loop_result(rig, i, responses))
    finally:
        rig.close()
    if not settling.settled and not settling.diverged:
        results = [dataclasses.replace(m, reliable=False, problems=m.problems + ("not_settled",), note="; ".join(filter(None, [
            m.note, f"the loop had not settled at the operating point after {settling.steps} samples"])))
            for m in results]
    if n == 1:
        return results[0]
    worst = max(results, key=lambda m: (m.Ms, -m.phase_margin_deg if math.isfinite(m.phase_margin_deg) else 0))
    notes = [f"{m.loop}: {m.note}" for m in results if m.note]
    return dataclasses.replace(worst, reliable=all(m.reliable for m in results), note="; ".join(notes),
                               per_loop=tuple(results), problems=tuple(dict.fromkeys(k for m in results
                                                                                     for k in m.problems)))


def format_margins(m: Margins) -> str:
    """One line for reports, e.g. "Ms 1.42, Mt 1.21, GM 8.3 dB at 12.1 rad/s, PM 52° at 3.4 rad/s, DM 0.27 s"."""
    if not math.isfinite(m.Ms):
        text = f"Ms inf ({m.note})"
    else:
        gm = "GM inf" if not math.isfinite(m.gain_margin) else \
            f"GM {m.gain_margin_db:.1f} dB at {m.phase_crossover_rad_s:.3g} rad/s"
        pm = "PM inf" if not math.isfinite(m.phase_margin_deg) else \
            f"PM {m.phase_margin_deg:.0f}° at {m.gain_crossover_rad_s:.3g} rad/s"
        dm = "DM inf" if not math.isfinite(m.delay_margin_s) else f"DM {m.delay_margin_s:.3g} s"
        text = f"Ms {m.Ms:.2f}, Mt {m.Mt:.2f}, {gm}, {pm}, {dm}"
        if not m.reliable:
            text += f" (unreliable: {m.note})"
    if m.per_loop:
        text += f" [worst loop: {m.loop}]"
    return text


def operating_point(config: TuningConfig, value: float | None = None) -> list[float]:
    """Setpoints per loop at the middle of their ranges, loop 0's replaced by `value` when given."""
    point = [0.5 * (l.setpoint_range[0] + l.setpoint_range[1]) for l in config.loops]
    if value is not None:
        point[0] = float(value)
    return point


def setpoint_range_points(config: TuningConfig) -> list[list[float]]:
    """The operating points a fixed PID must be robust at: every loop's setpoint at the low end, the middle and
    the high end of its setpoint_range (the loops together; duplicates dropped). A fixed PID is used at every
    setpoint, and a nonlinear plant's margins change over the range."""
    points = []
    for f in (0.0, 0.5, 1.0):
        point = [float(l.setpoint_range[0] + f * (l.setpoint_range[1] - l.setpoint_range[0])) for l in config.loops]
        if point not in points:
            points.append(point)
    return points


def margins_of(config: TuningConfig, gains: GainValues, point: list[float]) -> Margins:
    """Margins of constant gains (Kp, Ti, Td, coupling lists) at an operating point (setpoints per loop).

    The experiment is deterministic (identification: no noise, no disturbances), so each measurement is kept
    in the run's context (prlpid_fmi.runcontext) for the life of the run, keyed by the config, the FMU file's size and time, the gains and the point:
    a table row measured while it is projected onto the Ms limit and again as evidence is measured once. The
    first measurement returned at a config, FMU and point that predicts others (`_predicts`) is also kept as that
    point's plant response, for `predicted_ms` (first returned, not first measured: measurements made ahead on other
    cores, `keep_margins`, then give the same references as measuring them one by one).
    """
    place = _place(config, point)
    found = measured_margins(config, gains, point)
    if found is None:
        found = measure_margins(config, gains, point)
        keep_margins(config, gains, point, found)
    run = runcontext.current()
    if place not in run.references and _predicts(config, found):
        run.keep(run.references, place, (gains, MeasuredPlant(found.frequencies_rad_s, found.plant_response,
                                                              config.sample_time_s, tuple(point), ())))
    return found


def measure_margins(config: TuningConfig, gains: GainValues, point: list[float]) -> Margins:
    """margins_of's experiment itself, not kept (a worker process measuring ahead: tuning.margin_experiments)."""
    Kp, Ti, Td, coupling = gains
    return loop_margins(config, Kp, Ti, Td, point, coupling=coupling)


def measurement_key(config: TuningConfig, gains: GainValues, point) -> tuple:
    """What margins_of keeps a measurement under: the config, the FMU file, the point and the gains."""
    return _place(config, point) + (tuple(None if g is None else tuple(float(v) for v in g) for g in gains),)


def measured_margins(config: TuningConfig, gains: GainValues, point: list[float]) -> Margins | None:
    """What margins_of keeps for these gains and point, None when they were not measured (or no longer kept)."""
    return runcontext.current().measured.get(measurement_key(config, gains, point))


def keep_margins(config: TuningConfig, gains: GainValues, point: list[float], margins: Margins) -> None:
    """Keep a measurement of these gains and point (measure_margins, here or in another process) for margins_of."""
    run = runcontext.current()
    run.keep(run.measured, measurement_key(config, gains, point), margins)


# TuningConfig fields the closed-loop experiment never reads (ClosedLoopRig: the plant, its loops and limits, the
# PID law): the prior, the reward, the training episodes, their noise and disturbances
NOT_IN_EXPERIMENT = ("prior", "prior_mode", "forecast_horizon", "smoothing", "smoothing_window", "smoothing_alpha",
                     "reward", "divergence_penalty", "episode_steps", "setpoint_hold_steps", "setpoint_schedule",
                     "disturbances", "measurement_noise_std", "actuator_noise_std", "randomize", "load_disturbance",
                     "gain_mapping", "anchor_on", "anchor_bands")
_UNREAD = {f.name: f.default if f.default is not dataclasses.MISSING else f.default_factory()
           for f in dataclasses.fields(TuningConfig) if f.name in NOT_IN_EXPERIMENT}  # their defaults
# the controller's fields pid_structure reads only without a tuned_structure (_as_measured sets one), and the
# coupling's gain range: their defaults
_STRUCTURE = {f.name: f.default for f in dataclasses.fields(TuningConfig)
              if f.name in ("setpoint_weight", "derivative_weight", "measurement_filter", "coupling_range")}
_LOOP = LoopConfig(input="u", output="y")  # its setpoint and gain ranges: what _as_measured puts in every loop


def _place(config: TuningConfig, point) -> tuple:
    """What a measurement depends on besides the controller: the config as the experiment reads it (`_as_measured`:
    a search's config without the forecast, or a local design's held at one setpoint, measures what the scenario's
    does), the FMU file (size, time), the point."""
    fmu = fmu_file(config).stat()
    return repr(_as_measured(config)), fmu.st_size, fmu.st_mtime_ns, tuple(float(v) for v in point)


def _as_measured(config: TuningConfig) -> TuningConfig:
    """config with what the closed-loop experiment never reads at fixed values: NOT_IN_EXPERIMENT at their defaults,
    the loops' setpoint ranges and gain ranges and the coupling's range (it runs given gains at a given point), and
    the PID's structure as in force (loop.core.pid_structure: tuned_structure, or the controller's weights and
    filter, "tuned" resolved)."""
    loops = tuple(dataclasses.replace(l, setpoint_range=_LOOP.setpoint_range, Kp=_LOOP.Kp, Ti=_LOOP.Ti, Td=_LOOP.Td)
                  for l in config.loops)
    return dataclasses.replace(config, **_UNREAD, loops=loops, tuned_structure=tuple(zip(*pid_structure(config))),
                               **_STRUCTURE)


def _predicts(config: TuningConfig, m: Margins) -> bool:
    """A measurement that other controllers' Ms can be computed from: one independent loop (with several, the
    effective plant a loop sees depends on the other loops' PIDs), verified, on a finite response."""
    from prlpid_fmi.robustness.status import Robustness, status

    return (config.n_loops == 1 and not config.coupled and len(m.frequencies_rad_s) >= 2
            and bool(np.all(np.isfinite(m.plant_response))) and status(m) == Robustness.VERIFIED)


def predicted_ms(config: TuningConfig, gains: GainValues, point: list[float]) -> float | None:
    """Ms of constant gains at `point` computed, without an experiment, from the plant response measured there
    before (the first verified margins_of measurement of one independent loop at this config, FMU and point); None
    when there is none. The plant is the same whatever PID runs it (its linearisation at the point), so
    Ms = max |1 / (1 + C P)| on robustness.plant_response.MeasuredPlant's interpolated grid, and inf when the
    Nyquist winding of 1 + C P differs from the measured PID's (unstable). An estimate for deciding what to
    measure (tuning.fixed_pid.detune), never a margin to report: on a linear plant it is within 0.1 % of the
    measured Ms, while a nonlinear plant's response can differ with the controller."""
    found = runcontext.current().references.get(_place(config, point))
    Kp, Ti, _, _ = gains
    if found is None or len(Kp) != 1:
        return None
    reference, plant = GainValues(*found[0]), found[1]  # the gains it was measured with
    if math.isfinite(reference.Ti[0]) != math.isfinite(Ti[0]):
        return None  # with and without an integrator the windings differ by the arc at w = 0

    def controller(g):
        tf = pid_structure(config)[2][0]
        Kp, Ti, Td, _ = g
        return lambda w: pid_frequency_response(Kp[0], Ti[0], Td[0], config.sample_time_s, w,
                                                config.derivative_filter_N, tf, config.measurement_filter_order)
    C = controller(gains)
    if abs(plant.winding(C) - plant.winding(controller(reference))) >= 0.5 * math.pi:
        return math.inf
    return plant.sensitivity_peak(C)
