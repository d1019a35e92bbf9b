"""A frozen copy of prlpid_fmi/control/pid.py as it was before the 2-DOF law (commit 2860126): the reference
that the new law with b = c = 1 and Tf = 0 must reproduce bit for bit (tests/test_pid_two_dof.py). Do not edit.

Positional PID of paper eq. 2 and the cross-axis coupled MIMO PID of eq. 26-27.

Both are vectorised over ``n_loops`` independent loops: every signal and gain is a scalar or an
array of shape (n_loops,). Gains are passed on every step because the agent changes them online.

Discrete law (eq. 2), sample time dt = ``sample_time_s``::

    I(k) = I(k-1) + e(k)*dt                      error sum, includes the current error   [e.u. * s]
    D(k) = (e(k) - e(k-1)) / dt                  backward difference                      [e.u. / s]
    u(k) = Kp * (e(k) + I(k)/Ti + Td*D(k))       then clipped to [u_min, u_max]

- First sample after ``reset()``: e(-1) := e(0), so D(0) = 0 (no derivative kick).
- ``Ti = inf`` means no integral action (1/inf = 0). The error sum is still kept, exactly as
  eq. 2 writes it; with clamping it also stops growing while the output is saturated.
- Optional derivative filter (``derivative_filter_N``): D is passed through a first-order low pass
  with time constant Tf = Td/N, discretised with backward Euler
  (Tf*(Df(k) - Df(k-1))/dt + Df(k) = D(k))::

      Df(k) = (Tf*Df(k-1) + dt*D(k)) / (Tf + dt)

  Td = 0 gives Tf = 0, i.e. no filtering (and no derivative action anyway).

Anti-windup (``anti_windup``), with u_try = u computed from I(k-1) + e(k)*dt:

- "none": I(k) = I(k-1) + e(k)*dt.
- "clamping" (conditional integration): when u_try lies outside [u_min, u_max] and Kp*e(k) pushes
  further in that direction (for Kp > 0: e has the sign of the saturation), e(k)*dt is NOT added:
  I(k) = I(k-1). The output of that step is clip(u_try) (it is at the limit either way).
- "back_calculation": the continuous law dI/dt = e + (u_sat - u_unsat)/(Ki*Tt), Ki = Kp/Ti (I is the
  error sum, so the tracking signal is divided by Ki to get error units), discretised with
  backward Euler like the rectangular sum of eq. 2::

      I(k) = I(k-1) + dt*e(k) + dt*(u_sat(k) - u_unsat(k)) / (Ki*Tt),  u_unsat(k) = Kp*(e + I(k)/Ti + Td*D)

  Solved in closed form (clipping is piecewise linear and the saturation side does not change)::

      I(k)       = I(k-1) + dt*e(k) + g*(clip(u_try) - u_try)/Ki,   g = dt/(Tt + dt)
      u_unsat(k) = u_try + g*(clip(u_try) - u_try)

  This is unconditionally stable for any Tt > 0. Tt defaults, per step and per loop, to
  sqrt(Ti*Td), or Ti when Td == 0 (Astrom & Hagglund's rule). No correction where Ki == 0.

``unsaturated_u`` is u_try for "none" and "clamping", u_unsat(k) above for "back_calculation".

Signs: the gains are meant to be Kp >= 0, Ti > 0, Td >= 0 (not checked per step, for speed).

Inputs and outputs are numpy arrays of shape (n_loops,) (or scalars), but the arithmetic runs as a
loop over Python floats: a tuning problem has 1-3 loops, and for arrays that small numpy's per-call
overhead (1-4 us per ufunc, more for reductions) dominates. Measured for 3 loops with clamping:
36 us per step as masked numpy expressions, 9 us as this loop.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

ANTI_WINDUP_MODES = ("clamping", "back_calculation", "none")
COUPLING_NAMES = ("c_rp", "c_ry", "c_pr", "c_py", "c_yr", "c_yp")


def parallel_gains(Kp, Ti, Td):
    """Ideal (Kp, Ti, Td) -> parallel (Ki, Kd): Ki = Kp/Ti [1/s], Kd = Kp*Td [s]. Ti = inf gives Ki = 0."""
    Kp = np.asarray(Kp, dtype=float)
    return Kp / np.asarray(Ti, dtype=float), Kp * np.asarray(Td, dtype=float)


@dataclass
class PIDState:
    """Internal state of a PID, all arrays of shape (n_loops,).

    integral: error sum I [error units * s]; last_error: e(k-1) [error units]; derivative: last
    (filtered) derivative D [error units / s]; initialized: False until the first step after reset.
    """

    integral: np.ndarray
    last_error: np.ndarray
    derivative: np.ndarray
    initialized: bool

    def copy(self) -> "PIDState":
        return PIDState(self.integral.copy(), self.last_error.copy(), self.derivative.copy(), self.initialized)


def _per_loop(value, n_loops: int, name: str) -> list:
    """Scalar or (n_loops,) array/sequence -> list of n_loops floats."""
    if isinstance(value, np.ndarray):
        if value.shape == (n_loops,):
            return value.tolist()
        if value.ndim == 0:
            return [float(value)] * n_loops
    elif isinstance(value, (list, tuple)):
        if len(value) == n_loops:
            return [float(v) for v in value]
    else:
        return [float(value)] * n_loops
    raise ValueError(f"{name} must be a scalar or have shape ({n_loops},), got shape {np.shape(value)}")


class PID:
    """Positional PID (eq. 2) for ``n_loops`` independent loops with saturation and anti-windup.

    Args:
        sample_time_s: dt [s], > 0.
        n_loops: number of independent loops.
        u_min, u_max: output limits, scalars or (n_loops,) arrays (default unbounded).
        anti_windup: "clamping" | "back_calculation" | "none" (see module docstring).
        Tt: back-calculation tracking time constant [s], scalar or (n_loops,); None = sqrt(Ti*Td),
            or Ti when Td == 0, evaluated every step with the current gains.
        derivative_filter_N: None = unfiltered derivative; else filter time constant Td/N.

    ``unsaturated_u`` (n_loops,): u before saturation in the last step (zeros after reset); with
    back-calculation it includes the step's tracking correction (see module docstring).
    """

    def __init__(self, sample_time_s: float, n_loops: int = 1, u_min=-np.inf, u_max=np.inf,
                 anti_windup: str = "clamping", Tt=None, derivative_filter_N: float | None = None):
        if not (np.isfinite(sample_time_s) and sample_time_s > 0):
            raise ValueError(f"sample_time_s must be a finite number > 0, got {sample_time_s!r}")
        if isinstance(n_loops, bool) or int(n_loops) != n_loops or n_loops < 1:
            raise ValueError(f"n_loops must be an integer >= 1, got {n_loops!r}")
        if anti_windup not in ANTI_WINDUP_MODES:
            raise ValueError(f"anti_windup must be one of {ANTI_WINDUP_MODES}, got {anti_windup!r}")
        if derivative_filter_N is not None and not derivative_filter_N > 0:
            raise ValueError(f"derivative_filter_N must be > 0 or None, got {derivative_filter_N!r}")
        self.sample_time_s = float(sample_time_s)
        self.n_loops = n = int(n_loops)
        self._u_min = _per_loop(u_min, n, "u_min")
        self._u_max = _per_loop(u_max, n, "u_max")
        if any(not lo <= hi for lo, hi in zip(self._u_min, self._u_max)):
            raise ValueError(f"u_min must be <= u_max (and not NaN), got u_min={u_min!r}, u_max={u_max!r}")
        self.anti_windup = anti_windup
        self._Tt = None if Tt is None else _per_loop(Tt, n, "Tt")
        if self._Tt is not None and not all(t > 0 for t in self._Tt):
            raise ValueError(f"Tt must be > 0, got {Tt!r}")
        self.derivative_filter_N = None if derivative_filter_N is None else float(derivative_filter_N)
        self.reset()

    @property
    def u_min(self) -> np.ndarray:
        return np.array(self._u_min)

    @property
    def u_max(self) -> np.ndarray:
        return np.array(self._u_max)

    @property
    def Tt(self) -> np.ndarray | None:
        return None if self._Tt is None else np.array(self._Tt)

    @property
    def unsaturated_u(self) -> np.ndarray:
        return np.array(self._unsaturated_u)

    def reset(self) -> None:
        """Zero the error sum and derivative; the next step has no derivative kick."""
        n = self.n_loops
        self._integral = [0.0] * n
        self._last_error = [0.0] * n
        self._derivative = [0.0] * n
        self._initialized = False
        self._unsaturated_u = [0.0] * n

    def get_state(self) -> PIDState:
        """A copy of the internal state (later steps do not change it)."""
        return PIDState(np.array(self._integral), np.array(self._last_error), np.array(self._derivative),
                        self._initialized)

    def raw_state(self) -> tuple[list, list, list, bool]:
        """(integral, last_error, derivative, initialized) WITHOUT copying: the live lists of n_loops floats.

        For readers that copy the values out at once (the C forecast); never mutate them.
        """
        return self._integral, self._last_error, self._derivative, self._initialized

    def set_state(self, state: PIDState) -> None:
        """Restore a state from ``get_state`` (copied in, so ``state`` stays reusable)."""
        n = self.n_loops
        self._integral = _per_loop(np.asarray(state.integral, dtype=float), n, "PIDState.integral")
        self._last_error = _per_loop(np.asarray(state.last_error, dtype=float), n, "PIDState.last_error")
        self._derivative = _per_loop(np.asarray(state.derivative, dtype=float), n, "PIDState.derivative")
        self._initialized = bool(state.initialized)

    def copy(self) -> "PID":
        """An independent PID with the same settings and state."""
        return copy.deepcopy(self)

    def step(self, setpoint, measurement, Kp, Ti, Td) -> np.ndarray:
        """One sample with e = setpoint - measurement; returns saturated u, shape (n_loops,)."""
        return self.step_error(np.subtract(setpoint, measurement, dtype=float), Kp, Ti, Td)

    def step_error(self, error, Kp, Ti, Td) -> np.ndarray:
        """One sample of eq. 2 on a given error (scalar or (n_loops,)); returns saturated u (n_loops,).

        Kp [u per error unit], Ti [s] (> 0, inf = no integral), Td [s] (>= 0): scalars or (n_loops,).
        """
        n = self.n_loops
        return np.array(self.step_values(_per_loop(error, n, "error"), _per_loop(Kp, n, "Kp"),
                                         _per_loop(Ti, n, "Ti"), _per_loop(Td, n, "Td")))

    def step_values(self, errors: list, Kps: list, Tis: list, Tds: list) -> list:
        """`step_error` on lists of n_loops floats, unchecked; returns saturated u as a list. The hot path."""
        n = self.n_loops
        dt = self.sample_time_s
        N = self.derivative_filter_N
        mode = self.anti_windup
        if not self._initialized:
            self._last_error = list(errors)
            self._initialized = True
        integrals, last_errors, derivatives = self._integral, self._last_error, self._derivative
        u_out = [0.0] * n
        u_unsat_out = [0.0] * n

        for i in range(n):
            e, kp, ti, td = errors[i], Kps[i], Tis[i], Tds[i]
            d = (e - last_errors[i]) / dt
            if N is not None:
                tf = td / N
                d = (tf * derivatives[i] + dt * d) / (tf + dt)
            ki = kp / ti
            integral = integrals[i] + e * dt
            u_unsat = kp * (e + td * d) + ki * integral
            lo, hi = self._u_min[i], self._u_max[i]
            u = lo if u_unsat < lo else hi if u_unsat > hi else u_unsat  # NaN passes through
            if u != u_unsat:  # saturated
                if mode == "clamping":
                    if (u_unsat - u) * (kp * e) > 0:  # e*dt would push further into the limit
                        integral = integrals[i]
                elif mode == "back_calculation" and ki != 0:
                    Tt = self._Tt[i] if self._Tt is not None else (math.sqrt(ti * td) if td > 0 else ti)
                    tracked = dt / (Tt + dt) * (u - u_unsat)
                    integral += tracked / ki
                    u_unsat += tracked
            integrals[i] = integral
            last_errors[i] = e
            derivatives[i] = d
            u_out[i] = u
            u_unsat_out[i] = u_unsat

        self._unsaturated_u = u_unsat_out
        return u_out

    def preset_integral(self, u0: list, Kps: list, Tis: list) -> None:
        """Bumpless start: before the first step, set the error sum so that the integral term Kp/Ti*I equals u0.

        u0, Kps, Tis: lists of n_loops floats (u0 in control-signal units). Loops without integral
        action (Ti = inf or Kp = 0) keep I = 0. Call after reset(), before the first step.
        """
        for i in range(self.n_loops):
            ki = Kps[i] / Tis[i]
            self._integral[i] = u0[i] / ki if ki != 0 else 0.0


def coupling_matrix(coupling) -> np.ndarray:
    """(c_rp, c_ry, c_pr, c_py, c_yr, c_yp) -> 3x3 matrix C, zero diagonal, rows/columns (roll, pitch, yaw).

    e_couple = (r - y) + C @ y is eq. 27.
    """
    return np.array(_coupling_rows(_per_loop(coupling, 6, "coupling")))


def _coupling_rows(c: list) -> list:
    c_rp, c_ry, c_pr, c_py, c_yr, c_yp = c
    return [[0.0, c_rp, c_ry],
            [c_pr, 0.0, c_py],
            [c_yr, c_yp, 0.0]]


def _coupled_errors(r: list, y: list, c: list) -> list:
    """Eq. 27 on lists: e_i = (r_i - y_i) + sum_j C[i][j] * y_j, summed left to right (C's diagonal is 0,
    kept in the sum so that the arithmetic is exactly the matrix form's and the C forecast's)."""
    c_rp, c_ry, c_pr, c_py, c_yr, c_yp = c
    y0, y1, y2 = y
    return [r[0] - y0 + 0.0 * y0 + c_rp * y1 + c_ry * y2,
            r[1] - y1 + c_pr * y0 + 0.0 * y1 + c_py * y2,
            r[2] - y2 + c_yr * y0 + c_yp * y1 + 0.0 * y2]


class CoupledPID:
    """Cross-axis coupled PID of eq. 26-27 for (roll, pitch, yaw).

    Coupled error e = (r - y) + C @ y with C = coupling_matrix(coupling), i.e.
    e_roll = (r_roll - roll) + c_rp*pitch + c_ry*yaw, e_pitch = ... + c_pr*roll + c_py*yaw,
    e_yaw = ... + c_yr*roll + c_yp*pitch; each axis is then a PID of eq. 2 on its coupled error.
    Constructor arguments are those of PID (n_loops is fixed to 3). Angles in rad, u in N*m.
    """

    n_loops = 3

    def __init__(self, sample_time_s: float, u_min=-np.inf, u_max=np.inf, anti_windup: str = "clamping",
                 Tt=None, derivative_filter_N: float | None = None):
        self.pid = PID(sample_time_s, 3, u_min, u_max, anti_windup, Tt, derivative_filter_N)

    @property
    def sample_time_s(self) -> float:
        return self.pid.sample_time_s

    @property
    def unsaturated_u(self) -> np.ndarray:
        return self.pid.unsaturated_u

    def coupled_error(self, setpoint, measurement, coupling) -> np.ndarray:
        """e_couple (3,) of eq. 27 from setpoint (3,), measurement (3,), coupling (6,) in COUPLING_NAMES order."""
        return np.array(self._coupled_error(setpoint, measurement, coupling))

    def _coupled_error(self, setpoint, measurement, coupling) -> list:
        return _coupled_errors(_per_loop(setpoint, 3, "setpoint"), _per_loop(measurement, 3, "measurement"),
                               _per_loop(coupling, 6, "coupling"))

    def step(self, setpoint, measurement, Kp, Ti, Td, coupling) -> np.ndarray:
        """One sample of eq. 26; Kp, Ti, Td scalars or (3,); returns saturated u (3,)."""
        return self.pid.step_error(self._coupled_error(setpoint, measurement, coupling), Kp, Ti, Td)

    def step_values(self, r: list, y: list, Kps: list, Tis: list, Tds: list, c: list) -> list:
        """`step` on lists of floats (r, y, gains (3,), coupling (6,)), unchecked; returns u as a list."""
        return self.pid.step_values(_coupled_errors(r, y, c), Kps, Tis, Tds)

    def preset_integral(self, u0: list, Kps: list, Tis: list) -> None:
        self.pid.preset_integral(u0, Kps, Tis)

    def reset(self) -> None:
        self.pid.reset()

    def get_state(self) -> PIDState:
        return self.pid.get_state()

    def raw_state(self) -> tuple[list, list, list, bool]:
        return self.pid.raw_state()

    def set_state(self, state: PIDState) -> None:
        self.pid.set_state(state)

    def copy(self) -> "CoupledPID":
        return copy.deepcopy(self)
