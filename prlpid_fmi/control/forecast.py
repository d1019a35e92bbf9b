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
