"""The classical PID rules on a local model, and the load IAE they reach at each Ms: the bound under which the
setpoint search keeps the load IAE (tuning.design_rule, requirement 5: never worse than SIMC or AMIGO at equal Ms).

The rules (the ideal PID law, Kp in input units per measurement unit, Ti and Td in s), from the local model's unit
step response y_k (robustness.local_model: the ZOH discretisation, so y_k is the plant's response at k Ts):
- a stable, non-oscillatory model: K e^(-L s) / (T s + 1) by Astrom & Hagglund's tangent method (K the final value;
  L where the tangent at the steepest point crosses zero; T = t63 - L), L + Ts/2 for the hold;
  AMIGO's PID (Astrom & Hagglund 2004) Kp = (0.2 + 0.45 T / L) / K, Ti = (0.4 L + 0.8 T) L / (L + 0.1 T),
  Td = 0.5 L T / (0.3 L + T), its Kp scaled by a knob; SIMC's PI (Skogestad 2003) Kp = T / (K (tc + L)),
  Ti = min(T, 4 (tc + L)), tc = knob x L;
- one integrator: kv e^(-L s) / s from the ramp's asymptote (kv its slope, L where it crosses zero, + Ts/2);
  AMIGO Kp = knob x 0.45 / (kv L), Ti = 8 L, Td = 0.5 L; SIMC Kp = 1 / (kv (tc + L)), Ti = 4 (tc + L);
- otherwise (unstable, oscillatory, several integrators): no rule, and no bound.
Each rule is swept over KNOBS; `load_bound` turns each sweep into Ms -> the least load IAE the rule reaches at that
Ms or below, and takes the least over the rules.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.signal import lfilter

from prlpid_fmi.robustness.local_model import LocalModel

KNOBS = np.geomspace(0.05, 20.0, 96)  # AMIGO's Kp factor and SIMC's tc / L swept
OSCILLATORY = 0.1  # |imag| / |s| of a pole above which the model is taken as oscillatory (no rule)
STEP_SAMPLES = 200_000  # the longest step response computed for the fit [samples]

Rule = Callable[[float], tuple[float, float, float]]


def _poles_s(model: LocalModel) -> np.ndarray:
    """The model's poles mapped to s = ln(z) / Ts (rad/s)."""
    z = np.roots(model.denominator)  # A(q) = 1 + a_1 q + ... a_n q^n: z^n + a_1 z^(n-1) + ... read as descending in z
    z = z[np.abs(z) > 0]  # poles at z = 0 (pure delays) have no s
    with np.errstate(divide="ignore"):
        return np.log(z.astype(complex)) / model.sample_time_s


def _step(model: LocalModel, steps: int) -> np.ndarray:
    return lfilter(model.numerator, model.denominator, np.ones(steps))


def _horizon(poles: np.ndarray, Ts: float) -> int:
    """Samples for the step response to settle: 12 of the slowest nonzero time constant, at least 200."""
    rates = np.abs(poles.real)
    rates = rates[rates > 1e-12]
    slowest = 1.0 / float(np.min(rates)) if rates.size else Ts
    return int(min(STEP_SAMPLES, max(200, 12.0 * slowest / Ts)))


def fopdt(model: LocalModel) -> tuple[float, float, float] | None:
    """(K, T, L [s]) by the tangent method, or None (unstable, oscillatory, integrating, or no monotone rise)."""
    Ts = model.sample_time_s
    poles = _poles_s(model)
    if poles.size == 0 or np.any(poles.real >= -1e-9) or np.any(np.abs(poles.imag) > OSCILLATORY * np.abs(poles)):
        return None
    y = _step(model, _horizon(poles, Ts))
    K = float(y[-1])
    if not math.isfinite(K) or abs(K) < 1e-12:
        return None
    y = y / K
    t = np.arange(len(y)) * Ts  # the input held from sample 0 on: y[k] is the response at k Ts
    slope = np.gradient(y, t)
    i = int(np.argmax(slope))
    if slope[i] <= 0:
        return None
    L = float(t[i] - y[i] / slope[i])
    after = y[i:]
    if after[-1] < 1.0 - math.exp(-1.0):
        return None
    t63 = float(t[i:][int(np.argmax(after >= 1.0 - math.exp(-1.0)))])
    L = max(L, 0.0) + Ts / 2
    T = max(t63 - L, Ts)
    return K, T, L


def integrating(model: LocalModel) -> tuple[float, float] | None:
    """(kv [per s per input unit], L [s]) of a model with one integrator and otherwise stable poles, or None."""
    Ts = model.sample_time_s
    poles = _poles_s(model)
    at_one = np.abs(poles) < 1e-6 / Ts
    rest = poles[~at_one]
    if int(np.sum(at_one)) != 1 or np.any(rest.real >= -1e-9) or np.any(np.abs(rest.imag) > OSCILLATORY * np.abs(rest)):
        return None
    y = _step(model, _horizon(rest, Ts) if rest.size else 200)
    t = np.arange(len(y)) * Ts
    kv = float((y[-1] - y[-2]) / Ts)
    if not math.isfinite(kv) or abs(kv) < 1e-12:
        return None
    L = float(t[-1] - y[-1] / kv)
    return kv, max(L, 0.0) + Ts / 2


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
            gains = rule(float(k))
            if not all(math.isfinite(g) for g in gains) or gains[1] <= 0:
                continue
            point = assess(gains)
            if point is not None and all(math.isfinite(v) for v in point):
                found.append(point)
        if found:
            found.sort()
            curves.append((np.array([p[0] for p in found]), np.minimum.accumulate(np.array([p[1] for p in found]))))
    if not curves:
        return None
    return lambda m: min(float(np.interp(m, ms, least, left=math.inf)) for ms, least in curves)
