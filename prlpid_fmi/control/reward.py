"""Hierarchical reward of paper eq. 10-11 on (normalised) tracking errors.

Per loop, with e = e_k and e_prev = e_{k-1}::

    V      = e**2 / 2                       (Lyapunov candidate)
    dV     = V(e) - V(e_prev)
    r_add  = bonus_numerator / (|e| + bonus_offset)   if |e| < bonus_threshold else 0     (eq. 11)
    r      = -max(dV, 0) - alpha*min(V, v_clip) - beta*min(|e|, e_clip) + r_add         (eq. 10)

(V and |e| are >= 0, so clip(x, 0, c) = min(x, c).) On the first step of an episode pass
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
    """

    alpha: float = 1.0
    beta: float = 1.0
    v_clip: float = 0.5
    e_clip: float = 1.0
    bonus_threshold: float = 0.05
    bonus_numerator: float = 0.1
    bonus_offset: float = 0.05
    # weight of the control-variation term -w * min(|u_k - u_{k-1}| / control_scale, 1) per loop (the
    # environment adds it; prlpid_fmi.core.LoopCore.reward); it also weights effort in the fixed-PID search
    control_variation_weight: float = 0.0

    def __post_init__(self):
        for name in ("alpha", "beta", "bonus_threshold", "bonus_numerator", "control_variation_weight"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"RewardWeights.{name} must be >= 0, got {getattr(self, name)!r}")
        for name in ("v_clip", "e_clip", "bonus_offset"):
            if not getattr(self, name) > 0:
                raise ValueError(f"RewardWeights.{name} must be > 0, got {getattr(self, name)!r}")


DEFAULT_WEIGHTS = RewardWeights()


def _loop_reward(e: float, e_prev: float, w: RewardWeights) -> float:
    """Eq. 10-11 for one loop. Comparisons are arranged so that a NaN error yields NaN."""
    abs_e = e if e >= 0 else -e
    v = 0.5 * e * e
    v_growth = v - 0.5 * e_prev * e_prev
    r = -(0.0 if v_growth <= 0 else v_growth) \
        - w.alpha * (w.v_clip if v >= w.v_clip else v) \
        - w.beta * (w.e_clip if abs_e >= w.e_clip else abs_e)
    if abs_e < w.bonus_threshold:
        r += w.bonus_numerator / (abs_e + w.bonus_offset)
    return r


def _floats(x) -> list:
    a = np.asarray(x, dtype=float)
    return a.tolist() if a.ndim else [float(a)]


def hierarchical_reward_per_loop(error, previous_error, weights: RewardWeights = DEFAULT_WEIGHTS) -> np.ndarray:
    """Eq. 10 per loop: error, previous_error scalars or (n_loops,) -> rewards, shape (n_loops,)."""
    errors, previous = _floats(error), _floats(previous_error)
    if len(errors) != len(previous):
        raise ValueError(f"error and previous_error differ in length: {len(errors)} vs {len(previous)}")
    return np.array([_loop_reward(e, p, weights) for e, p in zip(errors, previous)])


def hierarchical_reward(error, previous_error, weights: RewardWeights = DEFAULT_WEIGHTS) -> float:
    """Eq. 10 averaged over loops: error, previous_error scalars or (n_loops,) -> float."""
    errors, previous = _floats(error), _floats(previous_error)
    if len(errors) != len(previous):
        raise ValueError(f"error and previous_error differ in length: {len(errors)} vs {len(previous)}")
    return sum([_loop_reward(e, p, weights) for e, p in zip(errors, previous)]) / len(errors)
