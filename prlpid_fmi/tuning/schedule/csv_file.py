"""The gain table as a CSV file: metadata comment lines, one row per breakpoint; written atomically, read back
exactly."""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from prlpid_fmi.control import COUPLING_NAMES
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.rundir import write_atomic
from prlpid_fmi.tuning.schedule.table import INTERPOLATION, PID_EQUATION, GainSchedule
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
