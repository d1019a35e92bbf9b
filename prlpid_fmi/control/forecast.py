"""Reward forecast (paper eq. 12-14): roll the prior model N steps ahead with the current gains.

The prior receives the plant's state, a copy of the PID's internal state drives it with fixed gains
(eq. 13) toward the current setpoint, and the mean of the N predicted rewards (eq. 14) is returned.
The plant itself is never stepped, reset or perturbed; the PID's state is restored afterwards.
"""
from __future__ import annotations

from typing import Callable, Protocol

import numpy as np


class PriorModel(Protocol):
    def step(self, u: np.ndarray) -> np.ndarray: ...


class RewardForecast:
    """Mean predicted reward over `horizon` steps of a prior model.

    Args:
        horizon: N >= 1, number of predicted steps.
        reward: reward(error (n_loops,), previous_error (n_loops,)) -> float, errors already normalised.
        measurement_scale: (n_loops,) divisor that normalises errors before the reward.
        divergence_bound: |normalised error| past which the prediction stops with `divergence_penalty`.
        rejected: exception type(s) the prior raises when it discards a step (counts as divergence).
    """

    def __init__(self, horizon: int, reward: Callable[[np.ndarray, np.ndarray], float],
                 measurement_scale: np.ndarray, divergence_bound: np.ndarray, divergence_penalty: float, rejected=()):
        if horizon < 1:
            raise ValueError(f"forecast horizon must be >= 1, got {horizon}")
        self.horizon = horizon
        self.reward = reward
        self.scale = np.asarray(measurement_scale, float)
        self.bound = np.asarray(divergence_bound, float)
        self.bound_list = self.bound.tolist()
        self.penalty = float(divergence_penalty)
        self.rejected = rejected
        self.last_rewards: list[float] = []
        self.last_measurements: list[np.ndarray] = []

    def mean_reward(self, prior: PriorModel, pid, setpoint: np.ndarray, measurement: np.ndarray,
                    control_law: Callable[[np.ndarray], np.ndarray]) -> float:
        """Predict N steps from the current measurement; return the mean predicted reward (eq. 14).

        `prior` must already hold the plant's state. `control_law(measurement) -> u` runs the PID
        with the fixed current gains (eq. 13) and returns the saturated u; its internal state is saved before and restored after.
        """
        saved = pid.get_state()
        rewards = self.last_rewards = []
        self.last_measurements = []
        previous_error = (setpoint - measurement) / self.scale
        y = measurement
        try:
            for _ in range(self.horizon):
                u = control_law(y)  # the PID saturates u itself
                try:
                    y = prior.step(u)
                except self.rejected:
                    rewards.append(self.penalty)
                    break
                error = (setpoint - y) / self.scale
                if not all(abs(e) <= b for e, b in zip(error.tolist(), self.bound_list)):  # also catches NaN
                    rewards.append(self.penalty)
                    break
                rewards.append(self.reward(error, previous_error))
                self.last_measurements.append(y)
                previous_error = error
        finally:
            pid.set_state(saved)
        return sum(rewards) / len(rewards)


class FmiForecast:
    """The reward forecast through the standard FMI path (any FMU that can serialize its state).

    Each call: copy the plant's state into the prior (get, serialize, deserialize, set) — or, for a
    different prior FMU, re-initialise it from `state_map` — apply `overrides` (nominal values of
    disturbed inputs and randomised parameters, prior parameters), roll N steps with the PID's
    current state and the given gains, restore the PID state. Signals are lists of n_loops floats.

    Args:
        plant, prior: FmuPlant instances. pid: the loop's PID or CoupledPID (its state is restored).
        horizon: N >= 1. scale, bound: per-loop measurement scale and divergence bound.
        penalty: reward of a step that diverges or is rejected (the prediction stops there).
        reward: reward(error, previous_error, u, u_prev) -> float on normalised errors.
        overrides: {name: value} set on the prior after each copy. state_map: {prior parameter: plant variable}.
    """

    def __init__(self, plant, prior, pid, horizon: int, scale, bound, penalty: float, reward,
                 overrides: dict | None = None, state_map: dict | None = None):
        if horizon < 1:
            raise ValueError(f"forecast horizon must be >= 1, got {horizon}")
        self.plant, self.prior, self.pid = plant, prior, pid
        self.horizon = horizon
        self.scale, self.bound = list(scale), list(bound)
        self.penalty = float(penalty)
        self.reward = reward
        self.overrides = dict(overrides or {})
        self.state_map = dict(state_map or {})
        self.coupled = hasattr(pid, "pid")
        self.last_rewards: list[float] = []
        self.last_measurements: list[list[float]] = []

    def _sync(self) -> None:
        if self.state_map:
            values = self.plant.get(list(self.state_map.values()))
            self.prior.reset(parameters=dict(zip(self.state_map.keys(), values)))
        else:
            self.plant.copy_state_to(self.prior)
            if self.overrides:
                self.prior.set(self.overrides)

    def mean_reward(self, setpoint, measurement, Kp, Ti, Td, coupling, u_prev) -> float:
        """Mean predicted reward over N steps from (setpoint, measurement) with fixed gains (eq. 12-14)."""
        from ..fmu import StepRejected

        self._sync()
        pid, n, scale, bound = self.pid, len(setpoint), self.scale, self.bound
        saved = pid.get_state()
        rewards = self.last_rewards = []
        measurements = self.last_measurements = []
        previous_error = [(setpoint[i] - measurement[i]) / scale[i] for i in range(n)]
        y = measurement
        try:
            for _ in range(self.horizon):
                if self.coupled:
                    u = pid.step_values(setpoint, y, Kp, Ti, Td, coupling)
                else:
                    u = pid.step_values([setpoint[i] - y[i] for i in range(n)], Kp, Ti, Td)
                try:
                    y = self.prior.step_values(u)
                except StepRejected:
                    rewards.append(self.penalty)
                    break
                error = [(setpoint[i] - y[i]) / scale[i] for i in range(n)]
                if not all(abs(error[i]) <= bound[i] for i in range(n)):  # also catches NaN
                    rewards.append(self.penalty)
                    break
                rewards.append(self.reward(error, previous_error, u, u_prev))
                measurements.append(y)
                previous_error, u_prev = error, u
        finally:
            pid.set_state(saved)
        return sum(rewards) / len(rewards)


def make_forecast(plant, prior, pid, *, horizon: int, scale, bound, penalty: float, weights, u_scale,
                  overrides: dict | None = None, state_map: dict | None = None, path: str = "auto", reward=None):
    """The reward forecast for plant + prior: one C call for bundled plants (path "auto"), else the FMI path.

    reward(error, previous_error, u, u_prev) -> float is the loop's step reward (LoopCore.reward).
    """
    if path not in ("auto", "fmi"):
        raise ValueError(f"forecast path must be 'auto' or 'fmi', got {path!r}")
    return FmiForecast(plant, prior, pid, horizon, scale, bound, penalty, reward, overrides, state_map)
