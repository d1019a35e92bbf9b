"""LoopCore: one closed loop (plant FMU, prior, PID, reward, setpoints, disturbances) stepped with gains.

The core takes gains in physical units (Kp, Ti [s], Td [s], coupling). Three drivers use it: the
agent's action path (PidTuningEnv: clip, smoothing, gain map), the fixed-PID search (constant gains)
and the gain-schedule replay (table lookup). None of them reaches into another's internals.

Random load steps (training.load_disturbance, with random setpoints only): the second half of every
setpoint hold has a load at one loop's plant input, drawn at reset (`_random_loads`).

One step k (sample time Ts), all signals plain Python lists of n_loops floats:
  FMU disturbances due at k -> reward forecast on the prior (eq. 12-14, before the plant moves)
  -> PID (eq. 2 / 26-27) on (setpoint_k, measurement_k) -> + actuator offsets and noise -> clip
  -> plant step -> measurement_{k+1} (+ offsets, noise) -> reward (eq. 10-11 + control-variation term).

Bumpless start: before the first PID step the PID is balanced at the first measurement with the plant's
input at t = 0 (its start value, clipped to the limits), i.e. the input that holds an initial steady state
(the two-tank needs 25 cm3/s): the output equals it when the plant starts at the setpoint, a setpoint weight
b != 1 adds no kick, and the rate limit moves from it (control.pid.PID.preset_output). The control-variation term of the first step
is taken against that input too.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.control import PID, CoupledPID
from prlpid_fmi.control.reward import mean_loop_reward
from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu import FmuPlant, StepRejected
from prlpid_fmi.fmu.resolve import resolve_fmu


@dataclass(frozen=True)
class Termination:
    """Why and when an episode ended before its last sample.

    kind: "nan" (the FMU returned a non-finite output), "discard" (doStep discarded the step), "error"
    (the FMU returned error or fatal), "crash" (the FMU's worker process died), "diverged" (|error| /
    measurement_scale passed divergence_bound). step: samples done including the failed one; time_s:
    when it happened [s] (a rejected step: its communication point); message: one line for the report;
    instance: for a crash inside an FMI call, which instance was in it ("plant" or "prior", from the worker's
    crumb), else "".
    """

    kind: str
    step: int
    time_s: float
    message: str
    instance: str = ""

    def as_dict(self) -> dict:
        return {"kind": self.kind, "step": self.step, "time_s": self.time_s, "message": self.message}

    @property
    def invalid_sample(self) -> bool:
        """True when the last sample holds no measurement (only a divergence keeps a real one)."""
        return self.kind != "diverged"


def control_scales(config: TuningConfig) -> list[float]:
    """Per loop, the control-signal span that normalises |u_k - u_{k-1}| in the reward [input units]:
    loop.control_scale, else u_max - u_min when both are finite, else Kp.high * measurement_scale."""
    out = []
    for l in config.loops:
        scale = l.control_scale
        if scale is None:
            span = l.u_max - l.u_min
            scale = span if np.isfinite(span) and span > 0 else l.Kp.high * l.measurement_scale
        out.append(float(scale))
    return out


def randomized_parameters(config: TuningConfig) -> list[tuple[str, float, float]]:
    """training/evaluation `randomize` as (parameter, low, high) triples."""
    spec = config.randomize or ()
    if isinstance(spec, dict):
        return [(name, float(lo), float(hi)) for name, (lo, hi) in spec.items()]
    return [(name, float(lo), float(hi)) for name, lo, hi in spec]


UNTUNED_SETPOINT_WEIGHT = 1.0  # b while controller.setpoint_weight is "tuned" and not yet tuned
UNTUNED_MEASUREMENT_FILTER_S = 0.0  # Tf while controller.measurement_filter is "tuned" and not yet tuned


def pid_structure(config: TuningConfig) -> tuple[list[float], list[float], list[float]]:
    """(b, c, Tf) lists of n_loops floats in force: config.tuned_structure when set, else the controller's
    setpoint_weight, derivative_weight and measurement_filter, "tuned" read as UNTUNED_* (the one rule)."""
    n = config.n_loops
    if config.tuned_structure is not None:
        return ([float(s[0]) for s in config.tuned_structure], [float(s[1]) for s in config.tuned_structure],
                [float(s[2]) for s in config.tuned_structure])
    b = UNTUNED_SETPOINT_WEIGHT if config.setpoint_weight == "tuned" else float(config.setpoint_weight)
    tf = UNTUNED_MEASUREMENT_FILTER_S if config.measurement_filter == "tuned" else float(config.measurement_filter)
    return [b] * n, [float(config.derivative_weight)] * n, [tf] * n


def make_pid(config: TuningConfig) -> PID | CoupledPID:
    """The scenario's PID law, the one construction every loop driver uses: one 2-DOF positional PID per loop
    (control.pid; eq. 2 with b = c = 1, Tf = 0), or the cross-axis coupled PID (eq. 26-27) of three loops;
    actuator limits, anti-windup, derivative filter and structure (pid_structure) from the config."""
    n = config.n_loops
    b, c, tf = pid_structure(config)
    args = dict(sample_time_s=config.sample_time_s, u_min=[float(l.u_min) for l in config.loops],
                u_max=[float(l.u_max) for l in config.loops], anti_windup=config.anti_windup,
                derivative_filter_N=config.derivative_filter_N, setpoint_weight=b, derivative_weight=c,
                measurement_filter_s=tf, measurement_filter_order=config.measurement_filter_order,
                u_rate_limit=[float(l.u_rate_limit) for l in config.loops], gain_change=config.gain_change)
    if config.coupled:
        if n != 3:
            raise PlantError(f"the cross-axis coupled PID needs 3 loops (roll, pitch, yaw), got {n}")
        return CoupledPID(**args)
    return PID(n_loops=n, **args)


def plant_limits(config: TuningConfig) -> dict:
    """FmuPlant's step_timeout_s (plant.step_timeout_s) and stop_time_s: an episode, the forecast's look-ahead
    beyond it and two samples of margin [s], so an FMU that enforces its stop time accepts every step."""
    steps = config.episode_steps + config.forecast_horizon + 2
    return {"step_timeout_s": config.step_timeout_s, "stop_time_s": steps * config.sample_time_s}


class LoopConstants:
    """What every core (LoopCore, and IsolatedCore in front of a worker process) exposes to its drivers, set
    from the config: config, n_loops, loop_names, inputs, scale, bound, u_min, u_max, u_scale, weights,
    penalty (lists of n_loops floats where per loop)."""

    def set_loop_constants(self, config: TuningConfig) -> int:
        """config, n_loops, loop_names, inputs, scale, bound, u_min, u_max, u_scale, weights, penalty from
        `config` (what every core exposes to its drivers); returns n_loops."""
        c = self.config = config
        self.n_loops = c.n_loops
        self.loop_names = [l.output for l in c.loops]
        self.inputs = [l.input for l in c.loops]
        self.scale = [float(l.measurement_scale) for l in c.loops]
        self.bound = [float(l.divergence_bound) for l in c.loops]
        self.u_min = [float(l.u_min) for l in c.loops]
        self.u_max = [float(l.u_max) for l in c.loops]
        self.u_scale = control_scales(c)
        self.weights = c.reward
        self.penalty = float(c.divergence_penalty)
        return self.n_loops


class LoopCore(LoopConstants):
    """The closed loop of one TuningConfig, stepped with PID gains.

    Args:
        config: the tuning problem.
        forecast_path: "auto" (one C call for bundled plants, the FMI path otherwise) | "fmi" (force
            the standard get/serialize/deserialize/set path, as for a third-party FMU).
    After reset/step (lists of n_loops floats): setpoint, measurement (the sample the next step uses),
    and after a step: applied_setpoint (what u was computed for), control_signal (u applied to the plant),
    pid_output (u before actuator offsets and noise), forecast_reward, step_reward, k (samples done),
    termination (None, or the Termination that ended the episode: why and when).
    """

    def __init__(self, config: TuningConfig, forecast_path: str = "auto"):
        c = config
        self.set_loop_constants(c)
        path = resolve_fmu(c.fmu, c.fmi_version)
        self.plant = FmuPlant(path, self.inputs, self.loop_names, c.sample_time_s, c.plant_parameters, "plant",
                              **plant_limits(c))
        self.plant.guard_leaks(c.leak_check_every, c.leak_limit_mb)
        self.pid = make_pid(c)
        self._randomize = randomized_parameters(c)
        for name, _, _ in self._randomize:
            self.plant.description.require(name, ("parameter", "input"), "a randomised parameter")
        self._fmu_disturbances = [d for d in c.disturbances if d.kind == "fmu"]
        self._fmu_defaults = {d.target: float(self.plant.get([d.target])[0]) for d in self._fmu_disturbances}
        self._fmu_events: dict[int, list[tuple[str, float]]] = {}
        for d in self._fmu_disturbances:
            self._fmu_events.setdefault(d.start_step, []).append((d.target, d.value))
            if d.end_step is not None:
                self._fmu_events.setdefault(d.end_step, []).append((d.target, self._fmu_defaults[d.target]))
        self._offsets = {kind: [(d.start_step, d.end_step, self.loop_names.index(d.target), d.value)
                                for d in c.disturbances if d.kind == kind] for kind in ("actuator", "measurement")}
        self._scenario_loads = list(self._offsets["actuator"])
        self.prior = self.forecast = None
        if c.forecast_horizon > 0:
            self.prior, self.forecast = self._make_prior(path, forecast_path)
        self.k = 0
        self.termination: Termination | None = None
        self._rng = np.random.default_rng(0)

    def _make_prior(self, path: Path, forecast_path: str):
        from prlpid_fmi.loop.forecast import make_forecast

        c = self.config
        prior_path = resolve_fmu(c.prior.fmu, c.fmi_version) if c.prior.fmu else path
        mode = "copy"
        if prior_path == path and not c.prior.state_map:
            mode = self.plant.description.prior_mode
            if mode is None:
                raise PlantError(f"{path.name}: cannot serve as its own prior ({self.plant.description.prior_summary()}); "
                                 "set strategies.forecast_horizon: 0, or give a prior.fmu with a state_map")
        if mode == "rollback" or (c.prior_mode == "rollback" and mode is not None and prior_path == path):
            # one instance: the plant itself, its state saved and set back
            prior = self.plant
        else:
            prior = FmuPlant(prior_path, self.inputs, self.loop_names, c.sample_time_s,
                             {**c.plant_parameters, **c.prior.parameters}, "prior", **plant_limits(c))
        if prior_path != path and not c.prior.state_map:
            raise PlantError(f"prior FMU {prior_path} differs from the plant {path}: its state cannot be "
                             "copied, so prior.state_map must say which prior parameters take which plant values")
        # The prior is a model: it knows the plant's state but not the disturbances acting on it nor the
        # randomised parameters, so those return to their nominal values after each state copy.
        nominal = {name: float(c.plant_parameters.get(name, self.plant.get([name])[0]))
                   for name, _, _ in self._randomize}
        overrides = {**self._fmu_defaults, **nominal, **c.prior.parameters}
        forecast = make_forecast(self.plant, prior, self.pid, horizon=c.forecast_horizon, scale=self.scale,
                                 bound=self.bound, penalty=self.penalty, weights=self.weights,
                                 u_scale=self.u_scale, overrides=overrides, state_map=dict(c.prior.state_map),
                                 path=forecast_path)
        return prior, forecast

    # -- episode ------------------------------------------------------------------------------
    def reset(self, rng: np.random.Generator, setpoint_schedule=None) -> None:
        """Start an episode: plant (with freshly drawn randomised parameters) at t = 0, PID reset.

        rng: the episode's random generator (setpoints, noise, randomised parameters).
        setpoint_schedule: ((step, setpoints), ...) for this episode instead of the config's.
        """
        c = self.config
        self._rng = rng
        self._schedule = setpoint_schedule if setpoint_schedule is not None else c.setpoint_schedule
        self.k = 0
        self.termination = None
        if self._randomize:
            drawn = {name: float(rng.uniform(lo, hi)) for name, lo, hi in self._randomize}
            y_true = self.plant.reset(parameters=drawn).tolist()
        else:
            y_true = self.plant.reset().tolist()
        self.pid.reset()
        self._bumpless = True
        u0 = self.plant.get(self.inputs).tolist()
        self.pid_output = [min(max(u, lo), hi) for u, lo, hi in zip(u0, self.u_min, self.u_max)]
        self.control_signal = list(self.pid_output)
        self._noise_y = self._noise_u = None
        if c.measurement_noise_std > 0:
            self._noise_y = rng.normal(0.0, c.measurement_noise_std, (c.episode_steps + 1, self.n_loops)).tolist()
        if c.actuator_noise_std > 0:
            self._noise_u = rng.normal(0.0, c.actuator_noise_std, (c.episode_steps + 1, self.n_loops)).tolist()
        self.setpoint = self._setpoint_at(0)
        self.random_loads = self._random_loads(rng)  # (start, end, loop, value) of this episode, public for replays
        self._offsets["actuator"] = self._scenario_loads + self.random_loads
        self.measurement = self._measure(y_true, 0)
        self.previous_error = [r - y for r, y in zip(self.setpoint, self.measurement)]
        self.applied_setpoint = list(self.setpoint)
        self.forecast_reward = self.step_reward = None

    def _random_loads(self, rng: np.random.Generator) -> list[tuple]:
        """training.load_disturbance: with random setpoints, in the second half of every setpoint hold a load
        step at a random loop's plant input, a random sign, load_disturbance x its control span; as actuator
        offsets (start, end, loop, value)."""
        c = self.config
        if not c.load_disturbance > 0 or self._schedule is not None:
            return []
        hold, loads = c.setpoint_hold_steps, []
        for start in range(0, c.episode_steps, hold):
            i = int(rng.integers(self.n_loops))
            sign = 1.0 if rng.random() < 0.5 else -1.0
            loads.append((start + hold // 2, start + hold, i, sign * c.load_disturbance * self.u_scale[i]))
        return loads

    def _setpoint_at(self, k: int) -> list[float]:
        c = self.config
        if self._schedule is not None:
            value = self._schedule[0][1]
            for start, values in self._schedule:
                if k >= start:
                    value = values
            return [float(v) for v in value]
        if k % c.setpoint_hold_steps == 0:
            lo = [l.setpoint_range[0] for l in c.loops]
            hi = [l.setpoint_range[1] for l in c.loops]
            self._random_setpoint = self._rng.uniform(lo, hi).tolist()
        return self._random_setpoint

    def _offset(self, kind: str, k: int, values: list[float]) -> list[float]:
        out = values
        for start, end, i, value in self._offsets[kind]:
            if start <= k and (end is None or k < end):
                out = list(out) if out is values else out
                out[i] += value
        return out

    def _noise(self, table, k: int) -> list[float]:
        if k >= len(table):  # a caller stepping past episode_steps: extend the pre-drawn noise
            std = self.config.measurement_noise_std if table is self._noise_y else self.config.actuator_noise_std
            table.extend(self._rng.normal(0.0, std, (k + 1 - len(table), self.n_loops)).tolist())
        return table[k]

    def _measure(self, y_true: list[float], k: int) -> list[float]:
        y = self._offset("measurement", k, y_true) if self._offsets["measurement"] else y_true
        if self._noise_y is not None:
            y = [a + b for a, b in zip(y, self._noise(self._noise_y, k))]
        return y

    def reward(self, error: list[float], previous_error: list[float], u: list[float], u_prev: list[float]) -> float:
        """Eq. 10-11 plus the control-variation term, mean over loops; errors normalised."""
        return mean_loop_reward(error, previous_error, self.weights, u, u_prev, self.u_scale)

    def step(self, Kp: list[float], Ti: list[float], Td: list[float], coupling: list[float] | None = None
             ) -> tuple[float, bool]:
        """One sample with gains Kp, Ti [s], Td [s] (lists of n_loops floats) and coupling (6 floats or None).

        Returns (reward, terminated): terminated when the plant rejects the step, a measurement is not
        finite, or |error| / measurement_scale exceeds divergence_bound (reward = divergence penalty).
        """
        self.begin_step()
        setpoint, measurement = self.setpoint, self.measurement
        if self._bumpless:
            self._bumpless = False
            self.pid.preset_output(self.pid_output, measurement, Kp, Ti)
        self.forecast_reward = None
        if self.forecast is not None:
            self.forecast_reward = self.forecast.mean_reward(setpoint, measurement, Kp, Ti, Td, coupling,
                                                             self.pid_output)
        if coupling is not None:
            u = self.pid.step_values(setpoint, measurement, Kp, Ti, Td, coupling)
        else:
            u = self.pid.step_values(setpoint, measurement, Kp, Ti, Td)
        return self._apply(u)

    def set_structure(self, setpoint_weight: list[float], derivative_weight: list[float],
                      measurement_filter_s: list[float]) -> None:
        """Change the PID's b, c and Tf (n_loops floats each) for the next episodes (the fixed-PID search);
        call between episodes."""
        self.pid.set_structure(setpoint_weight, derivative_weight, measurement_filter_s)

    def step_control(self, u: list[float]) -> tuple[float, bool]:
        """One sample with the control signal u (n_loops floats, before actuator offsets, noise and
        limits) instead of the PID: for open-loop tests and reference controllers. No forecast."""
        self.begin_step()
        self._bumpless = False
        self.forecast_reward = None
        return self._apply([float(x) for x in u])

    def begin_step(self) -> None:
        """Apply the FMU disturbances due at this sample (idempotent; every step calls it first)."""
        events = self._fmu_events.get(self.k)
        if events:
            self.plant.set(dict(events))

    def _apply(self, u: list[float]) -> tuple[float, bool]:
        """Apply the controller's output u: offsets, noise, limits, plant step, measurement, reward."""
        k, n, scale = self.k, self.n_loops, self.scale
        setpoint, measurement = self.setpoint, self.measurement
        error = [(setpoint[i] - measurement[i]) / scale[i] for i in range(n)]
        u_prev = self.pid_output
        self.pid_output = u
        applied = self._offset("actuator", k, u) if self._offsets["actuator"] else u
        if self._noise_u is not None:
            applied = [a + b for a, b in zip(applied, self._noise(self._noise_u, k))]
        umin, umax = self.u_min, self.u_max
        applied = [umin[i] if applied[i] < umin[i] else umax[i] if applied[i] > umax[i] else applied[i]
                   for i in range(n)]
        self.control_signal = applied
        failure = None
        try:
            y_true = self.plant.step_values(applied)
        except StepRejected as exc:
            y_true, failure = [float("nan")] * n, ("discard", str(exc))
        except PlantError as exc:  # doStep or reading the outputs returned error or fatal
            y_true, failure = [float("nan")] * n, ("error", str(exc))
        self.k = k = k + 1
        self.applied_setpoint = setpoint
        self.previous_error = [setpoint[i] - measurement[i] for i in range(n)]
        self.setpoint = self._setpoint_at(k)
        y = self.measurement = self._measure(y_true, k)
        new_error = [(setpoint[i] - y[i]) / scale[i] for i in range(n)]
        bound = self.bound
        if not all(abs(new_error[i]) <= bound[i] for i in range(n)):  # also catches NaN
            self.step_reward = None
            self.termination = self._why(failure, y_true, new_error)
            self.measurement = [v if v == v and abs(v) != float("inf") else 0.0 for v in y]
            return self.penalty, True
        self.step_reward = self.reward(new_error, error, u, u_prev)
        return (self.forecast_reward if self.forecast_reward is not None else self.step_reward), False

    def _why(self, failure, y_true: list[float], error: list[float]) -> "Termination":
        """The Termination of the step just done (k samples): a rejected step, a non-finite output or divergence."""
        t = self.k * self.config.sample_time_s
        if failure is not None:
            return Termination(failure[0], self.k, t - self.config.sample_time_s, " ".join(failure[1].split()))
        for name, v in zip(self.loop_names, y_true):
            if not math.isfinite(v):
                value = "NaN" if v != v else repr(v)
                return Termination("nan", self.k, t, f"{self.plant.path.name} returned {value} for {name} at t = {t:g} s")
        worst = max(range(self.n_loops), key=lambda i: abs(error[i]) / self.bound[i] if error[i] == error[i] else math.inf)
        return Termination("diverged", self.k, t,
                           f"diverged: |error| of {self.loop_names[worst]} exceeded the divergence bound "
                           f"({self.bound[worst]:g} x measurement_scale) at t = {t:g} s")

    def close(self) -> None:
        for p in (self.plant, self.prior):
            if p is not None:
                p.close()
