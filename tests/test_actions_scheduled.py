"""The adaptive policy anchored on the classical gain schedule (issue 23): action 0 reproduces the table bit for bit.

Truths from outside the map's code: the replay of the same table as a plain gain-scheduled PID (the path every
export is tested against), numpy.interp of the table at the setpoint each step saw, and the band formulas
g0(z)*f**a (Kp, Ti) and g0(z) + a*b*(high - low) (Td) computed here by hand.
"""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from prlpid_fmi.config import AnchorBands
from prlpid_fmi.loop.actions import ScheduledActionMap
from prlpid_fmi.loop.env import PidTuningEnv
from prlpid_fmi.loop.evaluation import rollout
from prlpid_fmi.loop.gains import Gains
from prlpid_fmi.tuning.design_result import DesignResult
from prlpid_fmi.run.state import anchor_name, run_anchor, training_anchor
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.scenario.presets import preset, scenario_path
from prlpid_fmi.tuning.schedule.csv_file import write_schedule_csv
from prlpid_fmi.tuning.schedule.replay import replay_schedule
from prlpid_fmi.tuning.schedule.table import schedule_from_rows

# a table over the two-tank's setpoint range [5, 15] cm whose gains differ at every breakpoint (so that a
# setpoint between breakpoints gets interpolated gains) and whose last Kp lies above the loop's Kp range (50)
ROWS = [(6.0, {"Kp": [4.0], "Ti": [30.0], "Td": [0.0]}),
        (10.0, {"Kp": [9.0], "Ti": [55.0], "Td": [0.4]}),
        (14.0, {"Kp": [60.0], "Ti": [80.0], "Td": [1.0]})]
META = {"loop_inputs": ("q_in",), "output_units": ("cm",), "input_units": ("cm3/s",)}


def _table(config):
    return schedule_from_rows(config, "setpoint[h2]", "cm", ROWS, META)


def test_action_zero_of_the_map_anchored_on_a_table_replays_the_table_bit_for_bit():
    config = dataclasses.replace(preset("two_tank"), forecast_horizon=0, episode_steps=400)
    assert config.measurement_noise_std > 0 and config.smoothing != "none"  # noise and smoothing are in the path
    table = _table(config)
    env = PidTuningEnv(config, anchor=table, info=False)
    zero = np.zeros(env.action_space.shape, np.float32)
    via_policy = rollout(lambda obs: zero, config, seed=3, env=env)
    env.close()
    _, via_table = replay_schedule(table, config, seed=3)
    for key in ("setpoint", "measurement", "control_signal", "pid_output"):
        assert np.array_equal(via_policy[key], via_table[key]), key
    setpoints = via_policy["setpoint"][:, 0]
    assert len(np.unique(setpoints)) > 2 and np.any((setpoints > 6.0) & (setpoints < 14.0) & (setpoints != 10.0))
    # the gains each step ran: numpy.interp of the table at the setpoint of that step (held outside the table)
    bp = np.array([r[0] for r in ROWS])
    for key in ("Kp", "Ti", "Td"):
        expected = np.interp(via_table.scheduling_value, bp, [r[1][key][0] for r in ROWS])
        assert np.array_equal(via_policy["gains"][key][:, 0], expected), key


def test_the_bands_act_around_the_table_at_the_scheduling_value():
    config = preset("two_tank")
    table = _table(config)
    loop = config.loops[0]
    m = ScheduledActionMap(config.loops, table, AnchorBands(Kp=3.0, Ti=2.0, Td=0.1))
    z = 8.0  # halfway between 6 and 10 cm: Kp0 = 6.5, Ti0 = 42.5, Td0 = 0.2
    Kp, Ti, Td, coupling = m.values_at([1.0, -1.0, 0.5], z)
    assert coupling is None
    assert Kp[0] == pytest.approx(6.5 * 3.0, rel=1e-14)
    assert Ti[0] == pytest.approx(42.5 / 2.0, rel=1e-14)
    assert Td[0] == pytest.approx(0.2 + 0.5 * 0.1 * (loop.Td.high - loop.Td.low), rel=1e-14)
    # the last row's Kp (60) lies above the loop's range (50): action 0 keeps it, a larger action cannot exceed it
    assert m.values_at([0.0, 0.0, 0.0], 14.0)[0] == [60.0]
    assert m.values_at([1.0, 0.0, 0.0], 20.0)[0] == [60.0]
    assert m.values_at([-1.0, 0.0, 0.0], 14.0)[0][0] == pytest.approx(20.0, rel=1e-14)


def test_tune_anchors_on_the_classical_schedule_unless_the_scenario_says_fixed_pid(tmp_path):
    scenario = load_scenario(scenario_path("two_tank"))
    assert scenario.tuning.anchor_on == "auto"
    table = _table(scenario.tuning)
    fixed = DesignResult.from_json({"gains": {"Kp": [7.0], "Ti": [40.0], "Td": [0.1]}})
    assert training_anchor(scenario, fixed, table) is table
    assert anchor_name(table) == "classical gain schedule"
    on_fixed = dataclasses.replace(scenario, tuning=dataclasses.replace(scenario.tuning, anchor_on="fixed_pid"))
    anchor = training_anchor(on_fixed, fixed, table)
    assert isinstance(anchor, Gains) and anchor.Kp.tolist() == [7.0] and anchor_name(anchor) == "fixed PID"
    absolute = dataclasses.replace(scenario, tuning=dataclasses.replace(scenario.tuning, gain_mapping="absolute"))
    assert training_anchor(absolute, fixed, table) is None and anchor_name(None) is None
    # a finished run gives back the anchor it trained around: the classical table from its CSV, bit for bit
    write_schedule_csv(table, tmp_path / "classical_schedule.csv")
    (tmp_path / "run.json").write_text(json.dumps({"anchor": "classical gain schedule"}))
    back = run_anchor(tmp_path, scenario, fixed)
    for key in ("breakpoints", "Kp", "Ti", "Td"):
        assert np.array_equal(getattr(back, key), getattr(table, key)), key
    (tmp_path / "run.json").write_text(json.dumps({"anchor": "fixed PID"}))
    assert isinstance(run_anchor(tmp_path, scenario, fixed), Gains)
    assert math.isfinite(back.gains_at(9.0)[0][0])


def test_anchor_on_is_a_scenario_option_with_one_clear_error(tmp_path, capsys):
    import yaml

    from prlpid_fmi.cli import main

    data = yaml.safe_load(scenario_path("first_order").read_text())
    data.setdefault("controller", {})["anchor_on"] = "classical"
    data["plant"]["fmu"] = "FirstOrderUnstable"
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(data))
    try:
        code = main(["validate", str(bad)])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert "anchor_on" in err and "classical" in err and "fixed_pid" in err and "Traceback" not in err
    data["controller"]["anchor_on"] = "fixed_pid"
    bad.write_text(yaml.safe_dump(data))
    assert load_scenario(bad).tuning.anchor_on == "fixed_pid"
