"""Closed-loop evaluation: run a policy (trained agent or fixed gains) on a TuningConfig and measure it."""
from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np

from .config import TuningConfig
from .env import PidTuningEnv
from .metrics import compute_metrics

Policy = Callable[[np.ndarray], np.ndarray]


def model_policy(model, vecnormalize=None) -> Policy:
    """Deterministic action of an SB3 model for one observation (normalised first when trained so)."""
    def act(obs: np.ndarray) -> np.ndarray:
        if vecnormalize is not None:
            obs = vecnormalize.normalize_obs(obs)
        action, _ = model.predict(obs, deterministic=True)
        return action
    return act


def rollout(policy: Policy, config: TuningConfig, seed: int = 0, forecast: bool = False,
            env: PidTuningEnv | None = None) -> dict[str, np.ndarray]:
    """One episode of `policy` on `config` (forecast off unless asked: it does not change the plant).

    env: an open PidTuningEnv built from this config to reuse (it is not closed); default: a new one.

    Returns arrays: time_s (n+1,), setpoint, measurement, control_signal (n+1, n_loops) — row k is the
    signal at t = k·Ts (control_signal's last row repeats), gains {Kp, Ti, Td: (n, n_loops), coupling},
    reward (n,), terminated (bool).
    """
    own_env = env is None
    if own_env:
        if not forecast:
            config = dataclasses.replace(config, forecast_horizon=0)
        env = PidTuningEnv(config)
    try:
        obs, info = env.reset(seed=seed)
        setpoints, measurements, controls, rewards, gains = [info["setpoint"]], [info["measurement"]], [], [], []
        terminated = truncated = False
        while not (terminated or truncated):
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            setpoints.append(env.setpoint.copy())
            measurements.append(info["measurement"])
            controls.append(info["control_signal"])
            rewards.append(reward)
            gains.append(info["gains"])
    finally:
        if own_env:
            env.close()
    controls.append(controls[-1])
    n = len(rewards)
    return {
        "time_s": np.arange(n + 1) * config.sample_time_s,
        "setpoint": np.array(setpoints), "measurement": np.array(measurements),
        "control_signal": np.array(controls), "reward": np.array(rewards),
        "gains": {k: np.array([g[k] for g in gains]) for k in gains[0]},
        "terminated": bool(terminated),
    }


def evaluate(policy: Policy, config: TuningConfig, seed: int = 0, intervals=None,
             env: PidTuningEnv | None = None) -> tuple[dict, dict]:
    """Roll out (on `env` if given) and compute metrics (prlpid_fmi.metrics.compute_metrics).

    Returns (metrics, trajectory)."""
    traj = rollout(policy, config, seed, env=env)
    metrics = compute_metrics(traj["time_s"], traj["setpoint"], traj["measurement"], traj["control_signal"],
                              config.sample_time_s, intervals=intervals,
                              loop_names=[l.output for l in config.loops])
    metrics["terminated"] = traj["terminated"]
    return metrics, traj
