"""Assess the deployable controllers of a run and pick one (rule: prlpid_fmi.deliver).

The gain schedule is replayed as a plain PID (no neural network) and the fixed PID runs with exactly
the gains the search returned, both on the evaluation schedule and on the Monte-Carlo set
(evaluation.randomize_samples episodes with parameters drawn from evaluation.randomize, seeds
evaluation.seed + 1, + 2, ...). Robustness margins (prlpid_fmi.margins) are measured at every
breakpoint of the schedule and at the middle of the setpoint range for the fixed PID.
"""
from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from .actions import Gains
from .baseline import margins_of, operating_point
from .deliver import Candidate, Decision, choose
from .evaluate import constant_gains, evaluate_gains
from .schedule import GainSchedule, replay_schedule


def _margins_at(config, gains, points: list[list[float]]) -> list:
    """Margins of gains(point) -> (Kp, Ti, Td, coupling) at each operating point."""
    out = []
    for point in points:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out.append(margins_of(config, gains(point), point))
    return out


def _monte_carlo(scenario) -> list:
    """The evaluation config with parameter randomisation, one per Monte-Carlo sample (seed offsets)."""
    samples = scenario.evaluation.randomize_samples
    config = scenario.evaluation_config()
    if samples <= 0 or not config.randomize:
        return []
    return [(config, scenario.evaluation.seed + 1 + i) for i in range(samples)]


def assess_fixed(scenario, gains: Gains) -> Candidate:
    """The fixed PID's evidence: evaluation, Monte-Carlo set, margins at mid-range."""
    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    fn = constant_gains(gains.Kp, gains.Ti, gains.Td, gains.coupling)
    plain = dataclasses.replace(config, randomize={}) if config.randomize else config
    metrics, _ = evaluate_gains(fn, plain, seed=scenario.evaluation.seed, intervals=intervals)
    mc = [evaluate_gains(fn, c, seed=s)[0] for c, s in _monte_carlo(scenario)]
    point = operating_point(config)
    margins = _margins_at(scenario.tuning, lambda p: fn(None), [point])
    return Candidate("fixed PID", metrics, mc, margins, [point[0]])


def assess_schedule(scenario, schedule: GainSchedule) -> Candidate:
    """The replayed schedule's evidence: evaluation, Monte-Carlo set, margins at every breakpoint."""
    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    plain = dataclasses.replace(config, randomize={}) if config.randomize else config
    metrics, _ = replay_schedule(schedule, plain, seed=scenario.evaluation.seed, intervals=intervals)
    mc = [replay_schedule(schedule, c, seed=s)[0] for c, s in _monte_carlo(scenario)]

    def gains(point):
        g = schedule.gains_at(point[0])
        return tuple(x.tolist() for x in g) + ((None,) if schedule.coupling is None else ())

    points = [operating_point(config, b) for b in schedule.breakpoints] \
        if schedule.variable.startswith("setpoint") else [operating_point(config)]
    return Candidate("gain schedule", metrics, mc, _margins_at(scenario.tuning, gains, points),
                     [p[0] for p in points])


def robust_schedule(schedule: GainSchedule, config, limit: float) -> tuple[GainSchedule, list[str]]:
    """The schedule with every row whose Ms exceeds `limit` detuned (baseline.detune) until it meets it.

    The agent's reward does not see robustness, so the gains it settles on can leave the Ms limit that
    the fixed PID it started from meets; this keeps the adaptation pattern of every row and restores the
    margin. Rows that cannot be detuned to the limit stay as they are (the deliverable then refuses the
    schedule). Returns (schedule, one note per detuned row). Setpoint-scheduled tables only.
    """
    from .baseline import detune

    if not schedule.variable.startswith("setpoint"):
        return schedule, []
    Kp, Ti, notes = schedule.Kp.copy(), schedule.Ti.copy(), []
    for j, b in enumerate(schedule.breakpoints):
        point = operating_point(config, b)
        row = (schedule.Kp[j].tolist(), schedule.Ti[j].tolist(), schedule.Td[j].tolist(),
               None if schedule.coupling is None else schedule.coupling[j].tolist())
        m = margins_of(config, row, point)  # conservative like the search: unreliable estimates count
        if m.Ms <= limit:
            continue
        ms = m.Ms
        fixed = detune(config, row, point, limit)
        if fixed is not None:
            Kp[j], Ti[j] = fixed[0], fixed[1]
            notes.append(f"row {b:g}: Ms {ms:.2f} > {limit:g}, detuned to Kp {np.round(Kp[j], 4).tolist()}, "
                         f"Ti {np.round(Ti[j], 4).tolist()}")
    return dataclasses.replace(schedule, Kp=Kp, Ti=Ti), notes


def assess(scenario, schedule: GainSchedule | None, fixed_gains: Gains) -> tuple[Decision, Candidate | None, Candidate]:
    """Evidence for both controllers and the decision (deliver.choose) with deploy.max_sensitivity."""
    limit = max_sensitivity(scenario)
    fixed = assess_fixed(scenario, fixed_gains)
    sched = assess_schedule(scenario, schedule) if schedule is not None else None
    return choose(sched, fixed, limit), sched, fixed


def max_sensitivity(scenario) -> float:
    """deploy.max_sensitivity of the scenario: the Ms limit no deployed controller may exceed."""
    return float(scenario.deploy.max_sensitivity)


def candidate_summary(c: Candidate) -> dict:
    """What metrics.json records of a candidate."""
    return {"metrics": c.metrics, "monte_carlo": c.monte_carlo,
            "margins": [{"operating_point": b, "Ms": m.Ms, "gain_margin": m.gain_margin,
                         "phase_margin_deg": m.phase_margin_deg, "reliable": m.reliable, "note": m.note}
                        for b, m in zip(c.breakpoints, c.margins)],
            "worst_Ms": c.worst_Ms if math.isfinite(c.worst_Ms) else None}
