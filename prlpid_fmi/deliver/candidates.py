"""The candidate gain tables of a run: built per deploy.schedule_by, projected onto the Ms limit, the best kept.

``deliverable_schedule`` is what `tune` calls: it builds the candidate tables of deploy.schedule_by
(auto: settled setpoint holds and error trajectories, prlpid_fmi.tuning.schedule.extraction.extract),
projects each onto the Ms limit (robust_schedule), and with more than one candidate keeps the one with the
lowest ISE summed over SELECTION_EPISODES further seeded training-distribution episodes (replayed as plain
PIDs, prlpid_fmi.tuning.schedule.replay.training_ise; a diverged episode scores infinity). The evaluation
schedule is never used for the choice.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from prlpid_fmi.deliver.evidence import error_loop, range_points
from prlpid_fmi.deliver.rule import meets
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.loop.evaluation import Policy
from prlpid_fmi.loop.gains import Gains
from prlpid_fmi.robustness.margins import margins_of, operating_point, predicted_ms
from prlpid_fmi.tuning.margin_experiments import measure_ahead
from prlpid_fmi.tuning.schedule.classical import robust_between
from prlpid_fmi.tuning.schedule.extraction import extract
from prlpid_fmi.tuning.schedule.replay import SELECTION_EPISODES, training_ise
from prlpid_fmi.tuning.schedule.table import GainSchedule

AUTO_CANDIDATES = ("setpoint", "error")  # what auto compares


def robust_schedule(schedule: GainSchedule, config, limit: float, workers: int | None = None,
                    reference: tuple | None = None) -> tuple[GainSchedule, list[str]]:
    """The schedule with every row whose Ms exceeds `limit` detuned (tuning.fixed_pid.detune) until it meets it.

    The agent's reward does not see robustness, so the gains it settles on can leave the Ms limit that
    the fixed PID it started from meets; this keeps the adaptation pattern of every row and restores the
    margin. A row is detuned only where the deliverable's rule (deliver.rule.meets) rejects it: a finite but
    unreliable estimate (a time-varying or nonlinear plant) cannot be judged, so it neither justifies a
    detune nor can confirm one. Rows that cannot be detuned to the limit stay as they are (the deliverable
    then refuses the schedule). Returns (schedule, one note per detuned row). Setpoint tables: each row
    at its own setpoint, then halfway between neighbours with the interpolated gains (tuning.schedule.classical.robust_between), where
    the deliverable checks them too. Error tables: each row at every point of range_points, detuned at its worst
    failing point until it meets the limit at all of them. Other variables: unchanged. The rows' first checks are
    measured ahead on `workers` processes (baseline.workers: tuning.margin_experiments). reference: gains (Kp, Ti,
    Td, coupling lists; the fixed PID) measured at a failing row's point before it is detuned where no plant response
    was measured there yet, so that detune predicts its scan from it instead of measuring every step.
    """
    from prlpid_fmi.tuning.fixed_pid import clearly_within, detune

    loop = error_loop(schedule)
    if not schedule.variable.startswith("setpoint") and loop is None:
        return schedule, []
    Kp, Ti, notes = schedule.Kp.copy(), schedule.Ti.copy(), []

    def points_of(b):
        return [operating_point(config, b)] if loop is None else range_points(config, loop)
    # a row predicted clearly within the limit at a point passes there without an experiment (the evidence of the
    # table that is assessed measures it); the others are measured ahead
    measure_ahead(config, [(schedule.row(j), p) for j, b in enumerate(schedule.breakpoints) for p in points_of(b)
                           if not clearly_within(config, schedule.row(j), p, limit)], workers)
    for j, b in enumerate(schedule.breakpoints):
        points = points_of(b)
        row, first = schedule.row(j), None
        for _ in points:  # each pass detunes at the worst failing point; that usually settles the others too
            failing = [(m.Ms, p) for m, p in ((margins_of(config, row, p), p) for p in points
                                              if not clearly_within(config, row, p, limit)) if not meets(m, limit)]
            if not failing:
                break
            ms, point = max(failing, key=lambda x: x[0])
            first = ms if first is None else first
            if reference is not None and predicted_ms(config, row, point) is None:
                margins_of(config, reference, point)  # the point's plant response (where verified) for detune
            fixed = detune(config, row, point, limit)
            if fixed is None:
                break
            row = (list(fixed[0]), list(fixed[1]), row[2], row[3])
        if row[0] != schedule.Kp[j].tolist() or row[1] != schedule.Ti[j].tolist():
            Kp[j], Ti[j] = row[0], row[1]
            notes.append(f"row {b:g}: Ms {first:.2f} > {limit:g}, detuned to Kp {np.round(Kp[j], 4).tolist()}, "
                         f"Ti {np.round(Ti[j], 4).tolist()}")
    schedule = dataclasses.replace(schedule, Kp=Kp, Ti=Ti)
    if loop is None:  # a setpoint table is also run between its breakpoints, with interpolated gains
        schedule, between = robust_between(schedule, config, limit, workers)
        notes += between
    return schedule, notes


@dataclass
class ScheduleChoice:
    """The policy's table `tune` assesses against the fixed PID (its variable: what it is scheduled on), the report's
    note on it, its rows detuned to meet the Ms limit (one line each), and the training ISE of each candidate kind
    when several were built ({kind: ISE}; None with one)."""

    table: GainSchedule
    note: str
    detuned_rows: list[str]
    training_ise: dict[str, float] | None = None


def deliverable_schedule(policy: Policy, scenario, seed: int, anchor: Gains | None = None) -> ScheduleChoice:
    """The table `tune` assesses against the fixed PID, as a ScheduleChoice.

    Candidates per scenario.deploy.schedule_by (auto: AUTO_CANDIDATES), each projected onto the Ms
    limit (robust_schedule); with several, the lowest training_ise wins. Raises PrlPidError
    when no candidate could be built (the message of each).
    """
    from prlpid_fmi.deliver.candidates import robust_schedule
    from prlpid_fmi.deliver.evidence import max_sensitivity

    config, limit = scenario.tuning, max_sensitivity(scenario)
    by = scenario.deploy.schedule_by
    kinds = AUTO_CANDIDATES if by == "auto" else (by,)
    built, errors = [], []
    for kind in kinds:
        try:
            schedule = extract(policy, config, kind, scenario.deploy.schedule_points, seed, anchor)
        except PrlPidError as exc:
            errors.append(f"{kind}: {exc}")
            continue
        note = ""
        if schedule.excluded:
            note = ("The closed loop diverged at setpoint(s) " + ", ".join(f"{v:g}" for v in schedule.excluded)
                    + ": left out of the schedule.\n")
        schedule, detuned = robust_schedule(schedule, config, limit, scenario.baseline.workers,
                                            anchor.values() if isinstance(anchor, Gains) else None)
        if detuned:
            note += (f"Rows of the gain schedule ({schedule.variable}) detuned (Kp / lambda, Ti and Td * lambda) to meet "
                     f"Ms <= {limit:g}: " + "; ".join(detuned) + ".\n")
        built.append((kind, schedule, note, detuned))
    if not built:
        raise PrlPidError("; ".join(errors))
    if len(built) == 1:
        kind, schedule, note, detuned = built[0]
        return ScheduleChoice(schedule, note, detuned)
    scores = {kind: training_ise(s, config, seed) for kind, s, _, _ in built}
    kind, schedule, note, detuned = min(built, key=lambda b: scores[b[0]])
    words = ", ".join(f"{k} {v:.4g}" for k, v in scores.items())
    note += (f"Gain schedule over {schedule.variable} chosen (deploy.schedule_by: auto): lowest ISE over "
             f"{SELECTION_EPISODES} seeded training episodes replayed as plain PIDs ({words}).\n")
    if errors:
        note += "Candidate(s) not built: " + "; ".join(errors) + ".\n"
    return ScheduleChoice(schedule, note, detuned, scores)
