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
- NativeForecast (prlpid_fmi.loop.forecast.native): one C call for the bundled plants; bit for bit the
  same result (tests/test_native.py).

`make_forecast` picks one.
"""
from __future__ import annotations

import math

from prlpid_fmi.control.reward import RewardWeights


class Forecast:
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
