"""Deploy a gain schedule as code for a PLC or a microcontroller: IEC 61131-3 ST, PLCopen XML, C99.

One intermediate description, ``DeployedController`` (built from a GainSchedule by ``from_schedule``),
is rendered by jinja2 templates shipped in ``prlpid_fmi/templates/deploy/``:

- ``st``: an IEC 61131-3 FUNCTION_BLOCK (``controller.st.j2``, body in ``st_body.j2``);
- ``plcopen``: PLCopen TC6 XML 2.01 holding the same block (``plcopen.xml.j2``, the same body);
- ``c``: a header and a source file, C99, no allocation, no libm (``controller.h.j2``, ``controller.c.j2``).

Every format computes exactly what ``prlpid_fmi.schedule.replay_schedule`` runs (and docs/deploy.md
describes), sample by sample:

1. scheduling value x: the setpoint, measurement or error (setpoint - measurement, uncoupled) of one
   loop, or an external input;
2. gains: numpy.interp's rule per table column — x <= first breakpoint: first row; x >= last: last
   row; x equal to a breakpoint: that row; else slope*(x - bp[j]) + T[j] with
   slope = (T[j+1] - T[j])/(bp[j+1] - bp[j]) (held outside the table, never extrapolated);
3. error e = setpoint - measurement, or the coupled error of eq. 27 summed left to right;
4. first sample after a reset: e(-1) := e(0); when any clipped start output u0 is non-zero, the error
   sum is preset to u0/(Kp/Ti) (bumpless start, as LoopCore does);
5. the positional PID of eq. 2 with the configured derivative filter and anti-windup, operation by
   operation as prlpid_fmi.control.pid.PID.step_values.

Back-calculation's tracking time Tt = sqrt(Ti*Td) is computed every sample from the interpolated
Ti and Td: ST calls the standard SQRT; C has its own correctly rounded square root (Newton's method
plus one exact-residual correction, no libm), so C reproduces Python's math.sqrt.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Optional

from typing import TYPE_CHECKING

from prlpid_fmi import __version__
from prlpid_fmi.errors import PrlPidError, RunError

if TYPE_CHECKING:
    from prlpid_fmi.tuning.schedule.table import GainSchedule
# numpy, the schedule and the PID are imported where used: the CLI imports this module for FORMATS

FORMATS = ("csv", "st", "plcopen", "c")
CODE_FORMATS = FORMATS[1:]
SUFFIX = {"st": ".st", "plcopen": ".xml", "c": ".c"}
_IDENTIFIER = re.compile(r"^[A-Za-z][A-Za-z0-9]*(_[A-Za-z0-9]+)*$")  # C and IEC 61131-3 (no '__', no trailing '_')
_C_KEYWORDS = frozenset("""auto break case char const continue default do double else enum extern float for goto if
inline int long register restrict return short signed sizeof static struct switch typedef union unsigned void
volatile while""".split())
LREAL_MAX = "1.7976931348623157E308"  # ST has no infinity: an unbounded limit is the largest LREAL

__all__ = ["DeployedController", "from_schedule", "render", "export_controller", "controller_name", "FORMATS",
           "csv_only_options", "deployable_files"]


@dataclass(frozen=True)
class DeployedController:
    """What every exported format carries: the table, the PID's settings and the scheduling variable.

    name: identifier (C prefix; the ST block is FB_<name>). breakpoints: (K,) strictly increasing;
    Kp, Ti [s], Td [s]: K rows of n_loops values; coupling: K rows of 6 (COUPLING_NAMES order) or None.
    schedule_kind: "setpoint" | "measurement" | "error" (of loop schedule_loop) | "external" (an input).
    u_min/u_max: n_loops limits (may be infinite). source: where the table came from (for comments).
    """

    name: str
    source: str
    sample_time_s: float
    loop_names: tuple
    loop_inputs: tuple
    output_units: tuple
    input_units: tuple
    breakpoints: tuple
    Kp: tuple
    Ti: tuple
    Td: tuple
    coupling: Optional[tuple]
    anti_windup: str
    derivative_filter_N: Optional[float]
    u_min: tuple
    u_max: tuple
    schedule_variable: str
    schedule_unit: str
    schedule_kind: str
    schedule_loop: Optional[int]

    @property
    def n_loops(self) -> int:
        return len(self.loop_names)

    @property
    def n_rows(self) -> int:
        return len(self.breakpoints)

    @property
    def coupled(self) -> bool:
        return self.coupling is not None

    @property
    def coupling_names(self) -> tuple:
        from prlpid_fmi.control import COUPLING_NAMES

        return COUPLING_NAMES

    @property
    def coupled_terms(self) -> list:
        """Eq. 27 per loop: [(coupling index, measurement index), ...] in summation order (C's zero diagonal dropped)."""
        rows = [[None, 0, 1], [2, None, 3], [4, 5, None]]  # coupling_matrix's layout, indices into COUPLING_NAMES
        return [[(c, j) for j, c in enumerate(row) if c is not None] for row in rows]

    def metadata(self) -> list[tuple[str, str]]:
        """(key, text) lines for the header comment of every format."""
        from prlpid_fmi.tuning.schedule.table import INTERPOLATION, PID_EQUATION

        lines = [("generated by", f"prlpid-fmi {__version__} from {self.source}"),
                 ("PID", PID_EQUATION + "; u clipped to [u_min, u_max]"),
                 ("sample time", f"{self.sample_time_s!r} s (call the block once every sample time)"),
                 ("scheduling variable", f"{self.schedule_variable}" + (f" [{self.schedule_unit}]" if self.schedule_unit
                                                                        else "")
                  + (" = setpoint - measurement of that loop" if self.schedule_kind == "error" else "")),
                 ("interpolation", INTERPOLATION),
                 ("anti-windup", self.anti_windup + (" (Tt = sqrt(Ti*Td), or Ti when Td = 0)"
                                                     if self.anti_windup == "back_calculation" else "")),
                 ("derivative filter", "none" if self.derivative_filter_N is None
                  else f"first order, Tf = Td/N, N = {self.derivative_filter_N!r}"),
                 ("error", "e = (r - y) + C*y (cross-axis coupling, paper eq. 27)" if self.coupled else "e = r - y")]
        for i, name in enumerate(self.loop_names):
            lines.append((f"loop {i + 1}", f"measurement {name} [{self.output_units[i] or 'y-unit'}] -> "
                                           f"{self.loop_inputs[i]} [{self.input_units[i] or 'u-unit'}], "
                                           f"u in [{self.u_min[i]!r}, {self.u_max[i]!r}]"))
        return lines


def controller_name(text: str) -> str:
    """An identifier valid in C and IEC 61131-3 made from `text` (e.g. an output file's stem)."""
    name = re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")
    if not name or not name[0].isalpha():
        name = "pid_" + name if name else "pid"
    return name + "_pid" if name in _C_KEYWORDS else name


def _check_name(name: str) -> str:
    if not _IDENTIFIER.match(name) or name in _C_KEYWORDS:
        raise PrlPidError(f"--name {name!r}: not usable as a C and IEC 61131-3 identifier "
                          "(expected a letter, then letters, digits and single underscores, e.g. two_tank_pid)")
    return name


def from_schedule(schedule: "GainSchedule", name: str, source: str = "a gain schedule") -> DeployedController:
    """The intermediate description of `schedule`; refuses tables a plain PID cannot run.

    Raises PrlPidError naming the problem: non-finite gains or breakpoints, Ti <= 0, Td < 0, an
    unknown anti-windup mode, a derivative filter N <= 0, or u_min > u_max.
    """
    import numpy as np

    from prlpid_fmi.control import COUPLING_NAMES
    from prlpid_fmi.control.pid import ANTI_WINDUP_MODES
    from prlpid_fmi.tuning.schedule.table import LOOP_VARIABLE

    s = schedule
    where = f"{source}: "
    _check_name(name)
    columns = {"Kp": s.Kp, "Ti": s.Ti, "Td": s.Td}
    if s.coupling is not None:
        columns["coupling"] = s.coupling
    checks = [(key, table, np.isfinite, "a finite number") for key, table in columns.items()]
    checks += [("Ti", s.Ti, lambda a: a > 0, "Ti > 0 s"), ("Td", s.Td, lambda a: a >= 0, "Td >= 0 s")]
    if not np.all(np.isfinite(s.breakpoints)):
        raise PrlPidError(f"{where}{s.variable}: breakpoints {s.breakpoints.tolist()} (expected finite numbers)")
    for key, table, ok, expected in checks:
        bad = np.argwhere(~ok(np.asarray(table, float)))
        if len(bad):
            j, i = bad[0]
            column = COUPLING_NAMES[i] if key == "coupling" else f"{key}[{s.loop_names[i]}]"
            raise PrlPidError(f"{where}{column}: row {j + 1} (breakpoint {float(s.breakpoints[j])!r}) "
                              f"(got {float(table[j, i])!r}; expected {expected})")
    if np.any(np.diff(s.breakpoints) <= 0):
        raise PrlPidError(f"{where}{s.variable}: breakpoints (got {s.breakpoints.tolist()}; expected strictly increasing)")
    if s.anti_windup not in ANTI_WINDUP_MODES:
        raise PrlPidError(f"{where}anti_windup: (got {s.anti_windup!r}; expected one of {', '.join(ANTI_WINDUP_MODES)})")
    if s.derivative_filter_N is not None and not (math.isfinite(s.derivative_filter_N) and s.derivative_filter_N > 0):
        raise PrlPidError(f"{where}derivative_filter_N: (got {s.derivative_filter_N!r}; expected a number > 0, or none)")
    if not (math.isfinite(s.sample_time_s) and s.sample_time_s > 0):
        raise PrlPidError(f"{where}sample_time_s: (got {s.sample_time_s!r}; expected a number > 0)")
    if np.any(~(s.u_min <= s.u_max)):
        raise PrlPidError(f"{where}u limits: (got u_min {s.u_min.tolist()}, u_max {s.u_max.tolist()}; "
                          "expected u_min <= u_max)")
    m = LOOP_VARIABLE.match(s.variable)
    if m and m.group(2) in s.loop_names:
        kind, loop = m.group(1), s.loop_names.index(m.group(2))
    else:
        kind, loop = "external", None

    def rows(a) -> tuple:
        return tuple(tuple(float(v) for v in row) for row in np.asarray(a, float))

    return DeployedController(
        name=name, source=source, sample_time_s=float(s.sample_time_s), loop_names=tuple(s.loop_names),
        loop_inputs=tuple(s.loop_inputs), output_units=tuple(s.output_units), input_units=tuple(s.input_units),
        breakpoints=tuple(float(v) for v in s.breakpoints), Kp=rows(s.Kp), Ti=rows(s.Ti), Td=rows(s.Td),
        coupling=None if s.coupling is None else rows(s.coupling), anti_windup=s.anti_windup,
        derivative_filter_N=None if s.derivative_filter_N is None else float(s.derivative_filter_N),
        u_min=tuple(float(v) for v in s.u_min), u_max=tuple(float(v) for v in s.u_max),
        schedule_variable=s.variable, schedule_unit=s.unit, schedule_kind=kind, schedule_loop=loop)


# -- literals ---------------------------------------------------------------------------------------

def c_real(x: float) -> str:
    """A C double literal that reads back as exactly `x` (shortest round trip); HUGE_VAL for infinities."""
    x = float(x)
    if math.isinf(x):
        return "HUGE_VAL" if x > 0 else "(-HUGE_VAL)"
    text = repr(x)
    return text if any(ch in text for ch in ".en") else text + ".0"


def st_real(x: float) -> str:
    """An IEC 61131-3 LREAL literal that reads back as exactly `x`: LREAL#[-]<digits>.<digits>[E<exp>].

    ST has no infinity; an infinite limit becomes the largest LREAL (clipping to it changes no finite u).
    """
    x = float(x)
    if math.isinf(x):
        return "LREAL#" + ("-" if x < 0 else "") + LREAL_MAX
    mantissa, _, exponent = repr(abs(x)).partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return "LREAL#" + ("-" if math.copysign(1.0, x) < 0 else "") + mantissa + (f"E{int(exponent)}" if exponent else "")


def st_comment(text: str) -> str:
    """Text safe inside an ST/Pascal comment (* ... *)."""
    return text.replace("(*", "( *").replace("*)", "* )")


# -- rendering --------------------------------------------------------------------------------------

def _environment():
    import jinja2

    env = jinja2.Environment(loader=jinja2.PackageLoader("prlpid_fmi", "templates/deploy"),
                             undefined=jinja2.StrictUndefined, keep_trailing_newline=True,
                             trim_blocks=True, lstrip_blocks=True, autoescape=False)
    env.filters.update(c=c_real, st=st_real, st_comment=st_comment)
    return env


def render(controller: DeployedController, fmt: str, basename: str | None = None,
           created: datetime | None = None) -> dict[str, str]:
    """The files of format `fmt` ("st", "plcopen", "c"): {file name: text}, in writing order.

    Names: <basename>.st; <basename>.xml; <basename>.h and <basename>.c (basename: default the
    controller's name). created: the PLCopen file header's time (default now, UTC).
    """
    env = _environment()
    base = basename or controller.name
    ctx = {"ctl": controller, "version": __version__, "P": controller.name.upper(), "p": controller.name,
           "fb": f"FB_{controller.name}", "header": f"{base}.h",
           "created": (created or datetime.now(timezone.utc)).strftime("%Y-%m-%dT%H:%M:%S")}
    if fmt not in CODE_FORMATS:
        raise PrlPidError(f"--format {fmt!r}: no code for it (expected one of {', '.join(CODE_FORMATS)})")
    return {f"{base}{suffix}": env.get_template(template).render(ctx) for suffix, template in _TEMPLATES[fmt]}


_TEMPLATES = {"st": ((".st", "controller.st.j2"),), "plcopen": ((".xml", "plcopen.xml.j2"),),
              "c": ((".h", "controller.h.j2"), (".c", "controller.c.j2"))}


def output_paths(output: Path, fmt: str) -> list[Path]:
    """The files `export --format fmt -o output` writes: output itself; for C, <stem>.h and <stem>.c beside it."""
    if fmt == "c":
        base = output.with_suffix("") if output.suffix in (".c", ".h") else output
        return [base.with_name(base.name + suffix) for suffix, _ in _TEMPLATES["c"]]
    return [output]


def export_controller(run_dir: str | Path, output: str | Path, fmt: str, fixed: bool = False,
                      name: str | None = None, force: bool = False) -> list[Path]:
    """Write the run's deployed controller (schedule.csv; fixed_pid.csv with `fixed`) as code; the paths written.

    output: the file to write (for C: <stem>.c, with <stem>.h beside it). name: the identifier in the
    code (default: made from the output file's stem). Files the run owns are never written; existing
    files only with `force`.
    """
    from prlpid_fmi import rundir as rd
    from prlpid_fmi.rundir import write_atomic
    from prlpid_fmi.run.tune import check_output
    from prlpid_fmi.tuning.schedule.table import read_schedule_csv

    run_dir, output = Path(run_dir), Path(output)
    table = run_dir / (rd.FIXED_PID_CSV if fixed else rd.SCHEDULE)
    if not table.is_file():
        what = "the tuned fixed PID (written by `tune` unless --no-baseline)" if fixed else \
            "the deployed controller (written by `tune` when a controller is deployable)"
        raise RunError(f"{table}: missing (expected {what})")
    paths = output_paths(output, fmt)
    for path in paths:
        check_output(run_dir, path, force)
    base = paths[0].with_suffix("").name if fmt == "c" else None
    controller = from_schedule(read_schedule_csv(table), name or controller_name(paths[0].stem),
                               source=f"{run_dir.name}/{table.name}")
    files = render(controller, fmt, basename=base)
    return [write_atomic(path, text) for path, text in zip(paths, files.values())]


def csv_only_options(args) -> list[str]:
    """The `export` options given that do not apply to args.format (CSV extraction vs code generation)."""
    if args.format == "csv":
        given = (("--fixed", args.fixed), ("--name", args.name is not None))
    else:
        given = (("--schedule-by", args.schedule_by is not None), ("--points", args.points is not None),
                 ("--replay", args.replay), ("--scenario", args.scenario is not None))
    return [option for option, present in given if present]


def deployable_files(run_dir: str | Path) -> str:
    """A report paragraph naming the run's deployable files and how to turn them into PLC or C code."""
    from prlpid_fmi import rundir as rd

    run_dir = Path(run_dir)
    have = [(f, what) for f, what in ((rd.SCHEDULE, "the deployed controller: a plain (gain-scheduled) PID table"),
                                      (rd.FIXED_PID_CSV, "the tuned fixed PID as a one-row table"))
            if (run_dir / f).is_file()]
    if not have:
        return "Deployable files: none (no controller was deployable).\n"
    lines = ["Deployable files:", ""] + [f"- `{f}`: {what}" for f, what in have]
    lines += ["", "As code for a PLC or a microcontroller (IEC 61131-3 Structured Text, PLCopen XML, C99; see "
                  "docs/deploy.md): `prlpid-fmi export RUN --format st|plcopen|c -o FILE`"
              + (" (`--fixed` for fixed_pid.csv)." if any(f == rd.FIXED_PID_CSV for f, _ in have) else ".")]
    return "\n".join(lines) + "\n"
