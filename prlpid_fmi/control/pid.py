"""The PID law: a 2-DOF positional PID (setpoint weights, measurement filter) and the coupled MIMO PID of eq. 26-27.

Both are vectorised over ``n_loops`` independent loops: every signal and gain is a scalar or an
array of shape (n_loops,). Gains are passed on every step because the agent changes them online;
the structure (setpoint weights b, c, measurement filter Tf) is held by the PID (``set_structure``).

Discrete law, sample time dt = ``sample_time_s``, per loop::

    yf(k) = F(y(k))                              measurement filter (Tf = 0: yf = y exactly)
    e(k)  = r(k) - y(k)                          integral error (unfiltered: no steady-state offset)
    ep(k) = b*r(k) - yf(k)                       proportional error, setpoint weight b in [0, 1]
    ed(k) = c*r(k) - yf(k)                       derivative error, c in {0, 1} (0: derivative on the measurement)
    I(k)  = I(k-1) + e(k)*dt                     error sum, includes the current error   [e.u. * s]
    D(k)  = (ed(k) - ed(k-1)) / dt               backward difference                      [e.u. / s]
    u(k)  = Kp * (ep(k) + I(k)/Ti + Td*D(k))     then clipped to [u_min, u_max]

With b = c = 1 and Tf = 0 this is paper eq. 2 exactly, bit for bit (1.0*r == r): the paper's variant.

- Measurement filter F (``measurement_filter_s`` Tf [s], ``measurement_filter_order`` 1 or 2): order 1 is
  the low pass 1/(1 + s Tf), order 2 two such sections of Tf/2 each, 1/(1 + s Tf/2)^2 (same mean delay Tf,
  critically damped); each section by backward Euler, x(k) = (T*x(k-1) + dt*in(k)) / (T + dt). The
  sections start at y(0) (no transient at the first sample). F feeds P and D only.
- First sample after ``reset()``: ed(-1) := ed(0), so D(0) = 0 (no derivative kick).
- ``Ti = inf`` means no integral action (1/inf = 0). The error sum is still kept, exactly as
  eq. 2 writes it; with clamping it also stops growing while the output is saturated.
- Optional derivative filter (``derivative_filter_N``): D is passed through a first-order low pass
  with time constant Td/N, discretised with backward Euler::

      Df(k) = (Tdf*Df(k-1) + dt*D(k)) / (Tdf + dt),   Tdf = Td/N

  Td = 0 gives Tdf = 0, i.e. no filtering (and no derivative action anyway).
- Bumpless start (``preset_output``): before the first sample the PID is balanced at the first measurement
  y(0) with the actuator's output u0, as if it had tracked setpoint = measurement in manual:
  I(-1) = (u0 - Kp*((b - 1)*y(0))) / Ki. So u(0) = u0 when r(0) = y(0) (no kick from b either), and a
  setpoint step at t = 0 acts through b like any later one (with b = 1 this is I(-1) = u0 / Ki).
- Rate limit (``u_rate_limit`` R [u units / s], per loop, inf = none): the output moves at most R*dt per
  sample from the previous output (u0 after the preset): the clip band of the sample is
  [max(u_min, u(k-1) - R*dt), min(u_max, u(k-1) + R*dt)], and the anti-windup below treats that band as the
  limits. The first sample after a reset without a preset is not rate limited.

Gain changes (``gain_change``): "positional" (the paper's eq. 2, the law above as it stands) or "bumpless".
"bumpless" rescales the error sum when (Kp, Ti, Td) differ from the previous sample's (Kp', Ti', Td'), before
anything else of sample k, so that the state's output does not jump::

    v    = Kp'*(ep(k-1) + Td'*D(k-1)) + Ki'*I(k-1)     the old gains on sample k-1's signals and sum
    I(k-1) := (v - Kp*(ep(k-1) + Td*D(k-1))) / Ki      the new gains then give v there  (Ki = Kp/Ti != 0)

(I(k-1) after the anti-windup, D the derivative as stored, filtered when N is set). Sample k then runs the
law above unchanged, so u_try(k) = v + Kp*(ep(k) - ep(k-1)) + Kp*Td*(D(k) - D(k-1)) + Ki*e(k)*dt: the output
moves only as the new controller answers the signals' change (at an equilibrium, not at all). With constant
gains nothing is rescaled and the law is bit for bit "positional". Edge cases:

- Ki = 0 (Ti = inf or Kp = 0) after the change: no integral term can hold the output, I is left as it is and
  u jumps by the change of the P and D terms and loses Ki'*I (a P or PD law has no state for its output); the
  output rate limit, when set, bounds that jump. Back from Ki = 0 to Ki != 0 is bumpless (the formula).
- A sign change of Kp: the same formula (Ki has the sign of Kp); the clamping test uses the new Kp*e.
- While saturated: v is the unsaturated value the state holds (not the clipped u), so the change neither
  winds the sum up nor down; the applied output stays at the limit as long as v is beyond it, and clamping and
  back-calculation act on sample k as without a change.
- The first sample after reset() (with or without preset_output) has no previous gains: no rescale.

Manual and tracking (``track_values``): a sample whose output is imposed per loop (a manual value, or the
actuator's actual position while an override or a limit acts) outputs it clipped to [u_min, u_max] (not rate
limited: the operator or the actuator moved it), advances the filters, ed, D, ep and the gains as a normal
sample, and balances the sum as preset_output does: I(k) = (u(k) - Kp*(ep(k) + Td*D(k))) / Ki (Ki = 0: I left
as it is). The next automatic sample continues from u(k) as from an automatic one: no bump on the transfer.

Anti-windup (``anti_windup``), with u_try = u computed from I(k-1) + e(k)*dt:

- "none": I(k) = I(k-1) + e(k)*dt.
- "clamping" (conditional integration): when u_try lies outside [u_min, u_max] and Kp*e(k) pushes
  further in that direction (for Kp > 0: e has the sign of the saturation), e(k)*dt is NOT added:
  I(k) = I(k-1). The output of that step is clip(u_try) (it is at the limit either way).
- "back_calculation": the continuous law dI/dt = e + (u_sat - u_unsat)/(Ki*Tt), Ki = Kp/Ti (I is the
  error sum, so the tracking signal is divided by Ki to get error units), discretised with
  backward Euler like the rectangular sum of eq. 2::

      I(k) = I(k-1) + dt*e(k) + dt*(u_sat(k) - u_unsat(k)) / (Ki*Tt)

  Solved in closed form (clipping is piecewise linear and the saturation side does not change)::

      I(k)       = I(k-1) + dt*e(k) + g*(clip(u_try) - u_try)/Ki,   g = dt/(Tt + dt)
      u_unsat(k) = u_try + g*(clip(u_try) - u_try)

  This is unconditionally stable for any Tt > 0. Tt defaults, per step and per loop, to
  sqrt(Ti*Td), or Ti when Td == 0 (Astrom & Hagglund's rule). No correction where Ki == 0.

``unsaturated_u`` is u_try for "none" and "clamping", u_unsat(k) above for "back_calculation".

Signs: the gains are meant to be Kp >= 0, Ti > 0, Td >= 0 (not checked per step, for speed).

Inputs and outputs are numpy arrays of shape (n_loops,) (or scalars), but the arithmetic runs as a
loop over Python floats: a tuning problem has 1-3 loops, and for arrays that small numpy's per-call
overhead (1-4 us per ufunc, more for reductions) dominates (docs/results.md, Speed).
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

ANTI_WINDUP_MODES = ("clamping", "back_calculation", "none")
GAIN_CHANGE_MODES = ("bumpless", "positional")  # what a change of (Kp, Ti, Td) does to the error sum
COUPLING_NAMES = ("c_rp", "c_ry", "c_pr", "c_py", "c_yr", "c_yp")


def parallel_gains(Kp, Ti, Td):
    """Ideal (Kp, Ti, Td) -> parallel (Ki, Kd): Ki = Kp/Ti [1/s], Kd = Kp*Td [s]. Ti = inf gives Ki = 0."""
    Kp = np.asarray(Kp, dtype=float)
    return Kp / np.asarray(Ti, dtype=float), Kp * np.asarray(Td, dtype=float)


FILTER_ORDERS = (1, 2)


@dataclass
class PIDState:
    """Internal state of a PID, all arrays of shape (n_loops,).

    integral: error sum I [error units * s]; last_error: ed(k-1), the derivative error of the last sample
    [error units]; derivative: last (filtered) derivative D [error units / s]; filtered: the measurement
    filter's output yf(k-1) [measurement units]; filter_stage: the first section's output of a second-order
    filter (equal to filtered for order 1); initialized: False until the first step after reset; last_output:
    the previous output u(k-1) the rate limit moves from (NaN: none yet); last_p_error: ep(k-1) [error units];
    last_gains: (3, n_loops) Kp [u per error unit], Ti [s], Td [s] of sample k-1 (NaN: none yet), what a
    bumpless gain change rescales the sum from (None: none).
    """

    integral: np.ndarray
    last_error: np.ndarray
    derivative: np.ndarray
    initialized: bool
    filtered: np.ndarray | None = None
    filter_stage: np.ndarray | None = None
    last_output: np.ndarray | None = None
    last_p_error: np.ndarray | None = None
    last_gains: np.ndarray | None = None

    def copy(self) -> "PIDState":
        return PIDState(self.integral.copy(), self.last_error.copy(), self.derivative.copy(), self.initialized,
                        *(None if a is None else a.copy() for a in (self.filtered, self.filter_stage, self.last_output,
                                                                    self.last_p_error, self.last_gains)))


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
    """2-DOF positional PID (module docstring; eq. 2 with b = c = 1, Tf = 0) for ``n_loops`` independent loops
    with saturation and anti-windup.

    Args:
        sample_time_s: dt [s], > 0.
        n_loops: number of independent loops.
        u_min, u_max: output limits, scalars or (n_loops,) arrays (default unbounded).
        anti_windup: "clamping" | "back_calculation" | "none" (see module docstring).
        Tt: back-calculation tracking time constant [s], scalar or (n_loops,); None = sqrt(Ti*Td),
            or Ti when Td == 0, evaluated every step with the current gains.
        derivative_filter_N: None = unfiltered derivative; else filter time constant Td/N.
        setpoint_weight: b in [0, 1] (scalar or (n_loops,)); 1 = the paper's proportional term.
        derivative_weight: c in [0, 1] (0: derivative on the measurement; 1: on the error, the paper's).
        measurement_filter_s: Tf [s] >= 0 of the measurement filter feeding P and D; 0 = none.
        measurement_filter_order: 1 or 2.
        u_rate_limit: R [u units / s] per loop (inf: none).
        gain_change: "positional" (eq. 2: a gain change acts on the whole sum) or "bumpless" (the sum is rescaled
            so that u does not jump; module docstring). The default is the paper's law; LoopCore runs the
            scenario's controller.gain_change.

    ``unsaturated_u`` (n_loops,): u before saturation in the last step (zeros after reset); with
    back-calculation it includes the step's tracking correction (see module docstring).
    """

    def __init__(self, sample_time_s: float, n_loops: int = 1, u_min=-np.inf, u_max=np.inf,
                 anti_windup: str = "clamping", Tt=None, derivative_filter_N: float | None = None,
                 setpoint_weight=1.0, derivative_weight=1.0, measurement_filter_s=0.0,
                 measurement_filter_order: int = 1, u_rate_limit=math.inf, gain_change: str = "positional"):
        if not (np.isfinite(sample_time_s) and sample_time_s > 0):
            raise ValueError(f"sample_time_s must be a finite number > 0, got {sample_time_s!r}")
        if isinstance(n_loops, bool) or int(n_loops) != n_loops or n_loops < 1:
            raise ValueError(f"n_loops must be an integer >= 1, got {n_loops!r}")
        if anti_windup not in ANTI_WINDUP_MODES:
            raise ValueError(f"anti_windup must be one of {ANTI_WINDUP_MODES}, got {anti_windup!r}")
        if derivative_filter_N is not None and not derivative_filter_N > 0:
            raise ValueError(f"derivative_filter_N must be > 0 or None, got {derivative_filter_N!r}")
        if measurement_filter_order not in FILTER_ORDERS:
            raise ValueError(f"measurement_filter_order must be one of {FILTER_ORDERS}, got {measurement_filter_order!r}")
        self.sample_time_s = float(sample_time_s)
        self.n_loops = n = int(n_loops)
        self._u_min = _per_loop(u_min, n, "u_min")
        self._u_max = _per_loop(u_max, n, "u_max")
        if any(not lo <= hi for lo, hi in zip(self._u_min, self._u_max)):
            raise ValueError(f"u_min must be <= u_max (and not NaN), got u_min={u_min!r}, u_max={u_max!r}")
        self.anti_windup = anti_windup
        if gain_change not in GAIN_CHANGE_MODES:
            raise ValueError(f"gain_change must be one of {GAIN_CHANGE_MODES}, got {gain_change!r}")
        self.gain_change = gain_change
        self._bumpless = gain_change == "bumpless"
        rate = _per_loop(u_rate_limit, n, "u_rate_limit")
        if not all(r > 0 for r in rate):
            raise ValueError(f"u_rate_limit must be > 0 (inf: none), got {u_rate_limit!r}")
        self._rate = None if all(r == math.inf for r in rate) else rate
        self._Tt = None if Tt is None else _per_loop(Tt, n, "Tt")
        if self._Tt is not None and not all(t > 0 for t in self._Tt):
            raise ValueError(f"Tt must be > 0, got {Tt!r}")
        self.derivative_filter_N = None if derivative_filter_N is None else float(derivative_filter_N)
        self.measurement_filter_order = int(measurement_filter_order)
        self.set_structure(setpoint_weight, derivative_weight, measurement_filter_s)
        self.reset()

    def set_structure(self, setpoint_weight, derivative_weight, measurement_filter_s) -> None:
        """Set b, c (in [0, 1]) and Tf [s] (>= 0), scalars or (n_loops,); the state is kept (a search changes
        them between episodes, after reset)."""
        n = self.n_loops
        b = _per_loop(setpoint_weight, n, "setpoint_weight")
        c = _per_loop(derivative_weight, n, "derivative_weight")
        tf = _per_loop(measurement_filter_s, n, "measurement_filter_s")
        if not all(0 <= v <= 1 for v in b + c):
            raise ValueError(f"setpoint weights must lie in [0, 1], got b={setpoint_weight!r}, c={derivative_weight!r}")
        if not all(0 <= v < math.inf for v in tf):
            raise ValueError(f"measurement_filter_s must be finite and >= 0, got {measurement_filter_s!r}")
        self._b, self._c, self._tf = b, c, tf
        self._section = [v / self.measurement_filter_order for v in tf]  # time constant of each filter section
        self._weighted = any(v != 1.0 for v in b + c) or any(tf)

    @property
    def weighted(self) -> bool:
        """Whether b, c or Tf differ from eq. 2's (b = c = 1, Tf = 0) in some loop: else ep = ed = e."""
        return self._weighted

    @property
    def setpoint_weight(self) -> np.ndarray:
        return np.array(self._b)

    @property
    def derivative_weight(self) -> np.ndarray:
        return np.array(self._c)

    @property
    def measurement_filter_s(self) -> np.ndarray:
        return np.array(self._tf)

    @property
    def u_rate_limit(self) -> np.ndarray:
        """|u(k) - u(k-1)| / Ts at most [u units / s] per loop (inf: none)."""
        return np.full(self.n_loops, math.inf) if self._rate is None else np.array(self._rate)

    @property
    def last_output(self) -> list:
        """The previous output per loop (NaN before the first, unless preset_output gave u0); live, never mutate."""
        return self._last_u

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
        """Zero the error sum and derivative; the next step has no derivative kick and starts the filter."""
        n = self.n_loops
        self._integral = [0.0] * n
        self._last_error = [0.0] * n
        self._derivative = [0.0] * n
        self._filtered = [0.0] * n
        self._stage = [0.0] * n
        self._last_u = [math.nan] * n  # the previous output (NaN: none yet, the rate limit waits)
        self._last_p = [0.0] * n  # ep(k-1)
        self._last_kp = [math.nan] * n  # the gains of sample k-1 (NaN: none yet, no rescale)
        self._last_ti = [math.nan] * n
        self._last_td = [math.nan] * n
        self._initialized = False
        self._unsaturated_u = [0.0] * n

    def get_state(self) -> PIDState:
        """A copy of the internal state (later steps do not change it)."""
        return PIDState(np.array(self._integral), np.array(self._last_error), np.array(self._derivative),
                        self._initialized, np.array(self._filtered), np.array(self._stage), np.array(self._last_u),
                        np.array(self._last_p), np.array([self._last_kp, self._last_ti, self._last_td]))

    def raw_state(self) -> tuple[list, list, list, bool, list, list]:
        """(integral, last_error, derivative, initialized, filtered, filter_stage) WITHOUT copying: the live
        lists of n_loops floats. For readers that copy the values out at once (the C forecast); never mutate them.
        """
        return self._integral, self._last_error, self._derivative, self._initialized, self._filtered, self._stage

    def raw_gain_state(self) -> tuple[list, list, list, list]:
        """(ep(k-1), Kp, Ti, Td of sample k-1) WITHOUT copying: the live lists of n_loops floats the bumpless
        rescale reads (gains NaN: none yet). For the C forecast, which copies them at every call; never mutate them."""
        return self._last_p, self._last_kp, self._last_ti, self._last_td

    def raw_structure(self) -> tuple[list, list, list]:
        """(b, c, Tf) WITHOUT copying: the live lists of n_loops floats (set_structure replaces them, never
        mutates them). For the C forecast, which copies them at every call; never mutate them."""
        return self._b, self._c, self._tf

    def set_state(self, state: PIDState) -> None:
        """Restore a state from ``get_state`` (copied in, so ``state`` stays reusable)."""
        n = self.n_loops
        self._integral = _per_loop(np.asarray(state.integral, dtype=float), n, "PIDState.integral")
        self._last_error = _per_loop(np.asarray(state.last_error, dtype=float), n, "PIDState.last_error")
        self._derivative = _per_loop(np.asarray(state.derivative, dtype=float), n, "PIDState.derivative")
        zeros = np.zeros(n)
        self._filtered = _per_loop(np.asarray(zeros if state.filtered is None else state.filtered, dtype=float), n,
                                   "PIDState.filtered")
        self._stage = _per_loop(np.asarray(zeros if state.filter_stage is None else state.filter_stage, dtype=float),
                                n, "PIDState.filter_stage")
        self._last_u = _per_loop(np.asarray(np.full(n, math.nan) if state.last_output is None else state.last_output,
                                            dtype=float), n, "PIDState.last_output")
        self._last_p = _per_loop(np.asarray(zeros if state.last_p_error is None else state.last_p_error, dtype=float),
                                 n, "PIDState.last_p_error")
        gains = np.full((3, n), math.nan) if state.last_gains is None else np.asarray(state.last_gains, dtype=float)
        if gains.shape != (3, n):
            raise ValueError(f"PIDState.last_gains must have shape (3, {n}), got {gains.shape}")
        self._last_kp, self._last_ti, self._last_td = (gains[j].tolist() for j in range(3))
        self._initialized = bool(state.initialized)

    def copy(self) -> "PID":
        """An independent PID with the same settings and state."""
        return copy.deepcopy(self)

    def step(self, setpoint, measurement, Kp, Ti, Td) -> np.ndarray:
        """One sample on (setpoint, measurement); returns saturated u, shape (n_loops,).

        Kp [u per error unit], Ti [s] (> 0, inf = no integral), Td [s] (>= 0): scalars or (n_loops,).
        """
        n = self.n_loops
        return np.array(self.step_values(_per_loop(setpoint, n, "setpoint"), _per_loop(measurement, n, "measurement"),
                                         _per_loop(Kp, n, "Kp"), _per_loop(Ti, n, "Ti"), _per_loop(Td, n, "Td")))

    def step_error(self, error, Kp, Ti, Td) -> np.ndarray:
        """One sample of the error form, setpoint = error and measurement = 0 (eq. 2 when b = c = 1, Tf = 0)."""
        n = self.n_loops
        return self.step(error, [0.0] * n, Kp, Ti, Td)

    def filter_measurement(self, measurements: list) -> list:
        """yf(k) from y(k) (lists of n_loops floats): advances the measurement filter's state, once per sample."""
        if not any(self._tf):
            return measurements
        dt = self.sample_time_s
        if not self._initialized:
            self._filtered = list(measurements)
            self._stage = list(measurements)
            return list(measurements)
        second = self.measurement_filter_order == 2
        out = list(measurements)
        for i, y in enumerate(measurements):
            T = self._section[i]
            if T == 0.0:
                continue
            x = (T * self._stage[i] + dt * y) / (T + dt)
            self._stage[i] = x
            if second:
                x = (T * self._filtered[i] + dt * x) / (T + dt)
            self._filtered[i] = x
            out[i] = x
        return out

    def weighted_errors(self, setpoints: list, measurements: list) -> tuple[list, list, list]:
        """(e, ep, ed) for one sample (lists of n_loops floats), advancing the measurement filter."""
        n = self.n_loops
        errors = [setpoints[i] - measurements[i] for i in range(n)]
        if not self._weighted:
            return errors, errors, errors
        yf = self.filter_measurement(measurements)
        b, c = self._b, self._c
        return (errors, [b[i] * setpoints[i] - yf[i] for i in range(n)],
                [c[i] * setpoints[i] - yf[i] for i in range(n)])

    def step_values(self, setpoints: list, measurements: list, Kps: list, Tis: list, Tds: list) -> list:
        """`step` on lists of n_loops floats, unchecked; returns saturated u as a list. The hot path."""
        return self.step_weighted(*self.weighted_errors(setpoints, measurements), Kps, Tis, Tds)

    def track_values(self, setpoints: list, measurements: list, Kps: list, Tis: list, Tds: list,
                     imposed: list) -> list:
        """One sample with the output imposed where imposed[i] is a number (manual value or the actuator's actual
        position, in u units; None: that loop runs the law): u = imposed clipped to [u_min, u_max], the state
        advances and the sum is balanced so that the next automatic sample starts from u (module docstring)."""
        return self.step_weighted(*self.weighted_errors(setpoints, measurements), Kps, Tis, Tds, imposed)

    def step_weighted(self, errors: list, p_errors: list, d_errors: list, Kps: list, Tis: list, Tds: list,
                      imposed: list | None = None) -> list:
        """One sample on the integral, proportional and derivative errors (e, ep, ed of the module docstring);
        imposed: as in track_values (None: every loop automatic)."""
        n = self.n_loops
        dt = self.sample_time_s
        N = self.derivative_filter_N
        mode = self.anti_windup
        if not self._initialized:
            self._last_error = list(d_errors)
            self._initialized = True
        integrals, last_errors, derivatives = self._integral, self._last_error, self._derivative
        last_p, last_kp, last_ti, last_td = self._last_p, self._last_kp, self._last_ti, self._last_td
        bumpless = self._bumpless
        rates, last_u = self._rate, self._last_u
        u_out = [0.0] * n
        u_unsat_out = [0.0] * n

        for i in range(n):
            e, kp, ti, td = errors[i], Kps[i], Tis[i], Tds[i]
            ed = d_errors[i]
            d = (ed - last_errors[i]) / dt
            if N is not None:
                tf = td / N
                d = (tf * derivatives[i] + dt * d) / (tf + dt)
            ki = kp / ti
            if bumpless and (kp != last_kp[i] or ti != last_ti[i] or td != last_td[i]) and last_kp[i] == last_kp[i]:
                if ki != 0:  # the new gains give the old output v on sample k-1's signals (module docstring)
                    kp0, d0, p0 = last_kp[i], derivatives[i], last_p[i]
                    v = kp0 * (p0 + last_td[i] * d0) + kp0 / last_ti[i] * integrals[i]
                    integrals[i] = (v - kp * (p0 + td * d0)) / ki
            last_p[i], last_kp[i], last_ti[i], last_td[i] = p_errors[i], kp, ti, td
            if imposed is not None and imposed[i] is not None:  # manual or tracking: u given, the sum balanced
                lo, hi = self._u_min[i], self._u_max[i]
                u = imposed[i]
                u = lo if u < lo else hi if u > hi else u
                if ki != 0:
                    integrals[i] = (u - kp * (p_errors[i] + td * d)) / ki
                last_errors[i] = ed
                derivatives[i] = d
                u_out[i] = u_unsat_out[i] = u
                continue
            integral = integrals[i] + e * dt
            u_unsat = kp * (p_errors[i] + td * d) + ki * integral
            lo, hi = self._u_min[i], self._u_max[i]
            if rates is not None and rates[i] != math.inf and last_u[i] == last_u[i]:  # rate limit: a moving band
                step = rates[i] * dt
                lo, hi = max(lo, last_u[i] - step), min(hi, last_u[i] + step)
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
            last_errors[i] = ed
            derivatives[i] = d
            u_out[i] = u
            u_unsat_out[i] = u_unsat

        self._unsaturated_u = u_unsat_out
        if rates is not None:
            self._last_u = list(u_out)
        return u_out

    def preset_output(self, u0: list, measurements: list, Kps: list, Tis: list) -> None:
        """Bumpless start: before the first step, balance the PID at the first measurement y(0) with output u0,
        as if it had been tracking setpoint = measurement (module docstring): I = (u0 - Kp*((b - 1)*y(0))) / Ki.
        So u(0) = u0 when r(0) = y(0), and a setpoint step at t = 0 acts through b like any other.

        u0, measurements, Kps, Tis: lists of n_loops floats (u0 in control-signal units). Loops without integral
        action (Ti = inf or Kp = 0) keep I = 0. u0 is also the previous output of the rate limit. Call after
        reset(), before the first step.
        """
        for i in range(self.n_loops):
            ki = Kps[i] / Tis[i]
            kick = Kps[i] * ((self._b[i] - 1.0) * measurements[i])
            self._integral[i] = (u0[i] - kick) / ki if ki != 0 else 0.0
        if self._rate is not None:
            self._last_u = [float(u) for u in u0]


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
    e_yaw = ... + c_yr*roll + c_yp*pitch; each axis is then the PID of the module docstring on its coupled
    errors: e from (r, y), ep from (b*r, yf) and ed from (c*r, yf), each through eq. 27.
    Constructor arguments are those of PID (n_loops is fixed to 3). Angles in rad, u in N*m.
    """

    n_loops = 3

    def __init__(self, sample_time_s: float, u_min=-np.inf, u_max=np.inf, anti_windup: str = "clamping",
                 Tt=None, derivative_filter_N: float | None = None, setpoint_weight=1.0, derivative_weight=1.0,
                 measurement_filter_s=0.0, measurement_filter_order: int = 1, u_rate_limit=math.inf,
                 gain_change: str = "positional"):
        self.pid = PID(sample_time_s, 3, u_min, u_max, anti_windup, Tt, derivative_filter_N, setpoint_weight,
                       derivative_weight, measurement_filter_s, measurement_filter_order, u_rate_limit, gain_change)

    @property
    def gain_change(self) -> str:
        return self.pid.gain_change

    @property
    def sample_time_s(self) -> float:
        return self.pid.sample_time_s

    @property
    def unsaturated_u(self) -> np.ndarray:
        return self.pid.unsaturated_u

    def set_structure(self, setpoint_weight, derivative_weight, measurement_filter_s) -> None:
        self.pid.set_structure(setpoint_weight, derivative_weight, measurement_filter_s)

    def coupled_error(self, setpoint, measurement, coupling) -> np.ndarray:
        """e_couple (3,) of eq. 27 from setpoint (3,), measurement (3,), coupling (6,) in COUPLING_NAMES order."""
        return np.array(_coupled_errors(_per_loop(setpoint, 3, "setpoint"), _per_loop(measurement, 3, "measurement"),
                                        _per_loop(coupling, 6, "coupling")))

    def step(self, setpoint, measurement, Kp, Ti, Td, coupling) -> np.ndarray:
        """One sample of eq. 26; Kp, Ti, Td scalars or (3,); returns saturated u (3,)."""
        return np.array(self.step_values(_per_loop(setpoint, 3, "setpoint"), _per_loop(measurement, 3, "measurement"),
                                         _per_loop(Kp, 3, "Kp"), _per_loop(Ti, 3, "Ti"), _per_loop(Td, 3, "Td"),
                                         _per_loop(coupling, 6, "coupling")))

    def step_values(self, r: list, y: list, Kps: list, Tis: list, Tds: list, c: list) -> list:
        """`step` on lists of floats (r, y, gains (3,), coupling (6,)), unchecked; returns u as a list."""
        return self.pid.step_weighted(*self.coupled_errors(r, y, c), Kps, Tis, Tds)

    def track_values(self, r: list, y: list, Kps: list, Tis: list, Tds: list, c: list, imposed: list) -> list:
        """step_values with the output imposed where imposed[i] is a number (PID.track_values)."""
        return self.pid.step_weighted(*self.coupled_errors(r, y, c), Kps, Tis, Tds, imposed)

    def coupled_errors(self, r: list, y: list, c: list) -> tuple[list, list, list]:
        """(e, ep, ed) of eq. 27 for one sample (lists of 3 floats), advancing the measurement filter."""
        pid = self.pid
        errors = _coupled_errors(r, y, c)
        if not pid.weighted:
            return errors, errors, errors
        yf = pid.filter_measurement(y)
        b, cw = pid.raw_structure()[:2]
        return (errors, _coupled_errors([b[i] * r[i] for i in range(3)], yf, c),
                _coupled_errors([cw[i] * r[i] for i in range(3)], yf, c))

    def preset_output(self, u0: list, measurements: list, Kps: list, Tis: list) -> None:
        self.pid.preset_output(u0, measurements, Kps, Tis)

    def reset(self) -> None:
        self.pid.reset()

    def get_state(self) -> PIDState:
        return self.pid.get_state()

    def raw_state(self) -> tuple:
        return self.pid.raw_state()

    def raw_structure(self) -> tuple[list, list, list]:
        return self.pid.raw_structure()

    def raw_gain_state(self) -> tuple[list, list, list, list]:
        return self.pid.raw_gain_state()

    def set_state(self, state: PIDState) -> None:
        self.pid.set_state(state)

    def copy(self) -> "CoupledPID":
        return copy.deepcopy(self)
