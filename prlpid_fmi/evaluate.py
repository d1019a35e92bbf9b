"""Closed-loop evaluation: run a policy (trained agent) or gains (fixed PID, gain schedule) and measure it.

Both drivers step the same LoopCore; `rollout` goes through the agent's action path (PidTuningEnv),
`gains_rollout` hands gains in physical units to the core directly. For the same seed, constant gains
given either way produce the same trajectory.
"""
from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np
from gymnasium.utils.seeding import np_random

from .config import TuningConfig
from .core import LoopCore
from .isolation import make_core
from .env import PidTuningEnv
from .metrics import compute_metrics

GAIN_NAMES = ("Kp", "Ti", "Td", "coupling")  # order of the gains tuple LoopCore.step takes
Policy = Callable[[np.ndarray], np.ndarray]
GainsFn = Callable[[LoopCore], tuple]  # core -> (Kp, Ti, Td, coupling) lists, called before each step


def model_policy(model, vecnormalize=None) -> Policy:
    """Deterministic action of an SB3 model for one observation (normalised first when trained so)."""
    def act(obs: np.ndarray) -> np.ndarray:
        if vecnormalize is not None:
            obs = vecnormalize.normalize_obs(obs)
        action, _ = model.predict(obs, deterministic=True)
        return action
    return act


class _Recorder:
    """Collects the signals of one episode from a LoopCore (row k of each signal is its value at t = k·Ts)."""

    def __init__(self, core: LoopCore):
        self.core = core
        self.setpoints, self.measurements = [list(core.setpoint)], [list(core.measurement)]
        self.controls, self.commands, self.rewards, self.gains = [], [], [], []

    def add(self, reward: float, gains: tuple) -> None:
        core = self.core
        self.setpoints.append(list(core.setpoint))
        self.measurements.append(list(core.measurement))
        self.controls.append(list(core.control_signal))
        self.commands.append(list(core.pid_output))
        self.rewards.append(reward)
        self.gains.append(gains)

    def trajectory(self, terminated: bool) -> dict:
        n = len(self.rewards)
        termination = self.core.termination if terminated else None
        if termination is not None and termination.invalid_sample:  # no measurement after the failed step
            self.measurements[-1] = [float("nan")] * len(self.measurements[-1])
        controls = self.controls + [self.controls[-1]] if self.controls else [list(self.core.control_signal)]
        gains = {name: np.array([g[i] for g in self.gains], float) for i, name in enumerate(GAIN_NAMES)
                 if self.gains and self.gains[0][i] is not None}
        return {
            "time_s": np.arange(n + 1) * self.core.config.sample_time_s,
            "setpoint": np.array(self.setpoints), "measurement": np.array(self.measurements),
            "control_signal": np.array(controls), "reward": np.array(self.rewards),
            "pid_output": np.array(self.commands).reshape(n, -1),
            "gains": gains, "terminated": bool(terminated),
            "termination": termination.as_dict() if termination is not None else None,
        }


def rollout(policy: Policy, config: TuningConfig, seed: int = 0, forecast: bool = False,
            env: PidTuningEnv | None = None, anchor=None) -> dict[str, np.ndarray]:
    """One episode of `policy` on `config` (forecast off unless asked: it does not change the plant).

    env: an open PidTuningEnv built from this config to reuse (it is not closed); default: a new one,
    with the anchored gain map centred on `anchor` (the fixed-PID Gains the policy was trained around).

    Returns arrays: time_s (n+1,), setpoint, measurement, control_signal (n+1, n_loops) — row k is the
    signal at t = k·Ts (control_signal's last row repeats; it is what the plant received, actuator
    offsets and noise included) — pid_output (n, n_loops, the controller's command), gains {Kp, Ti,
    Td: (n, n_loops), coupling}, reward (n,), terminated (bool), termination (None, or core.Termination's
    dict: kind, step, time_s, message; after a rejected step or a non-finite output the last measurement
    row is NaN).
    """
    own_env = env is None
    if own_env:
        if not forecast:
            config = dataclasses.replace(config, forecast_horizon=0)
        env = PidTuningEnv(config, info=False, anchor=anchor)
    try:
        obs, _ = env.reset(seed=seed)
        record = _Recorder(env.core)
        terminated = truncated = False
        while not (terminated or truncated):
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            record.add(reward, env.gains)
    finally:
        if own_env:
            env.close()
    return record.trajectory(terminated)


def gains_rollout(gains_fn: GainsFn, config: TuningConfig, seed: int = 0, core: LoopCore | None = None,
                  setpoint_schedule=None) -> dict[str, np.ndarray]:
    """One episode with gains in physical units from `gains_fn(core)` before every step; rollout's layout.

    core: an open LoopCore of this config to reuse (not closed); default: a new one with the forecast off.
    setpoint_schedule: overrides config.setpoint_schedule for this episode (((step, setpoints), ...)).
    """
    own_core = core is None
    if own_core:
        core = make_core(dataclasses.replace(config, forecast_horizon=0))
    try:
        core.reset(np_random(seed)[0], setpoint_schedule=setpoint_schedule)
        record = _Recorder(core)
        terminated = False
        for _ in range(core.config.episode_steps):
            gains = gains_fn(core)
            reward, terminated = core.step(*gains)
            record.add(reward, gains)
            if terminated:
                break
    finally:
        if own_core:
            core.close()
    return record.trajectory(terminated)


def constant_gains(Kp, Ti, Td, coupling=None) -> GainsFn:
    """A gains function that always returns the same gains (a fixed PID); arguments are (n_loops,) values."""
    gains = ([float(x) for x in np.atleast_1d(Kp)], [float(x) for x in np.atleast_1d(Ti)],
             [float(x) for x in np.atleast_1d(Td)], None if coupling is None else [float(x) for x in coupling])
    return lambda core: gains


def measure(traj: dict, config: TuningConfig, intervals=None) -> dict:
    """compute_metrics on a trajectory of `config`, plus whether and why the episode terminated.

    An episode that ended early is measured over the samples it has: a last sample without a
    measurement (a rejected step, a non-finite output) is left out, intervals are cut at the end
    (an entry then holds "requested_end_step") and intervals starting after it are left out.
    Adds "terminated" (bool) and "termination" (None or {kind, step, time_s, message}).
    """
    termination = traj.get("termination")
    n = len(traj["time_s"])
    if termination is not None and termination["kind"] != "diverged" and n > 1:
        n -= 1
    windows, cut = [], {}
    for iv in intervals or []:
        a, b = (int(v) for v in iv)
        if a < n:
            windows.append((a, min(b, n)))
            if b > n:
                cut[(a, min(b, n))] = b
    metrics = compute_metrics(traj["time_s"][:n], traj["setpoint"][:n], traj["measurement"][:n],
                              traj["control_signal"][:n], config.sample_time_s, intervals=windows or None,
                              loop_names=[l.output for l in config.loops],
                              events=sorted({d.start_step for d in config.disturbances}))
    for iv in metrics["intervals"]:
        if (iv["start_step"], iv["end_step"]) in cut:
            iv["requested_end_step"] = cut[(iv["start_step"], iv["end_step"])]
    metrics["terminated"] = traj["terminated"]
    metrics["termination"] = termination
    return metrics


def evaluate(policy: Policy, config: TuningConfig, seed: int = 0, intervals=None,
             env: PidTuningEnv | None = None, anchor=None) -> tuple[dict, dict]:
    """Roll out (on `env` if given; anchor as in rollout) and compute metrics (compute_metrics).

    Returns (metrics, trajectory)."""
    traj = rollout(policy, config, seed, env=env, anchor=anchor)
    return measure(traj, config, intervals), traj


def evaluate_gains(gains_fn: GainsFn, config: TuningConfig, seed: int = 0, intervals=None,
                   core: LoopCore | None = None) -> tuple[dict, dict]:
    """gains_rollout + metrics: (metrics, trajectory)."""
    traj = gains_rollout(gains_fn, config, seed, core=core)
    return measure(traj, config, intervals), traj
