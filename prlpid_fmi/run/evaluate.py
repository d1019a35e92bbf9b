"""Evaluate a run's controllers on its scenario's evaluation (or another scenario's): metrics, gains.csv,
plots and the evaluation part of report.md; `evaluate RUN` writes them into a new evaluations/<n>/."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from prlpid_fmi import rundir as rd
from prlpid_fmi.config import TuningConfig
from prlpid_fmi.deliver.rule import Deployed
from prlpid_fmi.report.markdown import deployed_section, loop_units, render_report
from prlpid_fmi.report.verdict import acceptance_section
from prlpid_fmi.run.gains_csv import trajectory_csv
from prlpid_fmi.run.state import (deployed_controller, load_policy, load_trained, on_other_evaluation, read_fixed_pid,
                                    run_anchor)
from prlpid_fmi.rundir import write_atomic, write_json
from prlpid_fmi.scenario.load import Scenario, scenario_to_yaml
from prlpid_fmi.tuning.design_result import DesignResult


@dataclass
class Evaluation:
    """The controllers of a run on one evaluation schedule: compute_metrics dicts and Trajectories.

    fixed / schedule (and their trajectories) are None when the run has no fixed PID or no gain table.
    """

    config: TuningConfig
    policy: dict
    policy_traj: object
    fixed: DesignResult | None = None
    fixed_traj: object = None
    schedule: dict | None = None
    schedule_traj: object = None


def evaluate_controllers(scenario: Scenario, policy, fixed: DesignResult | None, anchor=None, schedule=None) -> Evaluation:
    """Run the policy, the fixed PID (fixed_pid.json's content) and the gain table (a GainSchedule, replayed as a
    plain PID) on the scenario's evaluation, with its seed and intervals."""
    from prlpid_fmi.loop.evaluation import constant_gains, evaluate, evaluate_gains
    from prlpid_fmi.tuning.schedule.replay import replay_schedule

    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    seed = scenario.evaluation.seed
    policy_m, traj = evaluate(policy, config, seed=seed, intervals=intervals, anchor=anchor)
    result = Evaluation(config, policy_m, traj)
    if fixed is not None:
        result.fixed, result.fixed_traj = evaluate_gains(constant_gains(*fixed.gains.values()), config, seed=seed,
                                                         intervals=intervals)
    if schedule is not None:
        result.schedule, result.schedule_traj = replay_schedule(schedule, config, seed=seed, intervals=intervals)
    return result


def write_evaluation_files(out_dir: Path, scenario: Scenario, ev: Evaluation, fixed: DesignResult | None) -> None:
    """gains.csv (the policy's trajectory) and the response (whole and zoomed to its transients), control-signal and
    gains plots."""
    from prlpid_fmi.report import plots

    config = ev.config
    loop_names = [l.output for l in config.loops]
    write_atomic(out_dir / rd.GAINS, trajectory_csv(ev.policy_traj, loop_names, config.sample_time_s))
    plots.plot_response(ev.policy_traj, config, out_dir / rd.RESPONSE_PLOT, title=f"{scenario.name}: response",
                        baseline_traj=ev.fixed_traj, schedule_traj=ev.schedule_traj)
    plots.plot_control_signal(ev.policy_traj, config, out_dir / rd.CONTROL_SIGNAL_PLOT, baseline_traj=ev.fixed_traj,
                              schedule_traj=ev.schedule_traj, title=f"{scenario.name}: control signal")
    pairs = [(name, t) for name, t in ((plots.POLICY, ev.policy_traj), (plots.FIXED, ev.fixed_traj),
                                       (plots.SCHEDULE, ev.schedule_traj)) if t is not None]
    plots.save_figure(plots.step_response_figure(pairs, config, f"{scenario.name}: transients"),
                      out_dir / rd.STEP_RESPONSE_PLOT)
    plots.plot_gains(ev.policy_traj, config, out_dir / rd.GAINS_PLOT, baseline_gains=fixed.gains.as_dict() if fixed else None,
                     schedule_traj=ev.schedule_traj, title=f"{scenario.name}: PID gains set by the adaptive policy")


def evaluation_metrics(ev: Evaluation, fixed: DesignResult | None) -> dict:
    """metrics.json's evaluation part: the policy's metrics and the fixed PID's gains and metrics."""
    return {"policy": ev.policy, "fixed_pid": {"gains": fixed.gains.as_dict(), "metrics": ev.fixed} if fixed else None}


def evaluation_report(scenario: Scenario, ev: Evaluation, fixed: DesignResult | None, source: Path | None,
                      learning_curve: bool, opening: tuple[str, ...] = (), headline: str = "") -> str:
    """report.md of this evaluation, with `opening` sections between its title and the metric table; headline: the
    title's words after the scenario's name (report.markdown.render_report)."""
    return render_report(scenario, ev.policy, ev.fixed, fixed.gains.as_dict() if fixed else None, source,
                         loop_units(ev.config), learning_curve=learning_curve, opening=opening, headline=headline)


def evaluate_run(run_dir: str | Path, scenario_path: str | Path | None = None) -> Path:
    """Re-evaluate a trained run (optionally on another scenario's evaluation) into a new evaluations/<n>/:
    the policy, the fixed PID and the controller the run deployed, side by side."""
    run_dir = Path(run_dir)
    trained = load_trained(run_dir)
    scenario = trained if scenario_path is None else on_other_evaluation(trained, scenario_path)
    policy = load_policy(run_dir, trained.agent.algorithm)
    base = run_dir / rd.EVALUATIONS
    base.mkdir(exist_ok=True)
    n = 1 + max((int(p.name) for p in base.iterdir() if p.name.isdigit()), default=0)
    out_dir = base / str(n)
    out_dir.mkdir()
    fixed = read_fixed_pid(run_dir)
    deployed, schedule = deployed_controller(run_dir)
    write_atomic(out_dir / rd.SCENARIO, scenario_to_yaml(scenario))
    source = Path(scenario_path) if scenario_path is not None else run_dir / rd.SCENARIO
    ev = evaluate_controllers(scenario, policy, fixed, anchor=run_anchor(run_dir, trained, fixed), schedule=schedule)
    write_evaluation_files(out_dir, scenario, ev, fixed)
    metrics = evaluation_metrics(ev, fixed)
    opening = ()
    if deployed is not None:
        metrics["deployed"] = deployed
        metrics["deployed_schedule"] = ev.schedule if deployed in (Deployed.SCHEDULE, Deployed.CLASSICAL) else None
        opening = (deployed_section(deployed, ev.schedule, ev.fixed, loop_units(ev.config)),)
        acceptance = deployed_acceptance(run_dir, scenario)
        if acceptance is not None:
            metrics["deployed_acceptance"] = acceptance.as_dict()
            opening += (acceptance_section(deployed, acceptance),)
    metrics.update(other_tables(run_dir, ev.config, scenario, deployed))
    write_json(out_dir / rd.METRICS, metrics)
    verdict_words = ""
    if deployed is not None and "deployed_acceptance" in metrics:
        verdict_words = (f"the deployed {deployed} " + ("passes" if metrics["deployed_acceptance"]["passed"] else
                                                        "fails") + " the acceptance check here")
    write_atomic(out_dir / rd.REPORT, evaluation_report(scenario, ev, fixed, source, learning_curve=False,
                                                        opening=opening, headline=verdict_words))
    return out_dir


def deployed_acceptance(run_dir: Path, scenario: Scenario):
    """The acceptance check (deliver.acceptance) of the run's deployed controller (schedule.csv, replayed as a
    plain PID) on this scenario's evaluation; None when the run deployed nothing."""
    from prlpid_fmi.deliver.acceptance import Episode, check
    from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv
    from prlpid_fmi.tuning.schedule.replay import replay_schedule

    if not (run_dir / rd.SCHEDULE).is_file():
        return None
    table = read_schedule_csv(run_dir / rd.SCHEDULE)
    config, seed = scenario.evaluation_config(), scenario.evaluation.seed
    plain = dataclasses.replace(config, randomize={}) if config.randomize else config
    metrics, traj = replay_schedule(table, plain, seed=seed)
    return check([Episode("this evaluation", plain, seed, metrics, traj)],
                 lambda cfg, sd: replay_schedule(table, cfg, seed=sd),
                 scenario.deploy.max_overshoot, scenario.deploy.max_chatter)


def other_tables(run_dir: Path, config: TuningConfig, scenario: Scenario, deployed) -> dict:
    """{"adaptive_schedule", "classical_schedule"}: the metrics of the run's gain tables on this evaluation (replayed
    as plain PIDs) where the run has them (adaptive_schedule.csv, classical_schedule.csv), None where not; the
    deployed one is deployed_schedule already."""
    from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv
    from prlpid_fmi.tuning.schedule.replay import replay_schedule

    out = {}
    for key, name, kind in (("adaptive_schedule", rd.ADAPTIVE_SCHEDULE, Deployed.SCHEDULE),
                            ("classical_schedule", rd.CLASSICAL_SCHEDULE, Deployed.CLASSICAL)):
        path = run_dir / name
        if not path.is_file():
            out[key] = None
            continue
        table = read_schedule_csv(path)
        out[key] = replay_schedule(table, config, seed=scenario.evaluation.seed,
                                   intervals=list(scenario.evaluation.intervals) or None)[0]
        out[key]["deployed"] = deployed == kind
    return out
