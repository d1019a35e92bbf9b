"""PidTuningEnv: the one place where plant, prior, PID, smoothing, reward, setpoints and disturbances meet.

One step: action in [-1, 1] -> smoothing (eq. 19-21) -> gains -> reward forecast on the prior
(eq. 12-14, before the plant moves) -> PID (eq. 2 / eq. 26-27) -> saturation -> plant step ->
reward (eq. 10-11, or the forecast's mean) -> observation.

Observation, 4 features per loop (Table 1), each divided by the loop's measurement_scale and clipped
to [-10, 10]: setpoint r, measurement y, error e = r - y, and error rate (e_k - e_{k-1}) / Ts.
(r, y) locate the operating point the gains should depend on; (e, de/dt) are what a PID tuner reads
to decide between more proportional, integral or derivative action.
"""
from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np

from .actions import ActionMap, Gains
from .config import TuningConfig
from .control import CoupledPID, PID, hierarchical_reward, make_smoother
from .control.forecast import RewardForecast
from .errors import PlantError
from .fmu import FmuPlant, StepRejected, bundled_fmu, bundled_plant_names

OBS_CLIP = 10.0


def resolve_fmu(fmu: str, fmi_version: int = 2) -> Path:
    """A bundled plant's name -> its (freshly built if needed) FMU; otherwise the path itself."""
    if fmu in bundled_plant_names():
        return bundled_fmu(fmu, fmi_version)
    path = Path(fmu)
    if not path.is_file():
        raise PlantError(f"{fmu}: FMU file not found (and not a bundled plant: {', '.join(bundled_plant_names())})")
    return path


class PidTuningEnv(gym.Env):
    """Gymnasium environment in which the agent sets PID parameters every sample time.

    Args:
        config: the tuning problem (see prlpid_fmi.config.TuningConfig).
    Observation: float32 (4 * n_loops,). Action: float32 (3 * n_loops [+ 6 if coupled],) in [-1, 1].
    info: time_s, setpoint, measurement, control_signal (n_loops,), gains {Kp, Ti, Td[, coupling]}, forecast_reward.
    """

    metadata = {"render_modes": []}

    def __init__(self, config: TuningConfig, render_mode: str | None = None):
        self.config = c = config
        self.render_mode = render_mode
        n = c.n_loops
        self.loop_names = [l.output for l in c.loops]
        path = resolve_fmu(c.fmu, c.fmi_version)
        inputs, outputs = [l.input for l in c.loops], [l.output for l in c.loops]
        self.plant = FmuPlant(path, inputs, outputs, c.sample_time_s, c.plant_parameters, "plant")
        self.scale = np.array([l.measurement_scale for l in c.loops], float)
        self.u_min = np.array([l.u_min for l in c.loops], float)
        self.u_max = np.array([l.u_max for l in c.loops], float)
        self.bound = np.array([l.divergence_bound for l in c.loops], float)
        pid_args = dict(sample_time_s=c.sample_time_s, u_min=self.u_min, u_max=self.u_max,
                        anti_windup=c.anti_windup, derivative_filter_N=c.derivative_filter_N)
        if c.coupled:
            if n != 3:
                raise PlantError(f"the cross-axis coupled PID needs 3 loops (roll, pitch, yaw), got {n}")
            self.pid = CoupledPID(**pid_args)
        else:
            self.pid = PID(n_loops=n, **pid_args)
        self.action_map = ActionMap(c.loops, c.coupled, c.coupling_range)
        self.smoother = make_smoother(c.smoothing, window=c.smoothing_window, alpha=c.smoothing_alpha,
                                      n_params=self.action_map.size)
        self.prior = self.forecast = None
        if c.forecast_horizon > 0:
            prior_path = resolve_fmu(c.prior.fmu, c.fmi_version) if c.prior.fmu else path
            self.prior = FmuPlant(prior_path, inputs, outputs, c.sample_time_s,
                                  {**c.plant_parameters, **c.prior.parameters}, "prior")
            if prior_path != path and not c.prior.state_map:
                raise PlantError(f"prior FMU {prior_path} differs from the plant {path}: its state cannot be "
                                 "copied, so prior.state_map must say which prior parameters take which plant values")
            self.forecast = RewardForecast(c.forecast_horizon, self._reward, self.scale, self.bound,
                                           c.divergence_penalty, StepRejected)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.action_map.size,), np.float32)
        self.observation_space = gym.spaces.Box(-OBS_CLIP, OBS_CLIP, (4 * n,), np.float32)
        self._fmu_disturbances = [d for d in c.disturbances if d.kind == "fmu"]
        self._fmu_defaults = {d.target: self.plant.get([d.target])[0] for d in self._fmu_disturbances}
        # The prior is a model: it knows the plant's state but not the disturbances acting on it, so
        # disturbed FMU inputs/parameters go back to their nominal values after each state copy.
        self._prior_overrides = {**self._fmu_defaults, **c.prior.parameters}

    # -- pieces --------------------------------------------------------------------------------
    def _reward(self, error: np.ndarray, previous_error: np.ndarray) -> float:
        return hierarchical_reward(error, previous_error, self.config.reward)

    def _pid(self, setpoint, measurement, gains: Gains) -> np.ndarray:
        if self.config.coupled:
            return self.pid.step(setpoint, measurement, gains.Kp, gains.Ti, gains.Td, gains.coupling)
        return self.pid.step(setpoint, measurement, gains.Kp, gains.Ti, gains.Td)

    def _setpoint_at(self, k: int) -> np.ndarray:
        c = self.config
        if c.setpoint_schedule is not None:
            value = c.setpoint_schedule[0][1]
            for start, values in c.setpoint_schedule:
                if k >= start:
                    value = values
            return np.asarray(value, float)
        if k % c.setpoint_hold_steps == 0:
            lo = np.array([l.setpoint_range[0] for l in c.loops])
            hi = np.array([l.setpoint_range[1] for l in c.loops])
            self._random_setpoint = self.np_random.uniform(lo, hi)
        return self._random_setpoint

    def _offsets(self, kind: str, k: int) -> np.ndarray:
        out = np.zeros(self.config.n_loops)
        for d in self.config.disturbances:
            if d.kind == kind and d.start_step <= k and (d.end_step is None or k < d.end_step):
                out[self.loop_names.index(d.target)] += d.value
        return out

    def _apply_fmu_disturbances(self, k: int) -> None:
        for d in self._fmu_disturbances:
            if k == d.start_step:
                self.plant.set({d.target: d.value})
            elif d.end_step is not None and k == d.end_step:
                self.plant.set({d.target: self._fmu_defaults[d.target]})

    def _measure(self, y_true: np.ndarray, k: int) -> np.ndarray:
        y = y_true + self._offsets("measurement", k)
        if self.config.measurement_noise_std > 0:
            y = y + self.np_random.normal(0.0, self.config.measurement_noise_std, y.shape)
        return y

    def _observation(self) -> np.ndarray:
        e = self.setpoint - self.measurement
        rate = (e - self.previous_error) / self.config.sample_time_s
        obs = np.stack([self.setpoint, self.measurement, e, rate], axis=1) / self.scale[:, None]
        return np.clip(obs, -OBS_CLIP, OBS_CLIP).astype(np.float32).ravel()

    def _sync_prior(self) -> None:
        c = self.config
        if c.prior.state_map:
            values = self.plant.get(list(c.prior.state_map.values()))
            self.prior.reset(parameters=dict(zip(c.prior.state_map.keys(), values)))
        else:
            self.plant.copy_state_to(self.prior)
            if self._prior_overrides:
                self.prior.set(self._prior_overrides)

    # -- gym API -------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.k = 0
        y_true = self.plant.reset()
        self.pid.reset()
        self.smoother.reset()
        self.setpoint = self._setpoint_at(0)
        self.measurement = self._measure(y_true, 0)
        self.previous_error = self.setpoint - self.measurement
        return self._observation(), {"time_s": 0.0, "setpoint": self.setpoint.copy(),
                                     "measurement": self.measurement.copy()}

    def step(self, action):
        c = self.config
        k = self.k
        raw = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
        gains = self.action_map(self.smoother(raw))
        self._apply_fmu_disturbances(k)
        setpoint, measurement = self.setpoint, self.measurement
        error = (setpoint - measurement) / self.scale

        forecast_reward = None
        if self.forecast is not None:
            self._sync_prior()
            forecast_reward = self.forecast.mean_reward(
                self.prior, self.pid, setpoint, measurement, lambda y: self._pid(setpoint, y, gains))

        u = self._pid(setpoint, measurement, gains)
        u = u + self._offsets("actuator", k)
        if c.actuator_noise_std > 0:
            u = u + self.np_random.normal(0.0, c.actuator_noise_std, u.shape)
        u = np.clip(u, self.u_min, self.u_max)

        terminated = False
        try:
            y_true = self.plant.step(u)
        except StepRejected:
            y_true = np.full(c.n_loops, np.nan)
        self.k = k + 1
        self.previous_error = setpoint - measurement
        self.setpoint = self._setpoint_at(self.k)
        self.measurement = self._measure(y_true, self.k)
        new_error = (setpoint - self.measurement) / self.scale  # against the setpoint u was computed for
        if not np.all(np.isfinite(new_error)) or np.any(np.abs(new_error) > self.bound):
            terminated = True
            reward = c.divergence_penalty
            self.measurement = np.where(np.isfinite(self.measurement), self.measurement, 0.0)
        else:
            reward = forecast_reward if forecast_reward is not None else self._reward(new_error, error)
        truncated = self.k >= c.episode_steps
        info = {"time_s": self.k * c.sample_time_s, "setpoint": setpoint.copy(), "measurement": self.measurement.copy(),
                "control_signal": u, "gains": gains.as_dict(), "forecast_reward": forecast_reward,
                "step_reward": None if terminated else self._reward(new_error, error)}
        return self._observation(), float(reward), terminated, truncated, info

    def close(self):
        for p in (self.plant, self.prior):
            if p is not None:
                p.close()
