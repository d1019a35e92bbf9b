"""Where a stable loop's steady-state gain changes sign: an extremum of its steady-state map y_ss(u).

Per loop, at the scenario's operating point (plant.parameters; every other input at its start value), the input
is held at LEVELS levels evenly spaced over u_limits until the output settles (probe.open_loop.sweep_input). When
every level settles and the values rise then fall (or fall then rise) by more than SIGNIFICANT of their spread, with
at least two levels on each side, and the extremum's output lies within NEAR_RANGE of the setpoint range, the map
has an interior extremum the loop meets: past it the loop's gain has the other sign, so a PID that works on one side
drives the measurement away on the other, and setpoints beyond the extremum's value cannot be held at all.

Only a loop the probe reads as stable or static is swept. An open-loop-unstable plant (a multi-steady-state
reactor whose middle branch is unstable) is not: the static gain of its unstable branch has the other sign, yet
feedback with enough gain holds it, so that is no reason to refuse it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

LEVELS = 21
SIGNIFICANT = 0.01  # a rise or fall counts when larger than this part of the map's spread
NEAR_RANGE = 0.1  # an extremum counts when its output lies within this part of the setpoint range beyond it


@dataclass(frozen=True)
class Extremum:
    """An interior extremum of a loop's steady-state map: kind "maximum" | "minimum", at input u and output y, between
    the levels u_before and u_after that bracket it."""

    loop: str
    input: str
    kind: str
    u: float
    y: float
    u_before: float
    u_after: float

    def sentence(self) -> str:
        """What it means for the loop, in words."""
        beyond = "above" if self.kind == "maximum" else "below"
        return (f"the steady-state map of {self.loop} has a {self.kind} of {self.y:.4g} at {self.input} = {self.u:.4g} "
                f"(measured between {self.u_before:.4g} and {self.u_after:.4g}): the loop's gain changes sign there, "
                f"so a PID that holds {self.loop} on one side drives it away on the other, and no input holds a "
                f"setpoint {beyond} {self.y:.4g}; keep the setpoint range on one side of it (and u_limits on that "
                "side of the input), or schedule the controller's sign")


def extremum_of(levels, values, loop: str = "y", name: str = "u") -> Extremum | None:
    """The interior extremum of the map values(levels), both (n,), or None when it is monotone (within
    SIGNIFICANT of its spread)."""
    u, y = np.asarray(levels, float), np.asarray(values, float)
    if u.size < 3 or not np.all(np.isfinite(y)):
        return None
    spread = float(np.ptp(y))
    if spread <= 0:
        return None
    j_max, j_min = int(np.argmax(y)), int(np.argmin(y))
    for j, kind in ((j_max, "maximum"), (j_min, "minimum")):
        if 1 < j < u.size - 2:  # two levels on each side: a map that only bends at its last level saturates there
            rise = abs(y[j] - y[0]) > SIGNIFICANT * spread
            fall = abs(y[j] - y[-1]) > SIGNIFICANT * spread
            if rise and fall:
                return Extremum(loop, name, kind, float(u[j]), float(y[j]), float(u[j - 1]), float(u[j + 1]))
    return None


def loop_extrema(tuning) -> list[Extremum]:
    """The interior extrema of every stable loop's steady-state map over its u_limits (module docstring)."""
    from prlpid_fmi.fmu.resolve import resolve_fmu
    from prlpid_fmi.probe.open_loop import probe, sweep_input

    path = resolve_fmu(tuning.fmu, tuning.fmi_version)
    out = []
    for loop in tuning.loops:
        if not (math.isfinite(loop.u_min) and math.isfinite(loop.u_max) and loop.u_max > loop.u_min):
            continue
        result = probe(path, output=loop.output, inputs=[loop.input], start_values=dict(tuning.plant_parameters))
        r = result.responses[0]
        if r.kind not in ("stable", "static"):
            continue
        sweep = sweep_input(result, r, np.linspace(loop.u_min, loop.u_max, LEVELS))
        if not all(sweep.settled):
            continue
        found = extremum_of(sweep.levels, sweep.values, loop.output, loop.input)
        lo, hi = loop.setpoint_range
        margin = NEAR_RANGE * (hi - lo)
        if found is not None and lo - margin <= found.y <= hi + margin:  # where the loop's setpoints reach it
            out.append(found)
    return out


def extrema_in_worker(tuning) -> list[str]:
    """loop_extrema's sentences, measured in a worker process (an FMU that crashes or hangs there gives none)."""
    from prlpid_fmi.errors import PlantError
    from prlpid_fmi.fmu.resolve import resolve_fmu
    from prlpid_fmi.fmu.worker import call_in_worker

    try:
        path = resolve_fmu(tuning.fmu, tuning.fmi_version)
        found = call_in_worker(loop_extrema, tuning, fmus=[path], what="the steady-state map",
                               step_timeout_s=tuning.step_timeout_s)
    except (PlantError, OSError):
        return []
    return [e.sentence() for e in found]
