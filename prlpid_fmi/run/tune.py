"""`tune`: a scenario end to end on a run directory, as named stages.

    start        the scenario, seed and budget -> run.json and scenario.yaml (resume: read back)
    fixed_pid    the scenario -> the tuned fixed PID, fixed_pid.json and .csv (resume: read back)
    classical    on a nonlinear plant: local PID designs across the setpoint range -> classical_schedule.csv
    training     the scenario and the anchor (the classical schedule where built, else the fixed PID) -> the
                 trained policy, model.zip and checkpoints
    schedule     the policy -> the candidate gain table (deliver.candidates), or why there is none
    evaluation   policy, fixed PID and table on the evaluation -> metrics, gains.csv, plots
    choice       the evidence -> the deployed controller and why (deliver.evidence, deliver.rule)
    files        schedule.csv, metrics.json and report.md built once from the above; the learning curve

The directory's layout and its atomic writes live in prlpid_fmi.rundir: an existing run directory is never
overwritten, no command writes over a file a run owns, and each stage's result is on disk before the next
starts (the evaluation's metrics.json and report.md are rewritten, whole, once the choice is made).
"""
from __future__ import annotations

import dataclasses
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from prlpid_fmi import rundir as rd
from prlpid_fmi import runcontext
from prlpid_fmi.deliver.rule import Decision, Deployed
from prlpid_fmi.errors import ArgumentError, Interrupted, PrlPidError
from prlpid_fmi.report.markdown import (
    candidates_table,
    design_section,
    figure,
    frequency_section,
    loop_units,
    margins_table,
)
from prlpid_fmi.run.evaluate import (
    Evaluation,
    evaluate_controllers,
    evaluation_metrics,
    evaluation_report,
    write_evaluation_files,
)
from prlpid_fmi.run.record import RunRecord, TrainingStopped
from prlpid_fmi.run.state import (anchor_name, load_policy, prior_fallback_for, read_fixed_pid, training_anchor,
                                   with_isolation, with_prior_fallback, with_structure)
from prlpid_fmi.rundir import write_atomic, write_json
from prlpid_fmi.scenario.load import Scenario, load_scenario, scenario_to_yaml
from prlpid_fmi.schema.types import MAX_SEED

if TYPE_CHECKING:
    from prlpid_fmi.deliver.candidates import ScheduleChoice
    from prlpid_fmi.tuning.design_result import DesignResult


def tune(scenario_path: str | Path, timesteps: int | None = None, seed: int | None = None,
         out: str | Path | None = None, resume: bool = False, progress_bar: bool = True,
         baseline: bool = True, on_run_dir=None, crash: str | None = None) -> Path:
    """Train the scenario's agent, evaluate it against a tuned fixed PID, deploy the better plain PID.

    Returns the run directory. With resume, training continues from the run's latest checkpoint
    (its scenario.yaml, not `scenario_path`, defines the run). timesteps >= 1 and seed in [0, MAX_SEED] are
    checked, and the scenario loaded, before anything is created; a start refused before training produced a
    model or a checkpoint leaves no directory behind. progress_bar: training and fixed-PID search
    progress, and the steps after training, on stderr. baseline=False skips the fixed-PID search where
    nothing needs it: with the absolute gain map only (the anchored map trains around the fixed PID).
    on_run_dir(run_dir): called once the run directory exists (run.supervise). crash: with resume, the line of the
    crash that ended the previous process (run.supervise): said in the warning and kept in run.json.
    """
    if timesteps is not None and timesteps < 1:
        raise ArgumentError(f"{{timesteps}}: must be at least 1 (got {timesteps}; expected a number of training steps >= 1)")
    if seed is not None and not 0 <= seed <= MAX_SEED:
        raise ArgumentError(f"{{seed}}: out of range (got {seed}; expected an integer from 0 to {MAX_SEED})")
    scenario = load_scenario(scenario_path)
    # this run's own context (prlpid_fmi.runcontext): its measurements, every FMU call's timeout, its directory
    with runcontext.opened(step_timeout_s=scenario.tuning.step_timeout_s) as run:
        if not resume:  # a loop that cannot be closed is refused before anything is written (probe.feasibility)
            from prlpid_fmi.probe.feasibility import check_loops

            for note in check_loops(scenario.tuning, scenario.path or scenario_path):
                warnings.warn(note, stacklevel=2)
        run_dir, created = rd.prepare_run_dir(out, scenario.name, resume)
        crashed = rd.mark_active(run_dir)
        if on_run_dir is not None:
            on_run_dir(run_dir)
        run.run_dir = run_dir  # what a hang's one line says is kept
        try:
            return _tune(scenario, Path(scenario_path), run_dir, timesteps, seed, resume, progress_bar, baseline,
                         (crash or True) if crashed and resume else False)
        except BaseException as exc:
            if isinstance(exc, Interrupted):
                exc.run_dir = run_dir
            rd.discard_if_empty(run_dir, created)
            raise
        finally:
            rd.mark_inactive(run_dir)


@dataclass
class Started:
    """What the start stage settled: the scenario as run (seed and budget applied), the file it came from,
    and the run's record (run.json)."""

    scenario: Scenario
    source: Path
    record: RunRecord


@dataclass
class Choice:
    """The choice stage's result: the decision and the evidence of each candidate (deliver.rule.Candidate)."""

    decision: Decision
    schedule: object | None
    fixed: object
    classical: object | None = None


@dataclass
class ScheduleResult:
    """The schedule stage's result: the candidate table (None when none could be built), the report's note
    on it, how it was chosen (None without a table) and why none could be built."""

    table: object | None
    note: str = ""
    choice: ScheduleChoice | None = None
    error: str | None = None

    def record_in(self, record: RunRecord) -> None:
        """Set run.json's schedule_* fields from this result."""
        if self.choice is not None:
            record.schedule_by = self.choice.table.variable
            record.schedule_detuned_rows = self.choice.detuned_rows or None
            record.schedule_candidates_training_ise = self.choice.training_ise
        record.schedule_error = self.error


def _tune(scenario: Scenario, source: Path, run_dir: Path, timesteps: int | None, seed: int | None, resume: bool,
          progress_bar: bool, baseline: bool, crashed: bool | str = False) -> Path:
    from prlpid_fmi.progress import stage, stage_seconds

    stage_seconds(clear=True)  # this run's stage times from here (run.json's stage_seconds)
    started = start_stage(scenario, source, run_dir, timesteps, seed, resume, crashed)
    if started is None:
        return run_dir
    scenario, record = started.scenario, started.record
    scenario = isolation_stage(scenario, run_dir, record)
    fixed = fixed_pid_stage(scenario, run_dir, progress_bar, baseline)
    scenario = isolation_stage(with_structure(scenario, fixed), run_dir, record)  # the tuned b, c, Tf from here on
    classical = classical_stage(scenario, run_dir, fixed, record, progress_bar) if fixed is not None else None
    scenario = isolation_stage(scenario, run_dir, record)
    anchor = training_anchor(scenario, fixed, classical)
    record.anchor = anchor_name(anchor)
    record.write(run_dir)
    with stage("training", False):
        scenario = training_stage(scenario, run_dir, record, resume, anchor, progress_bar)
    scenario = isolation_stage(scenario, run_dir, record)
    started = dataclasses.replace(started, scenario=scenario)
    policy = load_policy(run_dir, scenario.agent.algorithm)
    table = schedule_stage(policy, scenario, anchor, progress_bar)
    table.record_in(record)
    ev = evaluation_stage(run_dir, scenario, started.source, policy, fixed, anchor, table.table, progress_bar)
    choice = choice_stage(scenario, table.table, fixed, progress_bar, classical) if fixed is not None else None
    files_stage(run_dir, started, ev, fixed, table, choice, classical)
    return run_dir


def start_stage(scenario: Scenario, source: Path, run_dir: Path, timesteps: int | None, seed: int | None,
                resume: bool, crashed: bool | str) -> Started | None:
    """The scenario as this run trains it, scenario.yaml (a new run) and run.json; None when a resumed run has
    finished already with this budget (nothing to do; said in a warning). crashed: the previous run ended abruptly
    (a string: the line of the crash that ended it)."""
    record = RunRecord(command=list(sys.argv), started=rd.now(), versions=rd.package_versions())
    if resume:
        scenario = load_scenario(run_dir / rd.SCENARIO)
        source = run_dir / rd.SCENARIO
        record = RunRecord.read(run_dir) or record
        record.resumed = rd.now()
        if crashed and scenario.tuning.isolation == "auto":
            why = crashed if isinstance(crashed, str) else "the previous run ended abruptly (did the FMU crash it?)"
            warnings.warn(f"{run_dir}: {why}; the run continues from its last checkpoint with the plant in a worker "
                          "process (plant.isolation: process)", stacklevel=3)
            record.isolation = "process"
            if isinstance(crashed, str):
                record.isolation_reason = crashed
        scenario = with_prior_fallback(with_isolation(scenario, record.isolation), record.prior_fallback)
    agent = scenario.agent
    if seed is not None:
        agent = dataclasses.replace(agent, seed=seed)
    if timesteps is not None:
        agent = dataclasses.replace(agent, total_timesteps=timesteps)
    if timesteps is not None or seed is not None:
        scenario = dataclasses.replace(scenario, agent=agent)
    finished, record.finished = record.finished, None
    if resume and finished and (record.trained_timesteps or 0) >= agent.total_timesteps \
            and (run_dir / rd.REPORT).is_file():
        warnings.warn(f"{run_dir}: finished already ({record.trained_timesteps} training steps; {rd.REPORT} "
                      "holds its result); nothing to do (a larger --timesteps trains on)", stacklevel=3)
        return None
    if not resume:
        write_atomic(run_dir / rd.SCENARIO, scenario_to_yaml(scenario))
    record.seed, record.total_timesteps, record.algorithm = agent.seed, agent.total_timesteps, agent.algorithm
    record.write(run_dir)
    return Started(scenario, source, record)


def isolation_stage(scenario: Scenario, run_dir: Path, record: RunRecord) -> Scenario:
    """The scenario with plant.isolation "process" once a worker crash in this process put its "auto" plant in a
    worker process (loop.isolated.crash_isolation; the warning is said there, once); run.json records it (isolation,
    and isolation_reason: the crash's line), so later stages' processes, `--resume`, `evaluate` and `export` follow."""
    from prlpid_fmi.loop.isolated import crash_isolation

    if scenario.tuning.isolation != "auto":
        return scenario
    line = crash_isolation(scenario.tuning)
    if line is None:
        return scenario
    record.isolation, record.isolation_reason = "process", line
    record.write(run_dir)
    return with_isolation(scenario, "process")


NO_BASELINE_ANCHORED = ("--no-baseline: the fixed PID is searched anyway, because the anchored gain map "
                        "(controller.gain_mapping: anchored, the default) trains around it; set controller.gain_mapping: "
                        "absolute to skip the search")


def fixed_pid_stage(scenario: Scenario, run_dir: Path, progress_bar: bool, baseline: bool) -> DesignResult | None:
    """The fixed PID first: the baseline, and the anchor the agent's gains move around (tuning.design_rule's
    DesignResult, written to fixed_pid.json and fixed_pid.csv); read back when the run has one (resume); None when
    `baseline` is off and the gain map is absolute (with the anchored map it is searched anyway, and a warning says so)."""
    from prlpid_fmi.deliver.evidence import max_sensitivity
    from prlpid_fmi.progress import Steps
    from prlpid_fmi.tuning import design_rule
    from prlpid_fmi.tuning.schedule.csv_file import write_schedule_csv
    from prlpid_fmi.tuning.schedule.table import fixed_schedule

    if (run_dir / rd.FIXED_PID).is_file():
        return read_fixed_pid(run_dir)
    if not baseline:
        if scenario.tuning.gain_mapping != "anchored":
            return None
        warnings.warn(NO_BASELINE_ANCHORED, stacklevel=2)
    b = scenario.baseline
    search = Steps("fixed-PID search", enabled=progress_bar)
    result = design_rule.tune_fixed_pid(scenario.tuning, seed=scenario.agent.seed, episodes=b.episodes,
                                          maxiter=b.maxiter, popsize=b.popsize, progress=search,
                                          max_sensitivity=max_sensitivity(scenario), baseline=b,
                                          deploy=scenario.deploy)
    search.close()
    write_json(run_dir / rd.FIXED_PID, result.as_json())
    write_schedule_csv(fixed_schedule(result.gains, with_structure(scenario, result).tuning), run_dir / rd.FIXED_PID_CSV)
    return result


def classical_stage(scenario: Scenario, run_dir: Path, fixed: DesignResult, record: RunRecord, progress_bar: bool):
    """The classical gain schedule (tuning.schedule.classical) where deploy.classical_schedule asks for it (auto: a
    plant nonlinear over the setpoint range), written to classical_schedule.csv; run.json records why it was or
    was not built (resume: read back). None when not built or when it could not be (said in run.json)."""
    from prlpid_fmi.progress import Steps
    from prlpid_fmi.tuning.schedule.classical import classical_schedule, wanted
    from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv, write_schedule_csv

    path = run_dir / rd.CLASSICAL_SCHEDULE
    if path.is_file():
        return read_schedule_csv(path)
    if record.classical_schedule is not None:  # decided before (resume): not built
        return None
    build, variation = wanted(scenario.deploy.classical_schedule, scenario.tuning, fixed.gains.values())
    why = {"built": build, "gain_variation": variation if variation == variation else None}
    table = None
    if build and scenario.tuning.coupled:
        why.update(built=False, why="the classical schedule is built for independent loops (controller.coupled)")
        build = False
    if build:
        steps = Steps("classical gain schedule", enabled=progress_bar)
        try:
            table, details = classical_schedule(scenario, fixed, steps)
            why.update(details)
            write_schedule_csv(table, path)
            table = read_schedule_csv(path)  # the file is the table: training's anchor, resume and evaluate read it
        except PrlPidError as exc:
            why.update(built=False, why=str(exc))
            table = None
        finally:
            steps.close()
    record.classical_schedule = why
    record.write(run_dir)
    return table


def training_stage(scenario: Scenario, run_dir: Path, record: RunRecord, resume: bool, anchor, progress_bar: bool
                   ) -> Scenario:
    """Train the agent around the anchor (resume: from the latest checkpoint) up to agent.total_timesteps;
    run.json records the steps trained. Returns the scenario as trained on (with a prior fallback, below).

    Episodes that keep ending at the same FMU fault (tuning.agent.FaultWatch) stop the training: when the forecast's
    prior (the FMU's second instance) was the instance in the crashing call, it is replaced once (the plant's own
    instance rolled back, or no forecast: run.state.prior_fallback_for; one warning, run.json "prior_fallback")
    and training goes on from the checkpoint; otherwise training ends there, said in one warning, run.json
    "training_stopped" and the report, and the run goes on with the policy learnt so far. The prior is blamed when
    the worker's crumb names it in the crashing call and the plant alone passes that time
    (loop.isolated.plant_alone_survives): a fault the plant meets at that time anyway reaches the prior first,
    which runs N samples ahead."""
    from prlpid_fmi.loop.isolated import plant_alone_survives
    from prlpid_fmi.tuning import agent as agent_module

    agent = scenario.agent
    resumed = resume
    while True:
        resume_from, done = rd.latest_checkpoint(run_dir, record.trained_timesteps or 0) if resumed else (None, 0)
        remaining = max(agent.total_timesteps - done, 0)
        if remaining <= 0:
            return scenario
        faults = agent_module.FaultWatch()
        model = agent_module.train(scenario.tuning, agent, run_dir, progress_bar=progress_bar,
                                   resume_from=resume_from, total_timesteps=remaining, anchor=anchor, faults=faults)
        record.trained_timesteps = int(model.num_timesteps)
        stopped = faults.stopped
        if stopped is None:
            record.write(run_dir)
            return scenario
        where = f"{faults.episodes} training episodes in a row ended at the same fault ({stopped.message})"
        if stopped.instance == "prior" and scenario.tuning.forecast_horizon and record.prior_fallback is None \
                and plant_alone_survives(scenario.tuning, stopped.time_s):
            fallback = prior_fallback_for(scenario)
            record.prior_fallback, record.prior_fallback_reason = fallback, where
            record.write(run_dir)
            warnings.warn(f"{where}: the forecast's prior (the FMU's second instance) crashes; the forecast now "
                          + ("rolls the plant's own instance ahead and back (the rollback prior)" if fallback == "rollback"
                             else "is off (strategies.forecast_horizon: 0)")
                          + " and training goes on from its last checkpoint", stacklevel=2)
            scenario = with_prior_fallback(scenario, fallback)
            resumed = True
            continue
        record.training_stopped = TrainingStopped(int(model.num_timesteps), faults.episodes, stopped.as_dict())
        record.write(run_dir)
        warnings.warn(f"training stopped early at step {int(model.num_timesteps)} of {agent.total_timesteps}: {where}; "
                      "nothing is learnt from such episodes; the run goes on with the policy trained so far",
                      stacklevel=2)
        return scenario


def schedule_stage(policy, scenario: Scenario, anchor, progress_bar: bool) -> ScheduleResult:
    """The policy's gain table per deploy.schedule_by (settled setpoint holds, error trajectories, or the better
    of both), its rows checked against the Ms limit; a PrlPidError becomes the report's note."""
    from prlpid_fmi.deliver.candidates import deliverable_schedule
    from prlpid_fmi.progress import stage

    try:
        with stage("gain schedule (tables from the policy, rows checked against the Ms limit)", progress_bar):
            choice = deliverable_schedule(policy, scenario, scenario.agent.seed, anchor)
        return ScheduleResult(choice.table, choice.note, choice)
    except PrlPidError as exc:
        return ScheduleResult(None, f"No gain schedule: {exc}\n", error=str(exc))


def evaluation_stage(run_dir: Path, scenario: Scenario, source: Path, policy, fixed: DesignResult | None, anchor, table,
                     progress_bar: bool) -> Evaluation:
    """Policy, fixed PID and table on the evaluation: gains.csv, the plots, and the evaluation's metrics.json
    and report.md (kept if a later stage fails)."""
    from prlpid_fmi.progress import stage

    with stage("evaluation", progress_bar):
        ev = evaluate_controllers(scenario, policy, fixed, anchor=anchor, schedule=table)
        write_evaluation_files(run_dir, scenario, ev, fixed)
        write_json(run_dir / rd.METRICS, evaluation_metrics(ev, fixed))
        write_atomic(run_dir / rd.REPORT, evaluation_report(scenario, ev, fixed, source, learning_curve=True))
    return ev


def choice_stage(scenario: Scenario, table, fixed: DesignResult, progress_bar: bool, classical=None) -> Choice:
    """The evidence for every plain PID (replays, Monte-Carlo set, held-out episodes, margins) and the decision."""
    from prlpid_fmi.deliver.evidence import assess
    from prlpid_fmi.progress import stage

    with stage("choice of the deployed controller (replays, Monte-Carlo set, margins)", progress_bar):
        decision, sched_c, fixed_c, classical_c = assess(scenario, table, fixed.gains, classical=classical)
    return Choice(decision, sched_c, fixed_c, classical_c)


def refusals(choice: Choice, limit: float) -> dict:
    """{Deployed member: why} for each candidate the deliverable rule refuses (deliver.rule.Candidate.problems: it
    fails the acceptance check or the Ms limit, or diverged); a candidate that only lost on ISE is not refused."""
    out = {}
    for c in (choice.fixed, choice.classical, choice.schedule):
        if c is not None and (problems := c.problems(limit)):
            out[Deployed(c.name)] = "; ".join(problems)
    return out


def training_note(record: RunRecord) -> str:
    """The report's lines on a training stopped early, or a prior replaced, for repeated FMU faults ("" if neither)."""
    note = ""
    if record.prior_fallback is not None:
        note += (f"\nThe forecast's prior was replaced ({'the rollback prior' if record.prior_fallback == 'rollback' else 'no forecast'}): "
                 f"{record.prior_fallback_reason or ''}.\n")
    stopped = record.training_stopped
    if stopped:
        note += (f"\n**Training stopped early** at step {stopped.steps}: {stopped.episodes} episodes in a row "
                 f"ended at the same fault ({stopped.termination['message']}); the policy is what was learnt "
                 "until then.\n")
    return note


def files_stage(run_dir: Path, started: Started, ev: Evaluation, fixed: DesignResult | None, table: ScheduleResult,
                choice: Choice | None, classical=None) -> None:
    """schedule.csv (the deployed controller), metrics.json and report.md built once from the stages' results,
    the learning curve, and run.json marked finished."""
    from prlpid_fmi.deliver.evidence import candidate_summary, max_sensitivity
    from prlpid_fmi.report import plots
    from prlpid_fmi.report.verdict import classical_note, headline, range_notes, verdict
    from prlpid_fmi.run.export import deployable_files
    from prlpid_fmi.tuning.schedule.csv_file import write_schedule_csv
    from prlpid_fmi.tuning.schedule.table import fixed_schedule

    scenario, record = started.scenario, started.record
    metrics, opening, title = evaluation_metrics(ev, fixed), (), ""
    figures = None
    if fixed is not None:
        from prlpid_fmi.progress import stage
        from prlpid_fmi.run.figures import write_run_figures

        with stage("figures", False):  # run.json stage_seconds: what the figures cost
            try:
                figures = write_run_figures(run_dir, scenario, ev, choice, fixed.gains, table.table, classical)
            except PrlPidError as exc:  # a replay the FMU failed: the run's results are written all the same
                warnings.warn(f"{run_dir}: figures not drawn: {exc}", stacklevel=2)
    if choice is not None:
        deployed = {Deployed.SCHEDULE: table.table, Deployed.CLASSICAL: classical,
                    Deployed.FIXED_PID: fixed_schedule(fixed.gains, scenario.tuning)
                    }.get(choice.decision.deploy)
        if deployed is not None:
            write_schedule_csv(deployed, run_dir / rd.SCHEDULE)
        refused = refusals(choice, max_sensitivity(scenario))
        if Deployed.FIXED_PID in refused:  # the tables of refused candidates say so in their header
            write_schedule_csv(fixed_schedule(fixed.gains, scenario.tuning),
                               run_dir / rd.FIXED_PID_CSV, not_deployable=refused[Deployed.FIXED_PID])
        if Deployed.CLASSICAL in refused and classical is not None:
            write_schedule_csv(classical, run_dir / rd.CLASSICAL_SCHEDULE, not_deployable=refused[Deployed.CLASSICAL])
        metrics.update(deployed=choice.decision.deploy, decision=list(choice.decision.reasons),
                       schedule_replay=candidate_summary(choice.schedule) if choice.schedule is not None else None,
                       fixed_pid_assessment=candidate_summary(choice.fixed),
                       classical_schedule_replay=candidate_summary(choice.classical)
                       if choice.classical is not None else None)
        from prlpid_fmi.probe.steady_state import extrema_in_worker

        extrema = extrema_in_worker(scenario.tuning)  # a sign change of a loop's gain past an extremum
        metrics["steady_state_extrema"] = extrema
        findings = tuple(extrema)
        if choice.decision.deploy == Deployed.NONE:
            findings += tuple(range_notes(fixed.gains, scenario.tuning.loops,
                                          scenario.baseline.widen_ranges))
        units = loop_units(scenario.tuning)
        title = headline(choice.decision)
        opening = (verdict(choice.decision, choice.schedule, choice.fixed, max_sensitivity(scenario),
                           scenario.tuning.gain_mapping, choice.classical, findings).rstrip(), "",
                   *((note, "") if (note := classical_note(record.classical_schedule)) else ()),
                   candidates_table(choice.schedule, choice.fixed, units, classical=choice.classical),
                   *((figure(figures.load_steps, "load steps at the plant input, the design's load experiment (the "
                                                 "load IAE row)"),) if figures else ()),
                   *((figure(figures.schedule_gains, "PID gains over the scheduling variable"),)
                     if figures and figures.schedule_gains else ()),
                   "### Robustness at each operating point", "",
                   margins_table((choice.fixed, choice.classical, choice.schedule), max_sensitivity(scenario),
                                 units[0]),
                   frequency_section(figures.frequency if figures else {}, max_sensitivity(scenario)),
                   design_section(fixed, [l.output for l in scenario.tuning.loops]))
    elif table.table is not None:
        write_schedule_csv(table.table, run_dir / rd.SCHEDULE)
    if table.table is not None:  # deployed or not: `evaluate` replays it on held-out schedules
        write_schedule_csv(table.table, run_dir / rd.ADAPTIVE_SCHEDULE,
                           not_deployable=refused.get(Deployed.SCHEDULE, "") if choice is not None else "")
    write_json(run_dir / rd.METRICS, metrics)
    report = evaluation_report(scenario, ev, fixed, started.source, learning_curve=True, opening=opening,
                               headline=title)
    if table.note:
        report += "\n" + table.note
    report += training_note(record)
    report += "\n" + deployable_files(run_dir)
    write_atomic(run_dir / rd.REPORT, report)
    plots.plot_learning_curve(run_dir / rd.MONITOR, run_dir / rd.LEARNING_CURVE_PLOT)
    from prlpid_fmi.progress import stage_seconds

    record.stage_seconds = stage_seconds()  # seconds per stage this process ran (progress.stage_seconds)
    record.finished = rd.now()
    record.write(run_dir)
