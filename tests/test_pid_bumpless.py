"""The bumpless gain change and the imposed output (manual, tracking) of control/pid.py, against outside truth.

Truths: hand-computed sequences (the arithmetic in the comments; dyadic numbers, so the floating-point law makes no
rounding error and the comparisons are `==`), the frozen eq. 2 code (tests/eq2_pid_reference.py) and the
positional law itself while gains are constant, and the invariant the rescale is built on: at an equilibrium
(r = y, e = 0, D = 0) a gain step moves u by less than 1e-12 of the actuator span. tests/pid_law_cases.py holds
further hand-checked cases of both that the exports and the C forecast run too.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from eq2_pid_reference import PID as Eq2PID
from prlpid_fmi.control.pid import GAIN_CHANGE_MODES, PID, CoupledPID

MODES = ("clamping", "back_calculation", "none")


def _pid(gain_change="bumpless", **kw):
    return PID(0.5, 1, gain_change=gain_change, **kw)


def test_three_samples_with_a_gain_step_by_hand():
    # dt 0.5, b = 1, c = 1, no limits; preset u0 = 1 at y(0) = 0.5: I(-1) = 1/Ki = 1 (Kp 1, Ti 1, Td 0).
    # k=0: [1, 1, 0] e = 1 - 0.5 = 0.5; D = 0; I_try = 1 + 0.25 = 1.25; u = 0.5 + 1.25 = 1.75; I = 1.25
    # k=1: [Kp 4, Ti 0.5, Td 0.25, Ki 8] gain change: v = 1*(0.5 + 0*0) + 1*1.25 = 1.75,
    #      I(0) := (1.75 - 4*(0.5 + 0.25*0))/8 = -0.03125; e = 1 - 0.75 = 0.25; D = (0.25 - 0.5)/0.5 = -0.5;
    #      I_try = -0.03125 + 0.125 = 0.09375; u = 4*(0.25 + 0.25*(-0.5)) + 8*0.09375 = 0.5 + 0.75 = 1.25
    #      (positional: I_try = 1.375, u = 0.5 + 11 = 11.5)
    # k=2: same gains, e = 1 - 1 = 0; D = (0 - 0.25)/0.5 = -0.5; I_try = 0.09375;
    #      u = 4*(0 + 0.25*(-0.5)) + 8*0.09375 = -0.5 + 0.75 = 0.25
    gains = [(1.0, 1.0, 0.0), (4.0, 0.5, 0.25), (4.0, 0.5, 0.25)]
    y = [0.5, 0.75, 1.0]
    expected = {"bumpless": [1.75, 1.25, 0.25], "positional": [1.75, 11.5, 10.5]}
    for law in GAIN_CHANGE_MODES:
        pid = _pid(law)
        pid.preset_output([1.0], [0.5], [1.0], [1.0])
        out = [pid.step_values([1.0], [y[k]], *([g] for g in gains[k]))[0] for k in range(3)]
        assert out == expected[law], law
    # positional k=2: e = 0, D = -0.5, I = 1.375; u = 4*(-0.125) + 8*1.375 = 10.5 (the hand value above)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("N", [None, 4.0])
@pytest.mark.parametrize("structure", [(1.0, 1.0, 0.0), (0.4, 0.0, 0.3)], ids=["eq2", "b0.4-c0-Tf0.3"])
def test_a_gain_step_at_equilibrium_moves_u_by_less_than_1e_12_of_the_span(mode, N, structure):
    """The pH case of the issue: 515 mL/min held, Kp/Ti 5.9 -> 20.7 and more; positional jumps, bumpless does not."""
    b, c, tf = structure
    rng = np.random.default_rng([len(mode), N is None, int(10 * b)])
    span = 1000.0
    for trial in range(40):
        pid = PID(0.1, 1, 0.0, span, mode, derivative_filter_N=N, setpoint_weight=b, derivative_weight=c,
                  measurement_filter_s=tf, gain_change="bumpless")
        r = float(rng.uniform(4.0, 7.0))
        u0 = float(rng.uniform(50.0, 950.0))
        g = [float(rng.uniform(0.5, 30.0)), float(rng.uniform(0.5, 20.0)), float(rng.uniform(0.0, 2.0))]
        pid.preset_output([u0], [r], [g[0]], [g[1]])
        u = [pid.step_values([r], [r], [g[0]], [g[1]], [g[2]])[0] for _ in range(5)]
        assert max(abs(v - u0) for v in u) < 1e-12 * span
        for _ in range(5):  # gain steps, a sign change of Kp among them
            g = [float(rng.choice([-1, 1]) * rng.uniform(0.5, 30.0)), float(rng.uniform(0.5, 20.0)),
                 float(rng.uniform(0.0, 2.0))]
            v = pid.step_values([r], [r], [g[0]], [g[1]], [g[2]])[0]
            assert abs(v - u0) < 1e-12 * span, (trial, g)


def test_positional_jumps_at_the_same_equilibrium():
    """The case above without the rescale: the issue's pump jump (515 -> 1000 mL/min) is reproduced."""
    pid = PID(0.1, 1, 0.0, 1000.0, gain_change="positional")
    pid.preset_output([515.0], [5.0], [5.9], [5.9 / 5.9])
    assert pid.step_values([5.0], [5.0], [5.9], [1.0], [0.0]) == [515.0]
    assert pid.step_values([5.0], [5.0], [20.7], [1.0], [0.0]) == [1000.0]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("N", [None, 5.0])
def test_constant_gains_bumpless_is_positional_and_eq2_bit_for_bit(mode, N):
    rng = np.random.default_rng([len(mode), N is None])
    kw = dict(u_min=[-1.5, -2.0], u_max=[1.5, 2.0], anti_windup=mode, derivative_filter_N=N)
    bumpless, positional, old = PID(0.1, 2, gain_change="bumpless", **kw), PID(0.1, 2, **kw), Eq2PID(0.1, 2, **kw)
    weighted = [PID(0.1, 2, gain_change=law, setpoint_weight=0.3, derivative_weight=0.0, measurement_filter_s=0.2,
                    measurement_filter_order=2, u_rate_limit=[3.0, math.inf], **kw) for law in GAIN_CHANGE_MODES]
    for episode in range(4):
        for p in (bumpless, positional, old, *weighted):
            p.reset()
        r, u0 = rng.uniform(-1, 1, 2).tolist(), rng.uniform(-1, 1, 2).tolist()
        Kp, Ti, Td = rng.uniform(0.5, 5, 2).tolist(), rng.uniform(0.2, 3, 2).tolist(), rng.uniform(0, 0.3, 2).tolist()
        bumpless.preset_output(u0, r, Kp, Ti)
        positional.preset_output(u0, r, Kp, Ti)
        old.preset_integral(u0, Kp, Ti)
        for p in weighted:
            p.preset_output(u0, r, Kp, Ti)
        for k in range(150):
            y = rng.normal(0, 0.7, 2).tolist()
            a = bumpless.step_values(r, y, Kp, Ti, Td)
            assert a == positional.step_values(r, y, Kp, Ti, Td) == old.step_values(
                [r[i] - y[i] for i in range(2)], Kp, Ti, Td), (episode, k)
            assert bumpless.unsaturated_u.tolist() == positional.unsaturated_u.tolist()
            w = [p.step_values(r, y, Kp, Ti, Td) for p in weighted]
            assert w[0] == w[1], (episode, k)


def test_a_change_while_saturated_keeps_the_output_at_the_limit_without_windup():
    # clamping, u_max = 1, dt 0.5, preset u0 = 0.5 (I(-1) = 0.5); r = 2, y = 0 throughout (e = 2 pushes up):
    # k=0: [1, 1, 0] I_try = 0.5 + 1 = 1.5, u_try = 2 + 1.5 = 3.5 -> u = 1, held: I = 0.5
    # k=1: [Kp 2, Ti 0.5, Ki 4] v = 1*2 + 1*0.5 = 2.5 (the state's output, beyond the limit),
    #      I(0) := (2.5 - 2*2)/4 = -0.375; I_try = -0.375 + 1 = 0.625; u_try = 4 + 2.5 = 6.5 -> u = 1; held: -0.375
    # k=2: y = 1.75 (e = 0.25): I_try = -0.375 + 0.125 = -0.25; u_try = 2*0.25 + 4*(-0.25) = -0.5; u = -0.5
    pid = _pid(u_min=-1.0, u_max=1.0, anti_windup="clamping")
    pid.preset_output([0.5], [0.0], [1.0], [1.0])
    assert pid.step_values([2.0], [0.0], [1.0], [1.0], [0.0]) == [1.0]
    assert pid.raw_state()[0] == [0.5]
    assert pid.step_values([2.0], [0.0], [2.0], [0.5], [0.0]) == [1.0]
    assert pid.raw_state()[0] == [-0.375]
    assert pid.step_values([2.0], [1.75], [2.0], [0.5], [0.0]) == [-0.5]
    # the state's output v is kept exactly across the change: Kp*ep + Ki*I = 2*2 + 4*(-0.375) = 2.5 = 1*2 + 1*0.5


def test_back_calculation_after_a_change_while_saturated():
    # back-calculation, u_max = 1, dt 0.5, Td = 0 (Tt = Ti); preset u0 = 0.5 at y = 0, Kp 1, Ti 1: I(-1) = 0.5.
    # k=0: e = 2: I_try = 1.5, u_try = 3.5, u = 1; g = 0.5/(1 + 0.5) = 1/3: I = 1.5 + (1 - 3.5)/3 = 2/3
    # k=1: [Kp 2, Ti 0.5, Ki 4] v = 2 + 2/3 = 8/3; I(0) := (8/3 - 4)/4 = -1/3; I_try = -1/3 + 1 = 2/3;
    #      u_try = 4 + 8/3 = 20/3; u = 1; Tt = 0.5, g = 0.5: I = 2/3 + 0.5*(1 - 20/3)/4 = -1/24
    pid = _pid(u_min=-1.0, u_max=1.0, anti_windup="back_calculation")
    pid.preset_output([0.5], [0.0], [1.0], [1.0])
    assert pid.step_values([2.0], [0.0], [1.0], [1.0], [0.0]) == [1.0]
    assert math.isclose(pid.raw_state()[0][0], 2 / 3, rel_tol=1e-15)
    assert pid.step_values([2.0], [0.0], [2.0], [0.5], [0.0]) == [1.0]
    assert math.isclose(pid.raw_state()[0][0], -1 / 24, rel_tol=1e-12)


def test_ki_zero_keeps_the_sum_and_the_change_back_is_bumpless():
    # dt 0.5; preset u0 = 1 at y = 1 (r = 1): I(-1) = 1 (Kp 1, Ti 1). At equilibrium:
    # Ti -> inf (Kp 1): Ki = 0, I kept at 1, u = 1*(0) + 0 = 0: the jump is the lost integral term (1 -> 0).
    # Ti -> 0.5 (Kp 2, Ki 4): v = 1*0 + 0*1 = 0, I := (0 - 0)/4 = 0, u = 0: continuous from the P-only output.
    pid = _pid()
    pid.preset_output([1.0], [1.0], [1.0], [1.0])
    assert pid.step_values([1.0], [1.0], [1.0], [1.0], [0.0]) == [1.0]
    assert pid.step_values([1.0], [1.0], [1.0], [math.inf], [0.0]) == [0.0]
    assert pid.raw_state()[0] == [1.0]
    assert pid.step_values([1.0], [1.0], [2.0], [0.5], [0.0]) == [0.0]
    assert pid.raw_state()[0] == [0.0]
    # Kp = 0 is the same edge (Ki = 0): the sum is kept, u = 0
    assert pid.step_values([1.0], [1.0], [0.0], [0.5], [0.0]) == [0.0]


def test_the_first_sample_after_reset_is_never_rescaled():
    """The preset balances with the first sample's gains; no previous gains exist before it."""
    for law in GAIN_CHANGE_MODES:
        pid = _pid(law)
        pid.step_values([1.0], [0.0], [1.0], [1.0], [0.0])
        pid.step_values([1.0], [0.0], [3.0], [2.0], [0.1])
        pid.reset()
        assert pid.raw_gain_state()[1] == [pid.raw_gain_state()[1][0]] and math.isnan(pid.raw_gain_state()[1][0])
        pid.preset_output([0.25], [0.5], [2.0], [0.5])
        assert pid.step_values([0.5], [0.5], [2.0], [0.5], [0.3]) == [0.25]


def test_manual_then_auto_by_hand_and_tracking_clipped():
    # dt 0.5, Kp 1, Ti 1, Td 0.5, b = 1, c = 0, u in [-2, 2]; r = 1.
    # k=0 manual 1.5 at y = 0.25: e = 0.75, ep = 0.75, ed = -0.25, D = 0; I = (1.5 - 1*(0.75 + 0))/1 = 0.75
    # k=1 manual 1 at y = 0.5: ep = 0.5, ed = -0.5, D = -0.5; I = (1 - (0.5 - 0.25))/1 = 0.75
    # k=2 auto, y = 0.5: e = 0.5, D = 0; I_try = 0.75 + 0.25 = 1; u = 1*(0.5 + 0) + 1 = 1.5
    #      (= 1 + Kp*Td*(0 - (-0.5)) + Ki*e*dt = 1 + 0.25 + 0.25: no bump)
    # k=3 tracking 5 (an override drove the valve beyond u_max): u = 2 (clipped); y = 0.75: ep = 0.25, ed = -0.75,
    #      D = -0.5; I = (2 - (0.25 - 0.25))/1 = 2
    # k=4 auto, y = 0.75: e = 0.25, D = 0; I_try = 2 + 0.125 = 2.125; u_try = 0.25 + 2.125 = 2.375 -> 2 (held: I = 2)
    # k=5 auto, y = 1.25: e = -0.25, ep = -0.25, ed = -1.25, D = -1; I_try = 2 - 0.125 = 1.875;
    #      u = (-0.25 + 0.5*(-1)) + 1.875 = 1.125
    pid = _pid(u_min=-2.0, u_max=2.0, derivative_weight=0.0)
    g = ([1.0], [1.0], [0.5])
    pid.preset_output([0.0], [0.25], [1.0], [1.0])
    assert pid.track_values([1.0], [0.25], *g, [1.5]) == [1.5]
    assert pid.track_values([1.0], [0.5], *g, [1.0]) == [1.0]
    assert pid.step_values([1.0], [0.5], *g) == [1.5]
    assert pid.track_values([1.0], [0.75], *g, [5.0]) == [2.0]
    assert pid.raw_state()[0] == [2.0]
    assert pid.step_values([1.0], [0.75], *g) == [2.0]
    assert pid.step_values([1.0], [1.25], *g) == [1.125]


def test_tracking_sets_the_rate_limits_origin_and_mixes_with_automatic_loops():
    # two loops, rate limit 1/s (0.5 per sample) on both, dt 0.5; loop 1 tracks 1.5, loop 2 runs the law.
    pid = PID(0.5, 2, -4.0, 4.0, "clamping", u_rate_limit=1.0, gain_change="bumpless")
    pid.preset_output([0.0, 0.0], [0.0, 0.0], [1.0, 1.0], [1.0, 1.0])
    u = pid.track_values([0.0, 1.0], [0.0, 0.0], [1.0, 1.0], [1.0, 1.0], [0.0, 0.0], [1.5, None])
    assert u == [1.5, 0.5]  # loop 1: tracked (not rate limited); loop 2: u_try = 1 + 0.5 = 1.5, band [-0.5, 0.5]
    u = pid.step_values([0.0, 1.0], [0.0, 0.0], [1.0, 1.0], [1.0, 1.0], [0.0, 0.0])
    assert u == [1.5, 1.0]  # loop 1 continues from 1.5 (e = 0); loop 2 moves 0.5 further


def test_coupled_pid_tracks_and_rescales_like_three_pids_without_coupling():
    rng = np.random.default_rng(5)
    coupled = CoupledPID(0.1, -2.0, 2.0, "back_calculation", gain_change="bumpless", setpoint_weight=0.5)
    single = [PID(0.1, 1, -2.0, 2.0, "back_calculation", gain_change="bumpless", setpoint_weight=0.5)
              for _ in range(3)]
    for k in range(60):
        r, y = rng.uniform(-1, 1, 3).tolist(), rng.normal(0, 0.5, 3).tolist()
        Kp, Ti, Td = rng.uniform(0.5, 4, 3).tolist(), rng.uniform(0.3, 3, 3).tolist(), rng.uniform(0, 0.2, 3).tolist()
        imposed = [float(rng.uniform(-3, 3)) if rng.random() < 0.3 else None for _ in range(3)]
        u = coupled.track_values(r, y, Kp, Ti, Td, [0.0] * 6, imposed)
        expected = [single[i].track_values([r[i]], [y[i]], [Kp[i]], [Ti[i]], [Td[i]], [imposed[i]])[0]
                    for i in range(3)]
        assert u == expected, k


def test_state_round_trip_carries_the_previous_gains():
    pid = _pid(setpoint_weight=0.5, derivative_filter_N=4.0)
    for k, g in enumerate([(1.0, 1.0, 0.2), (2.0, 0.5, 0.1), (3.0, 0.4, 0.3)]):
        pid.step_values([1.0], [0.1 * k], *([v] for v in g))
    state = pid.get_state()
    assert state.last_gains.tolist() == [[3.0], [0.4], [0.3]] and state.last_p_error.tolist() == [0.5 - 0.2]
    a = pid.step_values([1.0], [0.4], [5.0], [0.2], [0.0])
    pid.set_state(state)
    assert pid.step_values([1.0], [0.4], [5.0], [0.2], [0.0]) == a
    copy = state.copy()
    copy.last_gains[0, 0] = 99.0
    assert state.last_gains[0, 0] == 3.0
    with pytest.raises(ValueError, match="gain_change"):
        PID(0.1, gain_change="velocity")
