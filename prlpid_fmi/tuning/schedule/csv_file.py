"""The gain table as a CSV file: metadata comment lines, one row per breakpoint; written atomically, read back
exactly.

Per loop, every row carries Kp, Ti, Td, the parallel Ki, Kd (checked on reading) and the PID's structure
b, c, Tf (setpoint weight, derivative weight, measurement filter [s]; control.pid). The structure is not
scheduled: every row holds the same b, c, Tf for a loop, and a file whose rows disagree is refused. The
metadata line measurement_filter_order gives the filter's order. A file written before the 2-DOF law has
neither: it is read as b = c = 1, Tf = 0, order 1, the law (paper eq. 2) it was written with.

The metadata line u_rate_limit[<loop>] gives each loop's output rate limit [input units / s], inf for none; a
file written before the rate limit has no such line and is read as inf (no rate limit).

The metadata line gain_change (bumpless | positional, control.pid) says what a change of the interpolated gains
between samples does to the error sum; a file written before the bumpless law has none and is read as positional.
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np

from prlpid_fmi.control import COUPLING_NAMES
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.rundir import write_atomic
from prlpid_fmi.tuning.schedule.table import (
    BUMPLESS_START,
    GAIN_CHANGE_EQUATION,
    INTERPOLATION,
    MEASUREMENT_FILTER_EQUATION,
    PID_EQUATION,
    RATE_LIMIT_BAND,
    STRUCTURE_COLUMNS,
    GainSchedule,
)
from prlpid_fmi.version import __version__

_ANTI_WINDUP_TEXT = {
    "clamping": "clamping (conditional integration: e*Ts is not added to sum(e) while u is saturated "
                "and Kp*e pushes further into the limit)",
    "back_calculation": "back_calculation (tracking time constant Tt = sqrt(Ti*Td), or Ti when Td = 0)",
    "none": "none",
}


def _f(x) -> str:
    return repr(float(x))


def _metadata(s: GainSchedule) -> list[tuple[str, str]]:
    units = s.column_units()
    meta = [
        ("format", "prlpid-fmi gain schedule 1"),
        ("tool", f"prlpid-fmi {__version__}"),
        ("pid_form", "positional ideal (ISA) 2-DOF PID, paper eq. 2 with setpoint weights b (proportional), "
                     "c (derivative), a measurement filter Tf feeding P and D and an output rate limit R per loop "
                     "(b = c = 1, Tf = 0, R = inf: eq. 2 exactly); r = setpoint, y = measurement"
                     + ("; coupled errors (r - y) + C*y, paper eq. 27, for e, ep (b*r, yf) and ed (c*r, yf)"
                        if s.coupling is not None else "")),
        ("pid_equation", (f"{PID_EQUATION}; yf = y through the measurement filter: {MEASUREMENT_FILTER_EQUATION}; "
                          f"gain change: {GAIN_CHANGE_EQUATION[s.gain_change]}; "
                          "I includes the current e; ed_prev = ed at the first sample (no derivative kick); "
                          f"u then clipped to {RATE_LIMIT_BAND}; Ti = inf means no integral action; "
                          "b, c, Tf per loop in the b, c, Tf columns, R in u_rate_limit[<loop>]")),
        ("equivalent_parallel", "u = Kp*ep + Ki*I + Kd*D with Ki = Kp/Ti, Kd = Kp*Td"),
        ("sample_time_s", _f(s.sample_time_s)),
        ("scheduling_variable", s.variable),
        ("scheduling_unit", s.unit),
        ("interpolation", INTERPOLATION),
        ("gain_change", s.gain_change),
        ("anti_windup", s.anti_windup),
        ("anti_windup_method", _ANTI_WINDUP_TEXT.get(s.anti_windup, s.anti_windup)),
        ("derivative_filter_N", "none" if s.derivative_filter_N is None else _f(s.derivative_filter_N)),
        ("measurement_filter_order", str(s.measurement_filter_order)),
        ("bumpless_start", BUMPLESS_START),
        ("excluded_operating_points", "none" if not s.excluded else
         " ".join(_f(v) for v in s.excluded) + " (held setpoints where the closed loop diverged)"),
    ]
    for i, name in enumerate(s.loop_names):
        meta.append((f"loop[{name}]", f"input={s.loop_inputs[i]}; u_min={_f(s.u_min[i])}; u_max={_f(s.u_max[i])}; "
                                      f"output_unit={s.output_units[i]}; input_unit={s.input_units[i]}"))
    for i, name in enumerate(s.loop_names):  # [input units / s]; inf: none
        meta.append((f"u_rate_limit[{name}]", _f(s.u_rate_limit[i])))
    meta.append(("units", "; ".join(f"{c}={units[c]}" for c in s.columns())))
    return meta


NOT_DEPLOYABLE = "NOT DEPLOYABLE"  # the metadata key of a table the deliverable rule refused (its value: why)


def write_schedule_csv(schedule: GainSchedule, path, not_deployable: str = "") -> Path:
    """Write the schedule as CSV (metadata as "# key: value" lines, then header and rows), atomically.
    not_deployable: why the deliverable rule refused this table; written first as "# NOT DEPLOYABLE: why"."""
    s = schedule
    buf = io.StringIO()
    if not_deployable:
        buf.write(f"# {NOT_DEPLOYABLE}: {' '.join(not_deployable.split())}\n")
    for key, value in _metadata(s):
        buf.write(f"# {key}: {value}\n".replace(": \n", ":\n"))
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(s.columns())
    Ki, Kd = s.Ki, s.Kd
    for j, bp in enumerate(s.breakpoints):
        row = [_f(bp)]
        for i in range(s.n_loops):
            row += [_f(s.Kp[j, i]), _f(s.Ti[j, i]), _f(s.Td[j, i]), _f(Ki[j, i]), _f(Kd[j, i]),
                    _f(s.setpoint_weight[i]), _f(s.derivative_weight[i]), _f(s.measurement_filter_s[i])]
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


def not_deployable(path) -> str:
    """Why the table at `path` was refused ("# NOT DEPLOYABLE: ..."), "" for a deployable one."""
    return read_schedule_metadata(path).get(NOT_DEPLOYABLE, "")


_STRUCTURE_DEFAULTS = {"b": 1.0, "c": 1.0, "Tf": 0.0}  # the law of a file without the structure columns (eq. 2)


def _structure(path, table: np.ndarray, col: dict, loops: list) -> list[np.ndarray]:
    """b, c, Tf (n_loops,) from their columns: the one value of every row; a file without a kind's columns
    gets its _STRUCTURE_DEFAULTS. Raises PrlPidError for rows that disagree, or columns for some loops only."""
    out = []
    for kind in STRUCTURE_COLUMNS:
        names = [f"{kind}[{name}]" for name in loops]
        present = [c in col for c in names]
        if not any(present):
            out.append(np.full(len(loops), _STRUCTURE_DEFAULTS[kind]))
            continue
        if not all(present):
            missing = [name for name, ok in zip(names, present) if not ok]
            raise PrlPidError(f"{path}: column(s) {', '.join(missing)} missing (expected a {kind} column for every "
                              f"loop, or none: then {kind} = {_STRUCTURE_DEFAULTS[kind]!r})")
        values = []
        for name in names:
            column = table[:, col[name]]
            distinct = list(dict.fromkeys(column.tolist()))
            if len(distinct) != 1:
                raise PrlPidError(f"{path}: column {name}: the rows disagree ({', '.join(repr(v) for v in distinct)}); "
                                  f"expected one {kind} in every row (the PID structure is not scheduled)")
            values.append(distinct[0])
        out.append(np.array(values, float))
    return out


def _rate_limits(path, meta: dict, loops: list) -> np.ndarray:
    """u_rate_limit per loop from the u_rate_limit[<loop>] lines (missing: inf, a file written before the rate
    limit). Raises PrlPidError for a value that is not a number > 0."""
    out = []
    for name in loops:
        text = meta.get(f"u_rate_limit[{name}]", "inf")
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not value > 0:
            raise PrlPidError(f"{path}: u_rate_limit[{name}]: (got {text!r}; expected a number > 0 "
                              "[input units / s], or inf: none)")
        out.append(value)
    return np.array(out, float)


def read_schedule_csv(path) -> GainSchedule:
    """Parse a CSV written by write_schedule_csv (exact round trip). Checks Ki/Kd against Kp, Ti, Td, and that
    every row has the same b, c, Tf per loop; a file without those columns (written before the 2-DOF law)
    reads as b = c = 1, Tf = 0, measurement_filter_order 1, one without u_rate_limit[<loop>] as inf (none), and one
    without gain_change as positional."""
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
    weight_b, weight_c, filter_tf = _structure(path, table, col, loops)
    order = meta.get("measurement_filter_order", "1")
    if order not in ("1", "2"):
        raise PrlPidError(f"{path}: measurement_filter_order: (got {order!r}; expected 1 or 2)")
    gain_change = meta.get("gain_change", "positional")  # a file written before the bumpless law: eq. 2's
    if gain_change not in GAIN_CHANGE_EQUATION:
        raise PrlPidError(f"{path}: gain_change: (got {gain_change!r}; expected {' or '.join(GAIN_CHANGE_EQUATION)})")
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
                       if v != "none"),
        setpoint_weight=weight_b, derivative_weight=weight_c, measurement_filter_s=filter_tf,
        measurement_filter_order=int(order), u_rate_limit=_rate_limits(path, meta, loops), gain_change=gain_change)
    if np.any(np.diff(s.breakpoints) <= 0):
        raise PrlPidError(f"{path}: breakpoints ({variable}) must be strictly increasing")
    if not (np.allclose(get("Ki"), s.Ki, rtol=1e-9, atol=0) and np.allclose(get("Kd"), s.Kd, rtol=1e-9, atol=0)):
        raise PrlPidError(f"{path}: the Ki/Kd columns disagree with Kp/Ti/Td (Ki = Kp/Ti, Kd = Kp*Td); "
                          "edit Kp, Ti, Td and recompute Ki, Kd")
    return s
