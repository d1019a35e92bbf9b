"""Hierarchical reward of paper eq. 10-11 on (normalised) tracking errors.

Per loop, with e = e_k and e_prev = e_{k-1}::

    V      = e**2 / 2                       (Lyapunov candidate)
    dV     = V(e) - V(e_prev)
    r_add  = bonus_numerator / (|e| + bonus_offset)   if |e| < bonus_threshold else 0     (eq. 11)
    r      = -max(dV, 0) - alpha*min(V, v_clip) - beta*min(|e|, e_clip) + r_add         (eq. 10)

(V and |e| are >= 0, so clip(x, 0, c) = min(x, c).) Optionally, per loop, a control-variation term
penalises moves of the control signal u (the saturated PID output)::

    r_cv   = -control_variation_weight * min(|u_k - u_{k-1}| / u_scale, 1)

with u_scale > 0 the loop's control span [input units]; it is 0 when u is not given or the weight is 0.
On the first step of an episode pass
previous_error = error, so dV = 0. The paper writes the difference as V_{k+1} - V_k; computed after
the step that produced e_k, it is the growth of V over that step. A NaN error gives a NaN reward.

Several loops: ``hierarchical_reward`` returns the MEAN of the per-loop rewards, so the reward's
scale (and the meaning of the divergence penalty and the bonus) does not depend on the number of
loops; ``hierarchical_reward_per_loop`` returns them individually.

Errors are expected in normalised units (the caller divides by each loop's measurement scale), so
one set of weights serves a level in cm and an angle in rad.

Arguments are scalars or numpy arrays of shape (n_loops,); the arithmetic is a loop over Python
floats because, for the 1-3 loops of a tuning problem, it is several times faster than a dozen
numpy calls on tiny arrays (the reward is evaluated up to N+1 times per environment step).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RewardWeights:
    """Weights and bounds of eq. 10-11; these defaults are the project's single source of truth.

    alpha, beta: weights of clip(V) and clip(|e|) (the paper gives no values; 1.0 each).
    v_clip, e_clip: upper clip bounds of V [error units^2] and |e| [error units]. e_clip = 1.0 is
    the size of a typical (normalised) setpoint step, and v_clip = e_clip**2/2 = 0.5 makes both
    terms saturate at the same |e| = 1, so together they contribute at most -(alpha*v_clip +
    beta*e_clip) = -1.5 per step. Beyond |e| = 1 only the unclipped -ReLU(dV) term (and the
    environment's divergence penalty) keep growing, as the paper intends for divergence.
    bonus_threshold, bonus_numerator, bonus_offset: eq. 11's 0.05, 0.1 and 0.05; the bonus is
    between 1.0 (|e| just under 0.05) and 2.0 (|e| = 0) per step.
    control_variation_weight: weight w of the control-variation term -w * min(|u_k - u_{k-1}| / u_scale, 1)
    per loop (at most -w per step, u_scale = the loop's control span); it also weights the moves of u in
    the fixed-PID search. Default 0.3: the smallest weight of benchmarks/bench_control_variation.py's grid at
    which the tuned fixed PID stops chattering on the noisy plants at most 5 % ISE cost (docs/results.md,
    "Control-variation weight"). 0 gives the paper's eq. 10.
    """

    alpha: float = 1.0
    beta: float = 1.0
    v_clip: float = 0.5
    e_clip: float = 1.0
    bonus_threshold: float = 0.05
    bonus_numerator: float = 0.1
    bonus_offset: float = 0.05
    control_variation_weight: float = 0.3

    def __post_init__(self):
        for name in ("alpha", "beta", "bonus_threshold", "bonus_numerator", "control_variation_weight"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"RewardWeights.{name} must be >= 0, got {getattr(self, name)!r}")
        for name in ("v_clip", "e_clip", "bonus_offset"):
            if not getattr(self, name) > 0:
                raise ValueError(f"RewardWeights.{name} must be > 0, got {getattr(self, name)!r}")


DEFAULT_WEIGHTS = RewardWeights()


def _loop_reward(e: float, e_prev: float, w: RewardWeights, u: float | None = None, u_prev: float = 0.0,
                 u_scale: float = 1.0) -> float:
    """Eq. 10-11 for one loop (+ the control-variation term when u is given). NaN in, NaN out.

    The C forecast (plant_sources/common/forecast.c) computes this in the same operation order.
    """
    abs_e = e if e >= 0 else -e
    v = 0.5 * e * e
    v_growth = v - 0.5 * e_prev * e_prev
    r = -(0.0 if v_growth <= 0 else v_growth) \
        - w.alpha * (w.v_clip if v >= w.v_clip else v) \
        - w.beta * (w.e_clip if abs_e >= w.e_clip else abs_e)
    if abs_e < w.bonus_threshold:
        r += w.bonus_numerator / (abs_e + w.bonus_offset)
    if u is not None and w.control_variation_weight != 0.0:
        variation = abs(u - u_prev) / u_scale
        r -= w.control_variation_weight * (1.0 if variation >= 1.0 else variation)  # min(., 1); NaN stays NaN
    return r


def mean_loop_reward(error: list, previous_error: list, w: RewardWeights, u: list | None = None,
                     u_prev: list | None = None, u_scale: list | None = None) -> float:
    """Eq. 10-11 (+ control variation when u is given) averaged over loops, on lists of n_loops floats.

    Unchecked, for the hot path; the sum runs left to right from 0.0, as in the C forecast.
    """
    total = 0.0
    if u is None:
        for i in range(len(error)):
            total += _loop_reward(error[i], previous_error[i], w)
    else:
        for i in range(len(error)):
            total += _loop_reward(error[i], previous_error[i], w, u[i], u_prev[i], u_scale[i])
    return total / len(error)


def _floats(x) -> list:
    a = np.asarray(x, dtype=float)
    return a.tolist() if a.ndim else [float(a)]


def _checked(error, previous_error, u, u_prev, u_scale) -> tuple:
    """Inputs as lists of floats of one length; u, u_prev and u_scale all given or all None."""
    errors, previous = _floats(error), _floats(previous_error)
    if len(errors) != len(previous):
        raise ValueError(f"error and previous_error differ in length: {len(errors)} vs {len(previous)}")
    if u is None and u_prev is None and u_scale is None:
        return errors, previous, None, None, None
    if u is None or u_prev is None or u_scale is None:
        raise ValueError("the control-variation term needs u, u_prev and u_scale together")
    u, u_prev, u_scale = _floats(u), _floats(u_prev), _floats(u_scale)
    if not len(u) == len(u_prev) == len(u_scale) == len(errors):
        raise ValueError(f"u, u_prev and u_scale need {len(errors)} values each, "
                         f"got {len(u)}, {len(u_prev)} and {len(u_scale)}")
    if not all(s > 0 for s in u_scale):
        raise ValueError(f"u_scale must be > 0, got {u_scale}")
    return errors, previous, u, u_prev, u_scale


def hierarchical_reward_per_loop(error, previous_error, weights: RewardWeights = DEFAULT_WEIGHTS,
                                 u=None, u_prev=None, u_scale=None) -> np.ndarray:
    """Eq. 10 per loop: error, previous_error scalars or (n_loops,) -> rewards, shape (n_loops,).

    u, u_prev (control signal now and one sample before) and u_scale (> 0), scalars or (n_loops,),
    add the control-variation term; without them it is 0.
    """
    errors, previous, u, u_prev, u_scale = _checked(error, previous_error, u, u_prev, u_scale)
    if u is None:
        return np.array([_loop_reward(e, p, weights) for e, p in zip(errors, previous)])
    return np.array([_loop_reward(errors[i], previous[i], weights, u[i], u_prev[i], u_scale[i])
                     for i in range(len(errors))])


def hierarchical_reward(error, previous_error, weights: RewardWeights = DEFAULT_WEIGHTS,
                        u=None, u_prev=None, u_scale=None) -> float:
    """Eq. 10 averaged over loops: error, previous_error scalars or (n_loops,) -> float.

    u, u_prev, u_scale: optional, together, as in hierarchical_reward_per_loop.
    """
    errors, previous, u, u_prev, u_scale = _checked(error, previous_error, u, u_prev, u_scale)
    return mean_loop_reward(errors, previous, weights, u, u_prev, u_scale)
