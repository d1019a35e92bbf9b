"""The report's opening paragraph: the deployed controller and why, in words."""
from __future__ import annotations

import math

from prlpid_fmi.deliver.rule import Candidate, Decision, Deployed
from prlpid_fmi.robustness.status import ms_text


def _ms(c: Candidate) -> str:
    return ms_text(c.worst_Ms)


def _points(c: Candidate) -> str:
    """Where a candidate's margins were measured, in words."""
    n = sum(isinstance(b, (int, float)) for b in c.breakpoints)  # the draws' estimates are labelled in words
    where = "its operating point" if n == 1 else f"{n} operating points of the setpoint range"
    return where + (f", on the nominal plant and {c.draws} parameter draws" if c.draws else "")


def _ratio(a: float, b: float) -> str:
    return f"{a / b:.2f}x" if b and math.isfinite(a) and math.isfinite(b) else "n/a"


def verdict(decision: Decision, schedule: Candidate | None, fixed: Candidate, max_sensitivity: float,
            gain_mapping: str = "anchored", classical: Candidate | None = None) -> str:
    """The report's opening paragraph, in words (markdown); gain_mapping: the run's controller.gain_mapping;
    classical: the classical gain schedule's evidence when one was built."""
    lines = ["## Verdict", ""]
    if decision.deploy == Deployed.CLASSICAL:
        c, f = classical, fixed
        lines.append(f"**Deploy the classical gain schedule** (schedule.csv: a local PID design at each of "
                     f"{len([b for b in c.breakpoints if isinstance(b, (int, float))])} operating points, "
                     f"interpolated over the setpoint; a plain gain-scheduled PID). On the evaluation its ISE is "
                     f"{_ratio(c.overall('ISE'), f.overall('ISE'))} the fixed PID's and its worst Ms {_ms(c)} (fixed "
                     f"PID {_ms(f)}; limit {max_sensitivity:g}). Ratios are classical schedule ÷ fixed PID.")
        if schedule is not None:
            lines.append("The adaptive schedule did not beat it (why: below).")
    elif decision.deploy == Deployed.SCHEDULE:
        s, f = schedule, fixed
        if math.isfinite(s.overall("Overshoot")) and f.overall("Overshoot") > 0:
            shape = f"its overshoot {_ratio(s.overall('Overshoot'), f.overall('Overshoot'))}"
        elif math.isfinite(s.overall("Overshoot")):  # the fixed PID does not overshoot: no ratio
            shape = f"its overshoot {s.overall('Overshoot'):.2g} % (fixed PID {f.overall('Overshoot'):.2g} %)"
        else:  # no setpoint step: disturbance rejection
            shape = f"its peak deviation {_ratio(s.overall('PeakDeviation'), f.overall('PeakDeviation'))}"
        lines.append(f"**Deploy the adaptive gain schedule** (schedule.csv, a plain gain-scheduled PID; no neural "
                     f"network). On the evaluation its ISE is {_ratio(s.overall('ISE'), f.overall('ISE'))} the fixed "
                     f"PID's, {shape}, and its worst Ms {_ms(s)} (fixed PID {_ms(f)}; limit "
                     f"{max_sensitivity:g}). Ratios are gain schedule ÷ fixed PID; lower is better.")
    elif decision.deploy == Deployed.FIXED_PID:
        lines.append(f"**Deploy the fixed PID** (schedule.csv holds it as a one-row table; also fixed_pid.csv). "
                     f"Its worst Ms is {_ms(fixed)} (limit {max_sensitivity:g}) over "
                     f"{_points(fixed)}.")
        if schedule is not None:
            the_map = ("wider controller.anchor_bands" if gain_mapping == "anchored" else
                       "the anchored gain map (controller.gain_mapping: anchored, which starts training at the fixed "
                       "PID)")
            lines.append(f"The adaptive schedule was not deployed (why: below). To try: a longer training budget "
                         f"(--timesteps), {the_map}, or training.randomize over the parameters that vary in your "
                         "plant.")
    else:
        lines.append(f"**Nothing here is safe to deploy**: no controller meets the robustness limit Ms <= "
                     f"{max_sensitivity:g} without diverging. Narrow the gain ranges, lower the sample time, or "
                     "check the plant's limits and operating range.")
    unverified = [c.name for c in (schedule, classical, fixed) if c is not None and c.unverified]
    if unverified:
        lines.append(f"Robustness could not be verified for: {', '.join(unverified)} (the frequency-response "
                     "estimate on the FMU was unreliable, e.g. a time-varying or strongly nonlinear plant); "
                     "the choice rests on the evaluation alone.")
    lines += [""] + [f"- {r}" for r in decision.reasons]
    return "\n".join(lines) + "\n"


def classical_note(record: dict | None) -> str:
    """One sentence on how run.json's "classical_schedule" record shaped the classical gain schedule ("" when there is
    nothing to say): not built and why, or its rows kept only part of the way from the fixed PID to the local designs
    (tuning.schedule.classical.best_blend)."""
    if not record:
        return ""
    if not record.get("built") and record.get("why"):
        return f"A classical gain schedule was considered and not built: {record['why']}."
    blend = record.get("follow_blend")
    if record.get("built") and blend is not None and blend < 1.0:
        return (f"The classical gain schedule's rows are {blend:g} of the way from the fixed PID to the local load "
                "designs (gains interpolated geometrically): on the training distribution's setpoint steps that table "
                "had the least ISE of those tried (run.json classical_schedule.training_ise_per_blend).")
    return ""
