"""Detuning a fixed PID onto the Ms limit (baseline.detune), checked against python-control's exact loop."""
import control
import numpy as np
import pytest

from prlpid_fmi.tuning.fixed_pid import DETUNE_STEP, detune
from prlpid_fmi.robustness.margins import operating_point
from prlpid_fmi.scenario.presets import preset
from tests.test_margins import first_order_zoh, pid_by_hand, reference_margins

CONFIG = preset("first_order")  # 1/(s - 1), Ts = 0.1 s
AGGRESSIVE = ([8.0], [0.3], [0.05], None)  # a stable loop with Ms about 7.5 on 1/(s - 1)


def exact_ms(gains):
    """Ms of the exact discrete loop; the closed loop must be stable for Ms to mean anything."""
    Kp, Ti, Td, _ = gains
    loop = pid_by_hand(Kp[0], Ti[0], Td[0]) * first_order_zoh(1.0)
    assert np.all(np.abs(control.feedback(loop, 1).poles()) < 1.0)
    return reference_margins(loop)[0]


TOGETHER = ([12.0], [0.2], [0.01], None)  # Ms about 7.6; the together rule meets the limit from here


@pytest.mark.parametrize("start, keep_ti", [(TOGETHER, False), (AGGRESSIVE, True)])
def test_detuned_gains_meet_the_limit_by_a_small_margin(start, keep_ti):
    """Kp / lambda with Ti and Td * lambda (the same controller, lambda times slower), or with keep_ti Kp / lambda
    alone; either way the smallest lambda that meets Ms <= 2 on the exact loop."""
    assert exact_ms(start) > 2.5  # the starting point violates the limit, so the check can fail
    Kp, Ti, Td, _ = detuned = detune(CONFIG, start, operating_point(CONFIG), 2.0, keep_ti=keep_ti)
    lam = start[0][0] / Kp[0]
    factor = 1.0 if keep_ti else lam
    assert lam > 1.0
    assert Ti[0] == pytest.approx(start[1][0] * factor) and Td[0] == pytest.approx(start[2][0] * factor)
    assert exact_ms(detuned) <= 2.0 * 1.01
    # the smallest detuning found (bisection on k of lambda = DETUNE_STEP**k, resolution <= 1/16 of a scan
    # interval): a clearly smaller lambda still violates the limit
    less = lam / DETUNE_STEP ** 0.5
    factor = 1.0 if keep_ti else less
    fewer = ([start[0][0] / less], [start[1][0] * factor], [start[2][0] * factor], None)
    assert exact_ms(fewer) > 2.0


def test_the_together_rule_keeps_the_high_frequency_gain_so_kp_alone_must_cure_it():
    """Kp / lambda with Td * lambda keeps Kp * Td, the sampled loop's gain near Nyquist: on 1/(s - 1) with Td = 0.05 s
    (Ts = 0.1 s) no lambda meets Ms <= 2 (a small one keeps the high-frequency gain, a large one leaves Kp < 1
    and the unstable pole), while Kp / lambda alone does; detune_over (the load design's check) tries both."""
    from prlpid_fmi.tuning.fixed_pid import detune_over

    assert detune(CONFIG, AGGRESSIVE, operating_point(CONFIG), 2.0) is None
    repaired = detune_over(CONFIG, AGGRESSIVE, [operating_point(CONFIG)], 2.0)
    assert repaired is not None and repaired[2] == AGGRESSIVE[2] and exact_ms(repaired) <= 2.0 * 1.01


def test_range_points_are_the_ends_and_middle_of_every_loops_range():
    from prlpid_fmi.robustness.margins import setpoint_range_points

    assert setpoint_range_points(CONFIG) == [[-1.0], [0.0], [1.0]]  # first_order: setpoint_range [-1, 1]
    quadrotor = preset("quadrotor")  # three loops: they move together, low end to high end
    ranges = [l.setpoint_range for l in quadrotor.loops]
    assert len(ranges) == 3
    assert setpoint_range_points(quadrotor) == [[lo for lo, _ in ranges], [0.5 * (lo + hi) for lo, hi in ranges],
                                                 [hi for _, hi in ranges]]


def test_a_fixed_pid_is_detuned_until_it_meets_the_limit_at_every_operating_point(monkeypatch):
    """A plant whose Ms grows towards the high end of the range (Ms = Kp * (1 + setpoint) / 4, a stand-in for
    margins_of): meeting the limit at mid-range (setpoint 0) is not enough; the worst point decides."""
    import types

    import prlpid_fmi.tuning.fixed_pid as fixed_pid

    monkeypatch.setattr(fixed_pid, "margins_of", lambda config, g, p: types.SimpleNamespace(
        Ms=g[0][0] * (1 + p[0]) / 4, reliable=True, problems=()))
    points = [[-1.0], [0.0], [1.0]]
    start = ([8.0], [1.0], [0.0], None)  # Ms 0, 2, 4 at the three points
    at_mid = fixed_pid.detune(CONFIG, start, [0.0], 2.0)
    assert at_mid[0][0] * 2 / 4 > 2.0  # detuned at mid-range only, it still fails at the high end
    everywhere = fixed_pid.detune_over(CONFIG, start, points, 2.0)
    assert all(everywhere[0][0] * (1 + p[0]) / 4 <= 2.0 for p in points)
    assert everywhere[0][0] == pytest.approx(4.0, rel=0.1)  # just enough: Kp * 2/4 <= 2 at the high end
    assert fixed_pid.detune_over(CONFIG, start, [[0.0]], 2.0) == start  # already meets a mid-range-only limit


def test_the_ms_of_other_gains_is_predicted_from_the_plant_response_measured_once(run_context):
    """robustness.margins.predicted_ms: after one measurement at a point, the Ms of other PIDs there follows from the
    measured plant response alone; checked against python-control's exact loop on 1/(s - 1), and a PID too weak to
    hold the unstable plant (Kp < 1) is predicted unstable (Nyquist), not given the small |S| it has on the circle."""
    from prlpid_fmi.robustness.margins import margins_of, predicted_ms

    point = [0.5]
    assert predicted_ms(CONFIG, TOGETHER, point) is None  # nothing measured there yet
    margins_of(CONFIG, ([4.0], [1.0], [0.1], None), point)
    for gains in (TOGETHER, ([6.0], [0.5], [0.0], None), ([3.0], [2.0], [0.05], None)):
        assert predicted_ms(CONFIG, gains, point) == pytest.approx(exact_ms(gains), rel=5e-3)
    weak = ([0.6], [5.0], [0.0], None)
    loop = pid_by_hand(0.6, 5.0, 0.0) * first_order_zoh(1.0)
    assert np.any(np.abs(control.feedback(loop, 1).poles()) > 1.0)  # unstable: the prediction must say so
    assert predicted_ms(CONFIG, weak, point) == float("inf")


@pytest.mark.parametrize("start, keep_ti", [(TOGETHER, False), (AGGRESSIVE, True)])
def test_detune_with_predictions_finds_what_measurements_alone_find_with_fewer_experiments(monkeypatch, run_context,
                                                                                           start, keep_ti):
    """detune decides its scan and bisection from predicted Ms where they lie clearly on one side of the limit and
    measures the rest and its result: the same gains as the search on measurements alone, from fewer experiments."""
    import prlpid_fmi.robustness.margins as margins
    import prlpid_fmi.tuning.fixed_pid as fixed_pid

    point = [-0.5]
    measured = []
    real = margins.loop_margins
    monkeypatch.setattr(margins, "loop_margins", lambda *a, **k: measured.append(a[1:4]) or real(*a, **k))
    fixed_pid.margins_of(CONFIG, start, point)  # the caller has measured the gains it detunes
    fast = fixed_pid.detune(CONFIG, start, point, 2.0, keep_ti=keep_ti)
    with_predictions = len(measured)
    run_context.measured.clear()
    run_context.references.clear()
    monkeypatch.setattr(fixed_pid, "predicted_ms", lambda *a: None)
    slow = fixed_pid.detune(CONFIG, start, point, 2.0, keep_ti=keep_ti)
    assert fast == slow
    assert with_predictions < len(measured) - 1  # the measurement-only count includes the start's measurement again


def test_a_pid_too_weak_for_the_unstable_plant_costs_one_experiment_not_a_scan(monkeypatch, run_context):
    """1/(s - 1) with Kp 0.6 < 1: no detuning (Kp / lambda, Ti and Td * lambda) holds the plant (python-control: every
    loop of the scan unstable). With the plant response measured at the point before (another PID's experiment),
    detune predicts that no k passes, measures the k of least predicted Ms, and returns None after that one
    experiment instead of scanning on measurements."""
    import prlpid_fmi.robustness.margins as margins
    import prlpid_fmi.tuning.fixed_pid as fixed_pid

    point = [0.5]
    weak = ([0.6], [5.0], [0.0], None)
    for k in fixed_pid.DETUNE_SCAN:  # Kp / lambda < 0.6 < 1: unstable whatever Ti (clipped into its range or not)
        lam = DETUNE_STEP ** k
        loop = pid_by_hand(0.6 / lam, 5.0 * lam, 0.0) * first_order_zoh(1.0)
        assert np.any(np.abs(control.feedback(loop, 1).poles()) > 1.0)
    fixed_pid.margins_of(CONFIG, ([4.0], [1.0], [0.1], None), point)  # a verified response at the point
    measured = []
    real = margins.loop_margins
    monkeypatch.setattr(margins, "loop_margins", lambda *a, **k: measured.append(a[1:4]) or real(*a, **k))
    assert fixed_pid.detune(CONFIG, weak, point, 2.0) is None
    assert len(measured) == 1


def test_predictions_the_measurement_contradicts_do_not_end_the_detuning(monkeypatch, run_context):
    """Where every k is predicted to fail but the measurement of the most promising one misses its prediction by
    more than PREDICTION_TOLERANCE (a nonlinear plant's response changes with the PID; here a prediction of Ms 3
    for every PID), detune does not give up: it finds what the search on measurements alone finds, within the limit
    on python-control's exact loop."""
    import prlpid_fmi.tuning.fixed_pid as fixed_pid

    point = [-0.5]
    fixed_pid.margins_of(CONFIG, TOGETHER, point)
    monkeypatch.setattr(fixed_pid, "predicted_ms", lambda *a: 3.0)
    found = fixed_pid.detune(CONFIG, TOGETHER, point, 2.0)
    assert found is not None and exact_ms(found) <= 2.0 * 1.01
    monkeypatch.setattr(fixed_pid, "predicted_ms", lambda *a: None)
    assert found == fixed_pid.detune(CONFIG, TOGETHER, point, 2.0)


def test_a_measuring_pid_above_the_limit_is_made_robust_where_it_becomes_a_candidate(run_context):
    """The stabilising PID is measured with at up to design_rule.MEASURING_MS_FACTOR x the limit; robust_setpoint_pid
    (what a candidate or fallback built from it deploys) detunes it onto the limit, checked on the exact loop; one
    within the limit stays as it is."""
    from prlpid_fmi.loop.gains import gains_from_values
    from prlpid_fmi.tuning.design_rule import MEASURING_MS_FACTOR
    from prlpid_fmi.tuning.fixed_pid import FixedPid, robust_setpoint_pid

    loose = ([6.0], [0.4], [0.05], None)  # Ms 2.75 on the exact loop
    assert 2.0 < exact_ms(loose) <= MEASURING_MS_FACTOR * 2.0  # a measuring PID the looser limit lets through
    found = FixedPid(np.zeros(3), gains_from_values(*loose), 1.0, 10)
    robust = robust_setpoint_pid(CONFIG, found, [0], 2.0)
    gains = robust.gains.values()
    assert gains[0][0] < loose[0][0] and exact_ms(gains) <= 2.0 * 1.01
    assert robust.cost != found.cost  # its J on the seeds again, for the new gains
    fine = FixedPid(np.zeros(3), gains_from_values(*gains), robust.cost, 10)
    assert robust_setpoint_pid(CONFIG, fine, [0], 2.0) is fine
