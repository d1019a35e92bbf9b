"""Can a scenario's loops be closed at all? Measured on the FMU before `tune` spends its search on them.

`validate` stays static (the schema and the FMU's description); `tune` calls `check_loops` before the
fixed-PID search, and `init` applies the same rules to the loop it proposes. Per loop, at the scenario's
operating point (plant.parameters; every other input at its start value):

- the loop's input is stepped (probe.open_loop): an output that does not move, or returns to where it was
  (a zero-gain pulse: a velocity under a spring), is refused: no PID can hold it at a setpoint;
- the input is held at REACH_LEVELS levels over u_limits until the output settles (open_loop.sweep_input): a
  stable or static output's setpoint_range must lie inside what it reaches there (2 % of the reach as
  tolerance); an integrating output, held at u_limits[0] and u_limits[1], must move one way at one limit and the
  other way at the other;
- a sample time longer than the loop can tolerate (an eighth of an oscillation period, half a time
  constant, half of 1/λ for an unstable plant) is a warning, not an error: the user may know better.
Unstable plants are not refused on reach: their open-loop trims say nothing of what a closed loop holds.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np

from prlpid_fmi.errors import PlantError, ScenarioError

REACH_TOLERANCE = 0.02           # setpoints may pass the measured reach by this part of it
REACH_LEVELS = 5                 # input levels over u_limits a stable output's reach is measured at


def loop_findings(tuning) -> tuple[list[str], list[str]]:
    """(problems, warnings) of every loop of a TuningConfig, each one line starting with its scenario key."""
    from prlpid_fmi.fmu.resolve import resolve_fmu
    from prlpid_fmi.probe.open_loop import probe, sweep_input

    path = resolve_fmu(tuning.fmu, tuning.fmi_version)
    problems, notes = [], []
    for i, loop in enumerate(tuning.loops):
        key = f"plant.loops[{i}]"
        result = probe(path, output=loop.output, inputs=[loop.input], start_values=dict(tuning.plant_parameters))
        r = result.responses[0]
        if r.kind == "none":
            problems.append(f"{key}: {loop.input} does not move {loop.output} (measured gain 0 for a step of "
                            f"{r.du:+.4g} from {r.u0:.4g}; expected an input that moves the measured output)")
            continue
        if r.zero_gain:
            problems.append(f"{key}: {loop.output} returns to where it was after a step of {loop.input} (measured "
                            f"steady gain {r.gain:.3g} after a pulse of {r.peak:.3g}: it is a rate of what the input "
                            "moves; expected an output the input holds, e.g. a position rather than its velocity)")
            continue
        lo_u, hi_u = loop.u_min, loop.u_max
        if r.kind in ("stable", "static", "integrating") and math.isfinite(lo_u) and math.isfinite(hi_u) and hi_u > lo_u:
            # an integrating output's slopes at both limits; a stable one's reach over the range (its steady-state
            # map need not be monotone: probe.steady_state)
            levels = [lo_u, hi_u] if r.kind == "integrating" else list(np.linspace(lo_u, hi_u, REACH_LEVELS))
            sweep = sweep_input(result, r, levels)
            sp_lo, sp_hi = loop.setpoint_range
            if r.kind == "integrating":
                if sweep.slopes[0] * sweep.slopes[1] > 0:
                    problems.append(f"{key}.u_limits: [{lo_u:g}, {hi_u:g}] cannot hold {loop.output}: it "
                                    f"{'rises' if sweep.slopes[0] > 0 else 'falls'} at both limits "
                                    f"({sweep.slopes[0]:.4g} and {sweep.slopes[1]:.4g} per s); expected limits "
                                    "around the input that holds it")
            elif all(sweep.settled):
                y_lo, y_hi = sweep.reach
                tol = REACH_TOLERANCE * (y_hi - y_lo)
                if sp_lo < y_lo - tol or sp_hi > y_hi + tol:
                    problems.append(f"{key}.setpoint_range: [{sp_lo:g}, {sp_hi:g}] is outside what {loop.input} "
                                    f"holds at steady state within u_limits [{lo_u:g}, {hi_u:g}] (measured: "
                                    f"{loop.output} from {y_lo:.4g} to {y_hi:.4g}); expected a range inside it")
        note = _sample_time_note(key, tuning.sample_time_s, r)
        if note:
            notes.append(note)
    return problems, notes


def _sample_time_note(key: str, ts: float, r) -> Optional[str]:
    """A warning when the control period is long for the loop's measured dynamics."""
    if r.period_s and ts > r.period_s / 8:
        limit, what = r.period_s / 8, f"its response oscillates with period {r.period_s:.4g} s"
    elif r.kind == "stable" and ts > r.time_constant_s / 2:
        limit, what = r.time_constant_s / 2, f"its time constant is {r.time_constant_s:.4g} s"
    elif r.kind == "unstable" and ts > 0.5 / r.growth_rate_per_s:
        limit, what = 0.5 / r.growth_rate_per_s, f"it grows as e^(λt), λ = {r.growth_rate_per_s:.4g} 1/s"
    else:
        return None
    return (f"plant.sample_time: {ts:g} s is long for {key} ({r.input} -> {r.output}): {what}; "
            f"expected at most {limit:.3g} s")


def check_loops(tuning, source: Optional[str | Path] = None) -> list[str]:
    """Refuse a scenario whose loops cannot be closed (ScenarioError, one line naming the file and each
    problem's key), else return the warnings. Always in a worker process (fmu.worker.call_in_worker): the check
    runs before the run directory exists, so an FMU that crashes or hangs here must not take the tool with it;
    an FMU that cannot be probed (it crashes, hangs, fails a step) gives a warning only: tune's own fault
    handling, with its run directory and --resume, then deals with it."""
    from prlpid_fmi.fmu.resolve import resolve_fmu
    from prlpid_fmi.fmu.worker import call_in_worker

    where = f"{source}: " if source else ""
    try:
        path = resolve_fmu(tuning.fmu, tuning.fmi_version)
        problems, notes = call_in_worker(loop_findings, tuning, fmus=[path], what="the loop check",
                                         step_timeout_s=tuning.step_timeout_s)
    except (PlantError, OSError) as exc:
        return [f"{where}the loops could not be measured before the search ({exc}); tuning without the check"]
    if problems:
        raise ScenarioError(where + "; ".join(problems))
    return [where + n for n in notes]
