"""The classical PID rules on a local model, and the load IAE they reach at each Ms: the bound under which the
setpoint search keeps the load IAE (tuning.design_rule, requirement 5: never worse than SIMC or AMIGO at equal Ms).

The rules (the ideal PID law, Kp in input units per measurement unit, Ti and Td in s), from the local model's unit
step response between the samples (`step_response`: the continuous plant behind the ZOH model):
- a stable, non-oscillatory model: K e^(-L s) / (T s + 1) by Astrom & Hagglund's tangent method (K the final value;
  L where the tangent at the steepest point crosses zero; T = t63 - L), then L + Ts/2 for the hold;
  AMIGO's PID (Astrom & Hagglund 2004) Kp = (0.2 + 0.45 T / L) / K, Ti = (0.4 L + 0.8 T) L / (L + 0.1 T),
  Td = 0.5 L T / (0.3 L + T), its Kp scaled by a knob; SIMC's PI (Skogestad 2003) Kp = T / (K (tc + L)),
  Ti = min(T, 4 (tc + L)), tc = knob x L;
- one integrator: kv e^(-L s) / s from the ramp's asymptote (kv its slope, L where it crosses zero, + Ts/2);
  AMIGO Kp = knob x 0.45 / (kv L), Ti = 8 L, Td = 0.5 L; SIMC Kp = 1 / (kv (tc + L)), Ti = 4 (tc + L);
- otherwise (unstable, oscillatory: a step response above 1.05 x its final value; several integrators): no rule,
  and no bound.
Each rule is swept over KNOBS; `load_bound` turns each sweep into Ms -> the least load IAE the rule reaches at that
Ms or below, and takes the least over the rules.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.linalg import expm, logm

from prlpid_fmi.robustness.local_model import LocalModel

KNOBS = np.geomspace(0.05, 20.0, 96)  # AMIGO's Kp factor and SIMC's tc / L swept
OVERSHOOT = 0.05  # a step (an integrator's: its rate) above (1 + this) x its final value: oscillatory, no rule
FINE = 20  # the step response between samples at Ts / FINE ...
MAX_POINTS = 20_000  # ... on at most this many points
SETTLE = 12.0  # the step response is computed over this many (+ 2 per order) of the slowest time constant

Rule = Callable[[float], tuple[float, float, float]]


def step_response(model: LocalModel) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(t [s], y, the continuous poles [1/s]) of the model's unit step response between its samples: the continuous
    plant behind the ZOH model (the matrix logarithm of its augmented transition [[A, B], [0, 1]] over Ts), on a grid
    of Ts / FINE (coarser where SETTLE + 2 x order slowest time constants need more than MAX_POINTS), its whole
    samples of dead time as a shift; None where the logarithm is not real (a pole on the negative real axis: no
    continuous plant) or the plant is unstable."""
    Ts = model.sample_time_s
    lead = int(np.argmax(np.abs(model.numerator) > 0))  # one zero from the hold, the rest dead time
    delay = max(lead - 1, 0) * Ts
    B, A = model.numerator[max(lead - 1, 0):], model.denominator
    n = max(len(A), len(B)) - 1
    if n < 1:
        return None
    b, a = np.pad(B, (0, n + 1 - len(B))), np.pad(A, (0, n + 1 - len(A)))  # in z: descending powers, a[0] = 1
    Ad = np.eye(n, k=-1)  # the controllable canonical form of b(z) / a(z)
    Ad[0, :] = -a[1:]
    Bd = np.eye(n, 1)
    Cd, Dd = (b[1:] - a[1:] * b[0]).reshape(1, n), b[0]
    augmented = np.block([[Ad, Bd], [np.zeros((1, n)), np.ones((1, 1))]])
    with np.errstate(all="ignore"):
        log = logm(augmented) / Ts
    if not np.all(np.isfinite(log)) or np.max(np.abs(np.imag(log))) > 1e-8 * max(np.max(np.abs(log)), 1.0):
        return None
    log = np.real(log)
    poles = np.linalg.eigvals(log[:n, :n])
    if np.any(poles.real > 1e-9):
        return None  # unstable: no rule
    rates = np.abs(poles.real)
    rates = rates[rates > 1e-9]
    span = (SETTLE + 2 * n) / float(np.min(rates)) if rates.size else 200 * Ts  # a chain of n lags settles later
    h = max(Ts / FINE, span / MAX_POINTS)
    transition = expm(log * h)
    x = np.zeros(n + 1)
    x[n] = 1.0  # the held unit input
    y = np.empty(int(span / h) + 1)
    for k in range(len(y)):
        y[k] = float((Cd @ x[:n])[0]) + Dd
        x = transition @ x
    return np.arange(len(y)) * h + delay, y, poles


def fopdt(model: LocalModel) -> tuple[float, float, float] | None:
    """(K, T, L [s]) by the tangent method on `step_response`, or None (unstable, integrating, oscillatory: a step
    above (1 + OVERSHOOT) K; or no continuous plant)."""
    found = step_response(model)
    if found is None:
        return None
    t, y, poles = found
    if np.any(poles.real >= -1e-9):
        return None
    K = float(np.sum(model.numerator) / np.sum(model.denominator))  # the static gain B(1) / A(1)
    if not math.isfinite(K) or abs(K) < 1e-12 or np.max(y / K) > 1.0 + OVERSHOOT:
        return None
    y = y / K
    slope = np.gradient(y, t)
    i = int(np.argmax(slope))
    if slope[i] <= 0 or y[-1] < 1.0 - math.exp(-1.0):
        return None
    L = float(t[i] - y[i] / slope[i])
    rising = np.maximum.accumulate(y[i:])  # monotone for the interpolation (a non-oscillatory step nearly is)
    t63 = float(np.interp(1.0 - math.exp(-1.0), rising, t[i:]))
    L = max(L, 0.0)
    return K, max(t63 - L, model.sample_time_s), L + model.sample_time_s / 2


def integrating(model: LocalModel) -> tuple[float, float] | None:
    """(kv [per s per input unit], L [s]) of a model with one integrator and otherwise stable poles (its ramp's
    asymptote: kv its slope, L where it crosses zero, + Ts/2 for the hold), or None (also where the rate overshoots
    its final value by more than OVERSHOOT)."""
    found = step_response(model)
    if found is None:
        return None
    t, y, poles = found
    at_zero = np.abs(poles) < 1e-6 / model.sample_time_s
    if int(np.sum(at_zero)) != 1 or np.any(poles[~at_zero].real >= -1e-9):
        return None
    rate = np.gradient(y, t)
    kv = float(rate[-1])
    if not math.isfinite(kv) or abs(kv) < 1e-12 or np.max(rate / kv) > 1.0 + OVERSHOOT:
        return None
    L = float(t[-1] - y[-1] / kv)
    return kv, max(L, 0.0) + model.sample_time_s / 2


def rules(model: LocalModel) -> dict[str, Rule]:
    """{"AMIGO": knob -> (Kp, Ti, Td), "SIMC": ...} for the model (module docstring), or {} where none applies."""
    lag = fopdt(model)
    if lag is not None:
        K, T, L = lag
        amigo = ((0.2 + 0.45 * T / L) / K, (0.4 * L + 0.8 * T) / (L + 0.1 * T) * L, 0.5 * L * T / (0.3 * L + T))
        return {"AMIGO": lambda k: (k * amigo[0], amigo[1], amigo[2]),
                "SIMC": lambda k: (T / (K * (k * L + L)), min(T, 4.0 * (k * L + L)), 0.0)}
    ramp = integrating(model)
    if ramp is not None:
        kv, L = ramp
        return {"AMIGO": lambda k: (k * 0.45 / (kv * L), 8.0 * L, 0.5 * L),
                "SIMC": lambda k: (1.0 / (kv * (k * L + L)), 4.0 * (k * L + L), 0.0)}
    return {}


def load_bound(model: LocalModel, assess: Callable[[tuple[float, float, float]], tuple[float, float] | None]
               ) -> Callable[[float], float] | None:
    """Ms -> the least load IAE that a rule (`rules`, each swept over KNOBS) reaches with Ms at most that: per rule
    the least load over its sweep's points with Ms <= m, linear in Ms between them (inf below its least Ms), then the
    least over the rules; None without a rule. assess((Kp, Ti, Td)) -> (Ms, load IAE) of those gains on the
    design's models, or None where they break a limit other than Ms (noise) or destabilise the loop."""
    curves = []
    for rule in rules(model).values():
        found = []
        for k in KNOBS:
            pid = rule(float(k))  # (Kp, Ti, Td) of one loop
            if not all(math.isfinite(g) for g in pid) or pid[1] <= 0:  # Ti
                continue
            point = assess(pid)
            if point is not None and all(math.isfinite(v) for v in point):
                found.append(point)
        if found:
            found.sort()
            curves.append((np.array([p[0] for p in found]), np.minimum.accumulate(np.array([p[1] for p in found]))))
    if not curves:
        return None
    return lambda m: min(float(np.interp(m, ms, least, left=math.inf)) for ms, least in curves)
