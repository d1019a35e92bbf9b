"""report.md rendering: the evaluation table, both deployable controllers, early ends and the plots.

Every metric carries its unit (the loop's output unit y and input unit u from the FMU); the ratio column
is adaptive policy ÷ fixed PID, where lower is better for every metric shown; a missing value is "–",
never `nan`; gains are numbers with their units. The run workflows (prlpid_fmi.run) compose report.md from
these sections.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from prlpid_fmi import rundir as rd
from prlpid_fmi.deliver.evidence import HOLDOUT_EPISODES
from prlpid_fmi.deliver.rule import Candidate, Deployed
from prlpid_fmi.fmu.resolve import loop_units as units_of_loops
from prlpid_fmi.loop.core import pid_structure
from prlpid_fmi.metrics import overall_metric
from prlpid_fmi.robustness.status import INFINITE_MS, ms_text, why
from prlpid_fmi.tuning.design_result import DesignReport, DesignResult, Followed
from prlpid_fmi.tuning.load_design import ACTIVE_TOLERANCE

METRIC_COLUMNS = ("ISE", "IAE", "ITAE", "Overshoot", "SettlingTime", "RiseTime", "SteadyStateError",
                  "PeakDeviation", "RecoveryTime", "ControlEffort", "TotalVariation", "Chatter")
# unit of each metric from the output unit y and the input unit u (prlpid_fmi.metrics docstring)
METRIC_UNITS = {"ISE": "{y}²·s", "IAE": "{y}·s", "ITAE": "{y}·s²", "Overshoot": "%", "SettlingTime": "s",
                "RiseTime": "s", "SteadyStateError": "{y}", "PeakDeviation": "{y}", "RecoveryTime": "s",
                "ControlEffort": "{u}²·s", "TotalVariation": "{u}",
                "Chatter": "fraction"}
GAIN_UNITS = {"Kp": "{u}/{y}", "Ti": "s", "Td": "s"}
PLOTS = ((rd.STEP_RESPONSE_PLOT, "the evaluation zoomed to each transient (setpoint change or disturbance)"),
         (rd.RESPONSE_PLOT, "measurement and setpoint of each controller, disturbances marked"),
         (rd.CONTROL_SIGNAL_PLOT, "control signal of each controller, actuator limits and disturbances marked"),
         (rd.GAINS_PLOT, "Kp, Ti, Td set by the adaptive policy, beside the fixed PID's and the gain ranges"),
         (rd.LEARNING_CURVE_PLOT, "training reward"))


def number(value, digits: int = 4) -> str:
    """A metric as text: `digits` significant digits; "–" for a missing or undefined (NaN) value, "never"
    for +inf (a loop that never settles or recovers within its segment, or an infinite Ms)."""
    if value is None:
        return "–"
    try:
        v = float(value)
    except (TypeError, ValueError):
        return "–"
    if math.isnan(v):
        return "–"
    return f"{v:.{digits}g}" if math.isfinite(v) else ("never" if v > 0 else "–")


def unit_label(key: str, y_unit: str, u_unit: str) -> str:
    """The metric's unit with the loop's units filled in ("" units become "y-unit" / "u-unit")."""
    base = key.split("[")[0]
    return METRIC_UNITS.get(base, "").format(y=y_unit or "y-unit", u=u_unit or "u-unit")


def _gains_text(gains: dict, y_unit: str, u_unit: str) -> str:
    parts = []
    for name, value in gains.items():
        if value is None:
            continue
        values = [float(v) for v in np.atleast_1d(np.asarray(value, dtype=float))]
        text = ", ".join(f"{v:.4g}" for v in values)
        unit = GAIN_UNITS.get(name, "").format(y=y_unit or "y-unit", u=u_unit or "u-unit")
        parts.append(f"{name} = {text}{' ' + unit if unit else ''}")
    return "; ".join(parts)


def ended_early_lines(named_metrics) -> list[str]:
    """Report lines for evaluations that ended before their last sample: when, why, what the metrics cover."""
    lines = []
    for name, m in named_metrics:
        t = (m or {}).get("termination")
        if t:
            lines += [f"**The {name}'s evaluation ended early** at step {t['step']} (t = {t['time_s']:g} s): "
                      f"{t['message']}. Its metrics cover the samples before that.", ""]
    return lines


def plot_links() -> list[str]:
    """The step response figure embedded, then markdown links to the run's plots."""
    return [figure(rd.STEP_RESPONSE_PLOT, "the evaluation zoomed to its transients"), "Plots:", ""] + \
        [f"- [{name}]({name}): {what}" for name, what in PLOTS] + [""]


def figure(path: str, caption: str) -> str:
    """A figure embedded in markdown, its caption below it (a paragraph each)."""
    return f"![{caption}]({path})\n\n*{caption[:1].upper() + caption[1:]}* ([{path}]({path}))\n"


def frequency_section(files: dict, limit: float) -> str:
    """The measured frequency responses behind the margins table (run.figures: {loop: {kind: path}}): per loop the
    Nyquist, |S| and |T|, and Bode figures embedded and the CSV named; "" when none were written."""
    lines = []
    for loop, kinds in files.items():
        lines += [f"Measured frequency responses of loop {loop} behind this table, per controller and operating point "
                  f"(data: [{kinds['csv']}]({kinds['csv']}), complex P, C, L = C P, S, T as real and imaginary parts):",
                  ""]
        for kind, caption in (("nyquist", f"Nyquist curve of L = C P with the Ms limit circle |1 + L| = 1/{limit:g}"),
                              ("sensitivity", f"|S| and |T| against the Ms limit {limit:g}"),
                              ("bode", "Bode plot of the plant P and the PID C")):
            if kind in kinds:
                lines.append(figure(kinds[kind], f"{caption}, loop {loop}"))
    return "\n".join(lines)


_DESIGNS = {"load": "designed for load rejection under the Ms and noise limits, then b for the setpoint response",
            "setpoint": "differential evolution on the training distribution's setpoint ISE"}


def render_report(scenario, policy_m: dict, fixed_m: dict | None, fixed_gains: dict | None,
                  source: Path | None = None, units: tuple[str, str] = ("", ""),
                  learning_curve: bool = True, opening: tuple[str, ...] = (), headline: str = "") -> str:
    """report.md of one evaluation: the metric table with units and the ratio adaptive ÷ fixed.

    opening: sections (markdown text each) placed between the title and the evaluation, in order (the verdict
    of `tune`, the deployed controller of `evaluate`); headline: the title's words after the scenario's name (the
    verdict's, report.verdict.headline), default: what the report compares."""
    y_unit, u_unit = units
    loops = policy_m["loops"]
    keys = [k for k in policy_m["overall"] if k.split("[")[0] in METRIC_COLUMNS]
    lines = [f"# {scenario.name}: {headline or 'adaptive PRL-PID policy vs tuned fixed PID'}", ""]
    if source is not None:
        lines += [f"Scenario file: `{source}`.", ""]
    lines += [f"Evaluation: {scenario.evaluation_config().episode_steps} steps at sample time "
              f"{scenario.tuning.sample_time_s:g} s; loops: {', '.join(loops)}"
              f"{f' (output in {y_unit}, control signal in {u_unit})' if y_unit or u_unit else ''}.", ""]
    lines += ended_early_lines([("adaptive policy", policy_m), ("fixed PID", fixed_m)])
    if fixed_gains:
        b, c, tf = pid_structure(scenario.tuning)
        structure = "; ".join(f"{name} = {', '.join(f'{v:.4g}' for v in values)}{unit}"
                              for name, values, unit in (("b", b, ""), ("c", c, ""), ("Tf", tf, " s")))
        lines += [f"Fixed PID ({_DESIGNS.get(scenario.baseline.objective, scenario.baseline.objective)}): "
                  + _gains_text(fixed_gains, y_unit, u_unit) + f"; {structure}.", ""]
    lines += ["Ratio = adaptive policy ÷ fixed PID; lower is better for every metric here "
              "(below 1: the adaptive policy is better). – = not defined (no setpoint step, no baseline, "
              "or a zero divisor); never = did not settle or recover within its segment.", "",
              "| metric | unit | adaptive policy | fixed PID | ratio (adaptive ÷ fixed) |", "|---|---|---|---|---|"]
    for k in keys:
        p = policy_m["overall"][k]
        f = fixed_m["overall"].get(k) if fixed_m else None
        ratio = None
        if f is not None and p is not None and math.isfinite(f) and math.isfinite(p) and f != 0:
            ratio = p / f
        lines.append(f"| {k} | {unit_label(k, y_unit, u_unit)} | {number(p)} | {number(f)} | {number(ratio, 3)} |")
    for name, m in (("adaptive policy", policy_m), ("fixed PID", fixed_m)):
        if m and m.get("intervals"):
            ise_u, iae_u = unit_label("ISE", y_unit, u_unit), unit_label("IAE", y_unit, u_unit)
            lines += ["", f"Per interval ({name}):", "", f"| steps | ISE [{ise_u}] | IAE [{iae_u}] |", "|---|---|---|"]
            for iv in m["intervals"]:
                ise = sum(v for k, v in iv.items() if k.split("[")[0] == "ISE")
                iae = sum(v for k, v in iv.items() if k.split("[")[0] == "IAE")
                lines.append(f"| {iv['start_step']}–{iv['end_step']} | {number(ise)} | {number(iae)} |")
    lines += [""] + [line for line in plot_links() if learning_curve or rd.LEARNING_CURVE_PLOT not in line]
    return "\n".join([lines[0], "", *opening, "\n".join(lines[2:])])


def deployed_section(deployed: Deployed, schedule_m: dict | None, fixed_m: dict | None,
                     units: tuple[str, str] = ("", "")) -> str:
    """An evaluation report's opening: what the run deployed (schedule.csv) and how it does on this evaluation."""
    lines = ["## Deployed controller on this evaluation", ""]
    if deployed in (Deployed.SCHEDULE, Deployed.CLASSICAL) and schedule_m is not None:
        kind = "adaptive" if deployed == Deployed.SCHEDULE else "classical"
        lines += [f"The run deployed its {kind} gain schedule (schedule.csv, replayed here as a plain gain-scheduled "
                  "PID, no neural network), beside the fixed PID:", "",
                  candidates_table(Candidate(f"{deployed} (deployed)", schedule_m),
                                   Candidate("fixed PID", fixed_m) if fixed_m else None, units, margins=False)]
    elif deployed == Deployed.FIXED_PID:
        lines += ["The run deployed the fixed PID (schedule.csv holds it as a one-row table): its column below is "
                  "the deployed controller.", ""]
    else:
        lines += ["The run deployed nothing (no controller met its robustness limit); the table below is for "
                  "comparison only.", ""]
    return "\n".join(lines)


def candidates_table(sched, fixed, units: tuple[str, str] = ("", ""), margins: bool = True, classical=None) -> str:
    """The deployable controllers side by side (plain PIDs, no neural network: the adaptive schedule, the classical
    one when built, the fixed PID), metrics with units; margins: with the worst-Ms row (their Candidates carry
    margins)."""
    y_unit, u_unit = units
    rows = [("ISE", "ISE"), ("IAE", "IAE"), ("Overshoot", "overshoot"), ("SettlingTime", "settling time"),
            ("PeakDeviation", "peak deviation (regulation)"), ("RecoveryTime", "recovery time (regulation)"),
            ("TotalVariation", "total variation of u"), ("Chatter", "chatter (u reversing, fraction of samples)")]
    cands = [c for c in (sched, classical, fixed) if c is not None]
    lines = ["| metric (evaluation) | unit | " + " | ".join(c.name for c in cands) + " |",
             "|---|---|" + "---|" * len(cands)]
    for key, label in rows:
        cells = [number(overall_metric(c.metrics["overall"], key)) for c in cands]
        lines.append(f"| {label} | {unit_label(key, y_unit, u_unit)} | " + " | ".join(cells) + " |")
    if margins:
        lines.append("| worst Ms (limit in the verdict) | – | " + " | ".join(ms_text(c.worst_Ms) for c in cands)
                     + " |")
    if all(not math.isnan(c.load_iae) for c in cands):
        lines.append(f"| load IAE per unit load, load steps at the plant input (low / mid / high setpoint) | "
                     f"{unit_label('IAE', y_unit, u_unit)} per {u_unit or 'u-unit'} | "
                     + " | ".join(number(c.load_iae) for c in cands) + " |")
    if all(not math.isnan(c.holdout_ise) for c in cands):
        lines.append(f"| ISE, {HOLDOUT_EPISODES} held-out training-distribution episodes | "
                     f"{unit_label('ISE', y_unit, u_unit)} | " + " | ".join(
                         "diverged" if math.isinf(c.holdout_ise) else number(c.holdout_ise) for c in cands) + " |")
    if all(not math.isnan(c.holdout_tv) for c in cands):
        lines.append(f"| total variation of u, the same episodes | {u_unit or 'u-unit'} | " + " | ".join(
            "diverged" if math.isinf(c.holdout_tv) else number(c.holdout_tv) for c in cands) + " |")
    if all(c.holdout_unsettled is not None for c in cands):
        lines.append(f"| episodes with a setpoint step left unsettled, of {HOLDOUT_EPISODES} | – | "
                     + " | ".join(str(c.holdout_unsettled) for c in cands) + " |")
    if any(c.monte_carlo for c in cands):
        ise = unit_label("ISE", y_unit, u_unit)
        lines.append(f"| mean ISE, Monte-Carlo set | {ise} | " + " | ".join(
            number(sum(overall_metric(m["overall"], "ISE") for m in c.monte_carlo) / len(c.monte_carlo))
            if c.monte_carlo else "–" for c in cands) + " |")
        lines.append(f"| worst ISE, Monte-Carlo set | {ise} | " + " | ".join(
            number(max((overall_metric(m["overall"], "ISE") for m in c.monte_carlo), default=None))
            for c in cands) + " |")
    return "\n".join(lines) + "\n"


def margins_table(candidates, limit: float, point_unit: str = "") -> str:
    """Every margin estimate of the candidates, one row per operating point: Ms, Mt, gain, phase and delay
    margins and the robustness state (robustness.status)."""
    lines = [f"| controller | operating point{f' [{point_unit}]' if point_unit else ''} | Ms | Mt | gain margin [dB] | "
             "phase margin [°] | delay margin [s] | state |", "|---|---|---|---|---|---|---|---|"]
    for c in candidates:
        if c is None:
            continue
        for b, m in zip(c.breakpoints, c.margins):
            point = f"{b:.4g}" if isinstance(b, (int, float)) else str(b)
            cells = " | ".join(_margin(v) for v in (m.Ms, m.Mt, m.gain_margin_db, m.phase_margin_deg, m.delay_margin_s))
            lines.append(f"| {c.name} | {point} | {cells} | {why(m, limit)} |")
    return "\n".join(lines) + "\n"


def _margin(value: float) -> str:
    """A margin as text: 3 significant digits, INFINITE_MS / "-∞" for infinite ones, "–" for NaN."""
    if math.isinf(value):
        return INFINITE_MS if value > 0 else "-∞"
    return number(value, 3)


def design_section(fixed: DesignResult, loop_names) -> str:
    """How the fixed PID was designed (its design report and structure), in words and one table."""
    report = fixed.report
    if report is None or report.details.objective != "load":
        return ""
    design = report.details
    b, c, tf = fixed.structure
    lines = ["## How the fixed PID was designed", "",
             "Kp, Ti, Td (and the measurement filter Tf) minimise the IAE of a load step at the plant input "
             f"({design.load_step:.0%} of the control span) at the low end, middle and high end of the setpoint "
             "range, subject to the Ms and noise limits; then the setpoint weight b shapes the setpoint response "
             "(tuning.design_rule; docs/architecture.md).", "",
             "| loop | Kp | Ti [s] | Td [s] | b | c | Tf [s] |", "|---|---|---|---|---|---|---|"]
    g = fixed.gains
    for i, name in enumerate(loop_names):
        lines.append(f"| {name} | {number(g.Kp[i], 4)} | {number(g.Ti[i], 4)} | {number(g.Td[i], 4)} | "
                     f"{number(b[i], 3)} | {number(c[i], 3)} | {number(tf[i], 4)} |")
    lines += ["", f"Load IAE per unit load (mean over the points) [output units·s per input unit]: "
                  f"{number(design.load_cost, 4)}; the search's optimum without the overshoot limit: "
                  f"{number(design.load_optimum, 4)}."]
    held = _active_limits(design.active_limits, loop_names, [e["point"] for e in design.estimates])
    if held:
        lines += ["", held]
    traded = design.traded_for_overshoot
    if traded and traded.feasible:
        lines.append(f"No setpoint weight kept the overshoot within the limit with the load-optimal gains, so the gains "
                     f"gave up load rejection ({number(traded.load_cost / design.load_optimum, 3)}x the optimum) "
                     f"for an overshoot of {number(traded.Overshoot, 3)} %.")
    refined = design.setpoint_refined
    if refined and refined.kept:
        lines.append(f"Within the load tolerance, gains searched on the identified local models for the least setpoint "
                     f"ISE replaced the load-optimal ones: setpoint ISE {number(refined.ISE / refined.ISE_before, 3)}"
                     f"x theirs with their b, load IAE {number(refined.load_cost / design.load_optimum, 3)}x the "
                     f"optimum, overshoot {number(refined.Overshoot, 3)} % (both on the FMU)"
                     + ("; its load IAE was held no worse than SIMC's or AMIGO's PID tuned to the same Ms on the "
                        "models." if refined.classical_bound else "."))
    followed = design.followed_setpoints
    replaced = bool(followed and followed.source)
    if traded and traded.nearest_load_tolerance:
        lines.append("No setpoint weight kept the overshoot within the limit with the load-optimal gains, and no gains "
                     "within the load tolerance (baseline.load_tolerance) did: the gains nearest it that meet the "
                     f"overshoot limit are kept, load IAE {number(traded.load_cost / design.load_optimum, 3)}x "
                     f"the optimum, overshoot {number(traded.Overshoot, 3)} % (the overshoot limit ranks above the "
                     "load tolerance).")
    elif traded and not traded.feasible:  # the load optimum stays, with the b of least overshoot
        best = (f"its best: load IAE {number(traded.load_cost / design.load_optimum, 3)}x the optimum, overshoot "
                f"{number(traded.Overshoot, 3)} %" if math.isfinite(traded.Overshoot) else
                "the setpoint episodes of its best candidate diverged")
        lines.append("No setpoint weight kept the overshoot within the limit with the load-optimal gains, and the search "
                     f"for gains that would, within the load tolerance, found none ({best})"
                     + ("." if replaced else ": the load-optimal gains are kept, with the setpoint weight of least "
                        f"overshoot (b = {number(b[0], 3)})."))
    weights = design.setpoint_weights
    if weights and not any(math.isfinite(w["ISE"]) for w in weights):
        lines.append(("With the load-optimal gains" if followed else "With these gains") + " the loop diverged on every "
                     "setpoint episode of the training distribution the setpoint weight is chosen on, whatever b"
                     + (": those setpoint steps are larger than the loop holds, so b was not chosen on its setpoint "
                        "response (the first b of the grid is kept)." if not followed else "."))
    if followed:
        lines.append(_followed_sentence(followed, design.load_optimum))
    chatter = design.chatter
    if chatter is not None and chatter.before > chatter.target:
        rang = (f"On the quiet episodes (steps across the whole setpoint range and random training setpoints, no "
                f"noise) the command oscillated at the sample rate on {chatter.before:.1%} of the samples, above "
                f"the design's {chatter.target:.1%} (a margin below deploy.max_chatter)")
        lines.append(rang + (f": the gains were detuned by lambda = {number(chatter.detuned_by, 3)} (Kp / lambda, Ti "
                             f"and Td x lambda) to {chatter.after:.1%}." if chatter.met else
                             ": no detuning in the design's range met it; the acceptance check decides."))
    lines += _rule_sentences(report)
    return "\n".join(lines) + "\n"


RELAXED_WORDS = {"measurement_filter": "a measurement filter was searched (controller.measurement_filter was not "
                                       "tuned)",
                 "max_noise_gain": "deploy.max_noise_gain", "max_noise_increment": "deploy.max_noise_increment"}


def _rule_sentences(report: DesignReport) -> list[str]:
    """The design report's following, relaxations and bound (tuning.design_rule) in words; none for a design
    written before the rule by priority."""
    following = report.following
    if following is None:
        return []
    out = []
    if following.diverged:
        out.append("On setpoint steps between the low, middle and high setpoint the loop diverged.")
    else:
        out.append(f"On setpoint steps between the low, middle and high setpoint it settles "
                   f"{following.steps - following.unsettled} of {following.steps}"
                   + (f" ({following.slow} slowly, after training.setpoint_hold_steps)" if following.slow else "")
                   + f", worst overshoot {number(following.overshoot, 3)} %.")
    if report.relaxed:
        parts = [RELAXED_WORDS[r.limit] if r.limit == "measurement_filter" else
                 f"{RELAXED_WORDS[r.limit]} {r.requested:.2%} raised to "
                 + (f"{r.used:.2%}" if math.isfinite(r.used) else "no limit") for r in report.relaxed]
        out.append("The noise limits are preferences, relaxed before they may cost following or settling the "
                   "setpoint steps: " + "; ".join(parts) + ".")
    if report.bound:
        out.append(f"The requirement that bound this design: {report.bound} (tuning.design_rule's order).")
    return out


def _followed_sentence(followed: Followed, load_optimum: float) -> str:
    """DesignDetails.followed_setpoints in words (tuning.design_rule.follow_setpoints)."""
    result = (f"load IAE {number(followed.load_cost / load_optimum, 3)}x the optimum, worst overshoot "
              f"{number(followed.Overshoot, 3)} % on those episodes")
    diverged = followed.load_optimal_diverged
    why = ("A fixed PID must follow the setpoint steps it is chosen on" if diverged else
           "deploy.max_overshoot is a limit of the deployed controller and baseline.load_tolerance a preference")
    if followed.source == "search" and followed.objective == "setpoint":
        return (f"{why}, so the load tolerance was dropped; the least load IAE within the Ms, noise and overshoot "
                "limits left setpoint steps between the low, middle and high setpoint unsettled, so these gains have "
                f"the least setpoint ISE within those limits ({result}"
                + (")." if followed.feasible else "; the overshoot limit could not be met).")
                + " Load rejection is what it costs.")
    if followed.source == "search":
        where = (" They were searched on the identified local models, then b chosen again and the overshoot checked "
                 "on the FMU's episodes." if followed.on_models and followed.on_models.kept else "")
        return (f"{why}, so the load tolerance was dropped: these gains have the least load IAE that meets the "
                f"overshoot limit on those episodes within the Ms and noise limits ({result}"
                + (")." if followed.feasible else "; the overshoot limit could not be met).")
                + where + " Load rejection is what it costs.")
    if followed.source == "stabilising PID":
        return (f"{why}, and no gains within the Ms and noise limits did, so the stabilising PID of the setpoint search "
                f"is kept, with its best setpoint weight ({result}).")
    if not diverged:
        best = (f"its best: {result}" if math.isfinite(followed.Overshoot) else
                "the setpoint episodes of its best candidate diverged")
        return f"Without the load tolerance no gains met the overshoot limit either ({best})."
    return ("A fixed PID must follow the setpoint steps it is chosen on, but neither a search without the load limit "
            "nor the stabilising PID of the setpoint search did: the load-optimal gains are kept. This plant's setpoint "
            "steps of the training distribution are larger than any PID found holds.")


LIMIT_WORDS = {"max_sensitivity": ("Ms", "deploy.max_sensitivity", False),
               "max_noise_gain": ("std(u) from the measurement noise", "deploy.max_noise_gain", True),
               "max_noise_increment": ("std(u_k - u_(k-1)) from the measurement noise", "deploy.max_noise_increment",
                                       True)}


def _active_limits(active: list[dict], loop_names, points: list) -> str:
    """One paragraph on the limits that hold the fixed PID's design (fixed_pid.json design.active_limits), "" if
    none: the worst estimate of each and where, what relaxing a noise limit would buy, and (Ms on its limit at an
    end of the design's points but not at all of them: the margins shrink towards that end) what that leaves."""
    parts, noise = [], False
    for name, (what, key, is_noise) in LIMIT_WORDS.items():
        found = [a for a in active if a["limit"] == name]
        if not found:
            continue
        worst = max(found, key=lambda a: a["value"])
        where = ", ".join(sorted({f"{loop_names[a['loop']]} = {number(a['point'][a['loop']], 4)}" for a in found}))
        value = f"{worst['value']:.1%} of the control span" if is_noise else f"{worst['value']:.2f}"
        bound = f"{worst['bound']:.1%}" if is_noise else f"{worst['bound']:g}"
        parts.append(f"{what} {value} against {key} {bound} (at {where})")
        noise |= is_noise
    if not parts:
        return ""
    text = (f"Limits that hold this design (its estimates within {ACTIVE_TOLERANCE:.0%} of them): " + "; ".join(parts)
            + ".")
    if noise:
        text += (" A design held by a noise limit filters the measurement and lowers its gains to meet it: where "
                 "larger control moves are acceptable, a larger limit gives a faster loop.")
    at_limit = [a["point"] for a in active if a["limit"] == "max_sensitivity"]
    if at_limit:
        text += (" Ms on its limit: the design spends all the robustness deploy.max_sensitivity allows there (a lower "
                 "limit gives a more robust, slower loop).")
        ends = [p for p in (points[:1] + points[-1:]) if p in at_limit]
        if ends and len({tuple(p) for p in at_limit}) < len({tuple(p) for p in points}):
            text += (" The margins shrink towards the end of the range where Ms meets its limit, so an excursion past "
                     "it (an overshoot beyond the setpoint range) has less.")
    return text


def loop_units(config) -> tuple[str, str]:
    """(output unit, input unit) of the first loop, joined with "/" over loops whose units differ."""
    ys, us = units_of_loops(config)
    return "/".join(dict.fromkeys(ys)) if any(ys) else "", "/".join(dict.fromkeys(us)) if any(us) else ""
