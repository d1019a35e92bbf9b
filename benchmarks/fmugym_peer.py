"""The peer a user would pick instead: FMUGym (`pip install fmugym`) tuning a PID on the same bundled FMU.

What a user adds to FMUGym, and no more: the PID gains (Kp, Ti, Td per loop, plus the six coupling
coefficients of eq. 27 for the quadrotor) are its action in physical units; the PID of eq. 2 with
clamping anti-windup runs in `_process_action` and returns the plant inputs; the reward is -sum(e^2);
the observation is (setpoints, measurements); a random setpoint per episode; FMUGym's own `terminations`
end an episode whose output leaves the divergence band, and its `stop_time` ends it after the scenario's
episode length. FMUGym forecasts nothing, smooths nothing and has no hierarchical reward.

FMUGym's own behaviour, kept as is: every reset re-extracts the FMU archive into a new temporary folder
and instantiates it again, and when `stop_time` or a termination is reached inside `step()` it resets
itself before stepping on (so a training loop that resets on `terminated` resets twice).

fmugym 0.2 declares gymnasium < 0.30; it runs unchanged on the gymnasium this project uses, so it is
installed beside it (`pip install --no-deps fmugym`, or the `bench` extra, which resolves to gymnasium 0.29).
"""
from __future__ import annotations

import numpy as np

try:
    import gymnasium as gym
    from fmpy import read_model_description
    from fmugym import FMUGym, FMUGymConfig, VarSpace
except ImportError as exc:  # the benchmark prints this and skips the column
    UNAVAILABLE = f"fmugym not importable ({exc}); install it with: pip install --no-deps 'fmugym>=0.2,<0.3'"
else:
    UNAVAILABLE = None

    class PidOnFmuGym(FMUGym):
        """FMUGym env whose action is the PID's gains; see the module docstring."""

        def __init__(self, config, *, gain_low, gain_high, setpoint_low, setpoint_high, u_min, u_max,
                     coupled: bool, start_values: dict):
            self.init_states = dict(start_values)  # {value reference: value}, set at every (re)initialisation
            self.gain_low, self.gain_high = np.asarray(gain_low, np.float32), np.asarray(gain_high, np.float32)
            self.setpoint_low, self.setpoint_high = np.asarray(setpoint_low), np.asarray(setpoint_high)
            self.u_min, self.u_max = np.asarray(u_min), np.asarray(u_max)
            self.n = len(self.setpoint_low)
            self.coupled = coupled
            self.setpoint = (self.setpoint_low + self.setpoint_high) / 2
            self.measurement = np.zeros(self.n)
            super().__init__(config)

        def _create_action_space(self, inputs):
            return gym.spaces.Box(self.gain_low, self.gain_high, dtype=np.float32)

        def _create_observation_space(self, outputs):
            return gym.spaces.Box(-np.inf, np.inf, (2 * self.n,), np.float32)

        def reset(self, seed=None, options=None):
            self.integral, self.last_error = np.zeros(self.n), None
            _, info = super().reset(seed=seed, options=options)
            self.setpoint = self.np_random.uniform(self.setpoint_low, self.setpoint_high)
            return self._get_obs(), info

        def _get_obs(self):
            self.measurement = super()._get_obs().astype(float)
            return np.concatenate([self.setpoint, self.measurement]).astype(np.float32)

        def _process_action(self, action):
            n, dt, y = self.n, self.dt_action, self.measurement
            kp, ti, td = action[0:3 * n:3], action[1:3 * n:3], action[2:3 * n:3]
            e = self.setpoint - y
            if self.coupled:  # eq. 27: e += C y, C = [[0, c_rp, c_ry], [c_pr, 0, c_py], [c_yr, c_yp, 0]]
                c = action[3 * n:]
                e = e + np.array([[0, c[0], c[1]], [c[2], 0, c[3]], [c[4], c[5], 0]]) @ y
            last = e if self.last_error is None else self.last_error
            integral = self.integral + e * dt
            u_try = kp * (e + integral / ti + td * (e - last) / dt)
            u = np.clip(u_try, self.u_min, self.u_max)
            self.integral = np.where((u_try - u) * (kp * e) > 0, self.integral, integral)  # clamping
            self.last_error = e
            return u

        def compute_reward(self, obs, info):
            return -float(np.sum((self.setpoint - self.measurement) ** 2))


def make_peer(tuning, fmu_path):
    """PidOnFmuGym for a TuningConfig's loops on `fmu_path` (the same FMU file PidTuningEnv loads)."""
    if UNAVAILABLE:
        raise RuntimeError(UNAVAILABLE)
    loops, ts = tuning.loops, tuning.sample_time_s
    inputs, outputs, terminations = VarSpace("inputs"), VarSpace("outputs"), VarSpace("terminations")
    for l in loops:
        inputs.add_var_box(l.input, l.u_min, l.u_max)
        outputs.add_var_box(l.output, -np.inf, np.inf)
        band = l.divergence_bound * l.measurement_scale
        terminations.add_var_box(l.output, l.setpoint_range[0] - band, l.setpoint_range[1] + band)
    config = FMUGymConfig(fmu_path=str(fmu_path), start_time=0.0, stop_time=tuning.episode_steps * ts,
                          sim_step_size=ts, action_step_size=ts, inputs=inputs, outputs=outputs,
                          random_vars=VarSpace("random_vars"), terminations=terminations)
    refs = {v.name: v.valueReference for v in read_model_description(str(fmu_path)).modelVariables}
    gain_low = [r.low for l in loops for r in (l.Kp, l.Ti, l.Td)] + [-tuning.coupling_range] * (6 * tuning.coupled)
    gain_high = [r.high for l in loops for r in (l.Kp, l.Ti, l.Td)] + [tuning.coupling_range] * (6 * tuning.coupled)
    return PidOnFmuGym(config, gain_low=gain_low, gain_high=gain_high,
                       setpoint_low=[l.setpoint_range[0] for l in loops],
                       setpoint_high=[l.setpoint_range[1] for l in loops],
                       u_min=[l.u_min for l in loops], u_max=[l.u_max for l in loops], coupled=tuning.coupled,
                       start_values={refs[name]: value for name, value in tuning.plant_parameters.items()})
