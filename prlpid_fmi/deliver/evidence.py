"""The evidence on both deployable controllers of a run, and the decision (rule: prlpid_fmi.deliver.rule).

The gain schedule is replayed as a plain PID (no neural network) and the fixed PID runs with exactly
the gains the search returned, both on the evaluation schedule and on the Monte-Carlo set
(evaluation.randomize_samples episodes with parameters drawn from evaluation.randomize, seeds
evaluation.seed + 1, + 2, ...), and on the load experiment of the fixed PID's design (tuning.load_experiment:
load steps at the plant input at the low end, middle and high end of the setpoint range). Robustness margins (prlpid_fmi.robustness.margins) are measured at every
breakpoint of a setpoint schedule; for every row of an error schedule (and its gains at error 0) at
the low end, middle and high end of the setpoint range (range_points); at the low end, middle and high end
for the fixed PID; and at the middle of the setpoint range for any other table. With training.randomize set,
every candidate's margins are also measured on the fixed-PID design's Monte-Carlo parameter draws
(tuning.load_experiment.parameter_samples): the fixed PID at the same three points, a setpoint schedule at its
breakpoints, every row of an error table and any other table at the middle of the range. Those estimates are
labelled "<point>, draw <n>" and count in the rule like the nominal ones.
"""
from __future__ import annotations

import dataclasses
import math
import warnings

from prlpid_fmi.deliver.acceptance import Episode, check, late, noise_free, random_loads
from prlpid_fmi.deliver.rule import Candidate, Decision, Deployed, choose_among
from prlpid_fmi.loop.evaluation import constant_gains, evaluate_gains, gains_rollout
from prlpid_fmi.loop.gains import Gains
from prlpid_fmi.robustness.margins import margins_of, operating_point, setpoint_range_points
from prlpid_fmi.robustness.status import status
from prlpid_fmi.tuning.full_range import full_range_episodes, quiet
from prlpid_fmi.tuning.load_experiment import load_experiment, parameter_samples
from prlpid_fmi.tuning.margin_experiments import measure_ahead
from prlpid_fmi.metrics import overall_metric
from prlpid_fmi.tuning.schedule.replay import replay_schedule
from prlpid_fmi.tuning.schedule.table import LOOP_VARIABLE, GainSchedule, fixed_schedule

HOLDOUT_EPISODES = 8  # further episodes the deliverable rule compares the schedule and the fixed PID on
HOLDOUT_SEED_OFFSET = 30_000


def _margins_at(config, gains, points: list[list[float]], workers: int | None) -> list:
    """Margins of gains(point) -> (Kp, Ti, Td, coupling) at each operating point (measured ahead on `workers`
    processes, baseline.workers: tuning.margin_experiments)."""
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        measure_ahead(config, [(gains(point), point) for point in points], workers)
        for point in points:
            out.append(margins_of(config, gains(point), point))
    return out


def _on_draws(scenario, gains, points: list[list[float]], label) -> tuple[list, list]:
    """(margins, labels) of gains(point) at each point on each Monte-Carlo parameter draw of the design
    (parameter_samples of scenario.tuning; none without training.randomize). label(point) -> the point's label."""
    margins, labels = [], []
    for n, draw in enumerate(parameter_samples(scenario.tuning), start=1):
        margins += _margins_at(draw, gains, points, scenario.baseline.workers)
        labels += [f"{_label(label(p))}, draw {n}" for p in points]
    return margins, labels


def _label(value) -> str:
    return f"{value:.4g}" if isinstance(value, (int, float)) else str(value)


def _monte_carlo(scenario) -> list:
    """The evaluation config with parameter randomisation, one per Monte-Carlo sample (seed offsets)."""
    samples = scenario.evaluation.randomize_samples
    config = scenario.evaluation_config()
    if samples <= 0 or not config.randomize:
        return []
    return [(config, scenario.evaluation.seed + 1 + i) for i in range(samples)]


def assess_fixed(scenario, gains: Gains) -> Candidate:
    """The fixed PID's evidence: evaluation, Monte-Carlo set, margins at the low end, middle and high end of the
    setpoint range (robustness.margins.setpoint_range_points)."""
    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    fn = constant_gains(gains.Kp, gains.Ti, gains.Td, gains.coupling)
    plain = dataclasses.replace(config, randomize={}) if config.randomize else config
    metrics, traj = evaluate_gains(fn, plain, seed=scenario.evaluation.seed, intervals=intervals)
    mc = [evaluate_gains(fn, c, seed=s)[0] for c, s in _monte_carlo(scenario)]
    points = setpoint_range_points(scenario.tuning)
    margins = _margins_at(scenario.tuning, lambda p: fn(None), points, scenario.baseline.workers)
    drawn, labels = _on_draws(scenario, lambda p: fn(None), points, lambda p: p[0])
    load = load_experiment(scenario.tuning, scenario.baseline.load_step,
                           lambda cfg: gains_rollout(fn, cfg, seed=0))
    return Candidate(Deployed.FIXED_PID.value, metrics, mc, margins + drawn, [p[0] for p in points] + labels,
                     load_iae=load, draws=len(parameter_samples(scenario.tuning)),
                     evaluation=Episode("the evaluation", plain, scenario.evaluation.seed, metrics, traj))


def assess_schedule(scenario, schedule: GainSchedule, name: str = Deployed.SCHEDULE.value) -> Candidate:
    """The replayed schedule's evidence: evaluation, Monte-Carlo set, margins at every breakpoint (and, for a
    setpoint table, halfway between neighbouring breakpoints, with the interpolated gains the PID runs there).
    name: the Candidate's (Deployed) name."""
    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    plain = dataclasses.replace(config, randomize={}) if config.randomize else config
    metrics, traj = replay_schedule(schedule, plain, seed=scenario.evaluation.seed, intervals=intervals)
    evaluation = Episode("the evaluation", plain, scenario.evaluation.seed, metrics, traj)
    mc = [replay_schedule(schedule, c, seed=s)[0] for c, s in _monte_carlo(scenario)]
    load = load_experiment(scenario.tuning, scenario.baseline.load_step,
                           lambda cfg: replay_schedule(schedule, cfg, seed=0)[1])

    def gains(point):
        return schedule.gains_object(point[0]).values()

    loop = error_loop(schedule)
    if loop is not None:  # every row, and the steady-state gains (error 0), at every operating point
        rows = [schedule.row(j) for j in range(len(schedule.breakpoints))] + [gains([0.0])]
        pairs = [(row, point) for row in rows for point in range_points(scenario.tuning, loop)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            measure_ahead(scenario.tuning, pairs, scenario.baseline.workers)
            margins = [margins_of(scenario.tuning, row, point) for row, point in pairs]
        def row_label(j: int, point) -> str:
            return (f"row {j + 1}" if j < len(rows) - 1 else "error 0") + f" at {_label(point[loop])}"

        labels = [row_label(j, point) for j in range(len(rows)) for point in range_points(scenario.tuning, loop)]
        middle = [operating_point(config)]
        for j, row in enumerate(rows):
            drawn, names = _on_draws(scenario, lambda p, row=row: row, middle, lambda p, j=j: row_label(j, p))
            margins, labels = margins + drawn, labels + names
        return Candidate(name, metrics, mc, margins, labels, load_iae=load,
                         draws=len(parameter_samples(scenario.tuning)), evaluation=evaluation)
    setpoints = schedule.variable.startswith("setpoint")
    points = [operating_point(config, b) for b in schedule.breakpoints] if setpoints else [operating_point(config)]
    labels = [p[0] for p in points]
    if setpoints:  # between breakpoints too: the interpolated gains are a PID of their own
        halves = [0.5 * (float(a) + float(b)) for a, b in zip(schedule.breakpoints[:-1], schedule.breakpoints[1:])]
        points += [operating_point(config, h) for h in halves]
        labels += [f"{_label(h)} (between breakpoints)" for h in halves]
    drawn, names = _on_draws(scenario, gains, points[:len(schedule.breakpoints) if setpoints else 1], lambda p: p[0])
    return Candidate(name, metrics, mc, _margins_at(scenario.tuning, gains, points, scenario.baseline.workers) + drawn,
                     labels + names,
                     load_iae=load, draws=len(parameter_samples(scenario.tuning)), evaluation=evaluation)


def error_loop(schedule: GainSchedule) -> int | None:
    """The loop index of an error[<loop>] table, None for any other scheduling variable."""
    m = LOOP_VARIABLE.match(schedule.variable)
    return schedule.loop_names.index(m.group(2)) if m and m.group(1) == "error" else None


def range_points(config, loop: int) -> list[list[float]]:
    """Operating points for an error table: loop `loop`'s setpoint at the low end, middle and high end of
    its setpoint_range (the other loops at the middle of theirs). An error table is used at every setpoint,
    so each of its rows must be robust over the whole range, not at one point."""
    lo, hi = config.loops[loop].setpoint_range
    points = []
    for value in (lo, 0.5 * (lo + hi), hi):
        point = operating_point(config)
        point[loop] = float(value)
        if point not in points:
            points.append(point)
    return points


def held_out(scenario, schedule: GainSchedule, seed: int, clean: bool = False, loads: bool = False
             ) -> list[Episode]:
    """HOLDOUT_EPISODES seeded episodes of the training distribution (scenario.tuning: its random setpoints, noise,
    disturbances, randomisation) of the table replayed as a plain PID, up to the first that diverges. The seeds
    (seed + HOLDOUT_SEED_OFFSET + i) are disjoint from those the table was built and chosen on, and from the
    evaluation's. clean: the same seeds without training.load_disturbance's random load steps and without
    measurement or actuator noise (the acceptance check's overshoot and chatter of the controller itself); with
    loads, without the noise only (the loads' recovery). The noise is drawn first from an episode's seed, so a clean
    replay of a noisy distribution draws other setpoints and loads: further held-out episodes, not the same ones."""
    config = scenario.tuning
    if clean:
        config = dataclasses.replace(quiet(config), load_disturbance=config.load_disturbance if loads else 0.0)
    out = []
    for i in range(HOLDOUT_EPISODES):
        s = seed + HOLDOUT_SEED_OFFSET + i
        metrics, traj = replay_schedule(schedule, config, seed=s)
        label = f"held-out episode {i + 1}"
        if clean:
            label = f"noise-free {label} (with load steps)" if loads else f"clean {label} (no load steps, no noise)"
        out.append(Episode(label, config, s, metrics, traj))
        if metrics.get("terminated"):
            break
    return out


def full_range(scenario, schedule: GainSchedule, seed: int) -> list[Episode]:
    """The table replayed as a plain PID on the full-range episodes of the training distribution
    (tuning.full_range: every step from one end of the setpoint range to the other, without load steps and noise)."""
    out = []
    for label, config, s in full_range_episodes(scenario.tuning, seed):
        metrics, traj = replay_schedule(schedule, config, seed=s)
        out.append(Episode(label, config, s, metrics, traj))
    return out


def _held_out_totals(episodes: list[Episode]) -> tuple[float, float, int]:
    """(ISE, total variation of u, episodes with an unsettled setpoint step) summed over the held-out episodes;
    ISE and total variation infinity when one diverged."""
    if any(e.metrics.get("terminated") for e in episodes):
        return math.inf, math.inf, sum(_unsettled(e) for e in episodes if not e.metrics.get("terminated"))
    return (sum(overall_metric(e.metrics["overall"], "ISE") for e in episodes),
            sum(overall_metric(e.metrics["overall"], "TotalVariation") for e in episodes),
            sum(_unsettled(e) for e in episodes))


def _unsettled(e: Episode) -> int:
    return int(bool(late(e.metrics, e.trajectory, steps_only=True)))


def assess(scenario, schedule: GainSchedule | None, fixed_gains: Gains, seed: int | None = None,
           classical: GainSchedule | None = None) -> tuple[Decision, Candidate | None, Candidate, Candidate | None]:
    """Evidence for every controller and the decision (deliver.rule.choose_among) with deploy.max_sensitivity:
    (decision, adaptive schedule's, fixed PID's, classical schedule's; None where there is none).

    seed: of the held-out training-distribution episodes (holdout_ise); None = scenario.agent.seed."""
    seed = scenario.agent.seed if seed is None else seed
    limit = max_sensitivity(scenario)
    fixed = assess_fixed(scenario, fixed_gains)
    sched = assess_schedule(scenario, schedule) if schedule is not None else None
    table = assess_schedule(scenario, classical, Deployed.CLASSICAL.value) if classical is not None else None
    for c, s in ((fixed, fixed_schedule(fixed_gains, scenario.tuning)), (sched, schedule), (table, classical)):
        if c is not None and s is not None:
            held = held_out(scenario, s, seed)
            c.holdout_ise, c.holdout_tv, c.holdout_unsettled = _held_out_totals(held)
            if not noise_free(scenario.tuning):  # settling and recovery judged on the noise-free replays below
                held = [dataclasses.replace(e, settling=False) for e in held]
                if random_loads(scenario.tuning):
                    held += held_out(scenario, s, seed, clean=True, loads=True)
            if random_loads(scenario.tuning) or not noise_free(scenario.tuning):
                held += held_out(scenario, s, seed, clean=True)  # overshoot and chatter without loads and noise
            held += full_range(scenario, s, seed)
            c.acceptance = check([c.evaluation, *held], lambda cfg, sd, s=s: replay_schedule(s, cfg, seed=sd),
                                 scenario.deploy.max_overshoot, scenario.deploy.max_chatter)
    decision = choose_among(sched, table, fixed, limit, scenario.deploy.allow_unverified)
    return decision, sched, fixed, table


def max_sensitivity(scenario) -> float:
    """deploy.max_sensitivity of the scenario: the Ms limit no deployed controller may exceed."""
    return float(scenario.deploy.max_sensitivity)


def candidate_summary(c: Candidate) -> dict:
    """What metrics.json records of a candidate."""
    return {"metrics": c.metrics, "monte_carlo": c.monte_carlo,
            "margins": [{"operating_point": b, "Ms": m.Ms, "Mt": m.Mt, "gain_margin": m.gain_margin,
                         "phase_margin_deg": m.phase_margin_deg, "delay_margin_s": m.delay_margin_s,
                         "state": status(m).value, "reliable": m.reliable, "note": m.note}
                        for b, m in zip(c.breakpoints, c.margins)],
            "worst_Ms": c.worst_Ms if math.isfinite(c.worst_Ms) else None, "parameter_draws": c.draws,
            "load_iae": None if math.isnan(c.load_iae) else c.load_iae,
            "holdout_total_variation": None if math.isnan(c.holdout_tv) else c.holdout_tv
            if math.isfinite(c.holdout_tv) else "inf", "holdout_unsettled_episodes": c.holdout_unsettled,
            "holdout_ise": None if math.isnan(c.holdout_ise) else c.holdout_ise if math.isfinite(c.holdout_ise)
            else "inf", "acceptance": c.acceptance.as_dict() if c.acceptance is not None else None}
