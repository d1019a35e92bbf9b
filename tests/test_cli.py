"""The prlpid-fmi command line end to end: every paper scenario, bring-your-own FMU, bad input."""
import copy
import json
import subprocess
import sys
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
import yaml

from prlpid_fmi.cli import main
from prlpid_fmi.fmu import FmuPlant, build_fmu
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv
from prlpid_fmi.tuning.schedule.replay import replay_schedule
from test_scenario import MISTAKES, _raw, _write

# A small budget so each end-to-end run takes seconds: short PPO rollouts, a token baseline search.
# one env keeps the step arithmetic of the resume test exact (8 envs train in rollouts of 8 x n_steps)
SMALL = {"agent": {"n_envs": 1, "n_steps": 128, "batch_size": 64, "checkpoint_every": 128},
         "baseline": {"episodes": 1, "maxiter": 1, "popsize": 2}, "deploy": {"schedule_points": 3}}


# time_varying: its margin estimates are unreliable, and the fixed-PID search counts them
# (conservatively), so a tiny-budget PID is detuned through a scan of margin experiments that takes
# minutes; the detuning is tested in test_fixed_pid/test_candidates/test_actions_anchored
TIME_VARYING = {"deploy": {"schedule_points": 3, "schedule_by": "setpoint", "max_sensitivity": 1e3}}


def _small_copy(src: Path, dst: Path, extra: dict | None = None) -> Path:
    doc = yaml.safe_load(src.read_text())
    if not Path(str(doc["plant"]["fmu"])).is_absolute() and str(doc["plant"]["fmu"]).endswith(".fmu"):
        doc["plant"]["fmu"] = str((src.parent / doc["plant"]["fmu"]).resolve())
    for section, values in {**SMALL, **(extra or {})}.items():
        doc.setdefault(section, {}).update(values)
    dst.write_text(yaml.safe_dump(doc, sort_keys=False))
    return dst


def _assert_png(path: Path):
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert path.stat().st_size > 10_000
    assert np.var(mpimg.imread(str(path))) > 1e-4


def test_run_directory_is_never_overwritten_and_resume_continues(tmp_path, capsys):
    scenario = _small_copy(scenario_path("first_order"), tmp_path / "s.yaml")
    run = tmp_path / "run"
    args = ["tune", str(scenario), "--timesteps", "256", "--out", str(run), "--no-progress", "--no-baseline"]
    assert main(args) == 0
    before = (run / "model.zip").read_bytes()
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exists" in err[0] and "--resume" in err[0]
    assert (run / "model.zip").read_bytes() == before
    assert main(["tune", str(scenario), "--timesteps", "512", "--out", str(run), "--resume", "--no-progress",
                 "--no-baseline"]) == 0
    assert json.loads((run / "run.json").read_text())["trained_timesteps"] == 512
    # resuming a finished run to the same budget does nothing and says so (no file is rewritten)
    files = {p: p.stat().st_mtime_ns for p in run.rglob("*") if p.is_file()}
    with pytest.warns(UserWarning, match=r"finished already \(512 training steps"):
        assert main(["tune", str(scenario), "--timesteps", "512", "--out", str(run), "--resume", "--no-progress",
                     "--no-baseline"]) == 0
    assert {p: p.stat().st_mtime_ns for p in run.rglob("*") if p.is_file()} == files


def test_evaluate_on_another_scenario_writes_a_new_evaluation(tmp_path, capsys):
    scenario = _small_copy(scenario_path("time_varying"), tmp_path / "s.yaml", TIME_VARYING)
    run = tmp_path / "run"
    assert main(["tune", str(scenario), "--timesteps", "256", "--out", str(run), "--no-progress", "--no-baseline"]) == 0
    wider = _small_copy(scenario_path("time_varying"), tmp_path / "wider.yaml",
                        {"evaluation": {"episode_steps": 100, "setpoints": [{"at_step": 0, "value": 2.5}],
                                        "intervals": [[0, 50], [50, 100]]}})
    assert main(["evaluate", str(run), "--scenario", str(wider)]) == 0
    assert main(["evaluate", str(run)]) == 0
    m = json.loads((run / "evaluations" / "1" / "metrics.json").read_text())
    assert [(i["start_step"], i["end_step"]) for i in m["policy"]["intervals"]] == [(0, 50), (50, 100)]
    assert (run / "evaluations" / "2" / "response.png").is_file()


MODEL_YAML = """\
name: OvenZone
description: "Heated zone: tau dT/dt = K*power - (T - T_ambient) + q_loss"
states: [T]
variables:
  - {name: power, causality: input, start: 0.0, unit: W, description: "Heater power"}
  - {name: q_loss, causality: input, start: 0.0, unit: K, description: "Load disturbance"}
  - {name: temperature, causality: output, unit: degC, description: "Zone temperature"}
  - {name: tau, causality: parameter, variability: tunable, start: 4.0, unit: s, description: "Time constant"}
  - {name: K, causality: parameter, variability: tunable, start: 0.05, unit: K/W, description: "Static gain"}
  - {name: T_ambient, causality: parameter, variability: tunable, start: 20.0, unit: degC, description: "Ambient"}
"""
MODEL_C = """\
#include "plant_model.h"
void model_initialize(ModelData *m) { m->x[0] = m->v[VR_T_ambient]; }
void model_derivatives(const ModelData *m, double t, const double *x, double *dx) {
    (void)t;
    dx[0] = (m->v[VR_K] * m->v[VR_power] - (x[0] - m->v[VR_T_ambient]) + m->v[VR_q_loss]) / m->v[VR_tau];
}
void model_outputs(ModelData *m) { m->v[VR_temperature] = m->x[0]; }
void model_constrain(double *x) { (void)x; }
"""


def test_bring_your_own_fmi3_fmu(tmp_path, capsys):
    src = tmp_path / "oven_src"
    src.mkdir()
    (src / "model.yaml").write_text(MODEL_YAML)
    (src / "model.c").write_text(MODEL_C)
    fmu = build_fmu("OvenZone", fmi_version=3, out_dir=tmp_path / "build", source_dir=src)
    assert main(["inspect", str(fmu)]) == 0
    assert "As prior     yes" in capsys.readouterr().out

    assert main(["init", str(fmu)]) == 0
    text = capsys.readouterr().out
    doc = yaml.safe_load(text)
    assert doc["plant"]["loops"][0]["input"] == "power" and doc["plant"]["loops"][0]["output"] == "temperature"
    doc["plant"]["loops"][0].update(setpoint_range=[30.0, 60.0], u_limits=[0.0, 1000.0], measurement_scale=10.0,
                                    gains={"Kp": [1.0, 200.0, "log"], "Ti": [0.5, 50.0, "log"],
                                           "Td": [0.0, 1.0, "linear"]})
    doc["evaluation"] = {"episode_steps": 200, "setpoints": [{"at_step": 0, "value": 40.0},
                                                            {"at_step": 100, "value": 55.0}]}
    scenario = tmp_path / "oven.yaml"
    scenario.write_text(yaml.safe_dump(doc, sort_keys=False))
    scenario = _small_copy(scenario, scenario)
    assert main(["validate", str(scenario)]) == 0

    run = tmp_path / "run"
    assert main(["tune", str(scenario), "--timesteps", "256", "--out", str(run), "--no-progress"]) == 0
    assert "Deployable files:" in (run / "report.md").read_text() and (run / "fixed_pid.csv").is_file()
    assert main(["export", str(run), "--format", "c", "--fixed", "-o", str(tmp_path / "oven_pid.c")]) == 0
    assert "oven_pid_step(" in (tmp_path / "oven_pid.h").read_text()
    table = tmp_path / "oven_gains.csv"
    assert main(["export", str(run), "-o", str(table), "--points", "4", "--replay"]) == 0
    out = capsys.readouterr().out
    assert "schedule (plain PID)" in out
    schedule = read_schedule_csv(table)
    assert len(schedule.breakpoints) == 4 and schedule.loop_names == ("temperature",)
    lines = table.read_text().splitlines()
    assert lines[0].startswith("#") and any("Ti" in line for line in lines if not line.startswith("#"))

    # The CSV is a plain PID anyone can run: the 2-DOF law written here from the CSV's columns (b, c, Tf) and
    # metadata, table lookup by setpoint, on a fresh instance of the user's FMU, reproduces the tool's no-NN replay.
    _, replayed = replay_schedule(schedule, load_scenario(scenario).evaluation_config())
    b, c, tf = (float(np.ravel(v)[0]) for v in (schedule.setpoint_weight, schedule.derivative_weight,
                                                schedule.measurement_filter_s))
    order, ts = schedule.measurement_filter_order, schedule.sample_time_s
    plant = FmuPlant(fmu, inputs=["power"], outputs=["temperature"], sample_time_s=ts)
    y = plant.reset()[0]
    u0 = min(max(float(plant.get(["power"])[0]), 0.0), 1000.0)  # the bumpless start: balanced at y0 with u0
    integral, ed_prev, stages = None, None, [y] * order
    bumpless = schedule.gain_change == "bumpless"  # the CSV's gain_change line (control/pid.py's docstring)
    last = None  # (Kp, Ti, Td, ep, D) of the previous sample
    measured = [y]
    for k in range(200):
        r = 40.0 if k < 100 else 55.0
        kp, ti, td = (float(np.ravel(g)[0]) for g in schedule.gains_at(r)[:3])
        if integral is None:
            integral = (u0 - kp * ((b - 1.0) * y)) / (kp / ti)
        elif bumpless and last[:3] != (kp, ti, td):  # the new gains give the old output on the last sample's signals
            kp0, ti0, td0, ep0, d0 = last
            v = kp0 * (ep0 + td0 * d0) + kp0 / ti0 * integral
            integral = (v - kp * (ep0 + td * d0)) / (kp / ti)
        yf = y
        if tf > 0 and k > 0:
            x = y
            for j in range(order):
                stages[j] = x = (tf / order * stages[j] + ts * x) / (tf / order + ts)
            yf = x
        e, ep, ed = r - y, b * r - yf, c * r - yf
        ed_prev = ed if ed_prev is None else ed_prev
        d = (ed - ed_prev) / ts
        u_try = kp * (ep + td * d) + kp / ti * (integral + e * ts)
        if 0.0 <= u_try <= 1000.0 or (u_try > 1000.0) != (kp * e > 0):
            integral += e * ts
        u = min(max(u_try, 0.0), 1000.0)
        ed_prev, last = ed, (kp, ti, td, ep, d)
        y = plant.step([u])[0]
        measured.append(y)
    plant.close()
    np.testing.assert_allclose(measured, replayed["measurement"][:, 0], rtol=0, atol=1e-9)


@pytest.mark.parametrize("case", MISTAKES, ids=[m[0] for m in MISTAKES])
def test_cli_bad_scenario_gives_one_line_and_exit_2(case, tmp_path, capsys):
    _, base, edit, key, shown = case
    doc = copy.deepcopy(_raw(base))
    edit(doc, tmp_path)
    path = _write(tmp_path, doc)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert str(path) in err and key in err and shown in err


def test_cli_errors_in_a_real_process(tmp_path):
    bad = _write(tmp_path, {"name": "x", "plant": {"fmu": "nowhere.fmu", "loops": [{"input": "u", "output": "y"}]}})
    for args in (["validate", str(bad)], ["tune", str(bad)], ["init", str(tmp_path / "missing.fmu")],
                 ["inspect", str(bad)], ["evaluate", str(tmp_path)]):
        proc = subprocess.run([sys.executable, "-m", "prlpid_fmi.cli", *args], capture_output=True, text=True)
        assert proc.returncode == 2, (args, proc.stderr)
        assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
