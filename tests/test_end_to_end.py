"""Every paper scenario end to end through the CLI with a small budget: tune writes every file, plot and report a
user is promised, and what it wrote reads back (its own file: the longest tests of the suite, so that pytest-xdist can
run them beside the rest of tests/test_cli.py)."""
import csv
import json

import pytest

from prlpid_fmi.cli import main
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.scenario.presets import PRESET_NAMES, scenario_path
from test_cli import TIME_VARYING, _assert_png, _small_copy


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_every_paper_scenario_runs_end_to_end(name, tmp_path, capsys):
    # The quadrotor: its barely trained policy's table rows are detuned through scans of three-loop margin experiments
    # (3 min for both candidates on one seed at Ms <= 2): one candidate here, the setpoint table, and Ms <= 4 (the
    # rule at 2 is tested on first_order, test_actions_anchored; the choice between candidates in test_candidates; at
    # 1e3 the Kp intervals of the design on the loop models fall back to the slower scan: 155 s against 87 s). Its
    # training episodes are halved (holds of 7.5 s): the load and setpoint experiments are as long as the holds.
    extra = {"deploy": {"schedule_points": 3, "max_sensitivity": 4.0, "schedule_by": "setpoint"},
             "training": {"episode_steps": 150, "setpoint_hold_steps": 75}} if name == "quadrotor" else None
    if name == "time_varying":
        extra = TIME_VARYING
    scenario = _small_copy(scenario_path(name), tmp_path / f"{name}.yaml", extra)
    run = tmp_path / "run"
    assert main(["tune", str(scenario), "--timesteps", "256", "--seed", "3", "--out", str(run), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "adaptive policy" in out and "fixed PID" in out
    for f in ("model.zip", "scenario.yaml", "run.json", "metrics.json", "gains.csv", "report.md", "fixed_pid.json"):
        assert (run / f).is_file(), f
    # a barely trained policy may not stabilise every operating point, and no controller may meet the
    # robustness limit: then schedule.csv is not written and the report says why
    report = (run / "report.md").read_text()
    assert (run / "schedule.csv").is_file() or "No gain schedule" in report or "Nothing here is safe" in report
    for png in ("response.png", "control_signal.png", "gains.png", "learning_curve.png"):
        _assert_png(run / png)
    info = json.loads((run / "run.json").read_text())
    assert info["seed"] == 3 and info["trained_timesteps"] >= 256
    assert info["versions"]["torch"].startswith("2.13.0") and "stable-baselines3" in info["versions"]
    resolved = load_scenario(run / "scenario.yaml")
    assert resolved.agent.seed == 3 and resolved.tuning == load_scenario(scenario).tuning
    # the engineer's figures (run.figures), embedded in the report, and the measured frequency responses per loop
    for png in ("step_response.png", "load_steps.png"):
        _assert_png(run / png)
        assert f"]({png})" in report
    from prlpid_fmi.report.frequency import CSV_COLUMNS, file_stem

    for loop in resolved.tuning.loops:
        csv_file = run / "frequency" / f"{file_stem(loop.output)}.csv"
        assert ",".join(CSV_COLUMNS) in csv_file.read_text().splitlines()
        if (run / "frequency" / f"nyquist_{file_stem(loop.output)}.png").is_file():
            assert f"](frequency/nyquist_{file_stem(loop.output)}.png)" in report
    metrics = json.loads((run / "metrics.json").read_text())
    assert {"policy", "fixed_pid", "deployed", "decision"} <= set(metrics)
    assert "ISE" in "".join(metrics["policy"]["overall"])
    from prlpid_fmi.deliver.rule import Deployed

    # every word a run may deploy (a nonlinear plant such as two_tank may deploy its classical schedule)
    assert metrics["deployed"] in ("gain schedule", "classical gain schedule", "fixed PID", "none")
    assert {d.value for d in Deployed} == {"gain schedule", "classical gain schedule", "fixed PID", "none"}
    assert (run / "fixed_pid.csv").is_file()
    with open(run / "gains.csv") as f:
        rows = list(csv.DictReader(f))
    steps = resolved.evaluation_config().episode_steps
    assert len(rows) <= steps and rows[0]["step"] == "0"
    loop = resolved.tuning.loops[0].output
    kp = float(rows[0][f"Kp[{loop}]"])
    assert float(rows[0][f"Ki[{loop}]"]) == pytest.approx(kp / float(rows[0][f"Ti[{loop}]"]), rel=1e-12)
