"""PidTuningEnv: the agent's action path in front of the loop core (prlpid_fmi.loop.core.LoopCore).

One step: action in [-1, 1] -> smoothing (eq. 19-21) -> gain map (anchored at the tuned fixed PID,
or the paper's absolute map) -> LoopCore.step(Kp, Ti, Td[, coupling]) -> observation.

Observation, 4 features per loop (Table 1), each divided by the loop's measurement_scale and clipped
to [-10, 10]: setpoint r, measurement y, error e = r - y, and error rate (e_k - e_{k-1}) / Ts.
(r, y) locate the operating point the gains should depend on; (e, de/dt) are what a PID tuner reads
to decide between more proportional, integral or derivative action.

Gain map: with `config.gain_mapping == "anchored"` and an anchor given (`anchor=`: the tuned fixed PID's Gains,
or a gain table, the classical gain schedule `tune` builds on a nonlinear plant), action 0 gives exactly the
anchor's gains (a table's at its scheduling variable's value, read before the step as a replay of the table
reads it); without an anchor, or with "absolute", the action maps over the whole gain ranges (paper).
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.control import make_smoother
from prlpid_fmi.loop.actions import ActionMap, AnchoredActionMap, ScheduledActionMap
from prlpid_fmi.loop.gains import gains_from_values
from prlpid_fmi.loop.isolated import make_core
from prlpid_fmi.loop.scheduling import SchedulingVariable

OBS_CLIP = 10.0


def is_anchored(config: TuningConfig, anchor) -> bool:
    """Whether the gain map is anchored: an anchor given and config.gain_mapping is "anchored"."""
    return anchor is not None and config.gain_mapping == "anchored"


def is_table(anchor) -> bool:
    """Whether an anchor is a gain table (tuning.schedule.table.GainSchedule), not one set of Gains."""
    return hasattr(anchor, "gains_at")


def make_action_map(config: TuningConfig, anchor=None) -> ActionMap:
    """The gain map of `config`: anchored at `anchor` (Gains, or a gain table) when given and config.gain_mapping is
    "anchored"."""
    if is_anchored(config, anchor):
        kind = ScheduledActionMap if is_table(anchor) else AnchoredActionMap
        return kind(config.loops, anchor, config.anchor_bands, config.coupled, config.coupling_range)
    return ActionMap(config.loops, config.coupled, config.coupling_range)


class PidTuningEnv(gym.Env):
    """Gymnasium environment in which the agent sets PID parameters every sample time.

    Args:
        config: the tuning problem (see prlpid_fmi.config.TuningConfig).
        anchor: the tuned fixed PID's Gains, or a gain table, the anchored map is centred on (None: absolute map).
        info: True (default) puts every signal of the step in the info dict; training passes False
            (SB3's Monitor needs none of them).
        forecast_path: "auto" | "fmi" (see LoopCore).
    Observation: float32 (4 * n_loops,). Action: float32 (3 * n_loops [+ 6 if coupled],) in [-1, 1].
    info (info=True): time_s, setpoint, measurement, control_signal (n_loops,), gains {Kp, Ti, Td[,
    coupling]}, forecast_reward, step_reward.
    """

    metadata = {"render_modes": []}

    def __init__(self, config: TuningConfig, render_mode: str | None = None, anchor=None,
                 info: bool = True, forecast_path: str = "auto"):
        self.config = c = config
        self.render_mode = render_mode
        self.core = make_core(config, forecast_path)  # in this process, or in a worker (plant.isolation)
        self.action_map = make_action_map(config, anchor)
        self._scheduling = (SchedulingVariable(anchor.variable, self.core)
                            if isinstance(self.action_map, ScheduledActionMap) else None)
        self.smoother = make_smoother(c.smoothing, window=c.smoothing_window, alpha=c.smoothing_alpha,
                                      n_params=self.action_map.size)
        self._info = info
        self._scale = self.core.scale
        self._inv_dt = 1.0 / c.sample_time_s
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.action_map.size,), np.float32)
        self.observation_space = gym.spaces.Box(-OBS_CLIP, OBS_CLIP, (4 * c.n_loops,), np.float32)
        self.gains = None

    # -- the core's parts, for tests and tools ---------------------------------------------------
    @property
    def plant(self):
        return self.core.plant

    @property
    def prior(self):
        return self.core.prior

    @property
    def forecast(self):
        return self.core.forecast

    @property
    def pid(self):
        return self.core.pid

    @property
    def loop_names(self):
        return self.core.loop_names

    @property
    def setpoint(self) -> np.ndarray:
        return np.array(self.core.setpoint)

    @property
    def measurement(self) -> np.ndarray:
        return np.array(self.core.measurement)

    def _observation(self) -> np.ndarray:
        core, obs = self.core, []
        for r, y, e_prev, s in zip(core.setpoint, core.measurement, core.previous_error, self._scale):
            e = r - y
            for v in (r / s, y / s, e / s, (e - e_prev) * self._inv_dt / s):
                obs.append(-OBS_CLIP if v < -OBS_CLIP else OBS_CLIP if v > OBS_CLIP else v)
        return np.array(obs, dtype=np.float32)

    # -- gym API -------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """options: {"setpoint_schedule": ((step, setpoints), ...)} holds other setpoints for this episode."""
        super().reset(seed=seed)
        self.core.reset(self.np_random, (options or {}).get("setpoint_schedule"))
        self.smoother.reset()
        info = {}
        if self._info:
            info = {"time_s": 0.0, "setpoint": np.array(self.core.setpoint),
                    "measurement": np.array(self.core.measurement)}
        return self._observation(), info

    def step(self, action):
        raw = [-1.0 if a < -1.0 else 1.0 if a > 1.0 else a for a in np.asarray(action, dtype=float).tolist()]
        smoothed = self.smoother.values(raw)
        if self._scheduling is None:
            gains = self.gains = self.action_map.values(smoothed)
        else:  # the table's gains at the scheduling variable's value before the step
            gains = self.gains = self.action_map.values_at(smoothed, self._scheduling())
        reward, terminated = self.core.step(*gains)
        truncated = self.core.k >= self.config.episode_steps
        info = {}
        if terminated and self.core.termination is not None:  # why the episode ended (tuning.agent's fault watch)
            info["termination"] = self.core.termination
        if self._info:
            core = self.core
            info = {**info, "time_s": core.k * self.config.sample_time_s, "setpoint": np.array(core.applied_setpoint),
                    "measurement": np.array(core.measurement), "control_signal": np.array(core.control_signal),
                    "gains": gains_from_values(*gains).as_dict(), "forecast_reward": core.forecast_reward,
                    "step_reward": core.step_reward}
        return self._observation(), float(reward), terminated, truncated, info

    def close(self):
        self.core.close()
