"""The three workflows on a run directory: tune a scenario end to end, re-evaluate a trained policy,
export its gain schedule. The directory's layout and its atomic writes live in rundir.py; an existing
run directory is never overwritten, and no command writes over a file a run owns.
"""
from __future__ import annotations

import csv
import dataclasses
import decimal
import io
import json
import sys
import warnings
from pathlib import Path

import numpy as np

from prlpid_fmi import rundir as rd
from prlpid_fmi.errors import Interrupted, PrlPidError, RunError
from prlpid_fmi.rundir import write_atomic, write_json
from prlpid_fmi.scenario.load import Scenario, load_scenario, scenario_to_yaml
from prlpid_fmi.schema.types import MAX_SEED

from prlpid_fmi.report.markdown import candidates_table, deployed_section, loop_units, render_report


# -- trajectories to CSV ---------------------------------------------------------------------------
def sample_times(steps: int, sample_time_s: float) -> np.ndarray:
    """t = k·Ts for k = 0..steps-1 [s], rounded to the decimals of Ts (0.3, not 0.30000000000000004)."""
    decimals = max(0, -decimal.Decimal(repr(float(sample_time_s))).as_tuple().exponent)
    return np.round(np.arange(steps) * sample_time_s, decimals)


def trajectory_csv(traj, loop_names: list[str], sample_time_s: float) -> str:
    """gains.csv text of an evaluate.Trajectory: one row per control step k (t = k·Ts, rounded to the
    sample time's decimals): setpoint, measurement, control signal and gains (Ki = Kp/Ti, Kd = Kp·Td)."""
    gains = traj.gains
    n = traj.steps
    times = sample_times(n, sample_time_s)
    header = ["step", "time_s"]
    for name in loop_names:
        header += [f"setpoint[{name}]", f"measurement[{name}]", f"control_signal[{name}]",
                   f"Kp[{name}]", f"Ti[{name}]", f"Td[{name}]", f"Ki[{name}]", f"Kd[{name}]"]
    coupling = gains.get("coupling")
    if coupling is not None:
        from prlpid_fmi.control import COUPLING_NAMES
        header += list(COUPLING_NAMES)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for k in range(n):
        row = [k, repr(float(times[k]))]
        for i in range(len(loop_names)):
            kp, ti, td = gains["Kp"][k][i], gains["Ti"][k][i], gains["Td"][k][i]
            row += [repr(float(v)) for v in (traj.setpoint[k][i], traj.measurement[k][i],
                                            traj.control_signal[k][i], kp, ti, td, kp / ti, kp * td)]
        if coupling is not None:
            row += [repr(float(v)) for v in coupling[k]]
        w.writerow(row)
    return buf.getvalue()


# -- the pieces of a run ---------------------------------------------------------------------------
def _one_line(exc: BaseException) -> str:
    """An exception's message with its whitespace (newlines included) collapsed."""
    return " ".join(str(exc).split())


def _policy(run_dir: Path, algorithm: str):
    from prlpid_fmi.loop.evaluation import model_policy
    from prlpid_fmi.tuning.agent import load_model

    path = run_dir / rd.MODEL
    try:
        model = load_model(path, algorithm)
    except Exception as exc:  # a damaged file can fail in zipfile, pickle or torch: all mean the same here
        raise RunError(f"{path}: cannot load the trained policy ({type(exc).__name__}: {_one_line(exc)}; "
                       f"expected a {algorithm.upper()} model.zip written by `tune`)") from None
    vecnorm = None
    if (run_dir / rd.VECNORMALIZE).is_file():
        import pickle

        try:
            with open(run_dir / rd.VECNORMALIZE, "rb") as f:
                vecnorm = pickle.load(f)
        except (pickle.UnpicklingError, EOFError, AttributeError, ValueError) as exc:
            raise RunError(f"{run_dir / rd.VECNORMALIZE}: cannot load the observation statistics "
                           f"({type(exc).__name__}: {_one_line(exc)}; expected the file written by `tune`)") from None
        vecnorm.training = False
    return model_policy(model, vecnorm)


def evaluate_into(run_dir: Path, scenario: Scenario, out_dir: Path, policy, fixed: dict | None,
                  source: Path | None = None, anchor=None, schedule=None, deployed: str | None = None) -> dict:
    """Evaluate `policy` (and the fixed PID) on the scenario's evaluation; write metrics, CSV, plots, report.

    source: the scenario file the evaluation comes from, named in the report. schedule: a GainSchedule (the
    policy's, or the run's deployed schedule.csv), replayed on the same evaluation and drawn in the plots as
    "gain schedule". deployed: what the run deployed ("gain schedule" | "fixed PID" | "none"; None: not known
    yet, as in `tune` before its choice); the report then opens with the deployed controller on this evaluation.
    """
    from prlpid_fmi.report import plots
    from prlpid_fmi.loop.evaluation import constant_gains, evaluate_gains
    from prlpid_fmi.loop.evaluation import evaluate
    from prlpid_fmi.tuning.schedule.table import replay_schedule

    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    seed = scenario.evaluation.seed
    policy_m, traj = evaluate(policy, config, seed=seed, intervals=intervals, anchor=anchor)
    fixed_m = fixed_traj = None
    if fixed is not None:
        g = fixed["gains"]
        fixed_m, fixed_traj = evaluate_gains(constant_gains(g["Kp"], g["Ti"], g["Td"], g.get("coupling")), config, seed=seed,
                                       intervals=intervals)
    schedule_m = schedule_traj = None
    if schedule is not None:
        schedule_m, schedule_traj = replay_schedule(schedule, config, seed=seed, intervals=intervals)
    loop_names = [l.output for l in config.loops]
    write_atomic(out_dir / rd.GAINS, trajectory_csv(traj, loop_names, config.sample_time_s))
    metrics = {"policy": policy_m, "fixed_pid": {"gains": fixed["gains"], "metrics": fixed_m} if fixed else None}
    if deployed is not None:
        metrics["deployed"] = deployed
        metrics["deployed_schedule"] = schedule_m if deployed == "gain schedule" else None
    write_json(out_dir / rd.METRICS, metrics)
    plots.plot_response(traj, config, out_dir / rd.RESPONSE_PLOT, title=f"{scenario.name}: response",
                        baseline_traj=fixed_traj, schedule_traj=schedule_traj)
    plots.plot_control_signal(traj, config, out_dir / rd.CONTROL_SIGNAL_PLOT, baseline_traj=fixed_traj,
                              schedule_traj=schedule_traj, title=f"{scenario.name}: control signal")
    plots.plot_gains(traj, config, out_dir / rd.GAINS_PLOT, baseline_gains=fixed["gains"] if fixed else None,
                     schedule_traj=schedule_traj, title=f"{scenario.name}: PID gains set by the adaptive policy")
    report = render_report(scenario, policy_m, fixed_m, fixed["gains"] if fixed else None, source,
                           loop_units(config), learning_curve=out_dir == run_dir)
    if deployed is not None:
        title, _, body = report.partition("\n")
        report = "\n".join([title, "", deployed_section(deployed, schedule_m, fixed_m, loop_units(config)),
                             body.lstrip("\n")])
    write_atomic(out_dir / rd.REPORT, report)
    return metrics


def tune(scenario_path: str | Path, timesteps: int | None = None, seed: int | None = None,
         out: str | Path | None = None, resume: bool = False, progress_bar: bool = True,
         baseline: bool = True) -> Path:
    """Train the scenario's agent, evaluate it against a tuned fixed PID, export the gain schedule.

    Returns the run directory. With resume, training continues from the run's latest checkpoint
    (its scenario.yaml, not `scenario_path`, defines the run). timesteps >= 1 and seed >= 0 are checked,
    and the scenario loaded, before anything is created; a start refused before training produced a
    model or a checkpoint leaves no directory behind. progress_bar: training and fixed-PID search
    progress, and the steps after training, on stderr.
    """
    if timesteps is not None and timesteps < 1:
        raise RunError(f"--timesteps: must be at least 1 (got {timesteps}; expected a number of training steps >= 1)")
    if seed is not None and not 0 <= seed <= MAX_SEED:
        raise RunError(f"--seed: out of range (got {seed}; expected an integer from 0 to {MAX_SEED})")
    scenario = load_scenario(scenario_path)
    run_dir, created = rd.prepare_run_dir(out, scenario.name, resume)
    crashed = rd.mark_active(run_dir)
    try:
        return _tune(scenario, Path(scenario_path), run_dir, timesteps, seed, resume, progress_bar, baseline,
                     crashed and resume)
    except BaseException as exc:
        if isinstance(exc, Interrupted):
            exc.run_dir = run_dir
        rd.discard_if_empty(run_dir, created)
        raise
    finally:
        rd.mark_inactive(run_dir)


def _isolated(scenario: Scenario, isolation: str) -> Scenario:
    """The scenario with plant.isolation `isolation` where it is "auto"."""
    if scenario.tuning.isolation != "auto" or isolation == "auto":
        return scenario
    return dataclasses.replace(scenario, tuning=dataclasses.replace(scenario.tuning, isolation=isolation))


def _tune(scenario: Scenario, source: Path, run_dir: Path, timesteps: int | None, seed: int | None, resume: bool,
          progress_bar: bool, baseline: bool, crashed: bool = False) -> Path:
    from prlpid_fmi.report import plots
    from prlpid_fmi.tuning.fixed_pid import tune_fixed_pid
    from prlpid_fmi.progress import Progress, stage
    from prlpid_fmi.deliver.evidence import assess, candidate_summary, max_sensitivity
    from prlpid_fmi.deliver.rule import verdict
    from prlpid_fmi.export.code import deployable_files
    from prlpid_fmi.tuning.schedule.table import fixed_schedule, write_schedule_csv
    from prlpid_fmi.tuning.schedule.trajectories import deliverable_schedule
    from prlpid_fmi.tuning.agent import train

    info = {"command": sys.argv, "started": rd.now(), "versions": rd.package_versions()}
    if resume:
        scenario = load_scenario(run_dir / rd.SCENARIO)
        source = run_dir / rd.SCENARIO
        info = {**json.loads((run_dir / rd.RUN_INFO).read_text()), "resumed": rd.now()}
        if crashed and scenario.tuning.isolation == "auto":
            warnings.warn(f"{run_dir}: the previous run ended abruptly (did the FMU crash it?); the plant now runs "
                          "in a worker process (plant.isolation: process)", stacklevel=2)
            info["isolation"] = "process"
        scenario = _isolated(scenario, info.get("isolation", "auto"))
    agent = scenario.agent
    if seed is not None:
        agent = dataclasses.replace(agent, seed=seed)
    if timesteps is not None:
        agent = dataclasses.replace(agent, total_timesteps=timesteps)
    if timesteps is not None or seed is not None:
        scenario = dataclasses.replace(scenario, agent=agent)
    if resume and info.pop("finished", None) and info.get("trained_timesteps", 0) >= agent.total_timesteps \
            and (run_dir / rd.REPORT).is_file():
        warnings.warn(f"{run_dir}: finished already ({info['trained_timesteps']} training steps; {rd.REPORT} "
                      "holds its result); nothing to do (a larger --timesteps trains on)", stacklevel=2)
        return run_dir
    if not resume:
        write_atomic(run_dir / rd.SCENARIO, scenario_to_yaml(scenario))
    info.update(seed=agent.seed, total_timesteps=agent.total_timesteps, algorithm=agent.algorithm)
    write_json(run_dir / rd.RUN_INFO, info)

    # 1. the fixed PID first: the baseline, and the anchor the agent's gains move around
    fixed = None
    if (run_dir / rd.FIXED_PID).is_file():  # resume: the search is done already
        fixed = json.loads((run_dir / rd.FIXED_PID).read_text())
    elif baseline or scenario.tuning.gain_mapping == "anchored":
        b = scenario.baseline
        search = Progress("fixed-PID search", "evaluations") if progress_bar else None
        result = tune_fixed_pid(scenario.tuning, seed=agent.seed, episodes=b.episodes, maxiter=b.maxiter,
                                popsize=b.popsize, callback=search.update if search else None,
                                max_sensitivity=max_sensitivity(scenario))
        if search:
            search.close()
        fixed = {"action": result.action.tolist(), "gains": result.gains.as_dict(), "cost": result.cost,
                 "evaluations": result.evaluations}
        write_json(run_dir / rd.FIXED_PID, fixed)
        write_schedule_csv(fixed_schedule(result.gains, scenario.tuning), run_dir / rd.FIXED_PID_CSV)
    anchor = _anchor(scenario, fixed)

    # 2. train around it
    resume_from, done = rd.latest_checkpoint(run_dir, info.get("trained_timesteps", 0)) if resume else (None, 0)
    remaining = max(agent.total_timesteps - done, 0)
    if remaining > 0:
        model = train(scenario.tuning, agent, run_dir, progress_bar=progress_bar, resume_from=resume_from,
                      total_timesteps=remaining, anchor=anchor)
        info["trained_timesteps"] = int(model.num_timesteps)
        write_json(run_dir / rd.RUN_INFO, info)

    # 3. read the policy's gain schedule, evaluate both (and the fixed PID), choose what to deploy
    policy = _policy(run_dir, agent.algorithm)
    schedule, note = None, ""
    try:  # deploy.schedule_by: settled setpoint holds, error trajectories, or the better of both (auto)
        with stage("gain schedule (tables from the policy, rows checked against the Ms limit)", progress_bar):
            schedule, note, chosen = deliverable_schedule(policy, scenario, agent.seed, anchor)
        info.update(chosen)
    except PrlPidError as exc:
        note = f"No gain schedule: {exc}\n"
        info["schedule_error"] = str(exc)
    with stage("evaluation", progress_bar):
        evaluate_into(run_dir, scenario, run_dir, policy, fixed, source, anchor=anchor, schedule=schedule)
    report = (run_dir / rd.REPORT).read_text(encoding="utf-8")
    if fixed is not None:
        with stage("choice of the deployed controller (replays, Monte-Carlo set, margins)", progress_bar):
            decision, sched_c, fixed_c = assess(scenario, schedule, gains_from_dict(fixed["gains"]))
        limit = max_sensitivity(scenario)
        deployed = {"gain schedule": schedule, "fixed PID": fixed_schedule(gains_from_dict(fixed["gains"]),
                                                                           scenario.tuning)}.get(decision.deploy)
        if deployed is not None:
            write_schedule_csv(deployed, run_dir / rd.SCHEDULE)
        metrics = json.loads((run_dir / rd.METRICS).read_text())
        metrics["deployed"] = decision.deploy
        metrics["decision"] = list(decision.reasons)
        metrics["schedule_replay"] = candidate_summary(sched_c) if sched_c is not None else None
        metrics["fixed_pid_assessment"] = candidate_summary(fixed_c)
        write_json(run_dir / rd.METRICS, metrics)
        title, _, body = report.partition("\n")
        opening = verdict(decision, sched_c, fixed_c, limit, scenario.tuning.gain_mapping).rstrip()
        report = "\n".join([title, "", opening, "",
                             candidates_table(sched_c, fixed_c, loop_units(scenario.tuning)), body.lstrip("\n")])
    elif schedule is not None:
        write_schedule_csv(schedule, run_dir / rd.SCHEDULE)
    if note:
        report += "\n" + note
    report += "\n" + deployable_files(run_dir)
    write_atomic(run_dir / rd.REPORT, report)
    plots.plot_learning_curve(run_dir / rd.MONITOR, run_dir / rd.LEARNING_CURVE_PLOT)
    info["finished"] = rd.now()
    write_json(run_dir / rd.RUN_INFO, info)
    return run_dir


def _anchor(scenario: Scenario, fixed: dict | None):
    """The fixed PID's Gains when the scenario's gain map is anchored (None: absolute map)."""
    if fixed is None or scenario.tuning.gain_mapping != "anchored":
        return None
    return gains_from_dict(fixed["gains"])


def gains_from_dict(g: dict):
    from prlpid_fmi.loop.actions import gains_from_values

    return gains_from_values(g["Kp"], g["Ti"], g["Td"], g.get("coupling"))


def _load_run(run_dir: Path) -> Scenario:
    if not (run_dir / rd.SCENARIO).is_file() or not (run_dir / rd.MODEL).is_file():
        raise RunError(f"{run_dir}: not a finished run directory (expected {rd.SCENARIO} and {rd.MODEL} from `tune`)")
    scenario = load_scenario(run_dir / rd.SCENARIO)
    try:  # a run whose plant crashed the tool once keeps its plant in a worker process
        isolation = json.loads((run_dir / rd.RUN_INFO).read_text()).get("isolation", "auto")
    except (OSError, ValueError, AttributeError):
        isolation = "auto"
    return _isolated(scenario, isolation)


def _on_other_evaluation(trained: Scenario, scenario_path: str | Path) -> Scenario:
    """Another scenario's evaluation (setpoints, disturbances, ...) around the trained run's loops."""
    other = load_scenario(scenario_path)
    if [(l.input, l.output) for l in other.tuning.loops] != [(l.input, l.output) for l in trained.tuning.loops] \
            or other.tuning.coupled != trained.tuning.coupled:
        raise RunError(f"{scenario_path}: plant.loops differ from the trained run's "
                       f"(got {[l.output for l in other.tuning.loops]}; expected the same loops and coupling)")
    return _isolated(dataclasses.replace(other, tuning=dataclasses.replace(
        other.tuning, loops=trained.tuning.loops, coupled=trained.tuning.coupled,
        coupling_range=trained.tuning.coupling_range)), trained.tuning.isolation)


def evaluate_run(run_dir: str | Path, scenario_path: str | Path | None = None) -> Path:
    """Re-evaluate a trained policy (optionally on another scenario's evaluation); a new evaluations/<n>/."""
    run_dir = Path(run_dir)
    trained = _load_run(run_dir)
    scenario = trained if scenario_path is None else _on_other_evaluation(trained, scenario_path)
    policy = _policy(run_dir, trained.agent.algorithm)
    base = run_dir / rd.EVALUATIONS
    base.mkdir(exist_ok=True)
    n = 1 + max((int(p.name) for p in base.iterdir() if p.name.isdigit()), default=0)
    out_dir = base / str(n)
    out_dir.mkdir()
    fixed = json.loads((run_dir / rd.FIXED_PID).read_text()) if (run_dir / rd.FIXED_PID).is_file() else None
    deployed, schedule = _deployed(run_dir)
    write_atomic(out_dir / rd.SCENARIO, scenario_to_yaml(scenario))
    source = Path(scenario_path) if scenario_path is not None else run_dir / rd.SCENARIO
    evaluate_into(run_dir, scenario, out_dir, policy, fixed, source, anchor=_anchor(trained, fixed),
                  schedule=schedule, deployed=deployed)
    return out_dir


def _deployed(run_dir: Path):
    """(what the run deployed, its schedule.csv as a GainSchedule when that is the adaptive schedule); (None,
    None) for a run whose choice was not made (no metrics.json entry, e.g. an absolute map without baseline)."""
    from prlpid_fmi.tuning.schedule.table import read_schedule_csv

    try:
        deployed = json.loads((run_dir / rd.METRICS).read_text()).get("deployed")
    except (OSError, ValueError, AttributeError):
        return None, None
    if deployed == "gain schedule" and (run_dir / rd.SCHEDULE).is_file():
        return deployed, read_schedule_csv(run_dir / rd.SCHEDULE)
    return (deployed, None) if deployed in ("fixed PID", "none") else (None, None)


def check_output(run_dir: Path, output: Path, force: bool = False) -> None:
    """Refuse an output file that is a directory, a file the run owns (even with force), or an existing
    file without force. Raises RunError."""
    owned = rd.owned_name(run_dir, output)
    if output.is_dir():
        raise RunError(f"{output}: is a directory (expected a file name for the gain schedule CSV)")
    if owned is not None:
        raise RunError(f"{output}: belongs to the run directory {run_dir} (its {owned}; expected a file outside "
                       f"the run's own files, e.g. {run_dir.name}_schedule.csv)")
    if output.exists() and not force:
        raise RunError(f"{output}: exists (expected a new file name, or --force to replace it)")


def _check_schedule_options(trained: Scenario, schedule_by: str, points: int) -> None:
    """--points >= 1, and --schedule-by a loop signal or a real variable of the run's plant FMU (RunError)."""
    from prlpid_fmi.loop.core import resolve_fmu
    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.tuning.schedule.table import LOOP_SIGNALS, LOOP_VARIABLE

    if points < 1:
        raise RunError(f"--points: must be at least 1 (got {points}; expected a number of operating points >= 1)")
    if schedule_by in LOOP_SIGNALS:
        return
    m, loops = LOOP_VARIABLE.match(schedule_by), [loop.output for loop in trained.tuning.loops]
    if m:
        if m.group(2) not in loops:
            raise RunError(f"--schedule-by: no loop measures {m.group(2)!r} (got {schedule_by!r}; expected "
                           f"{m.group(1)}[<loop>] with one of the loops: {', '.join(loops)})")
        return
    fmu = resolve_fmu(trained.tuning.fmu, trained.tuning.fmi_version)
    desc = describe_fmu(fmu)
    v = desc.variable(schedule_by)
    if v is None or not v.scalar_real:
        names = [x.name for x in desc.variables if x.scalar_real]
        shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
        raise RunError(f"--schedule-by: the plant {fmu.name} has no scalar real variable {schedule_by!r} (got "
                       f"{schedule_by!r}; expected {', '.join(LOOP_SIGNALS)}, <signal>[<loop>], or one of: {shown})")


def export_schedule(run_dir: str | Path, output: str | Path, schedule_by: str = "setpoint", points: int = 9,
                    replay: bool = False, scenario_path: str | Path | None = None,
                    force: bool = False) -> tuple[Path, dict | None]:
    """Write the tuned gain schedule CSV; with replay, run it as a plain PID and compare with the policy.

    output: a new file (an existing one only with force), never one of the run's own files.
    scenario_path: with replay, replay on this scenario's evaluation instead of the run's own.
    Returns (csv path, comparison or None): comparison = {"policy": metrics, "schedule": metrics}.
    """
    from prlpid_fmi.loop.evaluation import evaluate
    from prlpid_fmi.tuning.schedule.table import replay_schedule, write_schedule_csv
    from prlpid_fmi.tuning.schedule.trajectories import extract

    run_dir, output = Path(run_dir), Path(output)
    trained = _load_run(run_dir)
    check_output(run_dir, output, force)
    _check_schedule_options(trained, schedule_by, points)
    if scenario_path is not None and not replay:
        raise RunError(f"--scenario {scenario_path}: only used with --replay (expected --replay, or no --scenario)")
    scenario = trained if scenario_path is None else _on_other_evaluation(trained, scenario_path)
    policy = _policy(run_dir, trained.agent.algorithm)
    fixed = json.loads((run_dir / rd.FIXED_PID).read_text()) if (run_dir / rd.FIXED_PID).is_file() else None
    anchor = _anchor(trained, fixed)
    schedule = extract(policy, trained.tuning, schedule_by, points, trained.agent.seed, anchor)
    path = write_schedule_csv(schedule, output)
    if not replay:
        return path, None
    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    seed = scenario.evaluation.seed
    policy_m, _ = evaluate(policy, config, seed=seed, intervals=intervals, anchor=anchor)
    schedule_m, _ = replay_schedule(schedule, config, seed=seed, intervals=intervals)
    return path, {"policy": policy_m, "schedule": schedule_m}
