"""FMI quirks of real exporters, rebuilt as fault FMUs (plant_sources/common/faults.h): a reset that does not
reset, a segfault in reset, a stop time that refuses later steps, a step that never returns, a banner on
stdout, garbage outputs, a binary named otherwise. Each ends as issue 22 asks: the CLI in a subprocess,
exit code, stdout and files checked; the truth comes from the switches (their times), not from the code."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from prlpid_fmi.fmu import FmuPlant, build_fmu
from prlpid_fmi.fmu.plant import compare_runs
from test_faults import ENV, TS, scenario_file

HANG_S = 3.0          # the hang's communication point [s]
STOP_S = 3.0          # the stop-time FMU's DefaultExperiment stopTime [s]; the scenario's episodes last 5 s
TIMEOUT_S = 0.5       # plant.step_timeout_s / --step-timeout of these tests
FAULTS = {
    "hang": {"PRLPID_FAULT_HANG_AFTER_S": HANG_S, "PRLPID_FAULT_GATED": None},
    "reset_noop": {"PRLPID_FAULT_RESET_NOOP": None},
    "reset_crash_before_init": {"PRLPID_FAULT_CRASH_IN_RESET_BEFORE_INIT": None},
    "reset_crash": {"PRLPID_FAULT_CRASH_IN_RESET": None},
    "stop": {"PRLPID_FAULT_STOP_TIME": STOP_S},
    "banner": {"PRLPID_FAULT_BANNER": None},
    "denormal": {"PRLPID_FAULT_DENORMAL_AFTER_S": 0.5},
}


@pytest.fixture(scope="module")
def fault_fmus(tmp_path_factory):
    root = tmp_path_factory.mktemp("exporters")
    built = {name: build_fmu("FirstOrderUnstable", out_dir=root / name, defines=d) for name, d in FAULTS.items()}
    built["misnamed"] = build_fmu("FirstOrderUnstable", out_dir=root / "misnamed", binary_name="fou_20sim")
    return built


def run_cli(*args: str, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "prlpid_fmi", *args], capture_output=True, text=True,
                          env={**ENV, **(env or {})}, timeout=timeout)


def error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.startswith("prlpid-fmi: error:")]


def one_line_exit_2(proc: subprocess.CompletedProcess, *words: str) -> str:
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    lines = error_lines(proc.stderr)
    assert len(lines) == 1, proc.stderr[-3000:]
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


# -- a step that never returns -----------------------------------------------------------------------
def test_a_hang_in_process_ends_tune_with_one_line_and_keeps_the_run(fault_fmus, tmp_path):
    """The hang starts once the fixed PID is saved (the gate file opens it): tune ends within twice its step
    timeout, exit 2, one line naming the FMU, the call and the time; fixed_pid.json and the run stay, with the
    .active marker from which --resume runs the plant in a worker process (test_faults' segfault test)."""
    gate = tmp_path / "gate"
    scenario = scenario_file(tmp_path, fault_fmus["hang"], forecast_horizon=0,
                             plant={"step_timeout_s": TIMEOUT_S})
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "prlpid_fmi", "-q", "tune", str(scenario), "--out", str(run),
                             "--timesteps", "100000", "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**ENV, "PRLPID_FAULT_GATE": str(gate)})
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None and not (run / "fixed_pid.json").is_file():
        time.sleep(0.05)
    assert (run / "fixed_pid.json").is_file(), proc.communicate()[1][-3000:]
    gate.write_text("")
    opened = time.monotonic()
    out, err = proc.communicate(timeout=60)
    ended = time.monotonic() - opened
    done = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
    line = one_line_exit_2(done, "FirstOrderUnstable.fmu", "fmi2DoStep", f"did not return within {TIMEOUT_S:g} s",
                           str(run), "--resume")
    assert float(line.split("from t = ")[1].split(" s")[0]) >= HANG_S - 1e-9  # where the stage under way met it
    # Within twice the timeout of the hang, plus the time the run takes from the gate to t = 3 s of the next stage
    # (a second on an idle machine, more on a loaded CI runner); without the watchdog communicate() times out.
    assert ended <= 2 * TIMEOUT_S + 10.0
    assert (run / "scenario.yaml").is_file() and (run / "run.json").is_file() and (run / ".active").is_file()
    assert (run / "fixed_pid.json").is_file() and (run / "fixed_pid.csv").is_file()


def test_a_hang_in_a_worker_ends_the_episode_like_a_crash(fault_fmus, tmp_path, monkeypatch):
    """isolation: process: the worker's watchdog ends the worker; the episode ends with a crash termination
    naming the call and the time, within twice the timeout; the next reset gets a fresh worker."""
    from prlpid_fmi.loop.isolated import IsolatedCore
    from prlpid_fmi.scenario.load import load_scenario

    import os

    from prlpid_fmi.fmu.worker import call_in_worker

    call_in_worker(os.getpid)  # workers fork from a server started once per process, here before the variable is set:
    gate = tmp_path / "gate"   # the worker must still see the caller's environment (fmu.worker.become_worker)
    gate.write_text("")
    monkeypatch.setenv("PRLPID_FAULT_GATE", str(gate))
    config = load_scenario(scenario_file(tmp_path, fault_fmus["hang"], forecast_horizon=0,
                                         plant={"step_timeout_s": TIMEOUT_S, "isolation": "process"})).tuning
    core = IsolatedCore(config)
    try:
        core.reset(np.random.default_rng(0))
        started, terminated = time.monotonic(), False
        for _ in range(200):  # Kp 3, Ti 1 on 1/(s - 1): well damped, so only the hang can end the episode
            _, terminated = core.step([3.0], [1.0], [0.0])
            if terminated:
                break
        assert time.monotonic() - started <= 2 * TIMEOUT_S + 3.0  # + the steps before t = 3 s on a loaded runner
        term = core.termination
        assert term.kind == "crash" and abs(term.time_s - HANG_S) <= TS / 2
        assert "fmi2DoStep from t = 3 s did not return within 0.5 s" in term.message
        gate.unlink()
        core.reset(np.random.default_rng(0))
        for _ in range(40):
            core.step([3.0], [1.0], [0.0])
        assert core.termination is None and core.crashes == 1
    finally:
        core.close()


def test_probe_and_init_of_a_hanging_fmu_end_with_one_line_and_nothing_on_stdout(fault_fmus, tmp_path):
    gate = tmp_path / "gate"
    gate.write_text("")
    for command in ("init", "probe"):
        started = time.monotonic()
        proc = run_cli(command, str(fault_fmus["hang"]), "--step-timeout", str(TIMEOUT_S),
                       *(["--plot", str(tmp_path / "p.png")] if command == "probe" else []),
                       env={"PRLPID_FAULT_GATE": str(gate)})
        one_line_exit_2(proc, "FirstOrderUnstable.fmu", "fmi2DoStep", "did not return within 0.5 s")
        assert proc.stdout == "" and time.monotonic() - started < 30
    assert not (tmp_path / "p.png").exists()


# -- stdout banners and garbage ------------------------------------------------------------------------
def test_init_keeps_the_fmus_banner_out_of_the_yaml(fault_fmus, tmp_path):
    proc = run_cli("init", str(fault_fmus["banner"]))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "fault switch banner" not in proc.stdout and "fault switch banner" in proc.stderr  # printf: stderr
    doc = yaml.safe_load(proc.stdout)
    assert doc["plant"]["loops"][0]["output"] == "y"


def test_garbage_outputs_end_probe_and_init_with_one_line(fault_fmus, tmp_path):
    for command in ("probe", "init"):
        proc = run_cli(command, str(fault_fmus["denormal"]), *(["--plot", str(tmp_path / "p.png")]
                                                                if command == "probe" else []))
        line = one_line_exit_2(proc, "FirstOrderUnstable.fmu", "fmi2DoStep", "garbage", "denormal")
        assert "t = 0.5 s" in line and proc.stdout == ""


def test_inspect_probe_names_a_denormal_output(fault_fmus):
    proc = run_cli("inspect", "--probe", str(fault_fmus["denormal"]))
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert any(line.startswith("FAIL  outputs") and "denormal" in line for line in proc.stdout.splitlines())


# -- resets ----------------------------------------------------------------------------------------------
def _episodes(config, n: int = 3) -> list[np.ndarray]:
    """n fixed-PID episodes on one loop core (reset between them): the measurements of each."""
    from prlpid_fmi.loop.evaluation import constant_gains, gains_rollout
    from prlpid_fmi.loop.isolated import make_core

    core = make_core(config)
    try:
        return [np.asarray(gains_rollout(constant_gains(3.0, 1.0, 0.05), config, seed=1, core=core)["measurement"])
                for _ in range(n)]
    finally:
        core.close()


def _config(tmp_path, fmu, **plant):
    from prlpid_fmi.scenario.load import load_scenario

    return load_scenario(scenario_file(tmp_path, fmu, forecast_horizon=0, plant=plant)).tuning


def test_a_reset_that_does_nothing_is_found_once_and_every_episode_instantiates_afresh(fault_fmus, tmp_path):
    path = fault_fmus["reset_noop"]
    with FmuPlant(path, ["u"], ["y"], TS, {"a": -1.0}) as plant:
        verdict = plant.check_reset()
        assert verdict.startswith("after fmi2Reset y stays at 0") and verdict.endswith("frozen")
    with pytest.warns(UserWarning, match="does not restore the start .*frozen.*instantiates the FMU afresh"):
        episodes = _episodes(_config(tmp_path, path))
    reference = _episodes(_config(tmp_path, "FirstOrderUnstable"), 1)[0]  # the same plant, a sound reset
    for measured in episodes:
        assert np.array_equal(measured, reference) and np.ptp(measured) > 0


def test_frozen_is_judged_against_the_inputs_change_never_a_slow_plant():
    moving = np.linspace(0.0, 1e-9, 12)[:, None]  # a slow plant: tiny, but it moves the same way twice
    assert compare_runs(["y"], ["u"], moving, moving.copy(), "fmi2Reset") == "ok"
    assert compare_runs(["y"], ["u"], moving, np.zeros_like(moving), "fmi2Reset").endswith("frozen")
    assert "differs" in compare_runs(["y"], ["u"], moving, moving + 1.0, "fmi2Reset")


def test_a_fresh_instance_is_never_reset_before_it_ran(fault_fmus, tmp_path):
    """The 20-sim 4.7 crane segfaults in a reset before the first initialisation (here: in a subprocess, so a
    segfault would show as its exit code): episodes, probe and init all run."""
    code = ("import sys; sys.path.insert(0, 'tests'); from pathlib import Path; "
            "from test_fmu_faults_exporters import _config, _episodes; "
            f"e = _episodes(_config(Path({str(tmp_path)!r}), {str(fault_fmus['reset_crash_before_init'])!r})); "
            "print(len(e))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=120,
                          cwd=Path(__file__).parent.parent)
    assert proc.returncode == 0 and proc.stdout.strip() == "3", proc.stderr[-3000:]
    assert run_cli("init", str(fault_fmus["reset_crash_before_init"])).returncode == 0


def test_a_reset_that_crashes_a_worker_is_blamed_on_the_reset_and_replaced_by_fresh_instances(fault_fmus,
                                                                                              tmp_path):
    """isolation: process: the reset check crashes the worker in fmi2Reset; the parent says so (not "while
    being instantiated"), remembers it, and the next worker instantiates afresh for every episode."""
    config = _config(tmp_path, fault_fmus["reset_crash"], isolation="process")
    with pytest.warns(UserWarning, match=r"crashed \(SIGSEGV\) in fmi2Reset at t = .*instantiates the FMU afresh"):
        episodes = _episodes(config)
    reference = _episodes(_config(tmp_path, "FirstOrderUnstable"), 1)[0]
    assert all(np.array_equal(m, reference) for m in episodes)


# -- the stop time --------------------------------------------------------------------------------------
def test_a_stop_time_is_set_up_so_the_fmu_accepts_every_step_and_its_error_is_shown_in_full(fault_fmus, tmp_path):
    path = fault_fmus["stop"]
    with FmuPlant(path, ["u"], ["y"], TS, {"a": -1.0}) as plant:  # no stop time set up: the FMU's 3 s holds
        assert plant.description.default_stop_time_s == STOP_S
        with pytest.raises(Exception) as refused:
            for _ in range(100):
                plant.step([0.1])
    text = str(refused.value)
    assert "fmi2DoStep from t = 3 s returned error: Exceeded model finish time: 3.1 > 3" in text
    assert "DefaultExperiment stopTime is 3 s" in text
    with FmuPlant(path, ["u"], ["y"], TS, {"a": -1.0}, stop_time_s=6.0) as plant:
        for _ in range(60):
            plant.step([0.1])
        assert plant.time == pytest.approx(6.0)
    config = _config(tmp_path, path)   # episodes of 5 s: the loop sets up its stop time
    assert config.episode_steps * TS > STOP_S
    episodes = _episodes(config, 2)
    assert all(len(m) == config.episode_steps + 1 for m in episodes)


# -- binaries --------------------------------------------------------------------------------------------
def test_a_binary_named_otherwise_gets_the_rename_hint(fault_fmus):
    proc = run_cli("probe", str(fault_fmus["misnamed"]))
    line = one_line_exit_2(proc, "rename binaries/linux64/fou_20sim.so to binaries/linux64/FirstOrderUnstable.so")
    assert "fmpy compile" not in line


def test_sigterm_during_a_call_that_never_returns_ends_the_process_with_one_line(fault_fmus, tmp_path):
    """The Python handler never runs during the C call; the watchdog sees the signal's wakeup byte and, the call
    still under way SIGNAL_GRACE_S later, ends the process with 128 + SIGTERM."""
    from prlpid_fmi.fmu.watchdog import SIGNAL_GRACE_S

    gate = tmp_path / "gate"
    gate.write_text("")
    code = ("import signal; from prlpid_fmi.errors import Interrupted\n"
            "def h(s, f): raise Interrupted(s)\n"
            "signal.signal(signal.SIGTERM, h)\n"
            "from prlpid_fmi.fmu import FmuPlant\n"
            f"p = FmuPlant({str(fault_fmus['hang'])!r}, ['u'], ['y'], 0.1, {{'a': -1.0}}, step_timeout_s=60)\n"
            "print('ready', flush=True)\n"
            "[p.step([0.1]) for _ in range(100)]\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**ENV, "PRLPID_FAULT_GATE": str(gate)})
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(0.5)
    sent = time.monotonic()
    proc.terminate()
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 128 + 15 and time.monotonic() - sent <= SIGNAL_GRACE_S + 5.0  # a loaded runner's exit
    lines = error_lines(err)
    assert len(lines) == 1 and "interrupted by SIGTERM while FirstOrderUnstable.fmu: fmi2DoStep from t = 3 s" in lines[0]
