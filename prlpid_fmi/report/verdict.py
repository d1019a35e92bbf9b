"""The report's opening paragraph: the deployed controller and why, in words."""
from __future__ import annotations

import math

from prlpid_fmi.deliver.acceptance import LONG_HOLD
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
            gain_mapping: str = "anchored", classical: Candidate | None = None, findings: tuple[str, ...] = ()) -> str:
    """The report's opening paragraph, in words (markdown); gain_mapping: the run's controller.gain_mapping;
    classical: the classical gain schedule's evidence when one was built; findings: what was found about the plant
    that explains why nothing passes (probe.steady_state), one sentence each."""
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
        lines.append("**Nothing here is safe to deploy.** No controller passes every check (it follows and settles "
                     f"every setpoint step, overshoots at most the limit, does not chatter, Ms <= {max_sensitivity:g}). "
                     "fixed_pid.csv and the candidates' tables are still written, marked NOT DEPLOYABLE in their "
                     "header. What failed, and what would change it:")
        lines.append("")
        for c in (fixed, classical, schedule):
            if c is not None:
                lines += [f"- the {c.name}: {p}." for p in _failed(c, max_sensitivity)]
        lines += [f"- {f[0].upper()}{f[1:]}." for f in findings]
        lines.append("")
    if decision.deploy != Deployed.NONE:
        lines += [f"Note: {f}." for f in findings]
    deployed = {Deployed.FIXED_PID: fixed, Deployed.CLASSICAL: classical, Deployed.SCHEDULE: schedule
                }.get(decision.deploy)
    if deployed is not None and deployed.acceptance is not None:
        lines += _acceptance_lines(deployed.acceptance)
    unverified = [c.name for c in (schedule, classical, fixed) if c is not None and c.unverified]
    if unverified:
        lines.append(f"Robustness could not be verified for: {', '.join(unverified)} (the frequency-response "
                     "estimate on the FMU was unreliable, e.g. a time-varying or strongly nonlinear plant); "
                     "the choice rests on the evaluation alone.")
    if decision.deploy != Deployed.NONE:  # NONE: each candidate's failures are listed above
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


def headline(decision: Decision) -> str:
    """The verdict in a few words, for report.md's first line."""
    if decision.deploy == Deployed.NONE:
        return "nothing here is safe to deploy"
    return f"deploy the {decision.deploy} (schedule.csv)"


def _failed(c: Candidate, max_sensitivity: float) -> list[str]:
    """Why a candidate is refused (deliver.rule.Candidate.problems), each failed acceptance check with what would
    change it."""
    checks = c.check_failures()
    out = [p for p in c.problems(max_sensitivity) if p not in checks]
    return out + [sentence + (f". To change it: {f.remedy}" if f.remedy else "")
                  for sentence, f in zip(checks, c.failed_checks())]


def _acceptance_lines(a) -> list[str]:
    """Sentences on a deployed controller's acceptance check (deliver.acceptance.Acceptance): overshoot above the
    user's limit, slow steps, excused setpoints."""
    out = []
    if a.above_user_overshoot > 0:
        out.append(f"Its overshoot beyond the measurement noise is {a.overshoot_pct:.0f} %, "
                   f"{a.above_user_overshoot:.0f} percentage points above "
                   f"deploy.max_overshoot ({a.user_overshoot_pct:g} %), within the acceptance limit "
                   f"{a.overshoot_limit_pct:g} %.")
    if a.steps:
        where = ("on the evaluation" if a.episodes == 1 else
                 f"over {a.episodes} replays (the evaluation, held-out episodes of the training distribution and "
                 "its full-range steps)")
        more = [f"{len(a.slow)} steps or disturbances settle only on a {LONG_HOLD}x longer hold (slow)" if a.slow else "",
                f"{len(a.excused)} excused" if a.excused else ""]
        out.append(f"It settles {a.settled} of {a.steps} setpoint steps within their holds {where}"
                   + "".join(f"; {m}" for m in more if m) + ".")
    if math.isfinite(a.noisy_chatter) and a.noisy_chatter > a.max_chatter:
        out.append(f"With the measurement noise its command reverses direction on {a.noisy_chatter:.0%} of the samples "
                   f"({a.noisy_chatter_where}; deploy.max_chatter {a.max_chatter:g} holds without noise): a "
                   "measurement filter (controller.measurement_filter: tuned, or a larger Tf) or a smaller Td would "
                   "spare the actuator.")
    out += [f"Slow: {s}." for s in a.slow[:5]]
    if len(a.slow) > 5:
        out.append(f"({len(a.slow) - 5} more slow steps in metrics.json.)")
    out += [f"Excused: {e}." for e in a.excused[:5]]
    return out


def acceptance_section(deployed: Deployed, a) -> str:
    """An evaluation report's verdict on the deployed controller by the acceptance check (deliver.acceptance,
    the rule `tune` deploys by): whether it still passes on this evaluation, and if not which check failed."""
    lines = ["## Acceptance check on this evaluation", ""]
    if a.passed:
        lines.append(f"**The deployed {deployed} passes** the acceptance check on this evaluation: it follows, settles "
                     f"every setpoint step (within a {LONG_HOLD}x longer hold where said below), overshoots at most "
                     f"{a.overshoot_limit_pct:g} % and does not chatter.")
    else:
        lines.append(f"**The deployed {deployed} fails** the acceptance check on this evaluation; do not rely on it "
                     "for these setpoints and disturbances:")
        lines.append("")
        lines += [f"- {f.check}: it {f.text}." + (f" To change it: {f.remedy}." if f.remedy else "")
                  for f in a.failures]
        lines.append("")
    lines += _acceptance_lines(a)
    return "\n".join(lines) + "\n"


AT_BOUND = 1.05  # a gain within this factor of its search range's end sits at it


def range_notes(gains, loops, widen: float) -> list[str]:
    """One sentence per gain of the fixed PID (loop.gains.Gains) that sits at an end of the range its search
    covered (plant.loops[i].gains, log ranges widened by baseline.widen_ranges: tuning.load_design): a range that
    may exclude the gains that work."""
    out = []
    for i, loop in enumerate(loops):
        for name in ("Kp", "Ti"):
            r, value = getattr(loop, name), getattr(gains, name)[i]
            lo, hi = (r.low / widen, r.high * widen) if r.scale == "log" else (r.low, r.high)
            if not (math.isfinite(value) and lo > 0):
                continue
            end = ("floor" if lo / AT_BOUND <= value <= lo * AT_BOUND else
                   "ceiling" if hi / AT_BOUND <= value <= hi * AT_BOUND else "")
            if end:
                out.append(f"the fixed PID's {name} {value:.4g} sits at the {end} of the range its search covered "
                           f"([{lo:.4g}, {hi:.4g}], from plant.loops[{i}].gains.{name} [{r.low:g}, {r.high:g}]): "
                           f"widen plant.loops[{i}].gains.{name} (or baseline.widen_ranges) so that it contains the "
                           "gains that work")
    return out
