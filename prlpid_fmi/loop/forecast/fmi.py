"""The reward forecast through FMI calls: any FMU that can serialize its state, a re-initialised prior (state_map),
or a single-instance rollback."""
from __future__ import annotations

from prlpid_fmi.control.reward import RewardWeights, mean_loop_reward
from prlpid_fmi.loop.forecast.base import Forecast


class FmiForecast(Forecast):
    """The forecast through the standard FMI calls (any FMU); arguments as Forecast plus

    state_map: {prior parameter: plant variable}; when given, the prior is reset each call with these
        parameters taken from the plant instead of receiving its state (a prior FMU that differs from
        the plant), and the overrides are not applied (the reset prior is nominal already).
    prior may be the plant itself: then each call holds the plant's state (FmuPlant.hold_state), applies
    the overrides, rolls the plant N steps and restores it, so the plant's trajectory is unchanged.

    After a call, `last_rewards` (list of floats) and `last_measurements` (list of n_loops-float lists,
    one per step the prior took) describe the roll-out.
    """

    def __init__(self, plant, prior, pid, horizon: int, scale, bound, penalty: float, weights: RewardWeights,
                 u_scale, overrides: dict | None = None, state_map: dict | None = None):
        from prlpid_fmi.fmu import StepRejected

        super().__init__(plant, prior, pid, horizon, scale, bound, penalty, weights, u_scale, overrides)
        self._rejected = StepRejected
        self.state_map = dict(state_map or {})
        self.rollback = prior is plant
        if self.rollback and self.state_map:
            raise ValueError("a state_map needs a prior FMU other than the plant")
        self.last_rewards: list[float] = []
        self.last_measurements: list[list[float]] = []

    def _sync(self) -> None:
        if self.rollback:
            self.plant.hold_state()
            if self.overrides:
                self.prior.set(self.overrides)
        elif self.state_map:
            values = self.plant.get(list(self.state_map.values()))
            self.prior.reset(parameters=dict(zip(self.state_map.keys(), values.tolist())))
        else:
            self.plant.copy_state_to(self.prior)
            if self.overrides:
                self.prior.set(self.overrides)

    def mean_reward(self, setpoint: list, measurement: list, Kp: list, Ti: list, Td: list, coupling: list | None,
                    u_prev: list) -> float:
        """Mean predicted reward over N steps from (setpoint, measurement) with fixed gains (eq. 12-14).

        All arguments are lists of n_loops floats (coupling: 6 floats, or None when not coupled);
        u_prev is the control signal of the previous sample.
        """
        self._sync()
        pid, prior, n, scale, bound = self.pid, self.prior, self.n_loops, self.scale, self.bound
        weights, u_scale = self.weights, self.u_scale
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
                    u = pid.step_values(setpoint, y, Kp, Ti, Td)
                try:
                    y = prior.step_values(u)
                except self._rejected:
                    rewards.append(self.penalty)
                    break
                measurements.append(y)
                error = [(setpoint[i] - y[i]) / scale[i] for i in range(n)]
                if not all(abs(error[i]) <= bound[i] for i in range(n)):  # also catches NaN
                    rewards.append(self.penalty)
                    break
                rewards.append(mean_loop_reward(error, previous_error, weights, u, u_prev, u_scale))
                previous_error, u_prev = error, u
        finally:
            pid.set_state(saved)
            if self.rollback:
                self.plant.restore_state()
        total = 0.0
        for r in rewards:
            total += r
        return total / len(rewards)
