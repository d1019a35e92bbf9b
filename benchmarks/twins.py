"""Independently written numpy twins of PidTuningEnv, the reference cost of the same logic without an FMU.

Written from the paper's equations and the scenario values, not from prlpid_fmi's control code (only
the scenario's TuningConfig is read, as data):

- PID of eq. 2 per loop, clamping anti-windup (e*dt is not added while the output is saturated and the
  error pushes further into the limit), no derivative kick on the first sample; for the quadrotor the
  cross-axis coupled error of eq. 26-27, e = (r - y) + C y.
- ERA smoothing (eq. 21, alpha from the scenario, 0.3 by default) of the raw action in [-1, 1].
- Action map: "log" ranges geometric, "linear" ranges affine, coupling in [-c, c].
- Hierarchical reward of eq. 10-11 (mean over loops) with the default weights.
- Reward forecast of eq. 12-14: copy the plant's numpy state vector into a prior, roll it N samples with
  the PID at the current gains (then restore the PID's state), mean of the N rewards.
- Plants by fixed-step RK4 with the same number of sub-steps per sample as the bundled FMU
  (its `fixed_step` start value, read from the FMU at run time): FirstOrderUnstable dx = a x + b u,
  TwoTank (plant_sources/TwoTank/model.c, levels never negative), QuadrotorAttitude (eq. 25).
- Observation, 4 features per loop: setpoint, measurement, error, error rate, divided by the loop's
  measurement scale and clipped to [-10, 10]; measurement and actuator noise; divergence ends the episode.

Random draws are made from `self.np_random` in the order the environment makes them (at reset the
episode's measurement noise, then its actuator noise, then the first setpoint; later setpoints as they
come), so with the same seed and actions a twin reproduces PidTuningEnv's trajectory (see `agreement`).

The twins hold vectors (action, gains, state, observation) in numpy, as a user would write them; the
per-loop arithmetic of the PID, the reward and the plant's right-hand side runs on Python floats, because
numpy on 1-6-element vectors costs about 10 us per RK4 sub-step (measured here), which would make the twin
measure numpy's call overhead instead of the logic. Nothing else is tuned for speed.
"""
from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree as ET
from zipfile import ZipFile

import gymnasium as gym
import numpy as np
import yaml

PLANT_SOURCES = Path(__file__).resolve().parents[1] / "plant_sources"
OBS_LIMIT = 10.0
# Eq. 10-11 weights (the defaults of the paper's reward): alpha, beta, V clip, |e| clip, bonus band.
REWARD_ALPHA, REWARD_BETA, V_CLIP, E_CLIP = 1.0, 1.0, 0.5, 1.0
BONUS_THRESHOLD, BONUS_NUMERATOR, BONUS_OFFSET = 0.05, 0.1, 0.05


def fmu_fixed_step(fmu_path: Path) -> float:
    """Start value of the `fixed_step` variable (internal RK4 step, s) in the FMU's modelDescription.xml."""
    with ZipFile(fmu_path) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    for var in root.iter():
        if var.get("name") == "fixed_step":
            start = var.get("start")
            if start is None:  # FMI 2.0: <ScalarVariable><Real start=.../></ScalarVariable>
                start = next(child.get("start") for child in var if child.get("start") is not None)
            return float(start)
    raise ValueError(f"{fmu_path}: no fixed_step variable in modelDescription.xml")


def plant_start_values(plant: str) -> dict[str, float]:
    """Start values of every variable with one in plant_sources/<plant>/model.yaml."""
    spec = yaml.safe_load((PLANT_SOURCES / plant / "model.yaml").read_text())
    return {v["name"]: float(v["start"]) for v in spec["variables"] if "start" in v}


# -- plants ------------------------------------------------------------------------------------------
class RK4Plant:
    """A plant integrated by fixed-step RK4: ceil(Ts / fixed_step) sub-steps of Ts / n per sample.

    `x` is the state, a numpy vector; `step(u)` takes the loop inputs (floats) and returns the loop
    outputs (floats), NaN when a state became non-finite (the last finite state is kept). `calls`
    counts the steps (the benchmark uses it to split the twin's time into RK4 and the rest).
    """

    def __init__(self, values: dict[str, float], inputs: list[str], outputs: list[str],
                 sample_time_s: float, fixed_step_s: float):
        self.v = dict(values)
        self.inputs, self.outputs = inputs, outputs
        self.n_sub = max(1, math.ceil(sample_time_s / fixed_step_s - 1e-9))
        self.dt = sample_time_s / self.n_sub
        self.calls = 0
        self.reset()

    def reset(self) -> None:
        self.x = np.array(self.initial_state(), dtype=float)

    def step(self, u) -> list[float]:
        self.calls += 1
        for name, value in zip(self.inputs, u):
            self.v[name] = value
        x, dt = self.x.tolist(), self.dt
        for _ in range(self.n_sub):
            k1 = self.derivatives(x)
            k2 = self.derivatives([xi + 0.5 * dt * ki for xi, ki in zip(x, k1)])
            k3 = self.derivatives([xi + 0.5 * dt * ki for xi, ki in zip(x, k2)])
            k4 = self.derivatives([xi + dt * ki for xi, ki in zip(x, k3)])
            x = self.constrain([xi + dt / 6.0 * (a + 2.0 * b + 2.0 * c + d)
                                for xi, a, b, c, d in zip(x, k1, k2, k3, k4)])
            if not all(math.isfinite(xi) for xi in x):
                return [math.nan] * len(self.outputs)
        self.x = np.array(x)
        return self.measure(x)

    def constrain(self, x: list[float]) -> list[float]:
        return x


class FirstOrderUnstable(RK4Plant):
    """dx/dt = a x + b u, y = x."""

    def initial_state(self):
        return [self.v["x0"]]

    def derivatives(self, x):
        return [self.v["a"] * x[0] + self.v["b"] * self.v["u"]]

    def measure(self, x):
        return [x[0]]


class TwoTank(RK4Plant):
    """Eq. 24: two interacting tanks, inflow q_in + q_d into tank 1, level h2 of tank 2 measured."""

    def initial_state(self):
        return [self.v["h1_0"], self.v["h2_0"]]

    def derivatives(self, x):
        v = self.v
        h1, h2 = x
        q12 = v["valve_factor"] * v["k1"] * math.sqrt(max(h1 - h2, 0.0))
        q_out = v["k2"] * math.sqrt(max(h2, 0.0))
        dh1 = (v["q_in"] + v["q_d"] - q12) / v["A1"]
        dh2 = (q12 - q_out) / v["A2"]
        if h1 <= 0.0 and dh1 < 0.0:  # an empty tank does not drain
            dh1 = 0.0
        if h2 <= 0.0 and dh2 < 0.0:
            dh2 = 0.0
        return [dh1, dh2]

    def constrain(self, x):
        return [max(x[0], 0.0), max(x[1], 0.0)]

    def measure(self, x):
        return [{"h1": x[0], "h2": x[1]}[name] for name in self.outputs]


class QuadrotorAttitude(RK4Plant):
    """Eq. 25: roll, pitch, yaw angles and rates with gyroscopic coupling; torques U_phi, U_theta, U_psi."""

    STATES = ("phi", "theta", "psi", "p", "q", "r")

    def initial_state(self):
        return [self.v[f"{s}0"] for s in self.STATES]

    def derivatives(self, x):
        v = self.v
        Ix, Iy, Iz = v["Ix"], v["Iy"], v["Iz"]
        p, q, r = x[3], x[4], x[5]
        return [p, q, r,
                (Iy - Iz) / Ix * q * r + v["U_phi"] / Ix,
                (Iz - Ix) / Iy * p * r + v["U_theta"] / Iy,
                (Ix - Iy) / Iz * p * q + v["U_psi"] / Iz]

    def measure(self, x):
        return [x[self.STATES.index(name)] for name in self.outputs]


PLANTS = {cls.__name__: cls for cls in (FirstOrderUnstable, TwoTank, QuadrotorAttitude)}


# -- control pieces -----------------------------------------------------------------------------------
def loop_reward(e: float, e_prev: float) -> float:
    """Eq. 10-11 for one loop on normalised errors: -ReLU(dV) - a clip(V) - b clip(|e|) + bonus."""
    v = 0.5 * e * e
    growth = v - 0.5 * e_prev * e_prev
    r = -max(growth, 0.0) - REWARD_ALPHA * min(v, V_CLIP) - REWARD_BETA * min(abs(e), E_CLIP)
    if abs(e) < BONUS_THRESHOLD:
        r += BONUS_NUMERATOR / (abs(e) + BONUS_OFFSET)
    return r


def reward(errors, previous) -> float:
    return sum(loop_reward(e, p) for e, p in zip(errors, previous)) / len(errors)


class TwinPID:
    """Eq. 2 per loop, clamping anti-windup; coupled error of eq. 27 when `coupled`."""

    def __init__(self, n_loops: int, sample_time_s: float, u_min, u_max, coupled: bool):
        self.n, self.dt, self.u_min, self.u_max, self.coupled = n_loops, sample_time_s, u_min, u_max, coupled
        self.reset()

    def reset(self) -> None:
        self.integral = [0.0] * self.n
        self.last_error = None

    def state(self):
        return list(self.integral), self.last_error

    def restore(self, state) -> None:
        self.integral, self.last_error = list(state[0]), state[1]

    def __call__(self, setpoint, measurement, gains: list[float]) -> list[float]:
        n, dt = self.n, self.dt
        errors = [r - y for r, y in zip(setpoint, measurement)]
        if self.coupled:  # c_rp, c_ry, c_pr, c_py, c_yr, c_yp
            c = gains[3 * n:]
            y = measurement
            errors[0] += c[0] * y[1] + c[1] * y[2]
            errors[1] += c[2] * y[0] + c[3] * y[2]
            errors[2] += c[4] * y[0] + c[5] * y[1]
        last = self.last_error if self.last_error is not None else errors
        u = []
        for i, e in enumerate(errors):
            kp, ti, td = gains[3 * i], gains[3 * i + 1], gains[3 * i + 2]
            integral = self.integral[i] + e * dt
            u_try = kp * (e + integral / ti + td * (e - last[i]) / dt)
            u_i = min(max(u_try, self.u_min[i]), self.u_max[i])
            if (u_try - u_i) * (kp * e) <= 0:  # not winding up further into a limit
                self.integral[i] = integral
            u.append(u_i)
        self.last_error = errors
        return u


# -- the environment ---------------------------------------------------------------------------------
class TwinEnv(gym.Env):
    """PidTuningEnv's step, reset, spaces and episode logic on a numpy/float plant.

    Args:
        config: the scenario's TuningConfig (read as data: loops, ranges, horizon, episodes, noise).
        fixed_step_s: the bundled FMU's internal RK4 step (s), see fmu_fixed_step.
    """

    metadata = {"render_modes": []}

    def __init__(self, config, fixed_step_s: float):
        c = config
        if c.smoothing not in ("era", "none") or c.anti_windup != "clamping" or c.derivative_filter_N is not None:
            raise ValueError("the twin implements ERA/no smoothing, clamping anti-windup and no derivative filter")
        if c.disturbances or c.setpoint_schedule is not None or c.prior.fmu or c.prior.parameters:
            raise ValueError("the twin covers the training scenarios: no disturbances, schedules or prior mismatch")
        loops = c.loops
        self.n = n = len(loops)
        self.Ts = c.sample_time_s
        inputs, outputs = [l.input for l in loops], [l.output for l in loops]
        values = {**plant_start_values(c.fmu), **c.plant_parameters}
        self.plant = PLANTS[c.fmu](values, inputs, outputs, c.sample_time_s, fixed_step_s)
        self.prior = PLANTS[c.fmu](values, inputs, outputs, c.sample_time_s, fixed_step_s)
        self.pid = TwinPID(n, c.sample_time_s, [l.u_min for l in loops], [l.u_max for l in loops], c.coupled)
        # bumpless start: the integral term starts at the plant's input at t = 0 (e.g. two_tank's trim q_in)
        self.u_start = [min(max(values.get(l.input, 0.0), l.u_min), l.u_max) for l in loops]
        self.u_min = np.array([l.u_min for l in loops])
        self.u_max = np.array([l.u_max for l in loops])
        self.sp_low = np.array([l.setpoint_range[0] for l in loops])
        self.sp_high = np.array([l.setpoint_range[1] for l in loops])
        self.scale = np.array([l.measurement_scale for l in loops])
        self.bound = np.array([l.divergence_bound for l in loops])
        ranges = [(r.low, r.high, r.scale) for l in loops for r in (l.Kp, l.Ti, l.Td)]
        ranges += [(-c.coupling_range, c.coupling_range, "linear")] * (6 if c.coupled else 0)
        low, high, scale = (np.array(column) for column in zip(*ranges))
        self.log_scale = scale == "log"
        self.low = np.where(self.log_scale, np.log(np.where(self.log_scale, low, 1.0)), low)
        self.span = np.where(self.log_scale, np.log(np.where(self.log_scale, high, 1.0)), high) - self.low
        self.alpha = 1.0 if c.smoothing == "none" else (c.smoothing_alpha or 0.3)
        self.horizon = c.forecast_horizon
        self.penalty = c.divergence_penalty
        self.episode_steps, self.hold_steps = c.episode_steps, c.setpoint_hold_steps
        self.noise_y, self.noise_u = c.measurement_noise_std, c.actuator_noise_std
        self.action_space = gym.spaces.Box(-1.0, 1.0, (len(ranges),), np.float32)
        self.observation_space = gym.spaces.Box(-OBS_LIMIT, OBS_LIMIT, (4 * n,), np.float32)

    def _noise(self, table, std, k):
        """Row k of a noise table drawn at reset (one row per sample), extended past the episode's end."""
        if k >= len(table):
            table.extend(self.np_random.normal(0.0, std, (k + 1 - len(table), self.n)))
        return table[k]

    def _measure(self, y):
        y = np.array(y)
        if self.noise_y > 0:
            y = y + self._noise(self.noise_y_table, self.noise_y, self.k)
        return y

    def _gains(self, smoothed) -> list[float]:
        frac = (smoothed + 1.0) / 2.0
        value = self.low + frac * self.span
        return np.where(self.log_scale, np.exp(value), value).tolist()

    def _observation(self):
        e = self.setpoint - self.measurement
        rate = (e - self.previous_error) / self.Ts
        obs = np.stack([self.setpoint, self.measurement, e, rate], axis=1) / self.scale[:, None]
        return np.clip(obs, -OBS_LIMIT, OBS_LIMIT).astype(np.float32).ravel()

    def _forecast(self, gains) -> float:
        """Mean reward of N prior samples from a copy of the plant's state (eq. 12-14)."""
        self.prior.x = self.plant.x.copy()
        self.prior.v = dict(self.plant.v)
        saved = self.pid.state()
        setpoint = self.setpoint.tolist()
        scale, bound = self.scale.tolist(), self.bound.tolist()
        previous = [(r - y) / s for r, y, s in zip(setpoint, self.measurement.tolist(), scale)]
        y = self.measurement.tolist()
        rewards = []
        for _ in range(self.horizon):
            y = self.prior.step(self.pid(setpoint, y, gains))
            error = [(r - yi) / s for r, yi, s in zip(setpoint, y, scale)]
            if not all(abs(e) <= b for e, b in zip(error, bound)):  # NaN fails too
                rewards.append(self.penalty)
                break
            rewards.append(reward(error, previous))
            previous = error
        self.pid.restore(saved)
        return sum(rewards) / len(rewards)

    def _draw_setpoint(self):
        if self.k % self.hold_steps == 0:
            self.setpoint = self.np_random.uniform(self.sp_low, self.sp_high)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.k = 0
        self.plant.reset()
        self.pid.reset()
        self.smoothed = None
        # Noise for the whole episode, measurement then actuator, drawn before the first setpoint.
        steps = (self.episode_steps + 1, self.n)
        self.noise_y_table = list(self.np_random.normal(0.0, self.noise_y, steps)) if self.noise_y > 0 else None
        self.noise_u_table = list(self.np_random.normal(0.0, self.noise_u, steps)) if self.noise_u > 0 else None
        self._draw_setpoint()
        self.measurement = self._measure(self.plant.measure(self.plant.x.tolist()))
        self.previous_error = self.setpoint - self.measurement
        return self._observation(), {}

    def step(self, action):
        raw = np.clip(np.asarray(action, dtype=float), -1.0, 1.0)
        self.smoothed = raw if self.smoothed is None else self.alpha * raw + (1.0 - self.alpha) * self.smoothed
        gains = self._gains(self.smoothed)
        setpoint, measurement = self.setpoint, self.measurement
        error = (setpoint - measurement) / self.scale
        if self.k == 0:
            for i, u0 in enumerate(self.u_start):
                ki = gains[3 * i] / gains[3 * i + 1]
                if u0 != 0.0 and ki != 0.0:
                    self.pid.integral[i] = u0 / ki
        forecast = self._forecast(gains) if self.horizon > 0 else None

        u = np.array(self.pid(setpoint.tolist(), measurement.tolist(), gains))
        if self.noise_u > 0:
            u = u + self._noise(self.noise_u_table, self.noise_u, self.k)
        y = self.plant.step(np.clip(u, self.u_min, self.u_max).tolist())

        self.k += 1
        self.previous_error = setpoint - measurement
        self._draw_setpoint()
        self.measurement = self._measure(y)
        new_error = (setpoint - self.measurement) / self.scale
        terminated = not np.all(np.abs(new_error) <= self.bound)  # NaN fails too
        if terminated:
            r = self.penalty
            self.measurement = np.where(np.isfinite(self.measurement), self.measurement, 0.0)
        else:
            r = forecast if forecast is not None else reward(new_error.tolist(), error.tolist())
        return self._observation(), float(r), terminated, self.k >= self.episode_steps, {}


def make_twin(config) -> TwinEnv:
    """The twin of PidTuningEnv(config) for a bundled plant, with the bundled FMU's sub-step count."""
    from prlpid_fmi.fmu import bundled_fmu

    return TwinEnv(config, fmu_fixed_step(bundled_fmu(config.fmu, config.fmi_version)))


def agreement(env, twin, steps: int, seed: int = 0) -> tuple[float, float]:
    """Max |difference| of observations and of rewards over `steps` steps with the same seeded random actions.

    Both are reset with `seed` and again (unseeded) whenever an episode ends; small values mean the twin
    does the same work as the environment.
    """
    actions = np.random.default_rng(seed).uniform(-1.0, 1.0, (steps, env.action_space.shape[0])).astype(np.float32)
    obs_a, _ = env.reset(seed=seed)
    obs_b, _ = twin.reset(seed=seed)
    d_obs = float(np.max(np.abs(obs_a - obs_b)))
    d_reward = 0.0
    for a in actions:
        obs_a, r_a, term_a, trunc_a, _ = env.step(a)
        obs_b, r_b, term_b, trunc_b, _ = twin.step(a)
        d_obs = max(d_obs, float(np.max(np.abs(obs_a - obs_b))))
        d_reward = max(d_reward, abs(r_a - r_b))
        if (term_a, trunc_a) != (term_b, trunc_b):
            return math.inf, math.inf
        if term_a or trunc_a:
            env.reset()
            twin.reset()
    return d_obs, d_reward
