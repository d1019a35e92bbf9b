"""Reward forecast (paper eq. 12-14): roll the prior model N steps ahead with the current gains.

Before the plant moves, the prior receives the plant's state, a copy of the PID's internal state
drives it with fixed gains (eq. 13) toward the current setpoint, and the mean of the N predicted
rewards (eq. 14) is returned. Per predicted step k = 1..N::

    u_k    = PID(setpoint, y_{k-1})            eq. 2 (or eq. 26-27 when coupled), saturated
    y_k    = prior.step(u_k)                   a discarded step ends the roll-out with the penalty
    e_k    = (setpoint - y_k) / scale          ends the roll-out with the penalty if |e_k| > bound (or NaN)
    r_k    = mean over loops of eq. 10-11 on (e_k, e_{k-1}) + control variation on (u_k, u_{k-1})

with y_0 = the measurement, e_0 its normalised error and u_0 = `u_prev`; the result is
sum(r_k) / (number of r_k), summed left to right. The plant is never stepped, reset or perturbed and
the PID's state is the same afterwards.

Two implementations of one interface, `mean_reward(setpoint, measurement, Kp, Ti, Td, coupling,
u_prev) -> float` on lists of n_loops floats (coupling: 6 floats or None):

- FmiForecast: the standard FMI path for any FMU that can serialize its state (get, serialize,
  deserialize, set), or, for a different prior FMU, a re-initialisation from `state_map`; or, when
  the prior *is* the plant (an FMU that cannot serialize its state or may be instantiated only once
  per process), a single-instance rollback: get the plant's own state, roll N steps, set it back.
- NativeForecast (prlpid_fmi.fmu.native_forecast): one C call for the bundled plants; bit for bit the
  same result (tests/test_native_forecast.py).

`make_forecast` picks one.
"""
from __future__ import annotations

import math

from prlpid_fmi.control.reward import RewardWeights, mean_loop_reward


class _Forecast:
    """What both implementations are built from, validated once.

    Args:
        plant, prior: FmuPlant instances; prior.inputs / prior.outputs are the loops' control inputs
            and measured outputs (n_loops each).
        pid: the loop's PID or CoupledPID; only read (its state is the same after a call).
        horizon: N >= 1 predicted samples.
        scale, bound: per loop, measurement scale (> 0) and divergence bound on |error| / scale.
        penalty: reward of the step that diverges or that the prior discards; the roll-out stops there.
        weights: RewardWeights of eq. 10-11 and the control-variation term.
        u_scale: per loop, control span (> 0) that normalises |u_k - u_{k-1}|.
        overrides: {prior variable: value} set on the prior after each state copy (the nominal values
            of disturbed FMU inputs/parameters and of randomised parameters, prior parameters).
    """

    def __init__(self, plant, prior, pid, horizon: int, scale, bound, penalty: float, weights: RewardWeights,
                 u_scale, overrides: dict | None = None):
        if isinstance(horizon, bool) or int(horizon) != horizon or horizon < 1:
            raise ValueError(f"forecast horizon must be an integer >= 1, got {horizon!r}")
        n = pid.n_loops
        self.plant, self.prior, self.pid = plant, prior, pid
        self.n_loops, self.horizon = n, int(horizon)
        self.scale, self.bound, self.u_scale = ([float(v) for v in x] for x in (scale, bound, u_scale))
        for name, values in (("scale", self.scale), ("bound", self.bound), ("u_scale", self.u_scale)):
            if len(values) != n:
                raise ValueError(f"forecast {name} needs {n} values (one per loop), got {len(values)}")
        if not all(s > 0 and math.isfinite(s) for s in self.scale + self.u_scale):
            raise ValueError(f"measurement and control scales must be finite and > 0, got {self.scale}, {self.u_scale}")
        if len(prior.inputs) != n or len(prior.outputs) != n:
            raise ValueError(f"the prior needs {n} inputs and {n} outputs (one per loop), "
                             f"got {list(prior.inputs)} and {list(prior.outputs)}")
        self.penalty = float(penalty)
        self.weights = weights
        self.overrides = {name: float(value) for name, value in (overrides or {}).items()}
        self.coupled = hasattr(pid, "pid")  # CoupledPID wraps a PID


class FmiForecast(_Forecast):
    """The forecast through the standard FMI calls (any FMU); arguments as _Forecast plus

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
                    u = pid.step_values([setpoint[i] - y[i] for i in range(n)], Kp, Ti, Td)
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


def make_forecast(plant, prior, pid, *, horizon: int, scale, bound, penalty: float, weights: RewardWeights, u_scale,
                  overrides: dict | None = None, state_map: dict | None = None, path: str = "auto"):
    """The reward forecast for this plant and prior.

    path: "auto" = one C call (NativeForecast) when plant and prior are instances of the same FMU file
    loaded once, without a state_map, and its binary exports prlpid_forecast with the ABI this package
    knows (the bundled plants); the FMI path otherwise. "fmi" forces the FMI path (as for a third-party
    FMU); "native" requires the C call (PlantError when it is not available).
    Both paths compute the reward from `weights` and `u_scale` with control.reward, so that they agree
    bit for bit. Other arguments: see _Forecast and FmiForecast.
    """
    if path not in ("auto", "fmi", "native"):
        raise ValueError(f"forecast path must be 'auto', 'fmi' or 'native', got {path!r}")
    args = (plant, prior, pid, horizon, scale, bound, penalty, weights, u_scale, overrides)
    if path != "fmi":
        from prlpid_fmi.loop.forecast.native import NativeForecast, native_unavailable

        reason = "a state_map re-initialises the prior" if state_map else native_unavailable(plant, prior)
        if reason is None:
            return NativeForecast(*args)
        if path == "native":
            from prlpid_fmi.errors import PlantError

            raise PlantError(f"{prior.path.name}: the one-call forecast is not available: {reason}")
    return FmiForecast(*args, state_map=state_map)
