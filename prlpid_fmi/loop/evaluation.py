"""Closed-loop evaluation: run a policy (trained agent) or gains (fixed PID, gain schedule) and measure it.

Both drivers step the same LoopCore; `rollout` goes through the agent's action path (PidTuningEnv),
`gains_rollout` hands gains in physical units to the core directly. For the same seed, constant gains
given either way produce the same trajectory.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np
from gymnasium.utils.seeding import np_random

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.loop.core import LoopCore, Termination
from prlpid_fmi.loop.env import PidTuningEnv
from prlpid_fmi.loop.gains import GainValues
from prlpid_fmi.loop.isolated import make_core
from prlpid_fmi.metrics import compute_metrics, fast_reversals

GAIN_NAMES = ("Kp", "Ti", "Td", "coupling")  # order of the gains tuple LoopCore.step takes
Policy = Callable[[np.ndarray], np.ndarray]
GainsFn = Callable[[LoopCore], GainValues]  # core -> the gains, called before each step


def model_policy(model, vecnormalize=None) -> Policy:
    """Deterministic action of an SB3 model for one observation (normalised first when trained so)."""
    def act(obs: np.ndarray) -> np.ndarray:
        if vecnormalize is not None:
            obs = vecnormalize.normalize_obs(obs)
        action, _ = model.predict(obs, deterministic=True)
        return action
    return act


@dataclasses.dataclass
class Trajectory:
    """The signals of one closed-loop episode of n control steps on n_loops loops (after python-control's
    TimeResponseData: named arrays instead of a dict of string keys).

    Row k of time_s, setpoint, measurement and control_signal is the value at t = k·Ts:
    time_s (n+1,) [s]; setpoint, measurement (n+1, n_loops) [output unit]; control_signal (n+1, n_loops)
    [input unit], what the plant received (after saturation, actuator offsets and noise; the last row
    repeats); pid_output (n, n_loops) the controller's command; reward (n,); gains {"Kp", "Ti", "Td":
    (n, n_loops), "coupling": (n, 6) when coupled} in physical units (Kp [u/y], Ti and Td [s]).
    terminated: the episode ended before its last sample; termination: why and when (core.Termination),
    None when it ran to the end; after a rejected step or a non-finite output the last measurement row
    is NaN. scheduling_value (n,): the scheduling variable read before each step of a schedule replay
    (schedule.replay_schedule), None otherwise. loads: the random load steps of the episode (loop.core,
    training.load_disturbance) as (start step, end step, loop index, value [input units]).

    ``traj["measurement"]`` reads a field by name, as the dicts this replaces did.
    """

    time_s: np.ndarray
    setpoint: np.ndarray
    measurement: np.ndarray
    control_signal: np.ndarray
    pid_output: np.ndarray
    reward: np.ndarray
    gains: dict
    terminated: bool = False
    termination: Termination | None = None
    scheduling_value: np.ndarray | None = None
    loads: tuple = ()  # the episode's random load steps (training.load_disturbance): (start, end, loop, value)

    @property
    def steps(self) -> int:
        """Control steps taken (n)."""
        return len(self.reward)

    def __getitem__(self, name: str):
        if name not in _TRAJECTORY_FIELDS:
            raise KeyError(name)
        return getattr(self, name)

    def get(self, name: str, default=None):
        """A field by name, `default` for a name that is not a field (dict.get's behaviour)."""
        return getattr(self, name) if name in _TRAJECTORY_FIELDS else default


_TRAJECTORY_FIELDS = frozenset(f.name for f in dataclasses.fields(Trajectory))


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

    def trajectory(self, terminated: bool) -> Trajectory:
        n = len(self.rewards)
        termination = self.core.termination if terminated else None
        if termination is not None and termination.invalid_sample:  # no measurement after the failed step
            self.measurements[-1] = [float("nan")] * len(self.measurements[-1])
        controls = self.controls + [self.controls[-1]] if self.controls else [list(self.core.control_signal)]
        gains = {name: np.array([g[i] for g in self.gains], float) for i, name in enumerate(GAIN_NAMES)
                 if self.gains and self.gains[0][i] is not None}
        return Trajectory(
            time_s=np.arange(n + 1) * self.core.config.sample_time_s,
            setpoint=np.array(self.setpoints), measurement=np.array(self.measurements),
            control_signal=np.array(controls), pid_output=np.array(self.commands).reshape(n, -1),
            reward=np.array(self.rewards), gains=gains, terminated=bool(terminated), termination=termination,
            loads=tuple(getattr(self.core, "random_loads", ())))


def rollout(policy: Policy, config: TuningConfig, seed: int = 0, forecast: bool = False,
            env: PidTuningEnv | None = None, anchor=None) -> Trajectory:
    """One episode of `policy` on `config` (forecast off unless asked: it does not change the plant).

    env: an open PidTuningEnv built from this config to reuse (it is not closed); default: a new one,
    with the anchored gain map centred on `anchor` (the fixed-PID Gains the policy was trained around).

    Returns the episode's Trajectory (a NaN last measurement row after a rejected step or a
    non-finite output).
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
                  setpoint_schedule=None) -> Trajectory:
    """One episode with gains in physical units from `gains_fn(core)` before every step.

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
    gains = GainValues([float(x) for x in np.atleast_1d(Kp)], [float(x) for x in np.atleast_1d(Ti)],
                       [float(x) for x in np.atleast_1d(Td)],
                       None if coupling is None else [float(x) for x in coupling])
    return lambda core: gains


def measure(traj: Trajectory, config: TuningConfig, intervals=None) -> dict:
    """compute_metrics on a trajectory of `config`, plus whether and why the episode terminated.

    An episode that ended early is measured over the samples it has: a last sample without a
    measurement (a rejected step, a non-finite output) is left out, intervals are cut at the end
    (an entry then holds "requested_end_step") and intervals starting after it are left out.
    Adds "terminated" (bool) and "termination" (None or {kind, step, time_s, message}). The scenario's disturbances
    and the episode's random load steps (traj.loads) are events: they split segments (metrics.compute_metrics).
    """
    termination = traj.termination
    n = len(traj.time_s)
    if termination is not None and termination.invalid_sample and n > 1:
        n -= 1
    windows, cut = [], {}
    for iv in intervals or []:
        a, b = (int(v) for v in iv)
        if a < n:
            windows.append((a, min(b, n)))
            if b > n:
                cut[(a, min(b, n))] = b
    # the controller's command per row (the last row repeats, like control_signal's), for Chatter
    command = np.concatenate([traj.pid_output, traj.pid_output[-1:]])[:n] if len(traj.pid_output) else None
    metrics = compute_metrics(traj.time_s[:n], traj.setpoint[:n], traj.measurement[:n],
                              traj.control_signal[:n], config.sample_time_s, intervals=windows or None,
                              loop_names=[l.output for l in config.loops],
                              events=sorted({d.start_step for d in config.disturbances}
                                            | {start for start, _, _, _ in traj.loads}),
                              u_range=[l.u_max - l.u_min for l in config.loops], command=command,
                              # the measurement noise is known here; actuator noise moves y by an amount only
                              # the data can tell (then the estimate)
                              noise_std=config.measurement_noise_std if config.actuator_noise_std == 0 else None)
    for iv in metrics["intervals"]:
        if (iv["start_step"], iv["end_step"]) in cut:
            iv["requested_end_step"] = cut[(iv["start_step"], iv["end_step"])]
    metrics["terminated"] = traj.terminated
    metrics["termination"] = termination.as_dict() if termination is not None else None
    return metrics


def command_chatter(traj: Trajectory, config: TuningConfig) -> float:
    """The worst loop's fast_reversals (metrics) of a Trajectory's PID output over its whole run (NaN: none)."""
    u = np.asarray(traj.pid_output)
    found = [x for x in (fast_reversals(u[:, i], loop.u_max - loop.u_min) for i, loop in enumerate(config.loops))
             if math.isfinite(x)]
    return max(found, default=math.nan)


def evaluate(policy: Policy, config: TuningConfig, seed: int = 0, intervals=None,
             env: PidTuningEnv | None = None, anchor=None) -> tuple[dict, Trajectory]:
    """Roll out (on `env` if given; anchor as in rollout) and compute metrics (compute_metrics).

    Returns (metrics, trajectory)."""
    traj = rollout(policy, config, seed, env=env, anchor=anchor)
    return measure(traj, config, intervals), traj


def evaluate_gains(gains_fn: GainsFn, config: TuningConfig, seed: int = 0, intervals=None,
                   core: LoopCore | None = None) -> tuple[dict, Trajectory]:
    """gains_rollout + metrics: (metrics, trajectory)."""
    traj = gains_rollout(gains_fn, config, seed, core=core)
    return measure(traj, config, intervals), traj
