"""The well-tuned fixed PID that every adaptive policy is reported against, and the anchor it learns around.

Constant Kp, Ti, Td (and coupling) are searched inside the scenario's gain ranges by differential
evolution. The search vector lives in [-1, 1]^n and is mapped like the paper's absolute action map
(geometric for log ranges), but the candidate gains drive the loop core directly (no action path).
Cost, mean over a few seeded training episodes (same setpoint ranges, noise, disturbances and
parameter randomisation as training, forecast off), per loop in normalised units::

    J = sum_k Ts * ( e_k**2 + w_cv * min(|u_k - u_{k-1}| / control_scale, 1) )

with w_cv = reward.control_variation_weight, the same weight the agent's reward uses, so the search
does not buy ISE with a chattering actuator. A diverging episode costs DIVERGED_COST.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution

from .actions import ActionMap, Gains, gains_from_values
from .config import TuningConfig
from .core import LoopCore
from .evaluate import gains_rollout

DIVERGED_COST = 1e6


@dataclass(frozen=True)
class FixedPid:
    """Result of the search: its vector in [-1, 1]^n, the gains (exactly those evaluated), the cost."""

    action: np.ndarray
    gains: Gains
    cost: float
    evaluations: int

    def gains_values(self) -> tuple:
        """(Kp, Ti, Td, coupling) lists, what LoopCore.step takes."""
        g = self.gains
        return (g.Kp.tolist(), g.Ti.tolist(), g.Td.tolist(), None if g.coupling is None else g.coupling.tolist())


def episode_cost(traj: dict, core: LoopCore) -> float:
    """J of one trajectory (see module docstring), DIVERGED_COST scaled by the steps missing when it diverged."""
    config = core.config
    scale = np.asarray(core.scale)
    e = (traj["setpoint"] - traj["measurement"]) / scale
    cost = float(np.sum(e ** 2) * config.sample_time_s)
    weight = getattr(config.reward, "control_variation_weight", 0.0)
    if weight:
        du = np.abs(np.diff(traj["pid_output"], axis=0)) / np.asarray(core.u_scale)
        cost += weight * float(np.sum(np.minimum(du, 1.0)) * config.sample_time_s) / config.n_loops
    if traj["terminated"]:
        cost += DIVERGED_COST * (1.0 + (config.episode_steps - len(traj["reward"])) / config.episode_steps)
    return cost


def _cost(vector: np.ndarray, core: LoopCore, gain_map: ActionMap, seeds: list[int]) -> float:
    gains = gain_map.values(vector.tolist())
    total = 0.0
    for seed in seeds:
        total += episode_cost(gains_rollout(lambda c: gains, core.config, seed=seed, core=core), core)
    return total / len(seeds)


def tune_fixed_pid(config: TuningConfig, seed: int = 0, episodes: int = 3, maxiter: int = 20,
                   popsize: int = 8, callback=None) -> FixedPid:
    """Search constant gains minimising J (module docstring) over `episodes` seeded training episodes.

    callback(evaluations_done, evaluations_expected): progress, called after every generation.
    """
    search = dataclasses.replace(config, forecast_horizon=0)
    gain_map = ActionMap(config.loops, config.coupled, config.coupling_range)
    seeds = [seed + i for i in range(episodes)]
    core = LoopCore(search)
    n = gain_map.size
    expected = (maxiter + 1) * popsize * n
    done = [popsize * n]

    def progress(*_args, **_kwargs):
        done[0] += popsize * n
        if callback is not None:
            callback(min(done[0], expected), expected)

    try:
        result = differential_evolution(_cost, [(-1.0, 1.0)] * n, args=(core, gain_map, seeds),
                                        maxiter=maxiter, popsize=popsize, seed=seed, polish=False, tol=1e-6,
                                        callback=progress)
    finally:
        core.close()
    return FixedPid(result.x, gains_from_values(*gain_map.values(result.x.tolist())), float(result.fun),
                    int(result.nfev))
