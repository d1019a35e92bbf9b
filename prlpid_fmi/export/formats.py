"""The code formats a gain table is exported as: a registry of CodeFormat entries over one intermediate form.

Each format renders ``DeployedController`` (prlpid_fmi.export.controller, built from a GainSchedule by
``from_schedule``) with jinja2 templates shipped in ``prlpid_fmi/export/templates/``:

- ``st``: an IEC 61131-3 FUNCTION_BLOCK (``controller.st.j2``, body in ``st_body.j2``);
- ``plcopen``: PLCopen TC6 XML 2.01 holding the same block (``plcopen.xml.j2``, the same body);
- ``c``: a header and a source file, C99, no allocation, no libm (``controller.h.j2``, ``controller.c.j2``).

A new format is one CodeFormat entry in ``CODE_FORMATS`` and its templates; the CLI's ``--format`` choices,
the output file names and the report's export hint all read the registry.

Every format computes exactly what ``prlpid_fmi.tuning.schedule.replay.replay_schedule`` runs (and
docs/deploy.md describes), sample by sample:

1. scheduling value x: the setpoint, measurement or error (setpoint - measurement, uncoupled) of one
   loop, or an external input;
2. gains: numpy.interp's rule per table column — x <= first breakpoint: first row; x >= last: last
   row; x equal to a breakpoint: that row; else slope*(x - bp[j]) + T[j] with
   slope = (T[j+1] - T[j])/(bp[j+1] - bp[j]) (held outside the table, never extrapolated);
3. measurement filter yf = F(y) of each loop (Tf = 0: yf = y; otherwise measurement_filter_order
   backward-Euler sections of Tf/order each, x = (T*x_prev + Ts*in)/(T + Ts), started at y on the first
   sample), operation by operation as prlpid_fmi.control.pid.PID.filter_measurement;
4. errors (PID.weighted_errors): e = setpoint - measurement (integral), ep = b*setpoint - yf
   (proportional), ed = c*setpoint - yf (derivative), or for the coupled PID each through eq. 27, summed
   left to right;
5. first sample after a reset, always: ed(-1) := ed(0), and the error sum is preset to
   (u0 - Kp*((b - 1)*measurement))/(Kp/Ti) (0 when Kp/Ti = 0) from the clipped start output u0 and the first
   measurement (bumpless start with no kick from b, and a setpoint step at that sample acts through b, as
   LoopCore does through PID.preset_output); u0 is also the previous output the rate limit moves from;
6. the 2-DOF positional PID u = Kp*(ep + Td*D) + (Kp/Ti)*I, D = (ed - ed_prev)/Ts, I = I_prev + e*Ts, with
   the configured derivative filter and anti-windup, clipped to [lo, hi] = [max(u_min, u_prev - R*Ts),
   min(u_max, u_prev + R*Ts)] for a loop with a rate limit R (else [u_min, u_max]), which the anti-windup
   treats as the limits; operation by operation as PID.step_weighted (eq. 2 exactly when b = c = 1, Tf = 0
   and no rate limit). The block keeps its previous output u_prev as state;
7. bumpless gain change (the table's gain_change "bumpless"): before 6, when the looked-up Kp, Ti, Td differ from the
   previous sample's and Ki != 0, the error sum is rescaled so that the new gains give the previous output on the
   previous sample's ep, D and sum (PID.step_weighted; not at the first sample);
8. manual and tracking per loop (C <name>_step_modes, ST Manual/ManualValue, Track/TrackValue; Track first): u is
   the imposed value clipped to the limits and the error sum is balanced to it, I = (u - Kp*(ep + Td*D))/Ki, as
   PID.track_values.

Back-calculation's tracking time Tt = sqrt(Ti*Td) is computed every sample from the interpolated
Ti and Td: ST calls the standard SQRT; C has its own correctly rounded square root without libm (x scaled
by powers of 4 into [1, 4), Newton's method, then a move to the neighbouring double while an exact
midpoint test says the root lies beyond it), so C reproduces Python's math.sqrt.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from prlpid_fmi.errors import ArgumentError
from prlpid_fmi.export.controller import DeployedController
from prlpid_fmi.version import __version__

# numpy, the schedule and the PID are imported where used: the CLI imports this module for FORMATS

LREAL_MAX = "1.7976931348623157E308"  # ST has no infinity: an unbounded limit is the largest LREAL


@dataclass(frozen=True)
class CodeFormat:
    """One code format: its `--format` name, what it is, and the files it writes as (suffix, template) pairs,
    in writing order."""

    name: str
    description: str
    files: tuple[tuple[str, str], ...]


CODE_FORMATS = {f.name: f for f in (
    CodeFormat("st", "IEC 61131-3 Structured Text", ((".st", "controller.st.j2"),)),
    CodeFormat("plcopen", "PLCopen XML", ((".xml", "plcopen.xml.j2"),)),
    CodeFormat("c", "C99", ((".h", "controller.h.j2"), (".c", "controller.c.j2"))),
)}
FORMATS = ("csv", *CODE_FORMATS)  # `export --format`: the gain table itself, or one of the code formats


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


def st_rate(x: float) -> str:
    """A rate limit as an LREAL literal: ST has no infinity, so no rate limit (inf) is written as 0 (a rate limit
    is > 0), which the block reads as none."""
    return st_real(0.0 if math.isinf(x) else x)


def st_comment(text: str) -> str:
    """Text safe inside an ST/Pascal comment (* ... *)."""
    return text.replace("(*", "( *").replace("*)", "* )")


# -- rendering --------------------------------------------------------------------------------------

def _environment():
    import jinja2

    env = jinja2.Environment(loader=jinja2.PackageLoader("prlpid_fmi.export", "templates"),
                             undefined=jinja2.StrictUndefined, keep_trailing_newline=True,
                             trim_blocks=True, lstrip_blocks=True, autoescape=False)
    env.filters.update(c=c_real, st=st_real, st_rate=st_rate, st_comment=st_comment)
    return env


def render(controller: DeployedController, fmt: str, basename: str | None = None,
           created: datetime | None = None) -> dict[str, str]:
    """The files of code format `fmt` (a CODE_FORMATS name): {file name: text}, in writing order.

    Names: <basename>.st; <basename>.xml; <basename>.h and <basename>.c (basename: default the
    controller's name). created: the PLCopen file header's time (default now, UTC).
    """
    env = _environment()
    base = basename or controller.name
    ctx = {"ctl": controller, "version": __version__, "P": controller.name.upper(), "p": controller.name,
           "fb": f"FB_{controller.name}", "header": f"{base}.h",
           "created": (created or datetime.now(timezone.utc)).strftime("%Y-%m-%dT%H:%M:%S")}
    if fmt not in CODE_FORMATS:
        raise ArgumentError(f"{{fmt}} {fmt!r}: no code for it (expected one of {', '.join(CODE_FORMATS)})")
    return {f"{base}{suffix}": env.get_template(template).render(ctx) for suffix, template in CODE_FORMATS[fmt].files}


def output_paths(output: Path, fmt: str) -> list[Path]:
    """The files `export --format fmt -o output` writes: output itself for a one-file format; for a format of
    several files (C: .h and .c), <stem><suffix> of each beside it (a suffix of the format's on output is
    dropped first)."""
    files = CODE_FORMATS[fmt].files
    if len(files) == 1:
        return [output]
    suffixes = [suffix for suffix, _ in files]
    base = output.with_suffix("") if output.suffix in suffixes else output
    return [base.with_name(base.name + suffix) for suffix in suffixes]
