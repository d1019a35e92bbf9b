"""Gain schedules: extraction from a policy, table interpolation, the CSV file, and the no-NN replay.

Truths used: the action -> gain maps written out by hand (log: low*(high/low)**frac, linear:
low + frac*(high - low), frac = (a + 1)/2), hand-interpolated table values, and the live policy's own
rollout (the replay of a constant-gain table must reproduce it bit for bit).
"""
import csv
import dataclasses

import numpy as np
import pytest

from prlpid_fmi import __version__
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.loop.evaluation import evaluate
from prlpid_fmi.scenario.presets import preset
from prlpid_fmi.tuning.schedule.table import INTERPOLATION, PID_EQUATION, GainSchedule
from prlpid_fmi.tuning.schedule.extraction import extract_schedule
from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv, read_schedule_metadata, write_schedule_csv
from prlpid_fmi.tuning.schedule.replay import replay_schedule

# first_order: Kp in [0.5, 30] log, Ti in [0.2, 20] log, Td in [0, 0.2] linear; setpoints in [-1, 1]
CONFIG = dataclasses.replace(preset("first_order"), smoothing="none",
                             setpoint_schedule=((0, (0.5,)), (80, (-0.5,))), episode_steps=160)
ACTION = np.array([0.1, -0.2, -0.6], np.float32)  # Kp 4.75, Ti 1.26 s, Td 0.04 s: settles


def kp_of(a):
    return 0.5 * (30.0 / 0.5) ** ((a + 1.0) / 2.0)


def ti_of(a):
    return 0.2 * (20.0 / 0.2) ** ((a + 1.0) / 2.0)


def td_of(a):
    return 0.0 + (a + 1.0) / 2.0 * 0.2


def constant(obs):
    return ACTION


def linear_kp(obs):
    """Kp action 0.5*r (obs[0] is the setpoint / measurement_scale = r), Ti action 0, Td action -1."""
    return np.array([0.5 * obs[0], 0.0, -1.0], np.float32)


def test_fixed_gain_policy_gives_its_gains_at_every_breakpoint():
    s = extract_schedule(constant, CONFIG, points=5, settle_steps=40)
    assert np.array_equal(s.breakpoints, np.linspace(-1.0, 1.0, 5))
    a = ACTION.astype(float)
    assert s.Kp.shape == (5, 1) and s.coupling is None
    assert s.Kp[:, 0] == pytest.approx([kp_of(a[0])] * 5, rel=1e-12)
    assert s.Ti[:, 0] == pytest.approx([ti_of(a[1])] * 5, rel=1e-12)
    assert s.Td[:, 0] == pytest.approx([td_of(a[2])] * 5, rel=1e-12)
    assert s.variable == "setpoint[y]" and s.loop_names == ("y",) and s.loop_inputs == ("u",)
    assert s.sample_time_s == 0.1 and s.anti_windup == "clamping"
    assert s.u_min.tolist() == [-10.0] and s.u_max.tolist() == [10.0]


def test_replay_of_a_fixed_gain_table_equals_the_live_policy_exactly(tmp_path):
    s = extract_schedule(constant, CONFIG, points=3, settle_steps=30)
    s = read_schedule_csv(write_schedule_csv(s, tmp_path / "schedule.csv"))  # through the file, as a PLC would
    metrics, traj = replay_schedule(s, CONFIG)
    live_metrics, live = evaluate(constant, CONFIG)
    for key in ("time_s", "setpoint", "measurement", "control_signal", "reward"):
        assert np.array_equal(traj[key], live[key]), key
    for key in ("Kp", "Ti", "Td"):
        assert np.array_equal(traj["gains"][key], live["gains"][key]), key
    assert metrics["overall"] == live_metrics["overall"]
    assert not traj["terminated"] and traj["scheduling_value"].tolist() == [0.5] * 80 + [-0.5] * 80


def test_setpoint_dependent_policy_gives_its_known_gain_function():
    points = [0.8, -0.6, 0.0, 0.3]  # unsorted on purpose
    s = extract_schedule(linear_kp, CONFIG, points=points, settle_steps=30)
    assert s.breakpoints.tolist() == sorted(points)
    assert s.Kp[:, 0] == pytest.approx([kp_of(0.5 * r) for r in sorted(points)], rel=1e-6)
    assert s.Ti[:, 0] == pytest.approx([ti_of(0.0)] * 4, rel=1e-12)
    assert np.all(s.Td == 0.0)


def test_replay_matches_a_setpoint_dependent_policy_at_breakpoints():
    # evaluation setpoints 0.5 and -0.5 lie on breakpoints of linspace(-1, 1, 5): the lookup is exact there
    s = extract_schedule(linear_kp, CONFIG, points=5, settle_steps=20)
    _, traj = replay_schedule(s, CONFIG)
    _, live = evaluate(linear_kp, CONFIG)
    assert np.allclose(traj["gains"]["Kp"], live["gains"]["Kp"], rtol=1e-6, atol=0)
    assert np.allclose(traj["measurement"], live["measurement"], rtol=1e-5, atol=1e-7)


def test_schedule_by_measurement_and_by_fmu_variable():
    by_meas = extract_schedule(constant, CONFIG, schedule_by="measurement", points=3, settle_steps=150)
    by_y = extract_schedule(constant, CONFIG, schedule_by="y", points=3, settle_steps=150)  # the FMU output
    assert by_meas.variable == "measurement[y]" and by_y.variable == "y"
    assert np.array_equal(by_meas.breakpoints, by_y.breakpoints)
    assert by_meas.breakpoints == pytest.approx([-1.0, 0.0, 1.0], abs=0.02)  # PI: settles on the setpoint
    with pytest.raises(PrlPidError):
        extract_schedule(constant, CONFIG, schedule_by="no_such_variable", points=2, settle_steps=5)


def test_variable_that_ignores_the_setpoint_collapses_to_one_row_with_its_unit():
    tv = dataclasses.replace(preset("time_varying"), smoothing="none")
    with pytest.warns(UserWarning, match="distinct breakpoint"):
        s = extract_schedule(constant, tv, schedule_by="a_t", points=3, settle_steps=30)
    assert s.unit == "1/s" and s.breakpoints.shape == (1,) and s.Kp.shape == (1, 1)
    assert s.Kp[0, 0] == pytest.approx(kp_of(float(ACTION[0])), rel=1e-12)


def test_diverging_operating_point_is_refused():
    unstable = lambda obs: np.array([-1.0, 1.0, -1.0], np.float32)  # Kp = 0.5 < 1 cannot hold 1/(s - 1)
    with pytest.warns(UserWarning, match="left out"), pytest.raises(PrlPidError, match="every operating point"):
        extract_schedule(unstable, CONFIG, points=[1.0], settle_steps=100)


def test_diverging_operating_points_are_left_out_and_named(tmp_path):
    def policy(obs):  # stable gains below setpoint 0.5, Kp = 0.5 (unstable for 1/(s - 1)) above
        return np.array([-1.0 if obs[0] > 0.5 else 0.5, 0.0, -1.0], np.float32)

    with pytest.warns(UserWarning, match="setpoint 1 "):
        s = extract_schedule(policy, CONFIG, points=[-1.0, 0.0, 1.0], settle_steps=100)
    assert s.excluded == (1.0,)
    np.testing.assert_allclose(s.breakpoints, [-1.0, 0.0], atol=1e-9)
    back = read_schedule_csv(write_schedule_csv(s, tmp_path / "s.csv"))
    assert back.excluded == (1.0,)
    assert "excluded_operating_points: 1.0" in (tmp_path / "s.csv").read_text()


def test_coupled_mimo_schedule_reports_every_loop_and_the_coupling(tmp_path):
    quad = dataclasses.replace(preset("quadrotor"), smoothing="none")
    action = np.linspace(-0.8, 0.8, 15).astype(np.float32)
    s = extract_schedule(lambda obs: action, quad, points=2, settle_steps=10)
    assert s.variable == "setpoint[phi]" and s.loop_names == ("phi", "theta", "psi")
    assert s.Kp.shape == (2, 3) and s.coupling.shape == (2, 6)
    assert s.coupling[0] == pytest.approx(-0.5 + (action[9:].astype(float) + 1) / 2, rel=1e-12)
    path = write_schedule_csv(s, tmp_path / "quad.csv")
    header = next(line for line in open(path) if not line.startswith("#")).strip().split(",")
    assert header[:6] == ["setpoint[phi]", "Kp[phi]", "Ti[phi]", "Td[phi]", "Ki[phi]", "Kd[phi]"]
    assert header[-6:] == ["c_rp", "c_ry", "c_pr", "c_py", "c_yr", "c_yp"]
    _assert_same(read_schedule_csv(path), s)


def _table(coupling=False):
    return GainSchedule(
        variable="h2", unit="cm", breakpoints=np.array([5.0, 10.0, 15.0]),
        Kp=np.array([[1.0, 2.0], [3.0, 4.0], [7.0, 2.0]]), Ti=np.array([[10.0, 1.0], [20.0, 1.0], [20.0, 3.0]]),
        Td=np.array([[0.0, 0.1], [0.5, 0.1], [1.0, 0.3]]),
        coupling=np.array([[0.1] * 6, [0.2] * 6, [-0.4] * 6]) if coupling else None,
        sample_time_s=0.1, loop_names=("h2", "h1"), loop_inputs=("q_in", "q_d"), output_units=("cm", "cm"),
        input_units=("cm3/s", "cm3/s"), anti_windup="back_calculation",
        u_min=np.array([0.0, -np.inf]), u_max=np.array([50.0, np.inf]), derivative_filter_N=8.0)


def test_gains_at_interpolates_linearly_and_clamps_at_the_ends():
    s = _table(coupling=True)
    kp, ti, td, c = s.gains_at(7.5)  # halfway between 5 and 10
    assert kp.tolist() == [2.0, 3.0] and ti.tolist() == [15.0, 1.0] and td.tolist() == [0.25, 0.1]
    assert c == pytest.approx([0.15] * 6)
    kp, ti, td, _ = s.gains_at(14.0)  # 80 % of the way from 10 to 15
    assert kp == pytest.approx([3.0 + 0.8 * 4.0, 4.0 - 0.8 * 2.0]) and td == pytest.approx([0.9, 0.26])
    for outside, row in ((-100.0, 0), (4.999, 0), (15.0, 2), (1e9, 2)):
        kp, ti, td, c = s.gains_at(outside)
        assert kp.tolist() == s.Kp[row].tolist() and ti.tolist() == s.Ti[row].tolist()
        assert td.tolist() == s.Td[row].tolist() and c.tolist() == s.coupling[row].tolist()
    assert len(_table().gains_at(10.0)) == 3


def _assert_same(a: GainSchedule, b: GainSchedule):
    for f in dataclasses.fields(GainSchedule):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(y, np.ndarray):
            assert x.dtype == y.dtype and np.array_equal(x, y), f.name
        else:
            assert x == y, f.name


def test_csv_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    s = _table(coupling=True)
    s.Kp = rng.uniform(0.1, 50, (3, 2)) / 3.0
    s.Ti = rng.uniform(1, 200, (3, 2)) / 7.0
    s.coupling = rng.uniform(-0.5, 0.5, (3, 6)) / 3.0
    s.breakpoints = np.array([5.0 / 3.0, 10.1, 1e-17 + 15.0])
    path = write_schedule_csv(s, tmp_path / "sub" / "s.csv")
    _assert_same(read_schedule_csv(path), s)
    s2 = _table()
    s2.derivative_filter_N, s2.unit, s2.output_units = None, "", ("", "")
    _assert_same(read_schedule_csv(write_schedule_csv(s2, tmp_path / "s2.csv")), s2)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["s.csv", "s2.csv", "sub"]  # no temp files left


def test_metadata_is_present_and_parseable_and_parallel_gains_are_consistent(tmp_path):
    path = write_schedule_csv(_table(), tmp_path / "s.csv")
    lines = path.read_text().splitlines()
    n_meta = next(i for i, line in enumerate(lines) if not line.startswith("# "))
    assert n_meta >= 10 and lines[0].startswith("# ")
    meta = read_schedule_metadata(path)
    assert meta["tool"] == f"prlpid-fmi {__version__}"
    assert PID_EQUATION in meta["pid_equation"] and "eq. 2" in meta["pid_form"]
    assert float(meta["sample_time_s"]) == 0.1
    assert meta["scheduling_variable"] == "h2" and meta["scheduling_unit"] == "cm"
    assert meta["interpolation"] == INTERPOLATION == "linear between breakpoints, held constant outside"
    assert meta["anti_windup"] == "back_calculation" and "Tt" in meta["anti_windup_method"]
    assert meta["loop[h2]"] == "input=q_in; u_min=0.0; u_max=50.0; output_unit=cm; input_unit=cm3/s"
    assert "u_min=-inf; u_max=inf" in meta["loop[h1]"]
    units = dict(part.split("=", 1) for part in meta["units"].split("; "))
    assert units["h2"] == "cm" and units["Ti[h2]"] == "s" and units["Kp[h2]"] == "(cm3/s)/cm"
    assert units["Ki[h1]"] == "(cm3/s)/(cm*s)" and units["Kd[h1]"] == "(cm3/s)*s/cm"
    rows = list(csv.DictReader(lines[n_meta:]))  # a plain CSV reader after the comment lines
    assert len(rows) == 3 and set(units) == set(rows[0])
    for row in rows:
        for loop in ("h2", "h1"):
            kp, ti, td = (float(row[f"{p}[{loop}]"]) for p in ("Kp", "Ti", "Td"))
            assert float(row[f"Ki[{loop}]"]) == kp / ti and float(row[f"Kd[{loop}]"]) == kp * td


def test_edited_file_with_stale_parallel_gains_is_refused(tmp_path):
    path = write_schedule_csv(_table(), tmp_path / "s.csv")
    text = path.read_text().replace("\n10.0,3.0,", "\n10.0,3.5,")  # Kp[h2] of row 2 edited, Ki left
    path.write_text(text)
    with pytest.raises(PrlPidError, match="Ki/Kd"):
        read_schedule_csv(path)


def test_replay_refuses_a_table_for_other_loops():
    with pytest.raises(PrlPidError, match="loops"):
        replay_schedule(_table(), CONFIG)


def test_points_that_fail_for_one_reason_get_one_warning_naming_them_all():
    """Setpoints failing alike once printed one warning each; now one per distinct reason. On the linear
    1/(s - 1) from x = 0, setpoints -1 and 1 diverge at the same sample (mirror images)."""
    import warnings

    unstable = lambda obs: np.array([-1.0, 1.0, -1.0], np.float32)  # Kp = 0.5 < 1 cannot hold 1/(s - 1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(PrlPidError, match="every operating point"):
            extract_schedule(unstable, CONFIG, points=[-1.0, 1.0], settle_steps=100)
    texts = [str(w.message) for w in caught if "left out of the schedule" in str(w.message)]
    assert len(texts) == 1, texts
    assert texts[0].startswith("the closed loop failed at setpoint[y] 2 setpoints (-1, 1) (diverged"), texts[0]
    assert texts[0].endswith("they are left out of the schedule")
