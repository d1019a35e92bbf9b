"""CLI conventions and run-file safety: --version, python -m, -q, bundled scenario names, progress on
stderr, file modes, and arguments that must never lose or overwrite a run's files (one line, exit 2)."""
import errno
import io
import json
import os
import shutil
import stat
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
import yaml

from prlpid_fmi import rundir
from prlpid_fmi.cli import main
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.bundled import SCENARIO_DIR
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.progress import Progress, format_duration, stage
from prlpid_fmi.run.export import export_schedule
from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv
from test_cli import _small_copy

BUNDLED = sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("prlpid-fmi")
    return lines[0]


def _tree(path: Path) -> dict:
    """{relative path: (size, mtime_ns)} of every file under path."""
    return {str(p.relative_to(path)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in sorted(path.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    """A tiny finished run (first_order, a token training budget, a token fixed-PID search)."""
    base = tmp_path_factory.mktemp("run")
    scenario = _small_copy(scenario_path("first_order"), base / "s.yaml")
    run = base / "run"
    old = os.umask(0o022)
    try:
        assert main(["-q", "tune", str(scenario), "--timesteps", "256", "--out", str(run)]) == 0
    finally:
        os.umask(old)
    return run


# -- version, module entry point, quiet ------------------------------------------------------------
def test_version_matches_the_installed_distribution(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"prlpid-fmi {metadata.version('prlpid-fmi')}"


def test_python_dash_m_runs_the_cli(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "prlpid_fmi", "--version"], capture_output=True, text=True,
                          cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout.strip() == f"prlpid-fmi {metadata.version('prlpid-fmi')}"
    proc = subprocess.run([sys.executable, "-m", "prlpid_fmi", "validate", "nonexistent_name"],
                          capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr


@pytest.mark.parametrize("argv", [["-q", "validate", "first_order"], ["validate", "first_order", "-q"],
                                  ["validate", "--quiet", "first_order"]])
def test_quiet_prints_nothing_on_success(argv, capsys):
    assert main(argv) == 0
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""


def test_without_quiet_validate_says_ok(capsys):
    assert main(["validate", "first_order"]) == 0
    assert capsys.readouterr().out.startswith(f"{SCENARIO_DIR / 'first_order.yaml'}: ok: first_order")


def test_a_bad_argument_is_one_line(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["tune", "first_order", "--timesteps", "many"])
    assert exit_.value.code == 2
    assert "--timesteps" in _one_error_line(capsys)


# -- bundled scenario names ------------------------------------------------------------------------
def test_bundled_scenarios_are_named_from_any_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert "first_order" in BUNDLED and "two_tank" in BUNDLED
    for name in BUNDLED:
        assert main(["validate", name]) == 0
        assert ": ok: " in capsys.readouterr().out


def test_an_existing_path_wins_over_a_bundled_name(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    doc = yaml.safe_load(scenario_path("first_order").read_text())
    doc["name"] = "local_copy"
    Path("first_order").write_text(yaml.safe_dump(doc))
    assert main(["validate", "first_order"]) == 0
    assert capsys.readouterr().out.startswith("first_order: ok: local_copy")


def test_an_unknown_name_lists_the_bundled_ones(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for argv in (["validate", "frist_order"], ["tune", "frist_order", "--out", "r"]):
        assert main(argv) == 2
        line = _one_error_line(capsys)
        assert line.startswith("prlpid-fmi: error: frist_order: ") and ", ".join(BUNDLED) in line
    assert list(tmp_path.iterdir()) == []


# -- refused starts leave nothing behind -----------------------------------------------------------
@pytest.mark.parametrize("extra, option", [(["--timesteps", "0"], "--timesteps"), (["--timesteps", "-5"], "--timesteps"),
                                           (["--seed", "-1"], "--seed"), (["--seed", str(2**32)], "--seed")])
def test_bad_numbers_are_refused_before_anything_is_created(extra, option, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    for out in ([], ["--out", "deep/run"]):
        assert main(["tune", "first_order", *out, *extra]) == 2
        line = _one_error_line(capsys)
        assert option in line and extra[1] in line
    assert list(tmp_path.iterdir()) == []


def test_bad_numbers_in_a_real_process(tmp_path):
    for extra in (["--timesteps", "0"], ["--seed", "-1"]):
        proc = subprocess.run([sys.executable, "-m", "prlpid_fmi", "tune", "first_order", *extra],
                              capture_output=True, text=True, cwd=tmp_path)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_out_naming_an_existing_file_is_one_line_and_the_file_is_kept(tmp_path, capsys):
    target = tmp_path / "notes.txt"
    target.write_text("mine")
    for resume in ([], ["--resume"]):
        assert main(["tune", "first_order", "--out", str(target), "--timesteps", "8", *resume]) == 2
        assert f"{target}: is a file" in _one_error_line(capsys)
    assert target.read_text() == "mine" and sorted(tmp_path.iterdir()) == [target]


def test_a_start_refused_after_the_directory_was_made_removes_it(tmp_path, monkeypatch, capsys):
    """A user error raised after prepare_run_dir, before any result, removes the folders it created."""
    import prlpid_fmi.tuning.design_rule

    def refuse(*args, **kwargs):
        raise PrlPidError("plant.fmu: FirstOrderUnstable: output y is NaN at t = 0.1 s")

    monkeypatch.setattr(prlpid_fmi.tuning.design_rule, "tune_fixed_pid", refuse)
    scenario = _small_copy(scenario_path("first_order"), tmp_path / "s.yaml")
    assert main(["-q", "tune", str(scenario), "--out", str(tmp_path / "a" / "b" / "run"), "--timesteps", "8"]) == 2
    assert "NaN" in _one_error_line(capsys)
    assert sorted(tmp_path.iterdir()) == [scenario]


def test_a_start_refused_after_the_fixed_pid_search_keeps_its_result(tmp_path, monkeypatch, capsys):
    import prlpid_fmi.tuning.agent

    def refuse(*args, **kwargs):
        raise PrlPidError("agent: cannot train (got a refusal from the test; expected nothing)")

    monkeypatch.setattr(prlpid_fmi.tuning.agent, "train", refuse)
    scenario = _small_copy(scenario_path("first_order"), tmp_path / "s.yaml")
    run = tmp_path / "run"
    assert main(["-q", "tune", str(scenario), "--out", str(run), "--timesteps", "8"]) == 2
    assert "cannot train" in _one_error_line(capsys)
    assert (run / "fixed_pid.json").is_file() and not (run / "model.zip").exists()


def test_an_os_error_is_one_line_naming_the_file(tmp_path, capsys):
    assert main(["tune", "first_order", "--out", "/dev/null/run", "--timesteps", "8"]) == 2
    assert _one_error_line(capsys) == "prlpid-fmi: error: /dev/null/run: Not a directory"


# -- export never loses a run's files --------------------------------------------------------------
def test_export_never_targets_a_file_the_run_owns(trained_run, tmp_path, capsys):
    before = _tree(trained_run)
    model = (trained_run / "model.zip").read_bytes()
    owned = ["model.zip", "metrics.json", "gains.csv", "schedule.csv", "report.md", "scenario.yaml", "run.json",
             "response.png", "checkpoints/new.csv", "monitor/x.csv", "evaluations/9/gains.csv"]
    for name in owned:
        for force in ([], ["--force"]):
            assert main(["export", str(trained_run), "-o", str(trained_run / name), *force]) == 2
            line = _one_error_line(capsys)
            assert str(trained_run / name) in line and "belongs to the run directory" in line
    # other spellings of the same file
    for spelling in (trained_run / ".." / trained_run.name / "model.zip", trained_run / "." / "model.zip"):
        assert main(["export", str(trained_run), "-o", str(spelling), "--force"]) == 2
        assert "belongs to the run directory" in _one_error_line(capsys)
    link = tmp_path / "link.zip"
    link.symlink_to(trained_run / "model.zip")
    assert main(["export", str(trained_run), "-o", str(link), "--force"]) == 2
    assert "belongs to the run directory" in _one_error_line(capsys)
    assert (trained_run / "model.zip").read_bytes() == model and _tree(trained_run) == before


def test_export_refuses_a_directory_and_an_existing_file_without_force(trained_run, tmp_path, capsys):
    assert main(["export", str(trained_run), "-o", str(tmp_path)]) == 2
    assert f"{tmp_path}: is a directory" in _one_error_line(capsys)
    existing = tmp_path / "gains.csv"
    existing.write_text("my own table\n")
    assert main(["export", str(trained_run), "-o", str(existing), "--points", "3"]) == 2
    assert "--force" in _one_error_line(capsys)
    assert existing.read_text() == "my own table\n"
    assert main(["-q", "export", str(trained_run), "-o", str(existing), "--points", "3", "--force"]) == 0
    assert capsys.readouterr().out == f"gain schedule written to {existing}\n"
    assert len(read_schedule_csv(existing).breakpoints) == 3


def test_scenario_without_replay_is_refused(trained_run, tmp_path, capsys):
    assert main(["export", str(trained_run), "-o", str(tmp_path / "s.csv"), "--scenario", "first_order"]) == 2
    assert "--replay" in _one_error_line(capsys)
    assert not (tmp_path / "s.csv").exists()


def test_replay_on_another_scenarios_evaluation(trained_run, tmp_path):
    other = _small_copy(scenario_path("first_order"), tmp_path / "other.yaml",
                        {"evaluation": {"episode_steps": 120, "setpoints": [{"at_step": 0, "value": 0.3},
                                                                           {"at_step": 60, "value": 0.8}],
                                        "intervals": [[0, 60], [60, 120]]}})
    _, own = export_schedule(trained_run, tmp_path / "own.csv", points=3, replay=True)
    _, moved = export_schedule(trained_run, tmp_path / "other.csv", points=3, replay=True, scenario_path=other)
    spans = [(i["start_step"], i["end_step"]) for i in moved["schedule"]["intervals"]]
    assert spans == [(0, 60), (60, 120)]
    assert [(i["start_step"], i["end_step"]) for i in moved["policy"]["intervals"]] == spans
    assert [(i["start_step"], i["end_step"]) for i in own["schedule"]["intervals"]] != spans


def test_a_corrupt_model_is_one_line_naming_it(trained_run, tmp_path, capsys):
    broken = tmp_path / "broken"
    shutil.copytree(trained_run, broken)
    (broken / "model.zip").write_bytes(b"PK\x03\x04 this is not a model")
    assert main(["evaluate", str(broken)]) == 2
    assert f"{broken / 'model.zip'}: cannot load the trained policy" in _one_error_line(capsys)
    assert not (broken / "evaluations").exists()
    assert main(["export", str(broken), "-o", str(tmp_path / "t.csv")]) == 2
    assert str(broken / "model.zip") in _one_error_line(capsys)
    assert not (tmp_path / "t.csv").exists()


def test_a_write_the_os_refuses_is_one_line_naming_the_file(trained_run, tmp_path, capsys):
    try:
        os.close(os.open("/sys/prlpid_probe", os.O_CREAT | os.O_WRONLY))
        pytest.skip("/sys is writable here")
    except OSError:
        pass
    assert main(["export", str(trained_run), "-o", "/sys/schedule.csv", "--points", "3"]) == 2
    assert _one_error_line(capsys).startswith("prlpid-fmi: error: /sys/schedule.csv: ")


def test_a_full_disk_while_plotting_is_one_line_naming_the_png(trained_run, tmp_path, monkeypatch, capsys):
    from matplotlib.figure import Figure

    def full(self, fname, **kwargs):
        with open(fname, "wb") as f:
            f.write(b"\x89PNG")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Figure, "savefig", full)
    assert main(["evaluate", str(trained_run)]) == 2
    line = _one_error_line(capsys)
    assert line.startswith("prlpid-fmi: error: ") and line.endswith("response.png: No space left on device")
    folder = Path(line.split("error: ")[1].split(":")[0]).parent
    assert not any(p.name.startswith(".") for p in folder.iterdir())  # no temporary file left behind


# -- what a run writes -----------------------------------------------------------------------------
def test_run_files_are_0644_under_umask_022(trained_run):
    files = [p for p in trained_run.rglob("*") if p.is_file() and not {"tensorboard", "evaluations"} & set(p.parts)]
    assert {"model.zip", "metrics.json", "gains.csv", "schedule.csv", "response.png", "report.md"} <= {
        p.name for p in files}
    assert {p.name: stat.S_IMODE(p.stat().st_mode) for p in files} == {p.name: 0o644 for p in files}


def test_evaluate_report_names_the_scenario_file(trained_run, tmp_path, capsys):
    other = _small_copy(scenario_path("first_order"), tmp_path / "wider.yaml")
    assert main(["-q", "evaluate", str(trained_run), "--scenario", str(other)]) == 0
    out_dir = Path(capsys.readouterr().out.split("evaluation written to ")[1].strip())
    assert f"Scenario file: `{other}`" in (out_dir / "report.md").read_text()
    assert main(["-q", "evaluate", str(trained_run)]) == 0
    out_dir = Path(capsys.readouterr().out.split("evaluation written to ")[1].strip())
    assert f"Scenario file: `{trained_run / 'scenario.yaml'}`" in (out_dir / "report.md").read_text()


def test_evaluate_takes_a_file_with_only_an_evaluation_section(trained_run, tmp_path, capsys):
    """A held-out schedule without copying the scenario: the file's `evaluation:` replaces the run's, everything
    else is the run's own scenario.yaml; a mistake in it is one line naming that file and the key, exit 2. Known
    answer: the same evaluation written into a full copy of the run's scenario gives the same metrics."""
    import yaml

    held_out = {"episode_steps": 80, "setpoints": [{"at_step": 0, "value": 0.3}, {"at_step": 40, "value": -0.6}]}
    only = tmp_path / "held_out.yaml"
    only.write_text(yaml.safe_dump({"evaluation": held_out}))
    assert main(["-q", "evaluate", str(trained_run), "--scenario", str(only)]) == 0
    out_dir = Path(capsys.readouterr().out.split("evaluation written to ")[1].strip())
    used = yaml.safe_load((out_dir / "scenario.yaml").read_text())
    own = yaml.safe_load((trained_run / "scenario.yaml").read_text())
    assert used["plant"] == own["plant"] and used["name"] == own["name"]
    assert [s["value"] for s in used["evaluation"]["setpoints"]] == [[0.3], [-0.6]]
    full = tmp_path / "full.yaml"
    full.write_text(yaml.safe_dump({**own, "evaluation": held_out}))
    assert main(["-q", "evaluate", str(trained_run), "--scenario", str(full)]) == 0
    full_dir = Path(capsys.readouterr().out.split("evaluation written to ")[1].strip())
    assert json.loads((out_dir / "metrics.json").read_text())["fixed_pid"] == \
        json.loads((full_dir / "metrics.json").read_text())["fixed_pid"]
    only.write_text(yaml.safe_dump({"evaluation": {**held_out, "episode_step": 80}}))
    assert main(["-q", "evaluate", str(trained_run), "--scenario", str(only)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(only) in err[0] and "evaluation.episode_step" in err[0]


def test_evaluate_opens_with_the_deployed_controller_on_that_evaluation(trained_run, tmp_path, capsys):
    """The deployed schedule.csv is replayed on the new evaluation. Known answer: a run that deploys the one-row
    table of the fixed PID (marked here as a deployed gain schedule) must score exactly the fixed PID's numbers."""
    run = tmp_path / "run"
    shutil.copytree(trained_run, run, ignore=shutil.ignore_patterns("evaluations"))
    m = json.loads((run / "metrics.json").read_text())
    (run / "schedule.csv").write_bytes((run / "fixed_pid.csv").read_bytes())
    (run / "metrics.json").write_text(json.dumps({**m, "deployed": "gain schedule"}))
    other = _small_copy(scenario_path("first_order"), tmp_path / "other.yaml",
                        {"evaluation": {"episode_steps": 90, "setpoints": [{"at_step": 0, "value": 0.5},
                                                                           {"at_step": 45, "value": -0.7}],
                                        "intervals": [[0, 45], [45, 90]]}})
    assert main(["-q", "evaluate", str(run), "--scenario", str(other)]) == 0
    out_dir = Path(capsys.readouterr().out.split("evaluation written to ")[1].strip())
    e = json.loads((out_dir / "metrics.json").read_text())
    assert e["deployed"] == "gain schedule"
    assert e["deployed_schedule"]["overall"] == pytest.approx(e["fixed_pid"]["metrics"]["overall"], rel=1e-12,
                                                               nan_ok=True)
    report = (out_dir / "report.md").read_text()
    assert report.index("## Deployed controller on this evaluation") < report.index("Scenario file:")
    assert "| metric (evaluation) | unit | gain schedule (deployed) | fixed PID |" in report
    # the fixture's own verdict (the fixed PID at this budget) is named as such
    assert main(["-q", "evaluate", str(trained_run)]) == 0
    out_dir = Path(capsys.readouterr().out.split("evaluation written to ")[1].strip())
    e = json.loads((out_dir / "metrics.json").read_text())
    assert e["deployed"] == json.loads((trained_run / "metrics.json").read_text())["deployed"]
    if e["deployed"] == "fixed PID":
        assert "The run deployed the fixed PID" in (out_dir / "report.md").read_text()


def test_tune_progress_goes_to_stderr_and_never_passes_the_target(tmp_path, capsys):
    scenario = _small_copy(scenario_path("first_order"), tmp_path / "s.yaml")
    run = tmp_path / "run"
    assert main(["tune", str(scenario), "--timesteps", "200", "--out", str(run)]) == 0
    out, err = capsys.readouterr()
    trained = json.loads((run / "run.json").read_text())["trained_timesteps"]
    assert trained > 200  # PPO collects whole rollouts past the target ...
    training = [line for line in err.splitlines() if line.startswith("prlpid-fmi: training: ")]
    assert training[0] == "prlpid-fmi: training: 0/200 steps (0 %)"  # ... the progress does not
    assert training[-1].startswith("prlpid-fmi: training: 200 steps in ")
    assert all(int(line.split(": ")[2].split("/")[0].replace(",", "")) <= 200 for line in training[:-1])
    from prlpid_fmi.tuning.design_rule import STABILISING_GENERATIONS
    from prlpid_fmi.tuning.load_design import model_budget, polish_evaluations

    # the fixed-PID search step by step, each count against its own budget with the small baseline (maxiter 1,
    # popsize 2) over (Kp, Ti, Td): the stabilising setpoint search (generations + 1) * popsize * 3 evaluations,
    # the load search on the models with model_budget(1, 2) = (G, P): DE (G + 1) * P * 3 and its polish
    # polish_evaluations(G) * 3 at most; the experiments and the
    # Ms checks as steps with their durations
    search = [line[len("prlpid-fmi: fixed-PID search: "):] for line in err.splitlines()
              if line.startswith("prlpid-fmi: fixed-PID search: ")]
    G, P = model_budget(1, 2)
    budgets = {"stabilising PID (setpoint search)": (STABILISING_GENERATIONS + 1) * 2 * 3,
               # baseline.design_model identified (the default): the load search on the local models
               "load design on the identified local models (differential evolution, then Nelder-Mead)":
                   (G + 1) * P * 3 + polish_evaluations(G) * 3}
    for name, budget in budgets.items():
        counts = [line.split(": ", 1)[1] for line in search if line.startswith(name + ": ")]
        assert counts[0] == f"0/{budget:,} evaluations (0 %)", counts
        assert all(int(c.split("/")[0].replace(",", "")) <= budget for c in counts[1:-1] if "/" in c)
        done = int(counts[-1].split(" evaluations in ")[0].replace(",", ""))
        assert 0 < done <= budget and (done == budget) != ("done early" in counts[-1])
    steps = [line.split(" ...")[0] for line in search if line.endswith(" ...")]
    assert "load design: the identified models' choice verified on the FMU" in steps
    assert steps[0].startswith("Ms check on the FMU of the stabilising PID")
    assert steps[1] == "frequency response of the plant at 3 operating points"
    assert steps[-3].startswith("Ms check on the FMU (3 operating points")
    assert steps[-2] == "the command's chatter on the full-range and quiet training episodes (requirement 1)"
    assert steps[-1] == "setpoint steps across the setpoint range (requirement 1)"  # tuning.design_rule
    assert search[-1].startswith("done in ")
    assert "prlpid-fmi: training" not in out and "fixed-PID search:" not in out
    after = [line for line in err.splitlines() if line.startswith(("prlpid-fmi: gain schedule", "prlpid-fmi: evaluation",
                                                                     "prlpid-fmi: choice"))]
    assert len(after) == 6 and after[-1].startswith("prlpid-fmi: choice of the deployed controller")  # start, end x 3
    assert "run directory:" in out and "| metric |" in out


def test_quiet_tune_prints_only_the_run_directory(tmp_path, capsys):
    """-q: the run directory on stdout, no progress on stderr. --no-baseline with the anchored gain map warns that the
    fixed PID is searched anyway (the flag was silently ignored before; pytest records the warning instead of
    printing it, the CLI prints it as one `prlpid-fmi: warning:` line)."""
    scenario = _small_copy(scenario_path("first_order"), tmp_path / "s.yaml")
    with pytest.warns(UserWarning, match=r"^--no-baseline: the fixed PID is searched anyway, because the anchored gain "
                                         r"map \(controller.gain_mapping: anchored, the default\)"):
        assert main(["tune", str(scenario), "--timesteps", "64", "--out", str(tmp_path / "run"), "-q",
                     "--no-baseline"]) == 0
    out, err = capsys.readouterr()
    assert out == f"run directory: {tmp_path / 'run'}\n" and err == ""
    assert (tmp_path / "run" / "fixed_pid.json").is_file()


# -- build-fmus ------------------------------------------------------------------------------------
def test_no_plant_sources_is_one_line(tmp_path, monkeypatch, capsys):
    import prlpid_fmi.fmu.build as build

    monkeypatch.setattr(build, "PLANT_SOURCES", tmp_path)
    for argv in (["build-fmus"], ["check-plants"]):
        assert main(argv) == 2
        assert f"{tmp_path}: no bundled plant sources found" in _one_error_line(capsys)


def test_build_fmus_out_and_the_lock_in_the_cache(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    out = tmp_path / "fmus"
    assert main(["build-fmus", "FirstOrderUnstable", "--out", str(out)]) == 0
    assert capsys.readouterr().out == f"built {out / 'FirstOrderUnstable.fmu'}\n"
    assert sorted(p.name for p in out.iterdir()) == ["FirstOrderUnstable.fmu"]  # no lock, no temporary file
    assert stat.S_IMODE((out / "FirstOrderUnstable.fmu").stat().st_mode) == 0o666 & ~_umask()
    assert list((tmp_path / "cache").rglob(".build.lock"))
    assert main(["build-fmus", "NoSuchPlant", "--out", str(out)]) == 2
    assert "NoSuchPlant" in _one_error_line(capsys)
    assert main(["build-fmus", "TwoTank", "--out", str(out / "FirstOrderUnstable.fmu")]) == 2
    assert "FirstOrderUnstable.fmu: is a file" in _one_error_line(capsys)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# -- the pieces: atomic writer, ownership, progress ------------------------------------------------
def test_write_atomic_modes_and_kinds(tmp_path):
    old = os.umask(0o022)
    try:
        a = rundir.write_atomic(tmp_path / "a.txt", "é\n")
        b = rundir.write_atomic(tmp_path / "sub" / "b.bin", b"\x00\x01")
        c = rundir.write_atomic(tmp_path / "c.zip", lambda p: Path(p).write_bytes(b"zip"))
    finally:
        os.umask(old)
    assert a.read_bytes() == "é\n".encode() and b.read_bytes() == b"\x00\x01" and c.read_bytes() == b"zip"
    assert {stat.S_IMODE(p.stat().st_mode) for p in (a, b, c)} == {0o644}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "c.zip", "sub"]


def test_write_atomic_failure_keeps_the_old_file_and_names_the_target(tmp_path):
    target = tmp_path / "metrics.json"
    target.write_text("old")

    def fail(p):
        Path(p).write_text("half")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError) as exc:
        rundir.write_atomic(target, fail)
    assert exc.value.filename == str(target) and exc.value.errno == errno.ENOSPC
    assert target.read_text() == "old" and sorted(tmp_path.iterdir()) == [target]


def test_owned_names(tmp_path):
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    assert rundir.owned_name(run, run / "model.zip") == "model.zip"
    assert rundir.owned_name(run, run / "checkpoints" / "model_8_steps.zip") == "checkpoints"
    assert rundir.owned_name(run, tmp_path / "run" / ".." / "run" / "report.md") == "report.md"
    assert rundir.owned_name(run, run / "my_schedule.csv") is None
    assert rundir.owned_name(run, tmp_path / "model.zip") is None


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_progress_log_lines_every_interval_clamped_with_eta():
    clock, stream = FakeClock(), io.StringIO()
    p = Progress("training", "steps", total=50_000, stream=stream, clock=clock)
    for t, done in ((10.0, 1_000), (29.0, 14_500), (30.0, 15_000), (45.0, 22_000), (61.0, 51_200)):
        clock.t = 100.0 + t
        p.update(done)
    p.close()
    assert stream.getvalue().splitlines() == [
        "prlpid-fmi: training: 0/50,000 steps (0 %)",
        # 15,000 steps in 30 s: 500 steps/s, 35,000 left: 70 s
        "prlpid-fmi: training: 15,000/50,000 steps (30 %), 500 steps/s, ETA 1 min 10 s",
        # 51,200 done is shown as the target
        "prlpid-fmi: training: 50,000/50,000 steps (100 %), 820 steps/s, ETA 0 s",
        "prlpid-fmi: training: 50,000 steps in 1 min 01 s",
    ]


def test_progress_counts_resumed_work_but_not_in_the_rate():
    clock, stream = FakeClock(), io.StringIO()
    p = Progress("training", "steps", total=1_000, start=600, stream=stream, clock=clock, interval_s=5.0)
    clock.t += 10.0
    p.update(700)  # 100 steps in 10 s this session: 10 steps/s, 300 left
    assert stream.getvalue().splitlines()[-1] == "prlpid-fmi: training: 700/1,000 steps (70 %), 10 steps/s, ETA 30 s"


def test_progress_total_given_later_and_an_early_end():
    clock, stream = FakeClock(), io.StringIO()
    p = Progress("fixed-PID search", "evaluations", stream=stream, clock=clock)
    assert stream.getvalue() == ""
    clock.t += 2.0
    p.update(48, 504)
    clock.t += 1.0
    p.update(240, 504)
    p.close()
    lines = stream.getvalue().splitlines()
    assert lines[0] == "prlpid-fmi: fixed-PID search: 48/504 evaluations (10 %), 24 evaluations/s, ETA 19 s"
    assert lines[-1] == "prlpid-fmi: fixed-PID search: 240 evaluations in 3 s (stopped before 504: done early)"


def test_steps_show_each_step_with_its_own_count_or_duration():
    from prlpid_fmi.progress import Steps, counted

    clock, stream = FakeClock(), io.StringIO()
    steps = Steps("fixed-PID search", stream=stream, clock=clock)
    steps.step("search", 100)
    cost = counted(lambda x: x * x, steps)
    for i in range(40):
        clock.t += 0.05
        cost(float(i))
    steps.step("Ms check")
    clock.t += 4.0
    steps.close()
    assert stream.getvalue().splitlines() == [
        "prlpid-fmi: fixed-PID search: search: 0/100 evaluations (0 %)",
        "prlpid-fmi: fixed-PID search: search: 40 evaluations in 2 s (stopped before 100: done early)",
        "prlpid-fmi: fixed-PID search: Ms check ...",
        "prlpid-fmi: fixed-PID search: Ms check: done in 4 s",
        "prlpid-fmi: fixed-PID search: done in 6 s"]
    quiet = io.StringIO()
    silent = Steps("x", enabled=False, stream=quiet)
    silent.step("a", 10)
    silent.update(5)
    silent.close()
    assert quiet.getvalue() == ""


class FakeTerminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_on_a_terminal_redraws_one_line():
    clock, stream = FakeClock(), FakeTerminal()
    p = Progress("training", "steps", total=2_048, stream=stream, clock=clock)
    for k in range(1, 11):
        clock.t += 0.5
        p.update(300 * k)
    p.close()
    text = stream.getvalue()
    assert text.count("\n") == 1 and text.endswith("\n") and text.count("\r") == 12
    final = text.rsplit("\r", 1)[1]
    assert "2,048/2,048 steps 100 %" in final and "#" * 24 in final


def test_a_stage_says_when_it_starts_and_how_long_it_took():
    clock, stream = FakeClock(), io.StringIO()
    with stage("evaluation", stream=stream, clock=clock):
        clock.t += 75.0
    with stage("quiet", enabled=False, stream=stream, clock=clock):
        pass
    assert stream.getvalue().splitlines() == ["prlpid-fmi: evaluation ...",
                                              "prlpid-fmi: evaluation: done in 1 min 15 s"]


def test_stages_record_their_durations_shown_or_not():
    """progress.stage_seconds: every stage and Steps adds its duration under its name (the label before " ("), shown
    or not; clear=True starts afresh (what tune writes to run.json as stage_seconds)."""
    from prlpid_fmi.progress import Steps, stage_seconds

    stage_seconds(clear=True)
    clock, stream = FakeClock(), io.StringIO()
    with stage("evaluation (replays)", stream=stream, clock=clock):
        clock.t += 2.5
    with stage("training", enabled=False, clock=clock):
        clock.t += 40.0
    steps = Steps("fixed-PID search", enabled=False, clock=clock)
    steps.step("load design", 10)
    clock.t += 7.25
    steps.close()
    steps.close()  # once only
    with stage("evaluation", enabled=False, clock=clock):
        clock.t += 0.5
    assert stage_seconds(clear=True) == {"evaluation": 3.0, "training": 40.0, "fixed-PID search": 7.25}
    assert stage_seconds() == {}


def test_format_duration():
    assert [format_duration(s) for s in (0.4, 59.4, 61, 3599, 3600, 7325)] == [
        "0 s", "59 s", "1 min 01 s", "59 min 59 s", "1 h 00 min", "2 h 02 min"]


@pytest.mark.parametrize("argv", [["--help"]] + [[name, "--help"] for name in (
    "build-fmus", "inspect", "validate", "schema", "init", "probe", "tune", "sweep", "evaluate", "export",
    "check-plants")])
def test_every_help_prints_and_exits_0(argv, capsys):
    """--help of the tool and of every command prints its usage and exits 0 (a bare "%" in a command's
    one-line help once made the top-level --help end in a traceback)."""
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    out = capsys.readouterr().out
    assert exit_info.value.code == 0
    assert out.startswith("usage: prlpid-fmi")
    if argv == ["--help"]:
        assert "95 % interval" in out and "check-plants" in out  # every command listed, help text intact


@pytest.mark.parametrize("command", ["inspect", "probe", "init"])
@pytest.mark.parametrize("content, problem", [(None, "FMU file not found"),
                                              ("folder", "a folder, not an FMU file (an extracted FMU?"),
                                              (b"PK\x03\x04 not a zip", "not an FMU (expected a ZIP archive")])
def test_a_missing_or_broken_fmu_is_one_line_naming_the_file_once(command, content, problem, tmp_path, capsys):
    fmu = tmp_path / "plant.fmu"
    if content == "folder":
        fmu.mkdir()
    elif content is not None:
        fmu.write_bytes(content)
    assert main([command, str(fmu)]) == 2
    line = _one_error_line(capsys)
    assert problem in line and line.count(str(fmu)) == 1, line


@pytest.mark.parametrize("command", ["probe", "init"])
def test_an_fmu_with_sources_but_no_binary_says_how_to_compile_it(command, tmp_path, capsys):
    """probe and init once passed such an FMU to FMPy and reported only "Cannot find shared library"."""
    import zipfile

    from prlpid_fmi.fmu import bundled_fmu
    fmu = tmp_path / "plant.fmu"
    with zipfile.ZipFile(bundled_fmu("FirstOrderUnstable", 2)) as src, zipfile.ZipFile(fmu, "w") as dst:
        for name in src.namelist():
            if not name.startswith("binaries/"):
                dst.writestr(name, src.read(name))
    assert main([command, str(fmu)]) == 2
    line = _one_error_line(capsys)
    assert "no binary for this platform" in line and f"fmpy compile {fmu.name}" in line, line


@pytest.mark.parametrize("option, expected", [
    (["--points", "0"], "--points: must be at least 1 (got 0;"),
    (["--schedule-by", "banana"],
     "--schedule-by: the plant FirstOrderUnstable.fmu has no scalar real variable 'banana'"),
    (["--schedule-by", "setpoint[q]"], "--schedule-by: no loop measures 'q' (got 'setpoint[q]'; expected "
                                       "setpoint[<loop>] with one of the loops: y)")])
def test_export_names_a_bad_schedule_option_and_writes_nothing(option, expected, trained_run, tmp_path, capsys):
    out = tmp_path / "gains.csv"
    assert main(["export", str(trained_run), "-o", str(out)] + option) == 2
    assert expected in _one_error_line(capsys)
    assert not out.exists()


def test_integer_options_take_5e4_and_refuse_fractions_in_one_line(tmp_path, monkeypatch, capsys):
    from prlpid_fmi.cli import _whole_number

    assert [_whole_number(t) for t in ("50000", "50_000", "5e4", "5.0E4", "-1")] == [50000, 50000, 50000, 50000, -1]
    monkeypatch.chdir(tmp_path)
    for value in ("0.5", "inf", "nan", "abc"):
        with pytest.raises(SystemExit) as info:
            main(["tune", "first_order", "--timesteps", value])
        assert info.value.code == 2
        line = _one_error_line(capsys)
        assert f"--timesteps: not a whole number: {value!r} (expected a whole number" in line, line
    assert list(tmp_path.iterdir()) == []


def test_an_fmu_given_as_the_scenario_points_to_init(tmp_path, monkeypatch, capsys):
    from prlpid_fmi.fmu import bundled_fmu

    monkeypatch.chdir(tmp_path)
    fmu = bundled_fmu("FirstOrderUnstable", 2)
    for command in (["tune"], ["validate"]):
        assert main([*command, str(fmu)]) == 2
        line = _one_error_line(capsys)
        assert "a ZIP archive (an FMU?), not a scenario" in line and f"prlpid-fmi init {fmu} > scenario.yaml" in line
    assert list(tmp_path.iterdir()) == []
