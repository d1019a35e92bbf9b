"""Run directories: tune a scenario end to end, re-evaluate a trained policy, export its gain schedule.

A run directory holds everything needed to reproduce and judge a run:
  scenario.yaml    the resolved scenario (every key, defaults filled in)
  run.json         seed, timesteps, command, start/end time, package versions, platform
  model.zip        the trained policy (+ vecnormalize.pkl), checkpoints/, tensorboard/, monitor/
  metrics.json     adaptive policy vs the tuned fixed PID, overall and per interval
  gains.csv        time, setpoint, measurement, control signal, Kp, Ti, Td, ... at every step
  schedule.csv     the gain schedule (plain PID table, no neural network)
  report.md        the comparison as a table
  *.png            response, control signal, gains over time, learning curve
Outputs are written atomically; an existing run directory is never overwritten silently.
"""
from __future__ import annotations

import csv
import dataclasses
import datetime as dt
import io
import json
import os
import platform
import sys
from importlib import metadata
from pathlib import Path

import numpy as np

from .errors import PrlPidError
from .scenario import Scenario, load_scenario, scenario_to_yaml

PACKAGES = ("prlpid-fmi", "fmpy", "numpy", "scipy", "torch", "stable-baselines3", "gymnasium", "pyyaml", "matplotlib")
METRIC_COLUMNS = ("ISE", "IAE", "ITAE", "Overshoot", "SettlingTime", "RiseTime", "SteadyStateError",
                  "ControlEffort", "TotalVariation")


class RunError(PrlPidError):
    """A run directory cannot be used as asked (exists, missing files, ...)."""


# -- small I/O helpers ---------------------------------------------------------------------------
def write_text_atomic(path: Path, text: str) -> Path:
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path


def write_json(path: Path, data) -> Path:
    return write_text_atomic(path, json.dumps(data, indent=2, default=_json_default) + "\n")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version(), "platform": platform.platform()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")


def prepare_run_dir(out: str | Path | None, scenario: Scenario, resume: bool) -> Path:
    """The run directory: new (default runs/<name>-<UTC time>) or, with resume, an existing one."""
    if out is None:
        if resume:
            raise RunError("--resume needs --out RUN_DIR naming the run to continue")
        stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y%m%d-%H%M%S")
        out = Path("runs") / f"{scenario.name}-{stamp}"
    run_dir = Path(out)
    if resume:
        if not (run_dir / "scenario.yaml").is_file():
            raise RunError(f"{run_dir}: nothing to resume (no scenario.yaml; expected a run directory from `tune`)")
        return run_dir
    if run_dir.exists() and any(run_dir.iterdir()):
        raise RunError(f"{run_dir}: run directory exists and is not empty (got --out {run_dir}; "
                       "expected a new directory, or --resume to continue that run)")
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def latest_checkpoint(run_dir: Path, trained_timesteps: int = 0) -> tuple[Path | None, int]:
    """(model file with the most timesteps, its timesteps): a checkpoint, or model.zip after a finished
    training (run.json's trained_timesteps), or (None, 0)."""
    best: tuple[Path | None, int] = (None, 0)
    for p in (run_dir / "checkpoints").glob("model_*_steps.zip"):
        steps = int(p.stem.split("_")[1])
        if steps > best[1]:
            best = (p, steps)
    if (run_dir / "model.zip").is_file() and trained_timesteps >= best[1]:
        best = (run_dir / "model.zip", trained_timesteps)
    return best


# -- trajectories to CSV ---------------------------------------------------------------------------
def trajectory_csv(traj: dict, loop_names: list[str]) -> str:
    """gains.csv text: one row per control step k (t = k·Ts): setpoint, measurement, u and gains."""
    gains = traj["gains"]
    n = len(traj["reward"])
    header = ["step", "time_s"]
    for name in loop_names:
        header += [f"setpoint[{name}]", f"measurement[{name}]", f"control_signal[{name}]",
                   f"Kp[{name}]", f"Ti[{name}]", f"Td[{name}]", f"Ki[{name}]", f"Kd[{name}]"]
    coupling = gains.get("coupling")
    if coupling is not None:
        from .control import COUPLING_NAMES
        header += list(COUPLING_NAMES)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for k in range(n):
        row = [k, repr(float(traj["time_s"][k]))]
        for i in range(len(loop_names)):
            kp, ti, td = gains["Kp"][k][i], gains["Ti"][k][i], gains["Td"][k][i]
            row += [repr(float(v)) for v in (traj["setpoint"][k][i], traj["measurement"][k][i],
                                            traj["control_signal"][k][i], kp, ti, td, kp / ti, kp * td)]
        if coupling is not None:
            row += [repr(float(v)) for v in coupling[k]]
        w.writerow(row)
    return buf.getvalue()


# -- the pieces of a run ---------------------------------------------------------------------------
def _policy(run_dir: Path, algorithm: str):
    from .evaluate import model_policy
    from .train import load_model

    model = load_model(run_dir / "model.zip", algorithm)
    vecnorm = None
    if (run_dir / "vecnormalize.pkl").is_file():
        import pickle

        with open(run_dir / "vecnormalize.pkl", "rb") as f:
            vecnorm = pickle.load(f)
        vecnorm.training = False
    return model_policy(model, vecnorm)


def _report(scenario: Scenario, policy_m: dict, fixed_m: dict | None, fixed_gains: dict | None) -> str:
    loops = policy_m["loops"]
    keys = [k for k in policy_m["overall"] if k.split("[")[0] in METRIC_COLUMNS]
    lines = [f"# {scenario.name}: adaptive PRL-PID policy vs tuned fixed PID", "",
             f"Evaluation: {scenario.evaluation_config().episode_steps} steps at Ts = "
             f"{scenario.tuning.sample_time_s:g} s; loops: {', '.join(loops)}.", ""]
    if fixed_gains:
        lines += ["Fixed PID (differential evolution on the training distribution): " +
                  ", ".join(f"{k} = {np.round(np.asarray(v), 4).tolist()}" for k, v in fixed_gains.items()), ""]
    lines += ["| metric | adaptive policy | fixed PID | ratio |", "|---|---|---|---|"]
    for k in keys:
        p = policy_m["overall"][k]
        f = fixed_m["overall"][k] if fixed_m else float("nan")
        ratio = p / f if fixed_m and f not in (0.0,) and np.isfinite(f) else float("nan")
        lines.append(f"| {k} | {p:.4g} | {f:.4g} | {ratio:.3g} |")
    for name, m in (("adaptive policy", policy_m), ("fixed PID", fixed_m)):
        if m and m.get("intervals"):
            lines += ["", f"Per interval ({name}):", "", "| steps | ISE | IAE |", "|---|---|---|"]
            for iv in m["intervals"]:
                ise = sum(v for k, v in iv.items() if k.split("[")[0] == "ISE")
                iae = sum(v for k, v in iv.items() if k.split("[")[0] == "IAE")
                lines.append(f"| {iv['start_step']}–{iv['end_step']} | {ise:.4g} | {iae:.4g} |")
    return "\n".join(lines) + "\n"


def evaluate_into(run_dir: Path, scenario: Scenario, out_dir: Path, policy, fixed: dict | None) -> dict:
    """Evaluate `policy` (and the fixed PID) on the scenario's evaluation; write metrics, CSV, plots, report."""
    from . import plots
    from .baseline import constant_policy
    from .evaluate import evaluate

    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    seed = scenario.evaluation.seed
    policy_m, traj = evaluate(policy, config, seed=seed, intervals=intervals)
    fixed_m = fixed_traj = None
    if fixed is not None:
        fixed_m, fixed_traj = evaluate(constant_policy(np.array(fixed["action"])), config, seed=seed,
                                       intervals=intervals)
    loop_names = [l.output for l in config.loops]
    write_text_atomic(out_dir / "gains.csv", trajectory_csv(traj, loop_names))
    metrics = {"policy": policy_m, "fixed_pid": {"gains": fixed["gains"], "metrics": fixed_m} if fixed else None}
    write_json(out_dir / "metrics.json", metrics)
    plots.plot_response(traj, config, out_dir / "response.png", title=f"{scenario.name}: response",
                        baseline_traj=fixed_traj)
    plots.plot_control_signal(traj, config, out_dir / "control_signal.png", baseline_traj=fixed_traj)
    plots.plot_gains(traj, config, out_dir / "gains.png")
    write_text_atomic(out_dir / "report.md", _report(scenario, policy_m, fixed_m, fixed["gains"] if fixed else None))
    return metrics


def tune(scenario_path: str | Path, timesteps: int | None = None, seed: int | None = None,
         out: str | Path | None = None, resume: bool = False, progress_bar: bool = True,
         baseline: bool = True) -> Path:
    """Train the scenario's agent, evaluate it against a tuned fixed PID, export the gain schedule.

    Returns the run directory. With resume, training continues from the run's latest checkpoint
    (its scenario.yaml, not `scenario_path`, defines the run).
    """
    from . import plots
    from .baseline import tune_fixed_pid
    from .schedule import extract_schedule, write_schedule_csv
    from .train import train

    scenario = load_scenario(scenario_path)
    run_dir = prepare_run_dir(out, scenario, resume)
    info = {"command": sys.argv, "started": _now(), "versions": package_versions()}
    if resume:
        scenario = load_scenario(run_dir / "scenario.yaml")
        info = {**json.loads((run_dir / "run.json").read_text()), "resumed": _now()}
    agent = scenario.agent
    if seed is not None:
        agent = dataclasses.replace(agent, seed=seed)
    if timesteps is not None:
        agent = dataclasses.replace(agent, total_timesteps=timesteps)
    if timesteps is not None or seed is not None:
        scenario = dataclasses.replace(scenario, agent=agent)
    if not resume:
        write_text_atomic(run_dir / "scenario.yaml", scenario_to_yaml(scenario))
    info.update(seed=agent.seed, total_timesteps=agent.total_timesteps, algorithm=agent.algorithm)
    write_json(run_dir / "run.json", info)

    resume_from, done = latest_checkpoint(run_dir, info.get("trained_timesteps", 0)) if resume else (None, 0)
    remaining = max(agent.total_timesteps - done, 0)
    if remaining > 0:
        model = train(scenario.tuning, agent, run_dir, progress_bar=progress_bar, resume_from=resume_from,
                      total_timesteps=remaining)
        info["trained_timesteps"] = int(model.num_timesteps)
        write_json(run_dir / "run.json", info)

    policy = _policy(run_dir, agent.algorithm)
    fixed = None
    if baseline:
        b = scenario.baseline
        result = tune_fixed_pid(scenario.tuning, seed=agent.seed, episodes=b.episodes, maxiter=b.maxiter,
                                popsize=b.popsize)
        fixed = {"action": result.action.tolist(), "gains": result.gains.as_dict(), "cost": result.cost,
                 "evaluations": result.evaluations}
        write_json(run_dir / "fixed_pid.json", fixed)
    evaluate_into(run_dir, scenario, run_dir, policy, fixed)
    try:
        schedule = extract_schedule(policy, scenario.tuning, seed=agent.seed)
        write_schedule_csv(schedule, run_dir / "schedule.csv")
        note = ("" if not schedule.excluded else "\nThe closed loop diverged at setpoint(s) "
                + ", ".join(f"{v:g}" for v in schedule.excluded) + ": left out of schedule.csv.\n")
    except PrlPidError as exc:
        note = f"\nNo gain schedule: {exc}\n"
        info["schedule_error"] = str(exc)
    if note:
        write_text_atomic(run_dir / "report.md", (run_dir / "report.md").read_text(encoding="utf-8") + note)
    plots.plot_learning_curve(run_dir / "monitor", run_dir / "learning_curve.png")
    info["finished"] = _now()
    write_json(run_dir / "run.json", info)
    return run_dir


def _load_run(run_dir: Path) -> Scenario:
    if not (run_dir / "scenario.yaml").is_file() or not (run_dir / "model.zip").is_file():
        raise RunError(f"{run_dir}: not a finished run directory (expected scenario.yaml and model.zip from `tune`)")
    return load_scenario(run_dir / "scenario.yaml")


def evaluate_run(run_dir: str | Path, scenario_path: str | Path | None = None) -> Path:
    """Re-evaluate a trained policy (optionally on another scenario's evaluation); a new evaluations/<n>/."""
    run_dir = Path(run_dir)
    trained = _load_run(run_dir)
    scenario = trained
    if scenario_path is not None:
        other = load_scenario(scenario_path)
        if [(l.input, l.output) for l in other.tuning.loops] != [(l.input, l.output) for l in trained.tuning.loops] \
                or other.tuning.coupled != trained.tuning.coupled:
            raise RunError(f"{scenario_path}: plant.loops differ from the trained run's "
                           f"(got {[l.output for l in other.tuning.loops]}; expected the same loops and coupling)")
        scenario = dataclasses.replace(other, tuning=dataclasses.replace(
            other.tuning, loops=trained.tuning.loops, coupled=trained.tuning.coupled,
            coupling_range=trained.tuning.coupling_range))
    base = run_dir / "evaluations"
    base.mkdir(exist_ok=True)
    n = 1 + max((int(p.name) for p in base.iterdir() if p.name.isdigit()), default=0)
    out_dir = base / str(n)
    out_dir.mkdir()
    fixed = json.loads((run_dir / "fixed_pid.json").read_text()) if (run_dir / "fixed_pid.json").is_file() else None
    write_text_atomic(out_dir / "scenario.yaml", scenario_to_yaml(scenario))
    evaluate_into(run_dir, scenario, out_dir, _policy(run_dir, trained.agent.algorithm), fixed)
    return out_dir


def export_schedule(run_dir: str | Path, output: str | Path, schedule_by: str = "setpoint", points: int = 9,
                    replay: bool = False) -> tuple[Path, dict | None]:
    """Write the tuned gain schedule CSV; with replay, run it as a plain PID and compare with the policy.

    Returns (csv path, comparison or None): comparison = {"policy": metrics, "schedule": metrics}.
    """
    from .evaluate import evaluate
    from .schedule import extract_schedule, replay_schedule, write_schedule_csv

    run_dir = Path(run_dir)
    scenario = _load_run(run_dir)
    policy = _policy(run_dir, scenario.agent.algorithm)
    schedule = extract_schedule(policy, scenario.tuning, schedule_by=schedule_by, points=points,
                                seed=scenario.agent.seed)
    path = write_schedule_csv(schedule, Path(output))
    if not replay:
        return path, None
    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    seed = scenario.evaluation.seed
    policy_m, _ = evaluate(policy, config, seed=seed, intervals=intervals)
    schedule_m, _ = replay_schedule(schedule, config, seed=seed, intervals=intervals)
    return path, {"policy": policy_m, "schedule": schedule_m}
