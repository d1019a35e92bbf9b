"""Robustness margins measured on the FMU against exact references.

References come from outside the code under test: the plant's exact ZOH discretisation
(python-control c2d) or a hand linearisation of the Modelica equations, times the PID of eq. 2
written out by hand below, evaluated by python-control on a fine frequency grid.
"""
import dataclasses
import math

import control
import numpy as np
import pytest
from scipy.signal import lfilter

from prlpid_fmi.control.pid import PID
from prlpid_fmi.robustness.identification import ClosedLoopRig, measure_response
from prlpid_fmi.robustness.margins import Margins, format_margins, loop_margins, pid_transfer_function
from prlpid_fmi.scenario.presets import preset

TS = 0.1


def pid_by_hand(Kp, Ti, Td, Ts=TS, N=None):
    """Eq. 2: u = Kp (e + Ts/Ti sum e + Td Df), Df = backward-Euler low pass (Td/N) of the backward difference."""
    z = control.tf([1, 0], [1], Ts)
    Tf = Td / N if N else 0.0
    C = 1 + Td * (z - 1) / ((Tf + Ts) * z - Tf)
    if math.isfinite(Ti):
        C = C + (Ts / Ti) * z / (z - 1)
    return Kp * C


def first_order_zoh(a, Ts=TS):
    return control.c2d(control.tf([1.0], [1.0, -a]), Ts, "zoh")


def two_tank_zoh(h2, Ts=TS):
    """TwoTank.mo linearised at level h2 [cm] (steady inflow k2 sqrt(h2)), input q_in, output h2."""
    A1 = A2 = 15.52
    k1, k2 = 10.74, 7.89
    q = k2 * math.sqrt(h2)
    g1 = k1 / (2 * (q / k1))         # d q12 / d(h1 - h2) = k1 / (2 sqrt(h1 - h2)), sqrt(h1 - h2) = q / k1
    g2 = k2 / (2 * math.sqrt(h2))
    A = [[-g1 / A1, g1 / A1], [g1 / A2, -(g1 + g2) / A2]]
    return control.c2d(control.ss2tf(control.ss(A, [[1 / A1], [0.0]], [[0.0, 1.0]], [[0.0]])), Ts, "zoh")


def reference_margins(L, Ts=TS):
    """(Ms, gain margin, phase margin) of a discrete loop transfer function on a fine grid.

    Ms: max |1/(1+L)| on 40 000 log-spaced points; margins: python-control's frequency-data margins
    on 4 000 of them (they agree with its exact polynomial method to 1e-8 here); the crossings at DC
    and at Nyquist (where L is real) are added by hand; as python-control does, the gain margin
    closest to 1 and the smallest |phase margin| are kept.
    """
    w = np.geomspace(1e-5, np.pi / Ts, 40_000)
    Lw = L(np.exp(1j * w * Ts))
    Ms = float(np.max(np.abs(1 / (1 + Lw))))
    gm, pm, *_ = control.stability_margins(control.frd(Lw[::10], w[::10]), returnall=True)
    gms = list(np.atleast_1d(gm))
    for z in (1.0, -1.0):
        value = complex(L(z, warn_infinite=False))  # inf/nan at z = 1 with integral action
        if np.isfinite(value) and value.real < 0:
            gms.append(1 / abs(value.real))
            if z == 1.0:
                Ms = max(Ms, abs(1 / (1 + value.real)))
    gm = gms[int(np.argmin(np.abs(np.log(gms))))] if gms else math.inf
    pm = float(np.atleast_1d(pm)[np.argmin(np.abs(pm))]) if len(np.atleast_1d(pm)) else math.inf
    return Ms, gm, pm


def assert_close_margins(m, ref, gm_rel=0.01, pm_deg=1.0):
    Ms, gm, pm = ref
    assert m.reliable, m.note
    assert m.Ms == pytest.approx(Ms, rel=0.01)
    assert m.gain_margin == pytest.approx(gm, rel=gm_rel)
    assert abs(m.phase_margin_deg - pm) <= pm_deg


@pytest.mark.parametrize("Kp, Ti, Td, N", [(3.0, 2.0, 0.05, None), (2.0, math.inf, 0.3, 8.0), (1.5, 0.7, 0.0, None)])
def test_pid_transfer_function_is_the_implemented_pid(Kp, Ti, Td, N):
    """C(z) reproduces pid.py sample by sample on an arbitrary error sequence starting at 0."""
    rng = np.random.default_rng(0)
    e = np.concatenate([[0.0], rng.normal(size=300)])
    pid = PID(TS, derivative_filter_N=N)
    u = [pid.step_error(ek, Kp, Ti, Td)[0] for ek in e]
    C = pid_transfer_function(Kp, Ti, Td, TS, N)
    np.testing.assert_allclose(lfilter(C.num[0][0], C.den[0][0], e), u, rtol=1e-10, atol=1e-10)
    w = np.geomspace(1e-3, np.pi / TS, 50)
    z = np.exp(1j * w * TS)
    np.testing.assert_allclose(C(z), pid_by_hand(Kp, Ti, Td, N=N)(z), rtol=1e-12)


@pytest.mark.parametrize("scenario, a, gains", [
    ("first_order", 1.0, (3.0, 2.0, 0.05)),
    ("first_order", 1.0, (12.0, 3.0, 0.0)),       # upper gain margin at Nyquist
    ("first_order_1p5", 1.5, (3.0, 2.0, 0.05)),
    ("first_order_1p5", 1.5, (4.0, 1.5, 0.1)),
])
def test_unstable_first_order_matches_exact_zoh_loop(scenario, a, gains):
    Kp, Ti, Td = gains
    m = loop_margins(preset(scenario), [Kp], [Ti], [Td], [1.0])
    L = pid_by_hand(Kp, Ti, Td) * first_order_zoh(a)
    assert_close_margins(m, reference_margins(L))
    # the measured plant is the ZOH discretisation (u_k from y_k, held one sample, then y_{k+1})
    P = first_order_zoh(a)(np.exp(1j * m.frequencies_rad_s * TS))
    np.testing.assert_allclose(m.plant_response, P, rtol=1e-6)
    assert m.frequencies_rad_s[-1] == pytest.approx(np.pi / TS)


def test_derivative_filter_is_in_the_loop_transfer():
    config = dataclasses.replace(preset("first_order_1p5"), derivative_filter_N=5.0)
    m = loop_margins(config, [4.0], [1.5], [0.15], [0.5])
    L = pid_by_hand(4.0, 1.5, 0.15, N=5.0) * first_order_zoh(1.5)
    assert_close_margins(m, reference_margins(L))
    unfiltered = loop_margins(preset("first_order_1p5"), [4.0], [1.5], [0.15], [0.5])
    assert abs(unfiltered.Ms - m.Ms) > 0.05 * m.Ms  # the filter changes the answer measurably


def test_nearly_unstable_gain_has_large_ms_and_ordering_holds():
    """Kp just above the stabilising minimum of 1/(s - 1): Ms ~ 7, against Ms ~ 1.4 for a good PID."""
    config = preset("first_order")
    weak = loop_margins(config, [1.15], [12.0], [0.0], [0.5])
    good = loop_margins(config, [3.0], [2.0], [0.05], [0.5])
    ref_weak = reference_margins(pid_by_hand(1.15, 12.0, 0.0) * first_order_zoh(1.0))
    assert ref_weak[0] > 5
    assert_close_margins(weak, ref_weak)
    assert weak.Ms > 3 * good.Ms


def test_peak_at_dc_and_lower_gain_margin_of_p_control():
    """P control of 1/(s - 1): |S| peaks at DC (1/(Kp - 1)) and the gain margin 1/Kp is at w = 0."""
    m = loop_margins(preset("first_order"), [1.1], [math.inf], [0.0], [0.0])
    assert_close_margins(m, reference_margins(pid_by_hand(1.1, math.inf, 0.0) * first_order_zoh(1.0)))
    assert m.Ms == pytest.approx(10.0, rel=0.01)
    assert m.gain_margin == pytest.approx(1 / 1.1, rel=1e-3)
    assert m.phase_crossover_rad_s == 0.0


@pytest.mark.parametrize("gains, level", [((5.0, 20.0, 0.0), 10.0), ((20.0, 10.0, 1.0), 10.0), ((2.0, 50.0, 0.0), 5.0)])
def test_two_tank_matches_its_linearisation(gains, level):
    Kp, Ti, Td = gains
    m = loop_margins(preset("two_tank"), [Kp], [Ti], [Td], [level])
    assert_close_margins(m, reference_margins(pid_by_hand(Kp, Ti, Td) * two_tank_zoh(level)))


def test_loop_at_a_time_on_the_coupled_quadrotor():
    """Each loop broken at its plant input with the other two closed by the coupled PID (eq. 26-27).

    Around a still attitude the plant is three double integrators 1/(I s^2); the reference solves the
    closed other loops at every frequency: u_j = C_j (-y_j + sum_k c_jk y_k), y = G u, u_i = 1.
    """
    config = preset("quadrotor")
    Kp, Ti, Td = [2.0, 1.5, 3.0], [5.0, 6.0, 8.0], [0.6, 0.5, 0.7]
    coupling = [0.1, -0.05, 0.0, 0.1, 0.05, 0.0]
    m = loop_margins(config, Kp, Ti, Td, [0.1, -0.1, 0.2], coupling=coupling)
    c_rp, c_ry, c_pr, c_py, c_yr, c_yp = coupling
    Cm = np.array([[0, c_rp, c_ry], [c_pr, 0, c_py], [c_yr, c_yp, 0]])
    inertia = [0.4, 0.4, 0.8]
    w = np.geomspace(1e-3, np.pi / TS, 20_000)
    z = np.exp(1j * w * TS)
    G = [control.c2d(control.tf([1.0], [I, 0, 0]), TS, "zoh")(z) for I in inertia]
    C = [pid_by_hand(Kp[j], Ti[j], Td[j])(z) for j in range(3)]
    Ms_ref = []
    for i in range(3):
        j, k = [x for x in range(3) if x != i]
        # unknowns u_j, u_k (u_i = 1): u_j = C_j (-G_j u_j + sum_l c_jl G_l u_l)
        a11 = 1 + C[j] * G[j]
        a12 = -C[j] * Cm[j, k] * G[k]
        a21 = -C[k] * Cm[k, j] * G[j]
        a22 = 1 + C[k] * G[k]
        b1, b2 = C[j] * Cm[j, i] * G[i], C[k] * Cm[k, i] * G[i]
        det = a11 * a22 - a12 * a21
        u = np.zeros((3, len(w)), complex)
        u[i], u[j], u[k] = 1, (b1 * a22 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det
        Y = np.array(G) * u
        L = C[i] * (Y[i] - Cm[i] @ Y)
        Ms_ref.append(np.max(np.abs(1 / (1 + L))))
    assert len(m.per_loop) == 3
    for loop, ref in zip(m.per_loop, Ms_ref):
        assert loop.reliable, loop.note
        assert loop.Ms == pytest.approx(ref, rel=0.01)
    worst = int(np.argmax(Ms_ref))
    assert m.loop == config.loops[worst].output
    assert m.Ms == pytest.approx(Ms_ref[worst], rel=0.01)


def test_amplitude_is_halved_until_the_control_signal_stays_inside_its_limits():
    # u_op = -1 at y = 1; a peak of 12 would drive u far past the +-10 limits
    m = loop_margins(preset("first_order"), [3.0], [2.0], [0.05], [1.0], amplitude=[12.0])
    assert m.amplitude < 12.0 and m.reliable, m.note
    assert_close_margins(m, reference_margins(pid_by_hand(3.0, 2.0, 0.05) * first_order_zoh(1.0)))


def test_a_saturated_attempt_stops_within_its_period_and_the_last_attempt_is_measured_as_if_alone():
    """An attempt that hits a limit before the last is repeated at half the amplitude anyway: it ends within the
    period it saturated in, and the response is the one measured from the settled state at the final amplitude."""
    config = preset("two_tank")  # the pump's 0..50 cm3/s: a peak of 40 around its ~22 at 8 cm saturates
    Ts = config.sample_time_s
    rig = ClosedLoopRig(config, [5.0], [20.0], [0.0], [8.0])
    settling = rig.settle()
    C = lambda w: pid_transfer_function(5.0, 20.0, 0.0, Ts)(np.exp(1j * w * Ts))  # noqa: E731
    calls, simulate = [], rig.simulate

    def counted(loop, d):
        out = simulate(loop, d)
        calls.append(out[2])  # saturated
        return out
    rig.simulate = counted
    bins = [1, 3, 10, 30, 100]
    first = measure_response(rig, 0, bins, 1024, 40.0, C, settling.steps)
    assert first.amplitude < 40.0 and not first.saturated
    halvings = round(math.log2(40.0 / first.amplitude))
    # each saturated attempt ends in the call (its wait or one period) it saturated in
    assert sum(calls) == halvings >= 1
    alone = measure_response(rig, 0, bins, 1024, first.amplitude, C, settling.steps)
    np.testing.assert_array_equal(first.response, alone.response)
    assert first.periods == alone.periods
    rig.close()


def test_operating_point_at_a_limit_has_no_margins():
    # 45 cm needs q_in = 7.89 sqrt(45) = 53 cm3/s > 50: the pump sits at its limit
    m = loop_margins(preset("two_tank"), [5.0], [20.0], [0.0], [45.0])
    assert m.Ms == math.inf and not m.reliable
    assert "limit" in m.note


def test_unstable_closed_loop_has_no_margins():
    m = loop_margins(preset("first_order"), [0.5], [2.0], [0.0], [1.0])  # Kp < 1 cannot stabilise 1/(s - 1)
    assert m.Ms == math.inf and not m.reliable
    assert "diverge" in m.note
    assert format_margins(m).startswith("Ms inf (")


def test_time_varying_plant_is_flagged_after_one_experiment(monkeypatch):
    import prlpid_fmi.robustness.margins as margins

    experiments = []
    monkeypatch.setattr(margins, "measure_response",
                        lambda *a: experiments.append(measure_response(*a)) or experiments[-1])
    m = loop_margins(preset("time_varying"), [5.0], [2.0], [0.05], [1.0])
    assert not m.reliable
    assert "time-varying" in m.note
    assert len(experiments) == 1  # no refinement of an estimate that is flagged already
    experiments.clear()
    assert loop_margins(preset("first_order"), [3.0], [2.0], [0.05], [1.0]).reliable
    assert len(experiments) >= 2  # a good estimate is refined around its peak and crossovers


def test_the_period_follows_the_loops_settling_time(monkeypatch):
    """A fast loop (settled within 1024 samples, its crossings at bin 32 of 1024 or above, |L| > 20 at the lowest
    bin: PI with Ti 0.2 s on 1/(s - 1)) is measured with 1024-sample periods, not a fixed 4096, and matches its exact
    ZOH reference; the slow two-tank loop (settling over 800 samples, its crossover below bin 32 of 1024) is measured
    with longer periods and matches its linearisation."""
    import prlpid_fmi.robustness.margins as margins

    experiments = []
    monkeypatch.setattr(margins, "measure_response",
                        lambda *a: experiments.append(measure_response(*a)) or experiments[-1])
    m = loop_margins(preset("first_order"), [6.0], [0.2], [0.0], [1.0])
    assert_close_margins(m, reference_margins(pid_by_hand(6.0, 0.2, 0.0) * first_order_zoh(1.0)))
    assert {e.period for e in experiments} == {1024}
    experiments.clear()
    m = loop_margins(preset("two_tank"), [5.0], [20.0], [0.0], [10.0])
    assert_close_margins(m, reference_margins(pid_by_hand(5.0, 20.0, 0.0) * two_tank_zoh(10.0)))
    assert max(e.period for e in experiments) >= 4096


def test_a_measurement_is_kept_whatever_the_training_settings(monkeypatch):
    """margins_of measures once for configs that differ only in what the experiment never reads (the forecast,
    the training noise); a different sample time is a different experiment."""
    import prlpid_fmi.robustness.margins as margins
    from prlpid_fmi import runcontext

    measured = []
    monkeypatch.setattr(margins, "measure_margins", lambda *a: measured.append(a) or loop_margins(
        a[0], a[1][0], a[1][1], a[1][2], a[2]))
    config = preset("first_order")
    gains = ([3.0], [2.0], [0.05], None)
    with runcontext.opened():
        first = margins.margins_of(config, gains, [1.0])
        again = margins.margins_of(dataclasses.replace(config, forecast_horizon=0, measurement_noise_std=0.05),
                                   gains, [1.0])
        assert again is first and len(measured) == 1
        margins.margins_of(dataclasses.replace(config, sample_time_s=0.05), gains, [1.0])
        assert len(measured) == 2


def test_a_local_design_at_one_setpoint_measures_what_the_scenario_does(monkeypatch):
    """The classical schedule's local designs hold the setpoint range at one point, widen the gain ranges and carry
    the fixed PID's structure as tuned_structure; none of it is read by the experiment, so the scenario's
    measurement at that point with the same structure in force is kept for them. Another Tf is another experiment."""
    import prlpid_fmi.robustness.margins as margins
    from prlpid_fmi import runcontext
    from prlpid_fmi.config import GainRange

    measured = []
    monkeypatch.setattr(margins, "measure_margins", lambda *a: measured.append(a) or loop_margins(
        a[0], a[1][0], a[1][1], a[1][2], a[2]))
    config = dataclasses.replace(preset("first_order"), setpoint_weight=0.5, measurement_filter=0.2)
    gains = ([3.0], [2.0], [0.05], None)
    loop = dataclasses.replace(config.loops[0], setpoint_range=(1.0, 1.0), Kp=GainRange(0.01, 400.0, "log"))
    local = dataclasses.replace(config, loops=(loop,), measurement_filter="tuned", setpoint_weight="tuned",
                                tuned_structure=((0.5, config.derivative_weight, 0.2),))
    with runcontext.opened():
        first = margins.margins_of(config, gains, [1.0])
        assert margins.margins_of(local, gains, [1.0]) is first and len(measured) == 1
        other_filter = dataclasses.replace(local, tuned_structure=((0.5, config.derivative_weight, 0.3),))
        assert margins.margins_of(other_filter, gains, [1.0]).Ms != first.Ms and len(measured) == 2


def test_a_growing_oscillation_fails_and_a_time_varying_plant_stays_impossible():
    """PI control of a double integrator is never stable (I s^3 + Kp s^2 + Kp/Ti has no s term: not Hurwitz). With a
    small Kp the quadrotor's loops oscillate slowly, beating, and grow without leaving their divergence bound within
    the experiment: failed ("growing"), not "impossible" as for a plant that varies in time. The time-varying plant's
    swing stays level: impossible, as before."""
    from prlpid_fmi.robustness.status import Robustness, status

    m = loop_margins(preset("quadrotor"), [0.002] * 3, [1000.0] * 3, [0.0] * 3, [0.0] * 3, coupling=[0.0] * 6)
    assert status(m) == Robustness.FAILED and "growing" in m.problems and "unstable" in m.note
    m = loop_margins(preset("time_varying"), [5.0], [2.0], [0.05], [1.0])
    assert status(m) == Robustness.IMPOSSIBLE and m.problems[0] == "varying"


def test_format_margins_one_line():
    # L = C * P on three frequencies: 1, -0.5 and 2, so T = L / (1 + L) is 0.5, -1 and 2/3: Mt = 1 by hand;
    # the delay margin is PM / w_gc = 52.2 deg = 0.91106 rad over 3.4 rad/s = 0.26796 s
    w, ones = np.array([1.0, 2.0, 3.0]), np.ones(3, complex)
    m = Margins(1.4249, 3.0, 10 ** (8.3 / 20), 12.1, 52.2, 3.4, w, np.array([1.0, -0.5, 2.0], complex), ones, 0.4,
                True, "", "y")
    assert m.Mt == 1.0
    assert m.delay_margin_s == pytest.approx(52.2 * math.pi / 180 / 3.4, rel=1e-12)
    assert format_margins(m) == "Ms 1.42, Mt 1.00, GM 8.3 dB at 12.1 rad/s, PM 52° at 3.4 rad/s, DM 0.268 s"
    flagged = dataclasses.replace(m, reliable=False, note="the control signal reached a limit")
    assert format_margins(flagged).endswith("(unreliable: the control signal reached a limit)")


def test_replayed_settling_gives_the_same_response_as_the_state_snapshot():
    """FMUs that cannot serialize their state are brought back to the operating point by a replay."""
    config = preset("two_tank")
    responses = []
    for snapshots in (True, False):
        rig = ClosedLoopRig(config, [5.0], [20.0], [0.0], [8.0], snapshots=snapshots)
        settling = rig.settle()
        C = lambda w: pid_transfer_function(5.0, 20.0, 0.0, TS)(np.exp(1j * w * TS))  # noqa: E731
        responses.append(measure_response(rig, 0, [1, 3, 10, 30, 100], 1024, 0.5, C, settling.steps))
        rig.close()
    np.testing.assert_array_equal(responses[0].response, responses[1].response)
    assert responses[0].periods >= 2 and not responses[0].saturated


def test_operating_point_far_from_the_initial_state_is_approached_by_a_ramp():
    """A setpoint step from y = 0 to 2 would leave a divergence bound of 0.5 at once; the ramp does not."""
    config = preset("first_order")
    config = dataclasses.replace(config, loops=(dataclasses.replace(config.loops[0], divergence_bound=0.5),))
    m = loop_margins(config, [3.0], [2.0], [0.05], [2.0])
    assert_close_margins(m, reference_margins(pid_by_hand(3.0, 2.0, 0.05) * first_order_zoh(1.0)))
