"""A local linear model of the plant at one operating point, identified from its measured frequency response, and
the load response of any PID on it.

The model: a discrete transfer function in q = z^-1 from the plant input u_k to the measurement y_k,

    P(q) = (b_1 q + ... + b_n q^n) / (1 + a_1 q + ... + a_n q^n)      (b_0 = 0: u_k moves y_{k+1} first)

fitted to robustness.plant_response.MeasuredPlant's P(e^{j w Ts}) (the multisine experiment the Ms limits already
use: the ZOH discretisation of the plant, one sample of delay included) by Sanathanan-Koerner iterations: linear
least squares of the relative error |A P_meas - B| / (|A_prev| |P_meas|) over the measured frequencies, each weighted
by its estimate's reliability (MeasuredPlant.reliability: the measuring loop's |S|, full weight from
plant_response.RELIABLE_SENSITIVITY up; a closed-loop estimate where the loop gain is high is a ratio of small
signals), SK_ITERATIONS times. The order is the lowest of 1..MAX_ORDER whose RMS relative error over the measured
frequencies (weighted alike) is at most FIT_TOLERANCE; where none meets it, a dead time of d = 1..MAX_DELAY further
samples is tried (q^d B(q) / A(q): the numerator's leading zeros), lowest order first, then least d; where none fits
either, orders MAX_ORDER + 1 .. HIGH_ORDER without dead time (a high-order lag such as 1/(s + 1)^6; else the best of
them). A ZOH-discretised linear plant of order n is matched exactly at order n, with its delay when that is a whole
number of samples.

A fit with a pole and a zero both slower than the lowest measured octave (|ln z| / Ts below LOWEST_OCTAVE x the
lowest measured frequency) is not taken at its order (`unresolved`): the experiment cannot resolve such a pair, and a
fit adds one to follow the error of its lowest frequencies' estimates (two_tank at 500k, seed 0, before the weights:
poles at z = 1.00001 beside zeros at 1.00001, an unstable model of a stable plant that no PID stabilised, so the design
fell back to simulating the FMU).

The load response (`load_responses`): the loop held at the point, a step d at the plant input, the PID's
feedback law (control.pid: measurement filter F, integral of the unfiltered error, backward-difference derivative
with its filter Td/N on the filtered measurement; setpoint weights do not enter at a constant setpoint; output limits
and anti-windup ignored) in closed loop with P:

    dy/d = B Dc / (A Dc + B Nc),   du_pid/d = -B Nc / (A Dc + B Nc),   C = Nc / Dc (`feedback_polynomials`)

simulated with scipy.signal.lfilter per candidate. The setpoint response (`setpoint_response`): a unit setpoint step
through the reference path Cr = Nr / Dc (`reference_polynomial`: u = Cr r - C y, the setpoint weights b and c), dy/dr =
B Nr / (A Dc + B Nc).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from prlpid_fmi.robustness.plant_response import MeasuredPlant

MAX_ORDER = 4  # highest order tried
FIT_TOLERANCE = 0.02  # RMS relative error at which the lowest order is taken
SK_ITERATIONS = 20  # Sanathanan-Koerner re-weightings
MAX_DELAY = 40  # extra samples of dead time tried where no order fits without
ZERO_RESPONSE = 1e-12  # |P| at most this x the largest |P| measured: a zero of the plant, left out of the fit
HIGH_ORDER = 8  # orders MAX_ORDER + 1 .. HIGH_ORDER (no dead time) are tried last, where nothing above fits
LOWEST_OCTAVE = 2.0  # a pole and a zero both slower than this x the lowest measured frequency: a pair not resolved


@dataclass(frozen=True, eq=False)
class LocalModel:
    """P(q) at one operating point: numerator (n+1+d,) d + 1 leading zeros, then b_1..b_n, and denominator (n+1,) 1,
    a_1..a_n in powers of q = z^-1; sample_time_s [s]; point: the setpoints per loop; fit_error: RMS over the
    measured frequencies, weighted by their reliability, of |P_model - P_meas| / |P_meas|."""

    numerator: np.ndarray
    denominator: np.ndarray
    sample_time_s: float
    point: tuple
    fit_error: float

    @property
    def order(self) -> int:
        return len(self.denominator) - 1

    def response(self, omega) -> np.ndarray:
        """P(e^{j w Ts}) at omega [rad/s] (complex, omega's shape)."""
        q = np.exp(-1j * np.asarray(omega, float) * self.sample_time_s)
        return np.polyval(self.numerator[::-1], q) / np.polyval(self.denominator[::-1], q)

    def as_dict(self) -> dict:
        """{"point", "order", "numerator", "denominator", "fit_error"} (fixed_pid.json)."""
        return {"point": list(self.point), "order": self.order, "numerator": self.numerator.tolist(),
                "denominator": self.denominator.tolist(), "fit_error": float(self.fit_error)}


def _fit(omega: np.ndarray, P: np.ndarray, Ts: float, n: int, reliability: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(numerator, denominator) of order n by Sanathanan-Koerner iterations on the relative error, each frequency's
    weighted by its reliability (K,)."""
    q = np.exp(-1j * omega * Ts)
    powers = q[:, None] ** np.arange(1, n + 1)[None, :]  # (K, n): q^1 .. q^n
    weight = reliability / np.abs(P)
    a = np.zeros(n)
    for _ in range(SK_ITERATIONS):
        w = weight / np.abs(1.0 + powers @ a)
        # A P - B = P + sum a_i q^i P - sum b_i q^i: unknowns [a, b], real and imaginary parts stacked
        M = np.hstack([powers * P[:, None], -powers]) * w[:, None]
        rhs = -P * w
        x, *_ = np.linalg.lstsq(np.vstack([M.real, M.imag]), np.concatenate([rhs.real, rhs.imag]), rcond=None)
        if not np.all(np.isfinite(x)):
            break
        a = x[:n]
        b = x[n:]
    return np.concatenate([[0.0], b]), np.concatenate([[1.0], a])


def identify(plant: MeasuredPlant, max_order: int = MAX_ORDER, tolerance: float = FIT_TOLERANCE,
             max_delay: int = MAX_DELAY, high_order: int = HIGH_ORDER) -> LocalModel:
    """The LocalModel of a measured response (module docstring; frequencies where |P| <= ZERO_RESPONSE x its largest
    left out): the lowest order with fit_error <= tolerance; where no order meets it, the lowest order and then the
    least dead time of 1..max_delay extra samples that does (the numerator's leading zeros: q^d B(q) / A(q), fitted to
    P e^{j w Ts d}); where none does, the lowest order of max_order + 1..high_order without dead time (a high-order
    lag); else the model with the least fit_error. A fit with a pole and a zero in the lowest measured octave or
    below (`unresolved`) counts as not fitting."""
    omega = np.asarray(plant.frequencies_rad_s, float)
    P = np.asarray(plant.response, complex)
    # a zero of the plant on the grid (a double integrator's ZOH at the Nyquist frequency), measured as rounding
    # noise, is left out: the fit weighs relative errors
    nonzero = np.abs(P) > ZERO_RESPONSE * np.max(np.abs(P), initial=0.0)
    omega, P, reliability = omega[nonzero], P[nonzero], plant.reliability()[nonzero]
    if len(omega) < 2 or not np.all(np.isfinite(P)):
        raise ValueError("a local model needs a finite, nonzero response at two frequencies or more")
    Ts = float(plant.sample_time_s)
    best = None
    stages = ((range(1, max_order + 1), (0,)), (range(1, max_order + 1), range(1, max_delay + 1)),
              (range(max_order + 1, max(max_order, high_order) + 1), (0,)))
    for orders, delays in stages:
        for n in orders:
            if 2 * len(omega) < 2 * n + 1:
                break
            for d in delays:
                num, den = _fit(omega, P * np.exp(1j * omega * Ts * d), Ts, n, reliability)
                num = np.concatenate([np.zeros(d), num])
                model = LocalModel(num, den, Ts, tuple(plant.point), math.inf)
                relative = np.abs(model.response(omega) - P) / np.abs(P)
                error = float(np.sqrt(np.sum((reliability * relative) ** 2) / np.sum(reliability ** 2)))
                error = error if math.isfinite(error) and not unresolved(model, float(np.min(omega))) else math.inf
                model = LocalModel(num, den, Ts, tuple(plant.point), error)
                if best is None or error < best.fit_error:
                    best = model
                if error <= tolerance:
                    return model
    return best


def unresolved(model: LocalModel, lowest_rad_s: float) -> bool:
    """The model has a pole and a zero both slower than LOWEST_OCTAVE x lowest_rad_s [rad/s] (|ln z| / Ts below
    it): a pair that a response measured from lowest_rad_s up does not resolve."""
    below = LOWEST_OCTAVE * lowest_rad_s * model.sample_time_s  # |ln z| of a root that slow

    def slow(poly):
        roots = np.roots(np.trim_zeros(np.asarray(poly, float), "f")) if np.count_nonzero(poly) > 1 else []
        return any(abs(np.log(complex(r))) < below for r in roots if r != 0)
    return slow(model.denominator) and slow(model.numerator)


def measurement_filter(Tf: float, order: int, sample_time_s: float) -> tuple[np.ndarray, np.ndarray]:
    """control.pid's measurement filter F of Tf [s] as (num, den) in q: `order` backward-Euler sections
    x_k = (T x_{k-1} + Ts in_k) / (T + Ts) of T = Tf / order each; Tf = 0: none (1 / 1)."""
    Ts = float(sample_time_s)
    num, den = np.array([1.0]), np.array([1.0])
    if Tf > 0:
        T = Tf / order
        for _ in range(order):
            num, den = np.convolve(num, np.array([Ts / (T + Ts)])), np.convolve(den, np.array([1.0, -T / (T + Ts)]))
    return num, den


def derivative_denominator(Td: float, derivative_filter_N: float | None, sample_time_s: float) -> np.ndarray:
    """[Tdf + Ts, -Tdf], Tdf = Td / N (0 without a filter or Td): the backward-Euler derivative filter's denominator x
    Ts in q, D = (1 - q) / ((Tdf + Ts) - Tdf q) e."""
    Tdf = Td / derivative_filter_N if derivative_filter_N and Td != 0 else 0.0
    return np.array([Tdf + float(sample_time_s), -Tdf])


def feedback_polynomials(Kp: float, Ti: float, Td: float, sample_time_s: float,
                         derivative_filter_N: float | None = None, measurement_filter_s: float = 0.0,
                         measurement_filter_order: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(Nc, Dc) in powers of q = z^-1 of the PID's feedback law u = -C y at a constant setpoint (control.pid):
    C = Kp (F (1 + Td Fd (1 - q) / Ts) + Ts / (Ti (1 - q))), F the measurement filter (order 1: one backward-Euler
    section of Tf; order 2: two of Tf/2), Fd the derivative filter of Td/N. Ti = inf: no integral term."""
    Ts = float(sample_time_s)
    num_f, den_f = measurement_filter(measurement_filter_s, measurement_filter_order, Ts)
    dd = derivative_denominator(Td, derivative_filter_N, Ts)
    diff = np.array([1.0, -1.0])
    integral = math.isfinite(Ti)
    # common denominator den_f * dd (* (1 - q) with an integral term)
    num = np.convolve(num_f, dd)
    if Td != 0:
        num = _add(num, Td * np.convolve(num_f, diff))
    den = np.convolve(den_f, dd)
    if integral:
        num = _add(np.convolve(num, diff), (Ts / Ti) * den)
        den = np.convolve(den, diff)
    return Kp * num, den


def reference_polynomial(Kp: float, Ti: float, Td: float, sample_time_s: float, b: float, c: float = 0.0,
                         derivative_filter_N: float | None = None, measurement_filter_s: float = 0.0,
                         measurement_filter_order: int = 1) -> np.ndarray:
    """Nr in powers of q of the PID's reference path Cr = Nr / Dc, over `feedback_polynomials`' Dc (same arguments):
    Cr = Kp (b + Ts / (Ti (1 - q)) + c Td Fd (1 - q) / Ts) (control.pid: the integral of the unfiltered error, the
    setpoint unfiltered; Ti = inf: no integral term)."""
    Ts = float(sample_time_s)
    den_f = measurement_filter(measurement_filter_s, measurement_filter_order, Ts)[1]
    dd = derivative_denominator(Td, derivative_filter_N, Ts)
    diff = np.array([1.0, -1.0])
    base = np.convolve(den_f, dd)  # Dc without the integrator's (1 - q)
    num = b * base
    if c != 0 and Td != 0:
        num = _add(num, c * Td * np.convolve(den_f, diff))
    if math.isfinite(Ti):
        num = _add(np.convolve(num, diff), (Ts / Ti) * base)
    return Kp * num


def setpoint_response(model: LocalModel, Nc: np.ndarray, Dc: np.ndarray, Nr: np.ndarray, steps: int) -> np.ndarray:
    """y_k (steps,) after a unit setpoint step at sample 0, the loop at rest before: B Nr / (A Dc + B Nc)."""
    B, A = model.numerator, model.denominator
    den = _add(np.convolve(A, Dc), np.convolve(B, Nc))
    with np.errstate(over="ignore", invalid="ignore"):
        return lfilter(np.convolve(B, Nr), den, np.ones(int(steps)))


def _add(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a + b as polynomials in ascending powers of q (the shorter padded with zeros at the end)."""
    out = np.zeros(max(len(a), len(b)))
    out[:len(a)] += a
    out[:len(b)] += b
    return out


def closed_loop(model: LocalModel, Nc: np.ndarray, Dc: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(num_y, num_u, den) in q of the load responses dy/d = B Dc / den and du_pid/d = -B Nc / den,
    den = A Dc + B Nc."""
    B, A = model.numerator, model.denominator
    den = _add(np.convolve(A, Dc), np.convolve(B, Nc))
    return np.convolve(B, Dc), -np.convolve(B, Nc), den


def closed_loop_stable(model: LocalModel, Nc: np.ndarray, Dc: np.ndarray) -> bool:
    """Every root of A Dc + B Nc (in z) strictly inside the unit circle (`schur_stable`; leading zeros dropped as
    np.roots drops them, trailing ones are roots at z = 0)."""
    den = np.trim_zeros(closed_loop(model, Nc, Dc)[2])
    return bool(np.all(np.isfinite(den))) and schur_stable(den.tolist())


def schur_stable(coefficients: list[float]) -> bool:
    """Every root of c[0] z^n + c[1] z^(n-1) + ... + c[n] (c[0] != 0) strictly inside the unit circle, by the
    Schur-Cohn step-down: with k = c[n] / c[0], |k| < 1 and the degree n - 1 polynomial c[i] - k c[n - i] stable
    (a search asks this of every candidate at every point: 6 us against 46 us for np.roots)."""
    c = [float(x) for x in coefficients]
    while len(c) > 1:
        k = c[-1] / c[0]
        if not abs(k) < 1.0:
            return False
        n = len(c) - 1
        c = [c[i] - k * c[n - i] for i in range(n)]
    return True


def load_responses(model: LocalModel, Nc: np.ndarray, Dc: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(dy, du_pid), each (steps,), of a unit step at the plant input from sample 0 on: dy_k the measurement's
    change at sample k, du_pid_k the PID output's (its first nonzero value is at k = 1)."""
    num_y, num_u, den = closed_loop(model, Nc, Dc)
    step = np.ones(int(steps))
    with np.errstate(over="ignore", invalid="ignore"):
        return lfilter(num_y, den, step), lfilter(num_u, den, step)
