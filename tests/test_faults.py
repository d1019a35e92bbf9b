"""Misbehaving FMUs (plant_sources/common/faults.h, compiled in by -D switches), signals and resume.

Each FMU is the bundled first-order plant dx/dt = x + u with one fault from t = FAULT_S on; the
truth each test checks comes from the switch (its time, its kind), not from the code under test.
"""
from __future__ import annotations

import dataclasses
import json
import os
import re
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

from prlpid_fmi.cli import main
from prlpid_fmi.loop.core import LoopCore
from prlpid_fmi.loop.evaluation import constant_gains, gains_rollout
from prlpid_fmi.fmu import FmuPlant, build_fmu, describe_fmu, format_description
from prlpid_fmi.fmu.plant import rss_bytes
from prlpid_fmi.scenario.load import load_scenario

FAULT_S = 3.0
TS = 0.1
LEAK_BYTES = 1 << 20
FAULTS = {  # name: (C switches, modelDescription flags)
    "nan": ({"PRLPID_FAULT_NAN_AFTER_S": FAULT_S}, {}),
    "discard": ({"PRLPID_FAULT_DISCARD_AFTER_S": FAULT_S}, {}),
    "crash": ({"PRLPID_FAULT_CRASH_AFTER_S": FAULT_S}, {}),
    "no_state": ({"PRLPID_FAULT_NO_STATE": None}, {"canGetAndSetFMUstate": False, "canSerializeFMUstate": False}),
    "no_serialize": ({"PRLPID_FAULT_NO_SERIALIZE": None}, {"canSerializeFMUstate": False}),
    "once": ({"PRLPID_FAULT_ONCE_PER_PROCESS": None}, {"canBeInstantiatedOnlyOncePerProcess": True}),
    "leak": ({"PRLPID_FAULT_RESET_LEAK_BYTES": LEAK_BYTES}, {}),
}
ENV = {**os.environ, "PYTHONFAULTHANDLER": ""}


@pytest.fixture(scope="module")
def faulty(tmp_path_factory):
    """{fault: FMU path}, each built once per test module."""
    root = tmp_path_factory.mktemp("faulty")
    return {name: build_fmu("FirstOrderUnstable", out_dir=root / name, defines=d, capabilities=c)
            for name, (d, c) in FAULTS.items()}


def scenario_file(folder: Path, fmu, **plant) -> Path:
    """A tiny first-order scenario on `fmu` (episodes of 50 samples, so a fault at 3 s hits every one)."""
    doc = {
        "name": "faulty",
        "plant": {"fmu": str(fmu), "sample_time": TS, "parameters": {"a": 1.0}, **plant.pop("plant", {}),
                  "loops": [{"input": "u", "output": "y", "u_limits": [-10, 10], "setpoint_range": [-1, 1],
                             "measurement_scale": 1.0, "divergence_bound": 5.0,
                             "gains": {"Kp": [0.5, 30, "log"], "Ti": [0.2, 20, "log"], "Td": [0.0, 0.2, "linear"]}}]},
        "strategies": {"forecast_horizon": plant.pop("forecast_horizon", 3)},
        "agent": {"algorithm": "ppo", "total_timesteps": 256, "seed": 0, "n_envs": plant.pop("n_envs", 1),
                  "n_steps": 128, "batch_size": 64, "n_epochs": 1},
        "training": {"episode_steps": 50, "setpoint_hold_steps": 25},
        "evaluation": {"episode_steps": 50, "setpoints": [{"at_step": 0, "value": 0.5}], "intervals": [[0, 25], [25, 50]]},
        "baseline": {"episodes": 1, "maxiter": 1, "popsize": 2},
        # three rows per candidate gain schedule (9 by default): each row is a margin experiment, and the schedule
        # stage was most of every tune here; what these tests check is the fault handling around it
        "deploy": {"schedule_points": 3},
    }
    path = folder / "scenario.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prlpid_fmi", *args], capture_output=True, text=True, env=ENV,
                          timeout=600)


def complete(run_dir: Path) -> None:
    for name in ("metrics.json", "report.md", "gains.csv", "response.png", "learning_curve.png", "model.zip",
                 "fixed_pid.json"):
        assert (run_dir / name).is_file(), name


@pytest.mark.parametrize("fault", ["nan", "discard"])
def test_tune_and_evaluate_end_early_with_a_reason(faulty, tmp_path, fault, capsys):
    run = tmp_path / "run"
    assert main(["-q", "tune", str(scenario_file(tmp_path, faulty[fault])), "--out", str(run)]) == 0
    complete(run)
    metrics = json.loads((run / "metrics.json").read_text())
    for who in (metrics["policy"], metrics["fixed_pid"]["metrics"]):
        t = who["termination"]
        assert t["kind"] == fault
        assert FAULT_S - 1e-9 <= t["time_s"] <= FAULT_S + TS + 1e-9  # the switch's time, to one sample
        assert t["step"] == round(t["time_s"] / TS) + (1 if fault == "discard" else 0)
        # metrics cover the samples before the failure: the first interval whole, the second cut at its end
        first, second = who["intervals"]
        assert (first["start_step"], first["end_step"]) == (0, 25) and "requested_end_step" not in first
        assert second["end_step"] == t["step"] and second["requested_end_step"] == 50
        assert np.isfinite(who["overall"]["ISE"])
    assert metrics["deployed"] in ("none", "fixed PID", "gain schedule")
    assert not metrics["fixed_pid_assessment"]["metrics"]["terminated"] or metrics["deployed"] != "fixed PID"
    report = (run / "report.md").read_text()
    assert "ended early" in report and f"t = {metrics['policy']['termination']['time_s']:g} s" in report
    assert main(["-q", "evaluate", str(run)]) == 0
    again = json.loads((run / "evaluations" / "1" / "metrics.json").read_text())
    assert again["policy"]["termination"]["kind"] == fault
    assert "Traceback" not in capsys.readouterr().err


def test_a_forecast_on_an_fmu_without_state_is_one_line_and_without_it_a_complete_run(faulty, tmp_path, capsys):
    refused = scenario_file(tmp_path, faulty["no_state"])
    assert main(["validate", str(refused)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "strategies.forecast_horizon" in err[0] and "canGetAndSetFMUstate" in err[0]
    (tmp_path / "n0").mkdir()
    run = tmp_path / "run"
    assert main(["-q", "tune", str(scenario_file(tmp_path / "n0", faulty["no_state"], forecast_horizon=0)),
                 "--out", str(run)]) == 0
    complete(run)
    assert main(["-q", "evaluate", str(run)]) == 0


def test_rollback_prior_leaves_the_plant_bit_identical_and_forecasts_like_a_copy(faulty, tmp_path):
    """An FMU that cannot serialize its state forecasts on its own instance (hold, roll N, restore): the plant's
    trajectory equals the one without a forecast bit for bit, and every forecast equals the one a second
    instance of the regular plant computes through the FMI path."""
    base = load_scenario(scenario_file(tmp_path, "FirstOrderUnstable")).tuning
    base = dataclasses.replace(base, measurement_noise_std=0.01, episode_steps=25)  # before the fault time
    gains = constant_gains(3.0, 1.0, 0.05)
    for fault in ("no_serialize", "once"):
        config = dataclasses.replace(base, fmu=str(faulty[fault]))
        core = LoopCore(config)
        assert core.prior is core.plant
        with_forecast = gains_rollout(gains, config, seed=4, core=core)
        core.close()
        without = gains_rollout(gains, dataclasses.replace(config, forecast_horizon=0), seed=4)
        for key in ("measurement", "control_signal", "pid_output"):
            assert np.array_equal(with_forecast[key], without[key]), key

        copy_core, roll_core = LoopCore(base, forecast_path="fmi"), LoopCore(config)
        assert copy_core.prior is not copy_core.plant
        forecasts = []
        for core in (copy_core, roll_core):
            core.reset(np.random.default_rng(7))
            forecasts.append([])
            for _ in range(20):
                core.step([3.0], [1.0], [0.05])
                forecasts[-1].append(core.forecast_reward)
            core.close()
        assert forecasts[0] == forecasts[1]
        text = format_description(describe_fmu(faulty[fault]))
        assert "As prior     yes: single-instance rollback" in text


def test_once_per_process_is_read_and_training_runs_one_instance_per_process(faulty, tmp_path, capsys):
    d = describe_fmu(faulty["once"])
    assert d.once_per_process and d.prior_mode == "rollback"
    with FmuPlant(faulty["once"], ["u"], ["y"], TS):
        with pytest.raises(Exception, match="only one instance"):
            FmuPlant(faulty["once"], ["u"], ["y"], TS)
    run = tmp_path / "run"
    assert main(["-q", "tune", str(scenario_file(tmp_path, faulty["once"], n_envs=2)), "--out", str(run)]) == 0
    complete(run)
    assert main(["-q", "evaluate", str(run)]) == 0


def test_leak_guard_reinstantiates_an_fmu_whose_resets_grow(faulty, tmp_path):
    """Each reset of this FMU keeps 1 MB until the instance is freed: without the guard 60 resets hold 60 MB,
    with a check every 10 resets and a 4 MB limit the memory stays near 10 MB and a warning says why. (Each
    episode takes a step: an instance that has not moved since it was made or reset is not reset again.)"""
    config = load_scenario(scenario_file(tmp_path, faulty["leak"], plant={"leak_check_every": 0})).tuning
    core = LoopCore(config)
    start = rss_bytes()
    for _ in range(60):
        core.reset(np.random.default_rng(0))
        core.step([1.0], [1.0], [0.0])
    unguarded = rss_bytes() - start
    core.close()
    core = LoopCore(dataclasses.replace(config, leak_check_every=10, leak_limit_mb=4.0))
    start = rss_bytes()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(60):
            core.reset(np.random.default_rng(0))
            core.step([1.0], [1.0], [0.0])
    guarded = rss_bytes() - start
    # how often depends on whether glibc hands freed blocks back to the OS (its mmap threshold adapts),
    # so the bound that matters is on the memory held, below; at least one re-instantiation must happen
    assert core.plant.reinstantiations >= 1
    assert any("instantiated afresh" in str(w.message) for w in caught)
    core.close()
    assert unguarded >= 30 * LEAK_BYTES  # 60 MB kept; RSS shows at least half of it (allocator reuse varies)
    assert guarded <= 20 * LEAK_BYTES
    run = tmp_path / "run"
    assert main(["-q", "tune", str(scenario_file(tmp_path, faulty["leak"])), "--out", str(run)]) == 0
    complete(run)


def error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("prlpid-fmi: error:")]


def test_a_segfault_on_the_first_run_isolates_the_plant_and_repeated_faults_stop_training(faulty, tmp_path):
    """`tune` as written on an FMU that segfaults in doStep from 3 s, first run: the loop check's worker crashes, so
    the plant runs in a worker process for the rest of the run (one warning; run.json); every training episode then
    ends at that crash, so training stops after REPEATED_FAULT_EPISODES of them (one line; run.json; the report),
    and the run finishes: exit 0, a complete run directory, never a signal exit."""
    from prlpid_fmi.tuning.agent import REPEATED_FAULT_EPISODES

    scenario = scenario_file(tmp_path, faulty["crash"])
    run = tmp_path / "run"
    first = cli("-q", "tune", str(scenario), "--out", str(run), "--timesteps", "5000")
    assert first.returncode == 0, first.stderr[-3000:]
    assert "Traceback" not in first.stderr and not error_lines(first.stderr)
    complete(run)
    assert not (run / ".active").exists()
    info = json.loads((run / "run.json").read_text())
    assert info["isolation"] == "process"
    assert "crashed (SIGSEGV) in fmi2DoStep from t = 3 s" in info["isolation_reason"]  # the switch's time
    assert "loop check" in info["isolation_reason"]
    switched = [line for line in first.stderr.splitlines() if "for the rest of this run" in line]
    assert len(switched) == 1
    stopped = [line for line in first.stderr.splitlines() if "training stopped early" in line]
    assert len(stopped) == 1 and f"{REPEATED_FAULT_EPISODES} training episodes in a row" in stopped[0]
    record = info["training_stopped"]
    assert record["episodes"] == REPEATED_FAULT_EPISODES and record["termination"]["kind"] == "crash"
    # the truth: the crash at 3 s, reached by the plant, or N = 3 samples earlier by the forecast's prior
    t = record["termination"]["time_s"]
    assert FAULT_S - 3 * TS - 1e-9 <= t <= FAULT_S + TS + 1e-9
    # the Monitor's episode lengths: the last REPEATED_FAULT_EPISODES episodes all ended at that sample
    lengths = [int(row.split(",")[1]) for row in _monitor_rows(run)]
    assert lengths[-REPEATED_FAULT_EPISODES:] == [record["termination"]["step"]] * REPEATED_FAULT_EPISODES
    assert info["trained_timesteps"] == record["steps"] < 5000
    assert "Training stopped early" in (run / "report.md").read_text()
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["policy"]["termination"]["kind"] == "crash"
    evaluated = cli("-q", "evaluate", str(run))
    assert evaluated.returncode == 0 and "Traceback" not in evaluated.stderr, evaluated.stderr[-2000:]


def test_a_crashing_prior_in_the_tools_own_process_is_survived_and_replaced_by_the_rollback_prior(tmp_path):
    """An FMU whose second instance (the forecast's prior) crashes in doStep; nothing before training has a prior, so
    no worker saw the crash first: it kills the process running `tune` (in-process plant). The supervising parent
    resumes the run with the plant in a worker process (one warning naming the FMU, the call and the time); there
    every training episode ends at the prior's first step, so after REPEATED_FAULT_EPISODES of them the prior is
    blamed (the worker's crumb names it; the plant alone passes that time) and replaced by the rollback prior (the
    plant's own instance), and training completes. Exit 0, a complete run directory, never a signal exit."""
    from prlpid_fmi.tuning.agent import REPEATED_FAULT_EPISODES

    fmu = build_fmu("FirstOrderUnstable", out_dir=tmp_path / "fmu", defines={"PRLPID_FAULT_CRASH_IN_PRIOR": None})
    run = tmp_path / "run"
    first = cli("-q", "tune", str(scenario_file(tmp_path, fmu)), "--out", str(run))
    assert first.returncode == 0, first.stderr[-3000:]
    assert "Traceback" not in first.stderr and not error_lines(first.stderr)
    complete(run)
    info = json.loads((run / "run.json").read_text())
    assert info["isolation"] == "process" and "training_stopped" not in info
    reason = info["isolation_reason"]
    assert "FirstOrderUnstable.fmu crashed (SIGSEGV) in fmi2DoStep from t = 0 s of the forecast's prior" in reason
    assert "the tool's process" in reason
    assert sum("the run continues from its last checkpoint" in line for line in first.stderr.splitlines()) == 1
    assert info["prior_fallback"] == "rollback" and info["trained_timesteps"] >= 256
    assert sum("the forecast's prior (the FMU's second instance) crashes" in line
               for line in first.stderr.splitlines()) == 1
    # the truth: the prior crashes at its first step, so the episodes before the fallback lasted one sample; after
    # it none ends early (Kp, Ti of the fixed PID on 1/(s - 1), a fault-free plant instance)
    lengths = [int(row.split(",")[1]) for row in _monitor_rows(run)]
    assert lengths[:REPEATED_FAULT_EPISODES] == [1] * REPEATED_FAULT_EPISODES
    assert "Training stopped early" not in (run / "report.md").read_text()


def test_a_segfault_that_kills_the_resumed_run_too_is_one_line_and_exit_2(faulty, tmp_path):
    """plant.isolation: none keeps the crashing plant in the tool's process: the first run dies, the parent resumes
    it, that dies too: exit 2, one line naming the FMU, the call, the time and the run directory kept."""
    run = tmp_path / "run"
    failed = cli("-q", "tune", str(scenario_file(tmp_path, faulty["crash"], plant={"isolation": "none"})),
                 "--out", str(run))
    assert failed.returncode == 2, failed.stderr[-3000:]
    lines = error_lines(failed.stderr)
    assert len(lines) == 1 and "Traceback" not in failed.stderr, failed.stderr[-3000:]
    assert "FirstOrderUnstable.fmu crashed (SIGSEGV) in fmi2DoStep from t = 3 s" in lines[0]  # the switch's time
    assert "the tool's process" in lines[0] and f"the run directory {run} is kept" in lines[0]
    assert (run / "scenario.yaml").is_file() and (run / ".active").is_file()


def test_init_and_probe_survive_a_crash_and_the_scenario_isolates_the_plant(faulty, tmp_path):
    """init as written on an FMU that segfaults in doStep from 3 s: its worker crashes, the probe runs again with each
    run in a worker of its own, cut at the crash; the scenario it proposes has plant.isolation: process with the crash
    in its comment, loads, and its sample time follows the growth rate λ = a of dx/dt = a x + b u (here a = 2:
    1/(10 λ) = 0.05 s, snapped to 1-2-5). A crash too early to measure anything is exit 2 and one line naming it."""
    proc = cli("init", str(faulty["crash"]), "--set", "a=2")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr
    path = tmp_path / "init.yaml"
    path.write_text(proc.stdout)
    plant = yaml.safe_load(proc.stdout)["plant"]
    assert plant["isolation"] == "process" and plant["parameters"] == {"a": 2.0}
    line = next(line for line in proc.stdout.splitlines() if line.strip().startswith("isolation:"))
    assert "# FirstOrderUnstable.fmu crashed (SIGSEGV) in fmi2DoStep from t = 3 s" in line
    assert plant["sample_time"] == pytest.approx(0.05)
    scenario = load_scenario(path)
    assert scenario.tuning.isolation == "process"
    probe = cli("probe", str(faulty["crash"]), "--set", "a=2", "--plot", str(tmp_path / "p.png"))
    assert probe.returncode == 0, probe.stderr[-3000:]
    rate = float(re.search(r"λ = ([0-9.]+) 1/s", probe.stdout).group(1))
    assert rate == pytest.approx(2.0, rel=0.02)
    assert any("crashed (SIGSEGV)" in line and "plant.isolation: process" in line for line in probe.stdout.splitlines())
    early = build_fmu("FirstOrderUnstable", out_dir=tmp_path / "early", defines={"PRLPID_FAULT_CRASH_AFTER_S": 0.0})
    failed = cli("init", str(early))
    assert failed.returncode == 2 and failed.stdout == "", failed.stderr[-3000:]
    lines = error_lines(failed.stderr)
    assert len(lines) == 1 and "Traceback" not in failed.stderr, failed.stderr[-3000:]
    assert "crashed (SIGSEGV) in fmi2DoStep from t = 0 s" in lines[0]


def _monitor_rows(run: Path) -> list[str]:
    return [line for line in (run / "monitor" / "0.monitor.csv").read_text().splitlines()[2:] if line]


def test_sigterm_saves_a_checkpoint_and_resume_completes_to_the_target(tmp_path):
    scenario = scenario_file(tmp_path, "FirstOrderUnstable")
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "prlpid_fmi", "-q", "tune", str(scenario), "--out", str(run),
                             "--timesteps", "1000000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=ENV)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if (run / "monitor" / "0.monitor.csv").is_file() and len(_monitor_rows(run)) >= 12:
            break
        time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGTERM, err[-2000:]
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "interrupted by SIGTERM" in lines[0] and "--resume" in lines[0]
    checkpoints = sorted((run / "checkpoints").glob("model_*_steps.zip"))
    assert checkpoints
    done = max(int(p.stem.split("_")[1]) for p in checkpoints)
    before = _monitor_rows(run)
    assert done >= 12 * 50 and len(before) >= 12
    target = done + 300
    resumed = cli("-q", "tune", str(scenario), "--out", str(run), "--resume", "--timesteps", str(target))
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    trained = json.loads((run / "run.json").read_text())["trained_timesteps"]
    assert target <= trained < target + 128  # PPO collects whole rollouts of n_steps = 128
    after = _monitor_rows(run)
    assert after[:len(before)] == before and len(after) >= len(before) + 300 // 50 - 1
    # a damaged checkpoint: one line naming it
    (run / "checkpoints" / f"model_{10 * target}_steps.zip").write_bytes(b"not a zip")
    damaged = cli("tune", str(scenario), "--out", str(run), "--resume", "--timesteps", str(20 * target))
    assert damaged.returncode == 2
    err = [line for line in damaged.stderr.splitlines() if line.strip()]
    assert len(err) == 1 and f"model_{10 * target}_steps.zip: cannot resume from this checkpoint" in err[0]


def test_inspect_probe_gives_one_line_per_finding_with_a_verdict(faulty, capsys):
    from prlpid_fmi.fmu.dynamic_check import dynamic_check

    assert main(["inspect", "--probe", str(faulty["crash"])]) == 1  # the run to 4 s passes the crash at 3 s
    out = capsys.readouterr()
    probe = out.out.split("Dynamic checks (--probe):\n")[1].splitlines()
    assert all(line.split()[0] in ("PASS", "FAIL", "WARN", "SKIP") for line in probe)
    assert any(line.startswith("FAIL  state") and "crashed (SIGSEGV)" in line for line in probe)
    assert "Traceback" not in out.err

    by_check = {(f.check, f.verdict): f.message for f in dynamic_check(faulty["nan"])}
    assert "y is NaN at t = 3 s" in by_check[("outputs", "FAIL")]
    assert ("state", "PASS") in by_check and ("reset", "PASS") in by_check and ("instances", "PASS") in by_check

    leak = {f.check: f for f in dynamic_check(faulty["leak"])}
    assert leak["memory"].verdict == "WARN"
    per_reset_kb = float(leak["memory"].message.split("(")[1].split(" kB")[0])
    assert 0.9 * LEAK_BYTES / 1024 <= per_reset_kb <= 1.2 * LEAK_BYTES / 1024  # the switch's 1 MB per reset


def test_an_isolated_loop_gives_the_same_trajectories_as_in_process(tmp_path):
    """The worker draws the episode's setpoints and noise from the generator's state it is handed: policy
    rollouts with the forecast and fixed-gain rollouts are bit-identical isolated or not, episode after episode."""
    from prlpid_fmi.loop.env import PidTuningEnv
    from prlpid_fmi.loop.isolated import IsolatedCore

    config = dataclasses.replace(load_scenario(scenario_file(tmp_path, "FirstOrderUnstable")).tuning,
                                 measurement_noise_std=0.02)
    runs = {}
    for isolation in ("none", "process"):
        env = PidTuningEnv(dataclasses.replace(config, isolation=isolation), info=False)
        assert isinstance(env.core, IsolatedCore) == (isolation == "process")
        obs, _ = env.reset(seed=5)
        rows = []
        for episode in range(2):  # the second episode continues the same generator
            for k in range(config.episode_steps):
                obs, reward, terminated, truncated, _ = env.step(np.sin([0.3 * k, 0.2 * k, 0.1 * k]))
                rows.append((*obs, reward, env.core.forecast_reward))
                if terminated or truncated:
                    break
            obs, _ = env.reset()
        env.close()
        runs[isolation] = np.array(rows, float)
    assert np.array_equal(runs["none"], runs["process"])
