"""Gain schedules that carry transients: error[<loop>] tables, trajectory binning, the Ms rule, tune's choice.

Truths used: the exact ZOH discretisation of 1/(s - 1) (y+ = e^Ts*y + (e^Ts - 1)*u) closed by the
positional PID of eq. 2 written out by hand with gains interpolated from the table by hand; equal-count
bins and medians computed by hand; the action -> gain map written out by hand (log: low*(high/low)**frac);
the Ms limit checked on the projected rows with the margin estimate that was validated against exact
transfer functions in test_margins.py.
"""
import dataclasses
import math

import numpy as np
import pytest

from prlpid_fmi.deliver.evidence import assess_schedule, range_points
from prlpid_fmi.deliver.candidates import robust_schedule
from prlpid_fmi.robustness.margins import margins_of
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.scenario.presets import preset, scenario_path
from prlpid_fmi.scenario.load import load_scenario, scenario_to_yaml
from prlpid_fmi.tuning.schedule.table import GainSchedule, schedule_from_rows
from prlpid_fmi.tuning.schedule.extraction import extract_schedule
from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv, read_schedule_metadata, write_schedule_csv
from prlpid_fmi.tuning.schedule.replay import replay_schedule
from prlpid_fmi.tuning.schedule.trajectories import bin_rows, trajectory_schedule
from prlpid_fmi.deliver.candidates import deliverable_schedule
from prlpid_fmi.tuning.schedule.extraction import extract
from prlpid_fmi.tuning.schedule.replay import training_ise

TS = 0.1
# first_order, 1/(s - 1): Kp in [0.5, 30] log, Ti in [0.2, 20] log, Td in [0, 0.2] linear; u in [-10, 10]
PLAIN = dataclasses.replace(preset("first_order"), smoothing="none", forecast_horizon=0, episode_steps=120,
                            setpoint_schedule=((0, (0.5,)), (60, (-0.4,))))


def error_table(breakpoints, Kp, Ti, Td, config=PLAIN) -> GainSchedule:
    rows = lambda a: np.array(a, float).reshape(-1, 1)  # noqa: E731
    return GainSchedule(
        variable="error[y]", unit="", breakpoints=np.array(breakpoints, float), Kp=rows(Kp), Ti=rows(Ti), Td=rows(Td),
        coupling=None, sample_time_s=TS, loop_names=("y",), loop_inputs=("u",), output_units=("",),
        input_units=("",), anti_windup="clamping", u_min=np.array([-10.0]), u_max=np.array([10.0]))


def hand_replay(table: GainSchedule, setpoints: list[float]):
    """Closed loop by hand: 1/(s-1) discretised exactly, the table looked up at e = r - y, PID of eq. 2
    with clamping anti-windup; returns (u, y, e) per sample."""
    a = math.exp(TS)
    y, integral, e_prev = 0.0, 0.0, None
    us, ys, es = [], [], []
    bp = table.breakpoints
    for r in setpoints:
        e = r - y
        kp, ti, td = (float(np.interp(e, bp, col[:, 0])) for col in (table.Kp, table.Ti, table.Td))
        e_prev = e if e_prev is None else e_prev
        trial = integral + e * TS
        u_unsat = kp * (e + td * (e - e_prev) / TS) + kp / ti * trial
        u = min(max(u_unsat, -10.0), 10.0)
        if u != u_unsat and (u_unsat - u) * (kp * e) > 0:
            trial = integral
        integral, e_prev = trial, e
        us.append(u), ys.append(y), es.append(e)
        y = a * y + (a - 1.0) * u
    return np.array(us), np.array(ys), np.array(es)


TABLE = error_table([-0.3, 0.0, 0.3], Kp=[24.0, 3.0, 26.0], Ti=[1.0, 2.0, 0.8], Td=[0.02, 0.0, 0.05])


def test_error_table_replays_as_the_hand_computed_closed_loop(tmp_path):
    table = read_schedule_csv(write_schedule_csv(TABLE, tmp_path / "error.csv"))  # through the file
    _, traj = replay_schedule(table, PLAIN)
    setpoints = [0.5] * 60 + [-0.4] * 60
    u, y, e = hand_replay(TABLE, setpoints)
    assert not traj["terminated"] and len(traj["pid_output"]) == 120
    r_k, y_k = traj["setpoint"][:120, 0], traj["measurement"][:120, 0]  # the samples before each step
    # the lookup reads e = r - y exactly as the PID does, and the gains are np.interp of that
    assert np.array_equal(traj["scheduling_value"], r_k - y_k)
    assert np.allclose(y_k, y, rtol=0, atol=1e-7)
    assert np.allclose(traj["pid_output"][:, 0], u, rtol=0, atol=1e-6)
    assert np.allclose(traj["scheduling_value"], e, rtol=0, atol=1e-7)
    # the run exercises what it claims: saturation, both outer rows, and the middle row near e = 0
    assert np.any(np.abs(u) == 10.0)
    assert e.max() > 0.3 and e.min() < -0.3 and np.any(np.abs(e) < 0.05)
    assert len(np.unique(np.round(traj["gains"]["Kp"][:, 0], 9))) > 10


def test_error_table_csv_round_trip_is_exact_and_self_describing(tmp_path):
    path = write_schedule_csv(TABLE, tmp_path / "error.csv")
    back = read_schedule_csv(path)
    assert back.variable == "error[y]"
    for key in ("breakpoints", "Kp", "Ti", "Td", "u_min", "u_max"):
        assert np.array_equal(getattr(back, key), getattr(TABLE, key)), key
    meta = read_schedule_metadata(path)
    assert meta["scheduling_variable"] == "error[y]"
    assert path.read_text().splitlines()[len(meta)].split(",")[0] == "error[y]"


def test_settled_holds_refuse_the_error_variable():
    with pytest.raises(PrlPidError, match="trajectories"):
        extract_schedule(lambda obs: np.zeros(3, np.float32), PLAIN, schedule_by="error", points=3, settle_steps=5)


def test_equal_count_bins_give_hand_computed_medians():
    values = np.array([5.0, 1.0, 3.0, 2.0, 4.0, 6.0, 0.0])
    kp = np.array([[50.0], [10.0], [30.0], [20.0], [40.0], [60.0], [0.0]])  # 10 x value
    rows = bin_rows(values, {"Kp": kp}, 3)
    # sorted: 0 1 2 | 3 4 | 5 6 (np.array_split of 7 into 3: sizes 3, 2, 2)
    assert [r[0] for r in rows] == [1.0, 3.5, 5.5]
    assert [float(r[1]["Kp"][0]) for r in rows] == [10.0, 35.0, 55.0]
    with pytest.raises(PrlPidError):
        bin_rows(np.array([]), {"Kp": np.zeros((0, 1))}, 3)


def kp_of(a):
    return 0.5 * (30.0 / 0.5) ** ((a + 1.0) / 2.0)


def kp_action(e):
    """Kp action of error_policy: increasing in e, Kp between 3.15 and 16.2 (1/(s - 1) needs Kp > 1)."""
    return 0.3 + 0.4 * np.tanh(e)


def error_policy(obs):
    """Kp action kp_action(e) (obs[2] = e / measurement_scale = e), Ti action 0, Td action -1 (Td = 0)."""
    return np.array([kp_action(obs[2]), 0.0, -1.0], np.float32)


# training distribution of first_order: random setpoints in [-1, 1] held 100 samples, 200-sample episodes
TRAINING = dataclasses.replace(preset("first_order"), smoothing="none")


def test_trajectory_table_follows_a_policy_that_adapts_to_the_error():
    s = trajectory_schedule(error_policy, TRAINING, points=7, episodes=3, seed=1)
    assert s.variable == "error[y]" and 3 <= len(s.breakpoints) <= 7  # bins at rest (e = 0 exactly) merge
    assert np.all(np.diff(s.breakpoints) > 0)
    assert s.breakpoints[0] < 0.0 < s.breakpoints[-1]  # transients of both signs have rows
    # the median of a monotone function of e is that function of the median e (up to the two middle
    # samples of an even bin): each row's Kp is the policy's Kp at (about) the row's error
    expected = kp_of(kp_action(s.breakpoints))
    assert s.Kp[:, 0] == pytest.approx(expected, rel=0.05)
    assert np.all(np.diff(s.Kp[:, 0]) >= 0)
    assert np.allclose(s.Ti[:, 0], 0.2 * 100 ** 0.5, rtol=1e-6) and np.all(s.Td == 0.0)


def test_a_constant_policy_gives_its_gains_in_every_row_and_other_variables_work():
    action = np.array([0.1, -0.2, -0.6], np.float32)
    s = trajectory_schedule(lambda obs: action, TRAINING, schedule_by="measurement", points=4, episodes=2)
    assert s.variable == "measurement[y]" and s.breakpoints.shape == (4,)
    assert s.Kp[:, 0] == pytest.approx([kp_of(float(action[0]))] * 4, rel=1e-12)
    # the extraction's episodes come from the training distribution, not from a fixed schedule
    assert s.breakpoints[-1] - s.breakpoints[0] > 0.2


def test_extract_dispatches_error_to_trajectories_and_setpoint_to_settled_holds():
    by_error = extract(error_policy, TRAINING, "error[y]", 5, 0)
    by_setpoint = extract(error_policy, TRAINING, "setpoint", 3, 0)
    assert by_error.variable == "error[y]" and 2 <= len(by_error.breakpoints) <= 5
    assert by_setpoint.breakpoints.tolist() == [-1.0, 0.0, 1.0]  # held setpoints


def test_every_row_of_an_error_table_is_projected_onto_the_limit_over_the_setpoint_range():
    limit = 2.0
    table = error_table([-0.5, 0.0, 0.5], Kp=[28.0, 4.0, 28.0], Ti=[0.3, 2.0, 0.3], Td=[0.0, 0.0, 0.0],
                        config=TRAINING)
    points = range_points(TRAINING, 0)
    assert points == [[-1.0], [0.0], [1.0]]
    before = [max(margins_of(TRAINING, _row(table, j), p).Ms for p in points) for j in range(3)]
    assert before[0] > limit and before[1] <= limit  # the outer rows fail, the middle one passes
    projected, notes = robust_schedule(table, TRAINING, limit)
    assert len(notes) == 2 and notes[0].startswith("row -0.5")
    assert projected.Kp[1, 0] == 4.0 and projected.Ti[1, 0] == 2.0  # a row that meets the limit is untouched
    for j in (0, 2):  # detuned (Kp down, Ti up) until the row meets the limit at every operating point
        assert projected.Kp[j, 0] < 28.0 and projected.Ti[j, 0] > 0.3
        assert all(margins_of(TRAINING, _row(projected, j), p).Ms <= limit for p in points)


def _row(s: GainSchedule, j: int) -> tuple:
    return ([float(s.Kp[j, 0])], [float(s.Ti[j, 0])], [float(s.Td[j, 0])], None)


def test_assessment_measures_every_row_and_the_error_zero_gains_at_every_point():
    scenario = load_scenario(scenario_path("first_order"))
    table = error_table([-0.2, 0.3], Kp=[5.0, 7.0], Ti=[2.0, 1.5], Td=[0.0, 0.0])
    cand = assess_schedule(scenario, table)
    assert len(cand.margins) == 3 * 3  # (2 rows + gains at e = 0) x 3 setpoints
    assert cand.breakpoints == [f"{row} at {point:g}" for row in ("row 1", "row 2", "error 0") for point in (-1, 0, 1)]
    at_zero = ([float(np.interp(0.0, [-0.2, 0.3], [5.0, 7.0]))], [float(np.interp(0.0, [-0.2, 0.3], [2.0, 1.5]))],
               [0.0], None)
    assert cand.margins[-2].Ms == pytest.approx(margins_of(scenario.tuning, at_zero, [0.0]).Ms, rel=1e-9)


def test_scenario_option_schedule_by_loads_resolves_and_drives_the_candidates(tmp_path):
    text = scenario_path("first_order").read_text()
    assert load_scenario(scenario_path("first_order")).deploy.schedule_by == "auto"
    file = tmp_path / "s.yaml"
    file.write_text(text + "deploy: {schedule_by: error, schedule_points: 5}\n")
    scenario = load_scenario(file)
    assert scenario.deploy.schedule_by == "error"
    assert "schedule_by: error" in scenario_to_yaml(scenario)
    scenario = dataclasses.replace(scenario, tuning=TRAINING)
    choice = deliverable_schedule(error_policy, scenario, seed=0)
    assert choice.table.variable == "error[y]" and choice.training_ise is None  # one kind asked for: no comparison


def test_auto_keeps_the_candidate_with_the_lower_training_ise():
    scenario = load_scenario(scenario_path("first_order"))
    scenario = dataclasses.replace(scenario, tuning=TRAINING, deploy=dataclasses.replace(
        scenario.deploy, schedule_points=3, max_sensitivity=1e3))  # no projection: compare the raw tables
    choice = deliverable_schedule(error_policy, scenario, seed=0)
    schedule, note, scores = choice.table, choice.note, choice.training_ise
    assert set(scores) == {"setpoint", "error"}
    assert schedule.variable == ("error[y]" if scores["error"] < scores["setpoint"] else "setpoint[y]")
    assert "deploy.schedule_by: auto" in note
    # the score is the replay's ISE on the selection episodes, independent of the evaluation
    again = extract(error_policy, TRAINING, "error" if schedule.variable.startswith("error") else "setpoint", 3, 0)
    assert training_ise(again, TRAINING, 0) == pytest.approx(min(scores.values()), rel=1e-12)


def test_rows_closer_than_the_resolution_become_one():
    rows = [(0.0, {"Kp": np.array([2.0]), "Ti": np.array([1.0]), "Td": np.array([0.0])}),
            (1e-6, {"Kp": np.array([4.0]), "Ti": np.array([3.0]), "Td": np.array([0.1])}),
            (0.5, {"Kp": np.array([8.0]), "Ti": np.array([1.0]), "Td": np.array([0.0])})]
    meta = dict(loop_inputs=("u",), output_units=("",), input_units=("",))
    with pytest.warns(UserWarning, match="2 distinct"):
        s = schedule_from_rows(PLAIN, "error[y]", "", rows, meta, resolution=1e-3)
    assert s.breakpoints.tolist() == [5e-7, 0.5]
    assert s.Kp[:, 0].tolist() == [3.0, 8.0] and s.Ti[:, 0].tolist() == [2.0, 1.0] and s.Td[:, 0].tolist() == [0.05, 0.0]
    assert schedule_from_rows(PLAIN, "error[y]", "", rows, meta).breakpoints.shape == (3,)  # default: exact only


def test_a_row_whose_margins_cannot_be_judged_is_not_detuned(monkeypatch):
    # 1/(s - a(t)), a(t) = 0.5 + 0.25 (sin(0.2 pi t) + 1): no frequency response exists, so the multisine
    # estimate is finite but flagged unreliable; the deliverable's rule (deliver.meets) cannot judge it, so
    # robust_schedule measures the row once per operating point and spends no detuning scan on it.
    import prlpid_fmi.deliver.candidates as assess
    import prlpid_fmi.tuning.fixed_pid as baseline
    from prlpid_fmi.deliver.rule import counts

    config = preset("time_varying")
    table = error_table([0.0], Kp=[2.0], Ti=[1.0], Td=[0.0], config=config)
    seen, detunes = [], []
    monkeypatch.setattr(assess, "margins_of", lambda *a: seen.append(margins_of(*a)) or seen[-1])
    monkeypatch.setattr(baseline, "detune", lambda *a, **k: detunes.append(a))
    projected, notes = robust_schedule(table, config, 2.0)
    assert len(seen) == len(range_points(config, 0))
    # the premise: finite and unreliable everywhere, above the limit somewhere (the old rule detuned it)
    assert all(math.isfinite(m.Ms) and not counts(m) for m in seen) and max(m.Ms for m in seen) > 2.0
    assert detunes == [] and notes == []
    assert projected.Kp.tolist() == table.Kp.tolist() and projected.Ti.tolist() == table.Ti.tolist()


def test_a_setpoint_table_is_made_robust_between_its_breakpoints_too():
    """Two rows within a limit of 2.8 on 1/(s - 1) (Ms 2.70 and less, by python-control), but the gains halfway
    between them, which the PID runs at setpoint 0, have Ms 2.91: robust_schedule detunes both neighbours by the
    lambda the halfway gains need (Kp / lambda, Ti and Td * lambda commute with linear interpolation), so the
    halfway gains meet the limit."""
    from test_load_design import sensitivity_peak

    from prlpid_fmi.deliver.candidates import robust_schedule

    config = preset("first_order")
    rows = [(6.0, 0.5, 0.05), (10.0, 0.2, 0.0)]
    assert all(sensitivity_peak(1.0, *r) <= 2.71 for r in rows)
    assert sensitivity_peak(1.0, 8.0, 0.35, 0.025) > 2.9
    col = lambda i: np.array([[r[i]] for r in rows])  # noqa: E731
    table = GainSchedule(
        variable="setpoint[y]", unit="", breakpoints=np.array([-1.0, 1.0]), Kp=col(0), Ti=col(1), Td=col(2),
        coupling=None, sample_time_s=TS, loop_names=("y",), loop_inputs=("u",), output_units=("",),
        input_units=("",), anti_windup="clamping", u_min=np.array([-10.0]), u_max=np.array([10.0]))
    robust, notes = robust_schedule(table, config, 2.8)
    lam = table.Kp[:, 0] / robust.Kp[:, 0]
    assert lam[0] == pytest.approx(lam[1], rel=1e-12) and lam[0] > 1.0
    np.testing.assert_allclose(robust.Ti[:, 0], table.Ti[:, 0] * lam[0], rtol=1e-12)
    np.testing.assert_allclose(robust.Td[:, 0], table.Td[:, 0] * lam[0], rtol=1e-12)
    kp, ti, td = (float(g[0]) for g in robust.gains_at(0.0)[:3])
    assert sensitivity_peak(1.0, kp, ti, td) <= 2.8 * 1.01
    assert len(notes) == 1 and "rows -1 and 1" in notes[0]


def test_a_row_predicted_clearly_within_the_limit_costs_no_experiment(monkeypatch, run_context):
    """1/(s - 1), an error table whose middle row has Ms 1.26 by python-control (limit 2) and outer rows above it:
    with the plant's response measured at each operating point before (another PID's experiments), robust_schedule
    passes the middle row on its predicted Ms without an experiment and still detunes the outer rows onto the limit."""
    from test_load_design import sensitivity_peak

    import prlpid_fmi.robustness.margins as margins

    limit, middle = 2.0, (4.0, 2.0, 0.0)
    assert sensitivity_peak(1.0, *middle) < 0.9 * limit and sensitivity_peak(1.0, 12.0, 0.2, 0.0) > limit
    table = error_table([-0.5, 0.0, 0.5], Kp=[12.0, middle[0], 12.0], Ti=[0.2, middle[1], 0.2], Td=[0.0] * 3,
                        config=TRAINING)
    points = range_points(TRAINING, 0)
    for p in points:
        margins_of(TRAINING, ([3.0], [1.0], [0.0], None), p)  # a verified response at every point
    measured = []
    real = margins.loop_margins
    monkeypatch.setattr(margins, "loop_margins", lambda *a, **k: measured.append(a[1:4]) or real(*a, **k))
    projected, notes = robust_schedule(table, TRAINING, limit)
    assert ([4.0], [2.0], [0.0]) not in measured  # the middle row: predicted, not measured
    assert projected.Kp[1, 0] == 4.0 and len(notes) == 2
    for j in (0, 2):
        assert sensitivity_peak(1.0, projected.Kp[j, 0], projected.Ti[j, 0], 0.0) <= limit * 1.01
