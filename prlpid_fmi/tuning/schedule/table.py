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

Scheduling variables are named ``setpoint[<loop>]``, ``measurement[<loop>]``, ``error[<loop>]``
(the loop's output name) or an FMU variable name. At every step the value seen by the table lookup
is the current setpoint, the current (noisy, if noise is configured) measurement, the error
setpoint - measurement of that loop (the uncoupled error, also for a cross-coupled PID), or the FMU
variable read from the plant before the step — what a PLC reading the same signal would see.
Settled holds have no error to schedule on: error tables come from policy trajectories
(prlpid_fmi.transients).
"""
from __future__ import annotations

import csv
import dataclasses
import io
import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from prlpid_fmi import __version__
from prlpid_fmi.loop.actions import Gains
from prlpid_fmi.config import TuningConfig
from prlpid_fmi.rundir import write_atomic
from prlpid_fmi.control import COUPLING_NAMES, parallel_gains
from prlpid_fmi.loop.evaluation import GAIN_NAMES
from prlpid_fmi.errors import PrlPidError

Policy = Callable[[np.ndarray], np.ndarray]

SETTLED_FRACTION = 0.2  # gains and breakpoint: mean over the last 20 % of each hold
PID_EQUATION = "u = Kp*(e + (1/Ti)*sum(e)*Ts + Td*(e - e_prev)/Ts)"
INTERPOLATION = "linear between breakpoints, held constant outside"
_ANTI_WINDUP_TEXT = {
    "clamping": "clamping (conditional integration: e*Ts is not added to sum(e) while u is saturated "
                "and Kp*e pushes further into the limit)",
    "back_calculation": "back_calculation (tracking time constant Tt = sqrt(Ti*Td), or Ti when Td = 0)",
    "none": "none",
}
LOOP_SIGNALS = ("setpoint", "measurement", "error")  # scheduling variables read from a loop, not the FMU
LOOP_VARIABLE = re.compile(r"^(setpoint|measurement|error)\[(.+)\]$")  # <signal>[<loop output>]

__all__ = ["GainSchedule", "extract_schedule", "write_schedule_csv", "read_schedule_csv", "replay_schedule",
           "PID_EQUATION", "INTERPOLATION"]


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

    @property
    def n_loops(self) -> int:
        return len(self.loop_names)

    @property
    def Ki(self) -> np.ndarray:
        """Parallel integral gain Kp/Ti (K, n_loops) [u-unit / (y-unit*s)]."""
        return parallel_gains(self.Kp, self.Ti, self.Td)[0]

    @property
    def Kd(self) -> np.ndarray:
        """Parallel derivative gain Kp*Td (K, n_loops) [u-unit*s / y-unit]."""
        return parallel_gains(self.Kp, self.Ti, self.Td)[1]

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
        """gains_at as prlpid_fmi.actions.Gains (what PidTuningEnv's PID consumes)."""
        return Gains(*self.gains_at(value)) if self.coupling is not None else Gains(*self.gains_at(value), None)

    def columns(self) -> list[str]:
        """CSV header: variable, then Kp/Ti/Td/Ki/Kd per loop, then coupling coefficients."""
        cols = [self.variable]
        for name in self.loop_names:
            cols += [f"{p}[{name}]" for p in ("Kp", "Ti", "Td", "Ki", "Kd")]
        if self.coupling is not None:
            cols += list(COUPLING_NAMES)
        return cols

    def column_units(self) -> dict[str, str]:
        """Unit of every CSV column; u/y are the loop's input/output units (or the words if unknown)."""
        units = {self.variable: self.unit}
        for name, uu, yu in zip(self.loop_names, self.input_units, self.output_units):
            u, y = _group(uu or "u-unit"), _group(yu or "y-unit")
            units.update({f"Kp[{name}]": f"{u}/{y}", f"Ti[{name}]": "s", f"Td[{name}]": "s",
                          f"Ki[{name}]": f"{u}/({y}*s)", f"Kd[{name}]": f"{u}*s/{y}"})
        if self.coupling is not None:
            units.update({c: "1" for c in COUPLING_NAMES})
        return units


def _group(unit: str) -> str:
    """A unit as a factor: parenthesised when it is a compound such as cm3/s."""
    return f"({unit})" if re.search(r"[/* ]", unit) else unit


# -- extraction -------------------------------------------------------------------------------------

def _variable_name(schedule_by: str, loop_names: list[str]) -> str:
    if schedule_by in LOOP_SIGNALS:
        return f"{schedule_by}[{loop_names[0]}]"
    m = LOOP_VARIABLE.match(schedule_by)
    if m and m.group(2) not in loop_names:
        raise PrlPidError(f"{schedule_by!r}: no loop measures {m.group(2)!r} (loops: {', '.join(loop_names)})")
    return schedule_by


class _Probe:
    """Reads the scheduling variable from a LoopCore (before a step, as the lookup would)."""

    def __init__(self, variable: str, env):
        self.env = env
        m = LOOP_VARIABLE.match(variable)
        if m:
            self.kind, self.index = m.group(1), env.loop_names.index(m.group(2))
        else:
            env.plant.description.require(variable, None, "a scheduling variable")
            self.kind, self.name = "fmu", variable

    def __call__(self) -> float:
        if self.kind == "setpoint":
            return float(self.env.setpoint[self.index])
        if self.kind == "measurement":
            return float(self.env.measurement[self.index])
        if self.kind == "error":
            return float(self.env.setpoint[self.index]) - float(self.env.measurement[self.index])
        return float(self.env.plant.get([self.name])[0])

    def unit(self) -> str:
        d = self.env.plant.description
        name = self.env.loop_names[self.index] if self.kind != "fmu" else self.name
        v = d.variable(name)
        return (v.unit or "") if v is not None else ""


def _unit(env, name: str) -> str:
    v = env.plant.description.variable(name)
    return (v.unit or "") if v is not None else ""


def table_meta(core, config: TuningConfig) -> dict:
    """The loops' input names and units as GainSchedule fields (loop_inputs, output_units, input_units)."""
    return dict(loop_inputs=tuple(l.input for l in config.loops),
                output_units=tuple(_unit(core, l.output) for l in config.loops),
                input_units=tuple(_unit(core, l.input) for l in config.loops))


def _exact_mean(x: np.ndarray) -> np.ndarray:
    """Mean over axis 0 that returns the value itself, bit for bit, when all rows are equal."""
    return x[0] + np.mean(x - x[0], axis=0)


def _nominal(config: TuningConfig) -> TuningConfig:
    """`config` without parameter randomisation (schedules are read at nominal parameters)."""
    if config.randomize:
        return dataclasses.replace(config, randomize=type(config.randomize)())
    return config


def extract_schedule(policy: Policy, config: TuningConfig, schedule_by: str = "setpoint",
                     points: int | Sequence[float] = 9, settle_steps: int | None = None, seed: int = 0,
                     hold_setpoints: Sequence[float] | None = None, anchor: Gains | None = None) -> GainSchedule:
    """Record the gains `policy` settles on at operating points of the scheduling variable.

    The setpoint of the scheduled loop (the one named in ``setpoint[<loop>]`` / ``measurement[<loop>]``,
    else loop 0) is held at each of `points` values — an int K: evenly spaced over that loop's
    setpoint_range; a sequence: those setpoints. The other loops hold `hold_setpoints` (default: the
    middle of their setpoint_range; the scheduled loop's entry is ignored). Each hold is a fresh
    episode of `settle_steps` samples (default: config.episode_steps) from the plant's initial state,
    with forecast, noise and disturbances off and the config's smoothing on (so the recorded gains
    are the ones applied). Gains and breakpoint are means over the last 20 % of the hold.

    schedule_by: "setpoint", "measurement" (of loop 0), "setpoint[<loop>]", "measurement[<loop>]", or
    an FMU variable name. Rows are sorted by breakpoint; rows whose breakpoints coincide (a variable
    that does not depend on the setpoint) are averaged into one, with a warning.
    anchor: the fixed-PID gains the policy's anchored gain map was trained around (as in training).
    Raises PrlPidError when the closed loop diverges at an operating point (the table would be unsafe).
    """
    from prlpid_fmi.loop.env import PidTuningEnv

    names = [l.output for l in config.loops]
    variable = _variable_name(schedule_by, names)
    m = LOOP_VARIABLE.match(variable)
    if m and m.group(1) == "error":
        raise PrlPidError(f"{variable}: settled holds have no error to schedule on (expected setpoint, measurement "
                          "or an FMU variable; error tables come from policy trajectories, "
                          "prlpid_fmi.transients.trajectory_schedule)")
    loop = names.index(m.group(2)) if m else 0
    lo, hi = config.loops[loop].setpoint_range
    if isinstance(points, (int, np.integer)):
        if points < 1:
            raise PrlPidError(f"points must be >= 1, got {points}")
        setpoints = [0.5 * (lo + hi)] if points == 1 else list(np.linspace(lo, hi, int(points)))
    else:
        setpoints = [float(v) for v in points]
        if not setpoints:
            raise PrlPidError("points: no operating points given")
    steps = int(settle_steps if settle_steps is not None else config.episode_steps)
    if steps < 1:
        raise PrlPidError(f"settle_steps must be >= 1, got {steps}")
    others = (list(hold_setpoints) if hold_setpoints is not None
              else [0.5 * (l.setpoint_range[0] + l.setpoint_range[1]) for l in config.loops])
    if len(others) != config.n_loops:
        raise PrlPidError(f"hold_setpoints needs {config.n_loops} values, got {len(others)}")
    tail = max(1, math.ceil(SETTLED_FRACTION * steps))

    rows, excluded, failures = [], [], {}  # failures: reason -> setpoints (one warning per reason)
    held = _nominal(dataclasses.replace(config, episode_steps=steps, forecast_horizon=0, measurement_noise_std=0.0,
                                        actuator_noise_std=0.0, disturbances=()))
    env = PidTuningEnv(held, info=False, anchor=anchor)
    try:
        probe = _Probe(variable, env.core)
        unit = probe.unit()
        meta = table_meta(env.core, config)
        for sp in setpoints:
            hold = list(others)
            hold[loop] = float(sp)
            obs, _ = env.reset(seed=seed, options={"setpoint_schedule": ((0, tuple(hold)),)})
            values, gains = [], []
            for k in range(steps):
                values.append(probe())
                obs, _, terminated, _, _ = env.step(policy(obs))
                if terminated:
                    break
                gains.append(env.gains)
            if terminated:  # no safe gains exist there: leave the point out of the table
                excluded.append(float(sp))
                why = env.core.termination.message if env.core.termination else f"diverged at step {k + 1}"
                failures.setdefault(why, []).append(float(sp))
                continue
            g = {name: np.array([x[i] for x in gains[-tail:]], float) for i, name in enumerate(GAIN_NAMES)
                 if gains[0][i] is not None}
            rows.append((float(_exact_mean(np.array(values[-tail:]))),
                         {key: _exact_mean(v) for key, v in g.items()}))
    finally:
        env.close()

    for why, where in failures.items():
        points_text = f"setpoint {where[0]:g}" if len(where) == 1 else \
            f"{len(where)} setpoints ({', '.join(f'{v:g}' for v in where)})"
        warnings.warn(f"the closed loop failed at {variable} {points_text} ({why}); "
                      f"{'that operating point is' if len(where) == 1 else 'they are'} left out of the schedule",
                      stacklevel=2)
    if not rows:
        raise PrlPidError(f"the closed loop diverged at every operating point of {variable} "
                          f"({', '.join(f'{v:g}' for v in excluded)}): no gains can be scheduled; "
                          "train longer or narrow the operating range")
    return schedule_from_rows(config, variable, unit, rows, meta, excluded=tuple(excluded))


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
        return np.array([_exact_mean(np.array([g[key] for g in gs])) for _, gs in merged])

    coupled = "coupling" in rows[0][1]
    return GainSchedule(
        variable=variable, unit=unit, breakpoints=np.array([_exact_mean(np.array(v)) for v, _ in merged]),
        Kp=stack("Kp"), Ti=stack("Ti"), Td=stack("Td"), coupling=stack("coupling") if coupled else None,
        sample_time_s=float(config.sample_time_s), loop_names=tuple(names),
        anti_windup=config.anti_windup, u_min=np.array([l.u_min for l in config.loops], float),
        u_max=np.array([l.u_max for l in config.loops], float),
        derivative_filter_N=config.derivative_filter_N, excluded=tuple(excluded), **meta)


def fixed_schedule(gains: Gains, config: TuningConfig) -> GainSchedule:
    """The fixed PID as a one-row table (scheduled on loop 0's setpoint; one row is held everywhere)."""
    from prlpid_fmi.loop.core import resolve_fmu
    from prlpid_fmi.fmu import describe_fmu

    d = describe_fmu(resolve_fmu(config.fmu, config.fmi_version))

    def unit(name):
        v = d.variable(name)
        return (v.unit or "") if v is not None else ""

    lo, hi = config.loops[0].setpoint_range
    row = lambda a: np.asarray(a, float).reshape(1, -1)  # noqa: E731
    return GainSchedule(
        variable=f"setpoint[{config.loops[0].output}]", unit=unit(config.loops[0].output),
        breakpoints=np.array([0.5 * (lo + hi)]), Kp=row(gains.Kp), Ti=row(gains.Ti), Td=row(gains.Td),
        coupling=None if gains.coupling is None else row(gains.coupling), sample_time_s=float(config.sample_time_s),
        loop_names=tuple(l.output for l in config.loops), loop_inputs=tuple(l.input for l in config.loops),
        output_units=tuple(unit(l.output) for l in config.loops), input_units=tuple(unit(l.input) for l in config.loops),
        anti_windup=config.anti_windup, u_min=np.array([l.u_min for l in config.loops], float),
        u_max=np.array([l.u_max for l in config.loops], float), derivative_filter_N=config.derivative_filter_N)


# -- CSV ------------------------------------------------------------------------------------------

def _f(x) -> str:
    return repr(float(x))


def _metadata(s: GainSchedule) -> list[tuple[str, str]]:
    units = s.column_units()
    meta = [
        ("format", "prlpid-fmi gain schedule 1"),
        ("tool", f"prlpid-fmi {__version__}"),
        ("pid_form", "positional ideal (ISA) PID, paper eq. 2; e = setpoint - measurement"
                     + ("; coupled error e = (r - y) + C*y, paper eq. 27" if s.coupling is not None else "")),
        ("pid_equation", f"{PID_EQUATION}; sum(e) includes the current e; e_prev = e at the first sample; "
                         "u then clipped to [u_min, u_max]; Ti = inf means no integral action"),
        ("equivalent_parallel", "u = Kp*e + Ki*sum(e)*Ts + Kd*(e - e_prev)/Ts with Ki = Kp/Ti, Kd = Kp*Td"),
        ("sample_time_s", _f(s.sample_time_s)),
        ("scheduling_variable", s.variable),
        ("scheduling_unit", s.unit),
        ("interpolation", INTERPOLATION),
        ("anti_windup", s.anti_windup),
        ("anti_windup_method", _ANTI_WINDUP_TEXT.get(s.anti_windup, s.anti_windup)),
        ("derivative_filter_N", "none" if s.derivative_filter_N is None else _f(s.derivative_filter_N)),
        ("excluded_operating_points", "none" if not s.excluded else
         " ".join(_f(v) for v in s.excluded) + " (held setpoints where the closed loop diverged)"),
    ]
    for i, name in enumerate(s.loop_names):
        meta.append((f"loop[{name}]", f"input={s.loop_inputs[i]}; u_min={_f(s.u_min[i])}; u_max={_f(s.u_max[i])}; "
                                      f"output_unit={s.output_units[i]}; input_unit={s.input_units[i]}"))
    meta.append(("units", "; ".join(f"{c}={units[c]}" for c in s.columns())))
    return meta


def write_schedule_csv(schedule: GainSchedule, path) -> Path:
    """Write the schedule as CSV (metadata as "# key: value" lines, then header and rows), atomically."""
    s = schedule
    buf = io.StringIO()
    for key, value in _metadata(s):
        buf.write(f"# {key}: {value}\n".replace(": \n", ":\n"))
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(s.columns())
    Ki, Kd = s.Ki, s.Kd
    for j, bp in enumerate(s.breakpoints):
        row = [_f(bp)]
        for i in range(s.n_loops):
            row += [_f(s.Kp[j, i]), _f(s.Ti[j, i]), _f(s.Td[j, i]), _f(Ki[j, i]), _f(Kd[j, i])]
        if s.coupling is not None:
            row += [_f(c) for c in s.coupling[j]]
        w.writerow(row)
    return write_atomic(path, buf.getvalue())


def read_schedule_metadata(path) -> dict[str, str]:
    """The "# key: value" lines at the top of a schedule CSV, as a dict."""
    meta = {}
    with open(path, newline="") as f:
        for line in f:
            if not line.startswith("#"):
                break
            key, _, value = line[1:].strip().partition(":")
            meta[key.strip()] = value.strip()
    return meta


def read_schedule_csv(path) -> GainSchedule:
    """Parse a CSV written by write_schedule_csv (exact round trip). Checks Ki/Kd against Kp, Ti, Td."""
    meta = read_schedule_metadata(path)
    try:
        with open(path, newline="") as f:
            lines = [line for line in f if not line.startswith("#")]
        rows = list(csv.reader(lines))
        header, data = rows[0], [r for r in rows[1:] if r]
        loops = [k[len("loop["):-1] for k in meta if k.startswith("loop[")]
        info = {name: dict(part.split("=", 1) for part in meta[f"loop[{name}]"].split("; ")) for name in loops}
        variable = meta["scheduling_variable"]
        table = np.array([[float(x) for x in r] for r in data], float).reshape(len(data), len(header))
    except (KeyError, IndexError, ValueError) as exc:
        raise PrlPidError(f"{path}: not a prlpid-fmi gain schedule CSV ({exc})") from None
    col = {name: j for j, name in enumerate(header)}

    def get(p):
        return np.stack([table[:, col[f"{p}[{name}]"]] for name in loops], axis=1)

    if header[0] != variable or not data:
        raise PrlPidError(f"{path}: first column {header[0]!r} is not the scheduling variable {variable!r}, or no rows")
    coupled = all(c in col for c in COUPLING_NAMES)
    s = GainSchedule(
        variable=variable, unit=meta.get("scheduling_unit", ""), breakpoints=table[:, 0].copy(),
        Kp=get("Kp"), Ti=get("Ti"), Td=get("Td"),
        coupling=np.stack([table[:, col[c]] for c in COUPLING_NAMES], axis=1) if coupled else None,
        sample_time_s=float(meta["sample_time_s"]), loop_names=tuple(loops),
        loop_inputs=tuple(info[n]["input"] for n in loops),
        output_units=tuple(info[n].get("output_unit", "") for n in loops),
        input_units=tuple(info[n].get("input_unit", "") for n in loops),
        anti_windup=meta.get("anti_windup", "clamping"),
        u_min=np.array([float(info[n]["u_min"]) for n in loops]),
        u_max=np.array([float(info[n]["u_max"]) for n in loops]),
        derivative_filter_N=None if meta.get("derivative_filter_N", "none") == "none"
        else float(meta["derivative_filter_N"]),
        excluded=tuple(float(v) for v in meta.get("excluded_operating_points", "none").split(" (")[0].split()
                       if v != "none"))
    if np.any(np.diff(s.breakpoints) <= 0):
        raise PrlPidError(f"{path}: breakpoints ({variable}) must be strictly increasing")
    if not (np.allclose(get("Ki"), s.Ki, rtol=1e-9, atol=0) and np.allclose(get("Kd"), s.Kd, rtol=1e-9, atol=0)):
        raise PrlPidError(f"{path}: the Ki/Kd columns disagree with Kp/Ti/Td (Ki = Kp/Ti, Kd = Kp*Td); "
                          "edit Kp, Ti, Td and recompute Ki, Kd")
    return s


# -- replay ---------------------------------------------------------------------------------------

def replay_schedule(schedule: GainSchedule, config: TuningConfig, seed: int = 0,
                    intervals=None) -> tuple[dict, dict]:
    """Run the plain gain-scheduled PID (table lookup, no neural network) on the FMU; (metrics, trajectory).

    Design: the run uses PidTuningEnv with the config's (evaluation) setpoint schedule, noise and
    disturbances and the forecast off — exactly what prlpid_fmi.evaluate.rollout does for a policy —
    but the env's action map is replaced by the table: before each step the scheduling variable is
    read (setpoint, measurement or FMU variable, see the module docstring), gains_at gives Kp, Ti, Td
    (and coupling), and the env's own PID, saturation, anti-windup and plant stepping use them
    directly. No action smoothing and no action <-> gain mapping is involved, so the replay of a
    table with constant gains reproduces the rollout of the policy that produced them bit for bit.

    The Trajectory (evaluate.Trajectory) holds scheduling_value (n,). Metrics: compute_metrics, as
    evaluate() computes them. Raises PrlPidError when the table's loops or coupling do not match config.
    """
    from prlpid_fmi.loop.env import PidTuningEnv

    names = [l.output for l in config.loops]
    if list(schedule.loop_names) != names:
        raise PrlPidError(f"the schedule's loops {list(schedule.loop_names)} differ from the config's {names}")
    if (schedule.coupling is not None) != bool(config.coupled):
        raise PrlPidError("the schedule and the config disagree on whether the PID is cross-axis coupled")
    if not math.isclose(schedule.sample_time_s, config.sample_time_s, rel_tol=1e-12):
        warnings.warn(f"the schedule was tuned at Ts = {schedule.sample_time_s} s, the config runs at "
                      f"Ts = {config.sample_time_s} s", stacklevel=2)
    from prlpid_fmi.loop.isolated import make_core
    from prlpid_fmi.loop.evaluation import evaluate_gains

    config = dataclasses.replace(config, forecast_horizon=0)
    core = make_core(config)
    try:
        probe = _Probe(schedule.variable, core)
        values = []

        def table_gains(core):  # called before every step: read the scheduling variable, look the gains up
            z = probe()
            values.append(z)
            g = schedule.gains_object(z)
            return (g.Kp.tolist(), g.Ti.tolist(), g.Td.tolist(), None if g.coupling is None else g.coupling.tolist())

        metrics, traj = evaluate_gains(table_gains, config, seed=seed, intervals=intervals, core=core)
    finally:
        core.close()
    traj.scheduling_value = np.array(values)
    return metrics, traj
