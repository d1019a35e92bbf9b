"""Gain scheduling: turn a trained adaptive policy into a lookup table a plain PID in a PLC can run.

The adaptive policy changes Kp, Ti, Td (and the coupling coefficients) every sample. Near an
operating point it settles on nearly constant gains; a gain schedule records those settled gains at
K operating points ("breakpoints") of a scheduling variable, and a plain PID interpolates between
them. No neural network is needed to run the result.

- ``extract_schedule``: hold the setpoint of one loop at K values (forecast, noise and disturbances
  off), let the closed loop with the policy settle, and record the mean gains over the last 20 % of
  each hold. The breakpoint is the scheduling variable's mean over the same samples: the setpoint,
  the measurement, or any real FMU variable (e.g. ``a_t``, ``h1``).
- ``GainSchedule.gains_at``: linear interpolation between breakpoints, held constant outside them
  (no extrapolation: a gain outside the tested operating range is never invented).
- ``write_schedule_csv`` / ``read_schedule_csv``: a self-describing CSV (metadata in ``# `` lines).
- ``replay_schedule``: run the plain gain-scheduled PID on the FMU, no neural network involved.

The PID structure (setpoint weight b, derivative weight c, measurement filter Tf per loop, and the filter's
order; prlpid_fmi.control.pid) is not scheduled: a table carries one (b, c, Tf) per loop, the values the gains
were tuned with (loop.core.pid_structure of the config), and every consumer runs the table with them. So is
each loop's output rate limit (u_rate_limit, the config's LoopConfig.u_rate_limit; inf: none).

Scheduling variables are named ``setpoint[<loop>]``, ``measurement[<loop>]``, ``error[<loop>]``
(the loop's output name) or an FMU variable name. At every step the value seen by the table lookup
is the current setpoint, the current (noisy, if noise is configured) measurement, the error
setpoint - measurement of that loop (the uncoupled error, also for a cross-coupled PID), or the FMU
variable read from the plant before the step — what a PLC reading the same signal would see.
Settled holds have no error to schedule on: error tables come from policy trajectories
(prlpid_fmi.tuning.schedule.trajectories).
"""
from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass
from typing import Optional

import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.control import COUPLING_NAMES, parallel_gains
from prlpid_fmi.loop.gains import Gains, GainValues
from prlpid_fmi.loop.scheduling import LOOP_SIGNALS, LOOP_VARIABLE

# The discrete law of prlpid_fmi.control.pid, written in its evaluation order (the exports compute it so)
PID_EQUATION = ("u = Kp*(ep + Td*D) + (Kp/Ti)*I; I = I_prev + e*Ts; D = (ed - ed_prev)/Ts; "
                "e = r - y, ep = b*r - yf, ed = c*r - yf")
MEASUREMENT_FILTER_EQUATION = ("yf = x[n]; x[j] = (T*x_prev[j] + Ts*x[j-1])/(T + Ts) for j = 1..n, x[0] = y, "
                               "T = Tf/n (n = measurement_filter_order); x[j] = y at the first sample; "
                               "Tf = 0: yf = y exactly")
RATE_LIMIT_BAND = ("[lo, hi] = [max(u_min, u_prev - R*Ts), min(u_max, u_prev + R*Ts)] (R: the loop's output rate "
                   "limit; R = inf: [u_min, u_max]; u_prev: the previous output, u0 at the first sample), which the "
                   "anti-windup treats as the limits")
BUMPLESS_START = ("I_prev = (u0 - Kp*((b - 1)*y0))/Ki before every first sample (Ki = 0: I_prev = 0), from the "
                  "actuator's value u0 (also u0 = 0) and the first measurement y0, so that u = u0 when r = y (no kick "
                  "from b) and a setpoint step at the start acts through b; u_prev := u0")
INTERPOLATION = "linear between breakpoints, held constant outside"
GAIN_CHANGE_EQUATION = {  # what a change of (Kp, Ti, Td) between samples does (control.pid gain_change)
    "bumpless": ("when Kp, Ti or Td differ from the previous sample's (Kp', Ti', Td', Ki' = Kp'/Ti'), first "
                 "I_prev := (Kp'*(ep_prev + Td'*D_prev) + Ki'*I_prev - Kp*(ep_prev + Td*D_prev))/Ki, so that u does not "
                 "jump (D_prev: the derivative as kept, filtered with N; Ki = 0: I_prev kept); not at the first sample"),
    "positional": "none: a gain change acts on the whole sum I (the paper's eq. 2)",
}

__all__ = ["GainSchedule", "schedule_from_rows", "fixed_schedule", "table_meta", "exact_mean", "LOOP_SIGNALS",
           "LOOP_VARIABLE", "PID_EQUATION", "MEASUREMENT_FILTER_EQUATION", "INTERPOLATION", "STRUCTURE_COLUMNS",
           "RATE_LIMIT_BAND", "BUMPLESS_START", "GAIN_CHANGE_EQUATION"]

STRUCTURE_COLUMNS = ("b", "c", "Tf")  # per loop, after the gains: setpoint weight, derivative weight, filter [s]


@dataclass
class GainSchedule:
    """A gain table: row j holds the PID parameters to use when the scheduling variable equals breakpoints[j].

    variable: "setpoint[<loop>]", "measurement[<loop>]", "error[<loop>]" or an FMU variable name; unit: its unit ("" if unknown).
    breakpoints: (K,) strictly increasing. Kp, Ti [s], Td [s]: (K, n_loops). coupling: (K, 6) in
    COUPLING_NAMES order, or None for independent loops. sample_time_s: Ts of the PID law [s].
    loop_names: the measured outputs, loop_inputs: the driven inputs, output_units/input_units: their
    units ("" if unknown). anti_windup, derivative_filter_N and u_min/u_max (n_loops,): the PID settings
    the gains were tuned with. excluded: operating points (held setpoints) left out because the
    closed loop diverged there; the table does not cover them.
    setpoint_weight b, derivative_weight c, measurement_filter_s Tf [s] (n_loops,) and
    measurement_filter_order (1 | 2): the PID's structure, the same for every row (None: b = c = 1, Tf = 0,
    the law of paper eq. 2, which tables written before the 2-DOF law were tuned with).
    u_rate_limit (n_loops,): the PID's output rate limit per loop [input units / s], inf = none (None: none,
    as in tables written before the rate limit).
    gain_change: "bumpless" | "positional" (control.pid): what a change of the interpolated gains between samples
    does to the error sum; "positional" for tables written before the bumpless law.
    """

    variable: str
    unit: str
    breakpoints: np.ndarray
    Kp: np.ndarray
    Ti: np.ndarray
    Td: np.ndarray
    coupling: Optional[np.ndarray]
    sample_time_s: float
    loop_names: tuple
    loop_inputs: tuple
    output_units: tuple
    input_units: tuple
    anti_windup: str
    u_min: np.ndarray
    u_max: np.ndarray
    derivative_filter_N: Optional[float] = None
    excluded: tuple = ()
    setpoint_weight: Optional[np.ndarray] = None
    derivative_weight: Optional[np.ndarray] = None
    measurement_filter_s: Optional[np.ndarray] = None
    measurement_filter_order: int = 1
    u_rate_limit: Optional[np.ndarray] = None
    gain_change: str = "positional"

    def __post_init__(self):
        n = len(self.loop_names)
        for name, default in (("setpoint_weight", 1.0), ("derivative_weight", 1.0), ("measurement_filter_s", 0.0),
                              ("u_rate_limit", math.inf)):
            value = getattr(self, name)
            value = np.full(n, default) if value is None else np.array(value, dtype=float).reshape(-1)
            if value.shape != (n,):
                raise ValueError(f"{name}: one value per loop ({n}), got {getattr(self, name)!r}")
            setattr(self, name, value)
        self.measurement_filter_order = int(self.measurement_filter_order)

    @property
    def n_loops(self) -> int:
        return len(self.loop_names)

    @property
    def structure(self) -> tuple:
        """((b, c, Tf), ...) per loop: TuningConfig.tuned_structure's form (loop.core.pid_structure reads it)."""
        return tuple((float(b), float(c), float(tf)) for b, c, tf in
                     zip(self.setpoint_weight, self.derivative_weight, self.measurement_filter_s))

    @property
    def Ki(self) -> np.ndarray:
        """Parallel integral gain Kp/Ti (K, n_loops) [u-unit / (y-unit*s)]."""
        return parallel_gains(self.Kp, self.Ti, self.Td)[0]

    @property
    def Kd(self) -> np.ndarray:
        """Parallel derivative gain Kp*Td (K, n_loops) [u-unit*s / y-unit]."""
        return parallel_gains(self.Kp, self.Ti, self.Td)[1]

    def row(self, j: int) -> GainValues:
        """Row j as GainValues (coupling None for uncoupled loops)."""
        return Gains(self.Kp[j], self.Ti[j], self.Td[j], None if self.coupling is None else self.coupling[j]).values()

    def gains_at(self, value: float) -> tuple:
        """(Kp, Ti, Td) arrays (n_loops,) — plus coupling (6,) when coupled — at a scheduling value.

        Linear interpolation between neighbouring breakpoints, each parameter on its own (Ti and Td
        in seconds, as a PLC table would); outside [breakpoints[0], breakpoints[-1]] the end row is
        held (clamped): the table is never extrapolated.
        """
        x = float(value)
        if not math.isfinite(x):
            raise ValueError(f"scheduling value must be finite, got {value!r}")
        bp = self.breakpoints

        def col(a: np.ndarray) -> np.ndarray:
            return np.array([np.interp(x, bp, a[:, j]) for j in range(a.shape[1])])

        out = (col(self.Kp), col(self.Ti), col(self.Td))
        return out + (col(self.coupling),) if self.coupling is not None else out

    def gains_object(self, value: float) -> Gains:
        """gains_at as Gains (prlpid_fmi.loop.gains): what the loop core steps with."""
        return Gains(*self.gains_at(value)) if self.coupling is not None else Gains(*self.gains_at(value), None)

    def columns(self) -> list[str]:
        """CSV header: variable, then Kp/Ti/Td/Ki/Kd/b/c/Tf per loop, then coupling coefficients."""
        cols = [self.variable]
        for name in self.loop_names:
            cols += [f"{p}[{name}]" for p in ("Kp", "Ti", "Td", "Ki", "Kd", *STRUCTURE_COLUMNS)]
        if self.coupling is not None:
            cols += list(COUPLING_NAMES)
        return cols

    def column_units(self) -> dict[str, str]:
        """Unit of every CSV column; u/y are the loop's input/output units (or the words if unknown)."""
        units = {self.variable: self.unit}
        for name, uu, yu in zip(self.loop_names, self.input_units, self.output_units):
            u, y = _group(uu or "u-unit"), _group(yu or "y-unit")
            units.update({f"Kp[{name}]": f"{u}/{y}", f"Ti[{name}]": "s", f"Td[{name}]": "s",
                          f"Ki[{name}]": f"{u}/({y}*s)", f"Kd[{name}]": f"{u}*s/{y}",
                          f"b[{name}]": "1", f"c[{name}]": "1", f"Tf[{name}]": "s"})
        if self.coupling is not None:
            units.update({c: "1" for c in COUPLING_NAMES})
        return units


def _group(unit: str) -> str:
    """A unit as a factor: parenthesised when it is a compound such as cm3/s."""
    return f"({unit})" if re.search(r"[/* ]", unit) else unit


# -- extraction -------------------------------------------------------------------------------------


def structure_fields(config: TuningConfig) -> dict:
    """The config's PID structure (loop.core.pid_structure), the loops' rate limits and the gain-change law as
    GainSchedule fields."""
    from prlpid_fmi.loop.core import pid_structure

    b, c, tf = pid_structure(config)
    return dict(setpoint_weight=np.array(b, float), derivative_weight=np.array(c, float),
                measurement_filter_s=np.array(tf, float), measurement_filter_order=int(config.measurement_filter_order),
                u_rate_limit=np.array([float(l.u_rate_limit) for l in config.loops], float),
                gain_change=config.gain_change)


def table_meta(core, config: TuningConfig) -> dict:
    """The loops' input names and units as GainSchedule fields (loop_inputs, output_units, input_units)."""
    return dict(loop_inputs=tuple(l.input for l in config.loops),
                output_units=tuple(core.plant.description.unit_of(l.output) for l in config.loops),
                input_units=tuple(core.plant.description.unit_of(l.input) for l in config.loops))


def schedule_from_rows(config: TuningConfig, variable: str, unit: str, rows: list, meta: dict,
                       excluded: tuple = (), resolution: float | None = None) -> GainSchedule:
    """A GainSchedule from rows [(breakpoint, {"Kp": (n_loops,), "Ti": ..., "Td": ...[, "coupling": (6,)]})].

    Rows are sorted by breakpoint; a row whose breakpoint lies within `resolution` (default: 1e-9 of
    the span) of the previous one is averaged with it, with a warning. meta: loop_inputs, output_units,
    input_units (tuples).
    """
    names = [l.output for l in config.loops]
    rows = sorted(rows, key=lambda r: r[0])
    merged: list[list] = []
    span = max(abs(rows[-1][0] - rows[0][0]), abs(rows[0][0]), 1.0)
    tolerance = 1e-9 * span if resolution is None else max(float(resolution), 1e-9 * span)
    for value, g in rows:
        if merged and abs(value - merged[-1][0][-1]) <= tolerance:
            merged[-1][0].append(value)
            merged[-1][1].append(g)
        else:
            merged.append([[value], [g]])
    if len(merged) < len(rows):
        warnings.warn(f"{variable}: {len(rows)} operating points gave only {len(merged)} distinct breakpoint(s); "
                      "gains at equal breakpoints were averaged", stacklevel=3)

    def stack(key):
        return np.array([exact_mean(np.array([g[key] for g in gs])) for _, gs in merged])

    coupled = "coupling" in rows[0][1]
    return GainSchedule(
        variable=variable, unit=unit, breakpoints=np.array([exact_mean(np.array(v)) for v, _ in merged]),
        Kp=stack("Kp"), Ti=stack("Ti"), Td=stack("Td"), coupling=stack("coupling") if coupled else None,
        sample_time_s=float(config.sample_time_s), loop_names=tuple(names),
        anti_windup=config.anti_windup, u_min=np.array([l.u_min for l in config.loops], float),
        u_max=np.array([l.u_max for l in config.loops], float),
        derivative_filter_N=config.derivative_filter_N, excluded=tuple(excluded), **structure_fields(config), **meta)


def fixed_schedule(gains: Gains, config: TuningConfig) -> GainSchedule:
    """The fixed PID as a one-row table (scheduled on loop 0's setpoint; one row is held everywhere)."""
    from prlpid_fmi.fmu.resolve import loop_units

    output_units, input_units = loop_units(config)
    lo, hi = config.loops[0].setpoint_range
    row = lambda a: np.asarray(a, float).reshape(1, -1)  # noqa: E731
    return GainSchedule(
        variable=f"setpoint[{config.loops[0].output}]", unit=output_units[0],
        breakpoints=np.array([0.5 * (lo + hi)]), Kp=row(gains.Kp), Ti=row(gains.Ti), Td=row(gains.Td),
        coupling=None if gains.coupling is None else row(gains.coupling), sample_time_s=float(config.sample_time_s),
        loop_names=tuple(l.output for l in config.loops), loop_inputs=tuple(l.input for l in config.loops),
        output_units=tuple(output_units), input_units=tuple(input_units),
        anti_windup=config.anti_windup, u_min=np.array([l.u_min for l in config.loops], float),
        u_max=np.array([l.u_max for l in config.loops], float), derivative_filter_N=config.derivative_filter_N,
        **structure_fields(config))


# -- replay ---------------------------------------------------------------------------------------


def exact_mean(x: np.ndarray) -> np.ndarray:
    """Mean over axis 0 that returns the value itself, bit for bit, when all rows are equal."""
    return x[0] + np.mean(x - x[0], axis=0)
