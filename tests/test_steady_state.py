"""Where a stable loop's steady-state gain changes sign (prlpid_fmi.probe.steady_state), against analytic maps.

tests/plants/HumpLag: tau dy/dt = 4 ymax u (1 - u) - y, y_ss = 4 ymax u (1 - u), a maximum ymax at u = 1/2.
tests/plants/Bistable: tau dy/dt = y - y^3 + u from y = 0, the unstable middle branch (static gain 1/(3y^2 - 1) < 0
there, > 0 on the stable outer branches): feedback holds it, so it is not flagged.
"""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from prlpid_fmi.config import LoopConfig, TuningConfig
from prlpid_fmi.fmu import build_fmu
from prlpid_fmi.probe.feasibility import check_loops
from prlpid_fmi.probe.steady_state import LEVELS, extremum_of, loop_extrema

PLANTS = Path(__file__).parent / "plants"


@pytest.fixture(scope="module")
def plants(tmp_path_factory):
    out = tmp_path_factory.mktemp("steady_state")
    return {name: build_fmu(name, out_dir=out, source_dir=PLANTS / name) for name in ("HumpLag", "Bistable")}


def config(fmu, u_limits, parameters=None, setpoint_range=(0.0, 2.5)) -> TuningConfig:
    return TuningConfig(fmu=str(fmu), plant_parameters=parameters or {},
                        loops=(LoopConfig(input="u", output="y", u_min=u_limits[0], u_max=u_limits[1],
                                          setpoint_range=setpoint_range),))


def test_extremum_of_hand_made_maps():
    u = np.linspace(0, 1, 11)
    assert extremum_of(u, u ** 2) is None  # monotone
    e = extremum_of(u, -(u - 0.3) ** 2)
    assert e.kind == "maximum" and e.u == pytest.approx(0.3) and (e.u_before, e.u_after) == pytest.approx((0.2, 0.4))
    assert extremum_of(u, (u - 0.7) ** 2).kind == "minimum"
    assert extremum_of(u, np.where(u < 0.95, u, 0.95 - 1e-6)) is None  # a flat top within 1 % of the spread
    assert extremum_of(u, np.where(u < 0.95, u, 0.5)) is None  # a map that drops at its last level only saturates


@pytest.mark.parametrize("ymax", [1.0, 2.5])
def test_the_maximum_of_a_humped_stable_map_is_named_where_it_is(plants, ymax):
    (e,) = loop_extrema(config(plants["HumpLag"], (0.0, 1.0), {"ymax": ymax}))
    step = 1.0 / (LEVELS - 1)
    assert e.kind == "maximum" and abs(e.u - 0.5) <= step / 2
    assert e.y == pytest.approx(4 * ymax * e.u * (1 - e.u), rel=1e-3)  # the analytic map at the level found
    assert f"maximum of {e.y:.4g} at u = {e.u:.4g}" in e.sentence()
    # u_limits on one side of the maximum: a monotone map, nothing to say; setpoints far below the maximum neither
    assert loop_extrema(config(plants["HumpLag"], (0.0, 0.45), {"ymax": ymax})) == []
    assert loop_extrema(config(plants["HumpLag"], (0.0, 1.0), {"ymax": ymax}, (0.0, 0.5 * ymax))) == []


def test_an_unstable_branch_with_a_flipped_static_gain_is_neither_flagged_nor_refused(plants):
    tuning = config(plants["Bistable"], (-1.0, 1.0), setpoint_range=(-0.5, 0.5))  # across the middle branch
    assert loop_extrema(tuning) == []
    check_loops(tuning)  # no ScenarioError


def test_a_tune_on_a_humped_plant_names_the_extremum_in_its_report(plants, tmp_path):
    """End to end with token budgets: whatever is deployed, report.md names the maximum and metrics.json keeps it."""
    doc = {
        "name": "hump",
        "plant": {"fmu": str(plants["HumpLag"]), "sample_time": 0.1,
                  "loops": [{"input": "u", "output": "y", "u_limits": [0.0, 1.0], "setpoint_range": [0.2, 0.98],
                             "measurement_scale": 1.0, "divergence_bound": 5.0,
                             "gains": {"Kp": [0.05, 5, "log"], "Ti": [0.2, 20, "log"], "Td": [0.0, 0.2, "linear"]}}]},
        "agent": {"algorithm": "ppo", "total_timesteps": 128, "seed": 0, "n_envs": 1, "n_steps": 128,
                  "batch_size": 64, "n_epochs": 1},
        "training": {"episode_steps": 100, "setpoint_hold_steps": 50},
        "evaluation": {"episode_steps": 100, "setpoints": [{"at_step": 0, "value": 0.5}, {"at_step": 50, "value": 0.8}]},
        "baseline": {"episodes": 1, "maxiter": 1, "popsize": 2},
        "deploy": {"schedule_points": 3, "classical_schedule": False},
    }
    path = tmp_path / "hump.yaml"
    path.write_text(yaml.safe_dump(doc))
    run = tmp_path / "run"
    done = subprocess.run([sys.executable, "-m", "prlpid_fmi", "-q", "tune", str(path), "--out", str(run)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    report = (run / "report.md").read_text()
    peak = float(report.split("has a maximum of ")[1].split(" ")[0])
    assert peak == pytest.approx(1.0, rel=1e-3) and "at u = 0.5 " in report  # y_ss = 4 u (1 - u) at u = 0.5
    (said,) = json.loads((run / "metrics.json").read_text())["steady_state_extrema"]
    assert "changes sign" in said
