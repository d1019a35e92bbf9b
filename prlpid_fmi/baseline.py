"""The well-tuned fixed PID that every adaptive policy is reported against.

Constant Kp, Ti, Td (and coupling) are searched inside the same gain ranges the agent uses, by
differential evolution over the action space, minimising the mean normalised ISE over a few seeded
training episodes (same setpoint ranges, noise and disturbances as training, forecast off). It is
tuned on the training distribution, like the agent, and evaluated on the evaluation schedule.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution

from .actions import ActionMap, Gains
from .config import TuningConfig
from .env import PidTuningEnv
from .evaluate import rollout

DIVERGED_COST = 1e6


@dataclass(frozen=True)
class FixedPid:
    """Result of the search: the constant action, its gains and its training cost (normalised ISE)."""

    action: np.ndarray
    gains: Gains
    cost: float
    evaluations: int


def constant_policy(action: np.ndarray):
    """A policy that always returns `action` (a fixed PID)."""
    action = np.asarray(action, dtype=np.float32)
    return lambda obs: action


def _cost(action: np.ndarray, env: PidTuningEnv, seeds: list[int]) -> float:
    config = env.config
    scale = np.array([l.measurement_scale for l in config.loops])
    total = 0.0
    for seed in seeds:
        traj = rollout(constant_policy(action), config, seed=seed, env=env)
        e = (traj["setpoint"] - traj["measurement"]) / scale
        total += float(np.sum(e ** 2) * config.sample_time_s)
        if traj["terminated"]:
            total += DIVERGED_COST * (1.0 + (config.episode_steps - len(traj["reward"])) / config.episode_steps)
    return total / len(seeds)


def tune_fixed_pid(config: TuningConfig, seed: int = 0, episodes: int = 3, maxiter: int = 20,
                   popsize: int = 8) -> FixedPid:
    """Search constant gains minimising the mean normalised ISE over `episodes` seeded training episodes."""
    search = dataclasses.replace(config, forecast_horizon=0, smoothing="none")
    action_map = ActionMap(config.loops, config.coupled, config.coupling_range)
    seeds = [seed + i for i in range(episodes)]
    env = PidTuningEnv(search)
    try:
        result = differential_evolution(_cost, [(-1.0, 1.0)] * action_map.size, args=(env, seeds),
                                        maxiter=maxiter, popsize=popsize, seed=seed, polish=False, tol=1e-6)
    finally:
        env.close()
    return FixedPid(result.x, action_map(result.x), float(result.fun), int(result.nfev))
