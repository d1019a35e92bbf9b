"""PID (eq. 2) and cross-axis coupled PID (eq. 26-27) against hand-computed sequences.

Every expected number below was worked out by hand from the paper's equations; the working is in
the comments next to it.
"""
import numpy as np
import pytest

from prlpid_fmi.control import (ANTI_WINDUP_MODES, COUPLING_NAMES, PID, CoupledPID, PIDState,
                                coupling_matrix, parallel_gains)


def run(pid, errors, Kp, Ti, Td):
    return np.array([pid.step_error(e, Kp, Ti, Td)[0] for e in errors])


def test_parallel_gains():
    Ki, Kd = parallel_gains(2.0, 0.5, 0.1)
    assert Ki == pytest.approx(4.0) and Kd == pytest.approx(0.2)
    Ki, Kd = parallel_gains(np.array([2.0, 3.0]), np.array([np.inf, 1.5]), np.array([0.0, 2.0]))
    np.testing.assert_allclose(Ki, [0.0, 2.0])
    np.testing.assert_allclose(Kd, [0.0, 6.0])


def test_eq2_hand_computed_sequence():
    # Kp=2, Ti=0.5, Td=0.1, dt=0.1; setpoint 1, so e = 1 - y = 1, 0.5, 0, -0.5, 0.25, 0.25
    # k  I = sum e*dt   D = de/dt        u = 2*(e + I/0.5 + 0.1*D)
    # 0  0.1            0 (no kick)      2*(1    + 0.2 + 0)     =  2.4
    # 1  0.15           -5               2*(0.5  + 0.3 - 0.5)   =  0.6
    # 2  0.15           -5               2*(0    + 0.3 - 0.5)   = -0.4
    # 3  0.10           -5               2*(-0.5 + 0.2 - 0.5)   = -1.6
    # 4  0.125          7.5              2*(0.25 + 0.25 + 0.75) =  2.5
    # 5  0.15           0                2*(0.25 + 0.3 + 0)     =  1.1
    pid = PID(sample_time_s=0.1, anti_windup="none")
    measurements = [0.0, 0.5, 1.0, 1.5, 0.75, 0.75]
    u = [pid.step(1.0, y, 2.0, 0.5, 0.1)[0] for y in measurements]
    np.testing.assert_allclose(u, [2.4, 0.6, -0.4, -1.6, 2.5, 1.1], rtol=0, atol=1e-12)
    assert pid.get_state().integral[0] == pytest.approx(0.15)


def test_shapes_and_scalar_broadcast():
    pid = PID(0.1, n_loops=3)
    u = pid.step(np.array([1.0, 2.0, 3.0]), 0.0, 1.0, np.inf, 0.0)
    assert u.shape == (3,)
    np.testing.assert_allclose(u, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="shape"):
        pid.step_error(np.ones(2), 1.0, 1.0, 0.0)


def test_reset_restarts_without_derivative_kick():
    pid = PID(0.1, anti_windup="none")
    run(pid, [1.0, 3.0], 1.0, 1.0, 1.0)
    pid.reset()
    # after reset: I = 0.5*0.1 = 0.05, D = 0  ->  u = 0.5 + 0.05/1 = 0.55
    assert pid.step_error(0.5, 1.0, 1.0, 1.0)[0] == pytest.approx(0.55)


def test_clamping_stops_integration_and_recovers_earlier():
    # Kp=1, Ti=0.5 (Ki=2), Td=0, dt=0.1, limits +-1; errors 2,2,2,2 then -0.4,-0.4,-0.4
    errors = [2.0, 2.0, 2.0, 2.0, -0.4, -0.4, -0.4]
    # "none": I = 0.2, 0.4, 0.6, 0.8, 0.76, 0.72, 0.68
    #   u_unsat = e + 2I = 2.4, 2.8, 3.2, 3.6, 1.12, 1.04, 0.96 -> u = 1,1,1,1,1,1,0.96
    none = PID(0.1, u_min=-1.0, u_max=1.0, anti_windup="none")
    np.testing.assert_allclose(run(none, errors, 1.0, 0.5, 0.0), [1, 1, 1, 1, 1, 1, 0.96], atol=1e-12)
    # "clamping": while saturated with e > 0 the sum stays 0 -> u = 1,1,1,1; then
    #   I = -0.04, -0.08, -0.12; u = -0.4 + 2I = -0.48, -0.56, -0.64
    clamp = PID(0.1, u_min=-1.0, u_max=1.0, anti_windup="clamping")
    integrals = []
    u = []
    for e in errors:
        u.append(clamp.step_error(e, 1.0, 0.5, 0.0)[0])
        integrals.append(clamp.get_state().integral[0])
    np.testing.assert_allclose(u, [1, 1, 1, 1, -0.48, -0.56, -0.64], atol=1e-12)
    np.testing.assert_allclose(integrals, [0, 0, 0, 0, -0.04, -0.08, -0.12], atol=1e-12)
    # the unsaturated output is reported with the tentative sum: e + 2*(0 + 0.2) = 2.4
    clamp.reset()
    clamp.step_error(2.0, 1.0, 0.5, 0.0)
    assert clamp.unsaturated_u[0] == pytest.approx(2.4)


def test_clamping_integrates_when_error_pulls_out_of_saturation():
    # Kp=1, Ti=1, Td=1, dt=0.1, u_max=1. e = -1 then -0.5: D = 5, I = -0.1 - 0.05 = -0.15,
    # u_unsat = -0.5 - 0.15 + 5 = 4.35 > u_max but e < 0 pulls down -> the sum keeps e*dt.
    pid = PID(0.1, u_min=-10.0, u_max=1.0, anti_windup="clamping")
    run(pid, [-1.0, -0.5], 1.0, 1.0, 1.0)
    assert pid.unsaturated_u[0] == pytest.approx(4.35)
    assert pid.get_state().integral[0] == pytest.approx(-0.15)


def test_clamping_lower_limit():
    # Kp=1, Ti=0.5, e = -3: u_unsat = -3 - 0.6 = -3.6 < u_min = -1, e < 0 -> sum stays 0
    pid = PID(0.1, u_min=-1.0, u_max=1.0)
    assert pid.step_error(-3.0, 1.0, 0.5, 0.0)[0] == -1.0
    assert pid.get_state().integral[0] == 0.0


def test_back_calculation_hand_computed():
    # Kp=1, Ti=0.5 (Ki=2), Td=0, Tt=0.1, dt=0.1, limits +-1. Backward Euler of
    # dI/dt = e + (u_sat - u_unsat)/(Ki*Tt):  I_k = I_{k-1} + dt*e_k + (dt/(Ki*Tt))*(u_sat_k - u_unsat_k),
    # u_unsat_k = e_k + 2*I_k, solved by hand for I_k:
    # k0 e=2:   I = 0.2 + 0.5*(1 - (2 + 2I))        -> 2I = -0.3       I = -0.15,   u_unsat = 1.7
    # k1 e=2:   I = -0.15 + 0.2 + 0.5*(1 - 2 - 2I)  -> 2I = -0.45      I = -0.225,  u_unsat = 1.55
    # k2 e=-.4: I = -0.225 - 0.04 = -0.265, u = -0.4 - 0.53 = -0.93 (inside the limits)
    # k3 e=-.4: I = -0.305 + 0.5*(-1 + 0.4 - 2I)    -> 2I = -0.605     I = -0.3025, u_unsat = -1.005
    pid = PID(0.1, u_min=-1.0, u_max=1.0, anti_windup="back_calculation", Tt=0.1)
    u, unsat, integral = [], [], []
    for e in [2.0, 2.0, -0.4, -0.4]:
        u.append(pid.step_error(e, 1.0, 0.5, 0.0)[0])
        unsat.append(pid.unsaturated_u[0])
        integral.append(pid.get_state().integral[0])
    np.testing.assert_allclose(u, [1.0, 1.0, -0.93, -1.0], atol=1e-12)
    np.testing.assert_allclose(unsat, [1.7, 1.55, -0.93, -1.005], atol=1e-12)
    np.testing.assert_allclose(integral, [-0.15, -0.225, -0.265, -0.3025], atol=1e-12)


def test_back_calculation_default_tracking_time():
    # Td = 0 -> Tt = Ti = 0.5. k0, e=2: I = 0.2 + (0.1/(2*0.5))*(1 - 2 - 2I) -> 1.2 I = 0.1 -> I = 1/12
    pid = PID(0.1, u_min=-1.0, u_max=1.0, anti_windup="back_calculation")
    pid.step_error(2.0, 1.0, 0.5, 0.0)
    assert pid.get_state().integral[0] == pytest.approx(1.0 / 12.0)
    # Td = 0.08 -> Tt = sqrt(0.5*0.08) = 0.2. k0, e=2 (D=0): I = 0.2 + (0.1/(2*0.2))*(1 - 2 - 2I)
    #   -> 1.5 I = -0.05 -> I = -1/30
    pid = PID(0.1, u_min=-1.0, u_max=1.0, anti_windup="back_calculation")
    pid.step_error(2.0, 1.0, 0.5, 0.08)
    assert pid.get_state().integral[0] == pytest.approx(-1.0 / 30.0)


def test_infinite_Ti_gives_pd():
    # Kp=2, Td=0.1, dt=0.1, no integral: u = 2*(e + 0.1*de/dt)
    # e = 1, 0.5, 0, 0, 10  ->  2*1 = 2,  2*(0.5 - 0.5) = 0,  2*(0 - 0.5) = -1,  0,  2*(10 + 10) = 40 -> 5
    for mode in ANTI_WINDUP_MODES:
        pid = PID(0.1, anti_windup=mode, u_min=-1.5, u_max=5.0)
        np.testing.assert_allclose(run(pid, [1.0, 0.5, 0.0, 0.0, 10.0], 2.0, np.inf, 0.1),
                                   [2.0, 0.0, -1.0, 0.0, 5.0], atol=1e-12)
        assert pid.unsaturated_u[0] == pytest.approx(40.0)
        assert np.all(np.isfinite(pid.get_state().integral))


def test_derivative_filter_backward_euler():
    # N=2, Td=0.1 -> Tf = 0.05; dt=0.1: Df_k = (Tf*Df_{k-1} + dt*D_k)/(Tf + dt) = Df_{k-1}/3 + 2*D_k/3
    # e = 0, 1, 1, 1 -> D = 0, 10, 0, 0 -> Df = 0, 20/3, 20/9, 20/27
    # Kp=1, Ti=inf: u = e + 0.1*Df = 0, 1 + 2/3, 1 + 2/9, 1 + 2/27
    pid = PID(0.1, derivative_filter_N=2.0)
    u, d = [], []
    for e in [0.0, 1.0, 1.0, 1.0]:
        u.append(pid.step_error(e, 1.0, np.inf, 0.1)[0])
        d.append(pid.get_state().derivative[0])
    np.testing.assert_allclose(d, [0.0, 6.666666666666667, 2.2222222222222223, 0.7407407407407407])
    np.testing.assert_allclose(u, [0.0, 1.6666666666666667, 1.2222222222222223, 1.0740740740740742])


def test_unfiltered_derivative_is_raw_difference():
    pid = PID(0.1)
    run(pid, [0.0, 1.0], 1.0, np.inf, 0.1)
    assert pid.get_state().derivative[0] == pytest.approx(10.0)


def test_vector_loops_are_independent():
    # loop 0 as in test_eq2_hand_computed_sequence, loop 1 a P controller with Kp=3 and u_max=1
    pid = PID(0.1, n_loops=2, u_max=np.array([np.inf, 1.0]), anti_windup="none")
    errors = [(1.0, 0.1), (0.5, 0.2), (0.0, 0.5)]
    u = np.array([pid.step_error(np.array(e), np.array([2.0, 3.0]), np.array([0.5, np.inf]),
                                 np.array([0.1, 0.0])) for e in errors])
    np.testing.assert_allclose(u[:, 0], [2.4, 0.6, -0.4], atol=1e-12)
    np.testing.assert_allclose(u[:, 1], [0.3, 0.6, 1.0], atol=1e-12)


def test_state_round_trip_reproduces_outputs():
    pid = PID(0.1, n_loops=2, u_min=-2.0, u_max=2.0, anti_windup="back_calculation", derivative_filter_N=5.0)
    rng = np.random.default_rng(0)
    errors = rng.normal(size=(10, 2))
    gains = (np.array([1.5, 3.0]), np.array([0.4, 1.0]), np.array([0.2, 0.05]))
    for e in errors[:5]:
        pid.step_error(e, *gains)
    saved = pid.get_state()
    snapshot = saved.copy()
    first = [pid.step_error(e, *gains) for e in errors[5:]]
    # the saved state is a copy: stepping did not change it
    for name in ("integral", "last_error", "derivative"):
        np.testing.assert_array_equal(getattr(saved, name), getattr(snapshot, name))
    pid.set_state(saved)
    second = [pid.step_error(e, *gains) for e in errors[5:]]
    np.testing.assert_array_equal(first, second)
    # set_state copied in: the state object is still unchanged after more steps
    np.testing.assert_array_equal(saved.integral, snapshot.integral)


def test_fresh_state_has_no_derivative_kick_and_copy_is_independent():
    pid = PID(0.1)
    fresh = pid.get_state()
    assert fresh.initialized is False
    clone = pid.copy()
    pid.step_error(1.0, 1.0, 1.0, 1.0)
    assert pid.get_state().initialized is True
    assert clone.get_state().initialized is False
    pid.set_state(fresh)
    assert pid.step_error(5.0, 1.0, np.inf, 1.0)[0] == pytest.approx(5.0)  # D = 0 on the first sample


def test_set_state_rejects_wrong_shape():
    pid = PID(0.1, n_loops=2)
    with pytest.raises(ValueError, match="integral"):
        pid.set_state(PIDState(np.zeros(3), np.zeros(2), np.zeros(2), True))


@pytest.mark.parametrize("kwargs, match", [
    (dict(sample_time_s=0.0), "sample_time_s"),
    (dict(sample_time_s=0.1, n_loops=0), "n_loops"),
    (dict(sample_time_s=0.1, anti_windup="integrator_reset"), "anti_windup"),
    (dict(sample_time_s=0.1, u_min=1.0, u_max=-1.0), "u_min"),
    (dict(sample_time_s=0.1, derivative_filter_N=0.0), "derivative_filter_N"),
    (dict(sample_time_s=0.1, Tt=-1.0), "Tt"),
])
def test_invalid_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        PID(**kwargs)


# -- cross-axis coupled PID ------------------------------------------------------------------------

def test_coupling_matrix_layout():
    C = coupling_matrix([1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(C, [[0, 1, 2], [3, 0, 4], [5, 6, 0]])
    assert COUPLING_NAMES == ("c_rp", "c_ry", "c_pr", "c_py", "c_yr", "c_yp")


@pytest.mark.parametrize("name, expected", [
    # measurement (roll, pitch, yaw) = (1, 10, 100), setpoint = measurement, one coefficient = 1:
    ("c_rp", [10, 0, 0]), ("c_ry", [100, 0, 0]),
    ("c_pr", [0, 1, 0]), ("c_py", [0, 100, 0]),
    ("c_yr", [0, 0, 1]), ("c_yp", [0, 0, 10]),
])
def test_each_coupling_coefficient_reaches_its_axis(name, expected):
    coupling = np.zeros(6)
    coupling[COUPLING_NAMES.index(name)] = 1.0
    y = np.array([1.0, 10.0, 100.0])
    pid = CoupledPID(0.1)
    np.testing.assert_allclose(pid.coupled_error(y, y, coupling), expected)
    # P-only: u = e_couple
    np.testing.assert_allclose(pid.step(y, y, 1.0, np.inf, 0.0, coupling), expected)


def test_zero_coupling_equals_three_independent_pids():
    kw = dict(u_min=-0.5, u_max=0.5, anti_windup="clamping", derivative_filter_N=8.0)
    coupled = CoupledPID(0.1, **kw)
    separate = [PID(0.1, **kw) for _ in range(3)]
    Kp, Ti, Td = np.array([1.0, 2.0, 0.5]), np.array([0.5, 2.0, np.inf]), np.array([0.1, 0.0, 0.3])
    rng = np.random.default_rng(1)
    for _ in range(20):
        r, y = rng.normal(size=3), rng.normal(size=3)
        u = coupled.step(r, y, Kp, Ti, Td, np.zeros(6))
        expected = [separate[i].step(r[i], y[i], Kp[i], Ti[i], Td[i])[0] for i in range(3)]
        np.testing.assert_array_equal(u, expected)


def test_coupled_pid_hand_computed_two_steps():
    # setpoint (0.1, 0.2, 0.3), measurement (0.05, 0.1, 0.5), coupling (c_rp..c_yp) = 0.1 .. 0.6
    # e_roll  = 0.05 + 0.1*0.1  + 0.2*0.5 = 0.16
    # e_pitch = 0.1  + 0.3*0.05 + 0.4*0.5 = 0.315
    # e_yaw   = -0.2 + 0.5*0.05 + 0.6*0.1 = -0.115
    # Kp = (1, 2, 3), Ti = (0.5, 1, 2), Td = 0.1, dt = 0.1; first step D = 0, I = e*0.1:
    # u = (0.16 + 0.016/0.5, 2*(0.315 + 0.0315/1), 3*(-0.115 - 0.0115/2)) = (0.192, 0.693, -0.36225)
    pid = CoupledPID(0.1)
    setpoint, coupling = np.array([0.1, 0.2, 0.3]), np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    Kp, Ti, Td = np.array([1.0, 2.0, 3.0]), np.array([0.5, 1.0, 2.0]), 0.1
    u = pid.step(setpoint, np.array([0.05, 0.1, 0.5]), Kp, Ti, Td, coupling)
    np.testing.assert_allclose(u, [0.192, 0.693, -0.36225], atol=1e-12)
    # second step, measurement (0, 0, 0): e_couple = setpoint = (0.1, 0.2, 0.3)
    # D = (0.1-0.16, 0.2-0.315, 0.3+0.115)/0.1 = (-0.6, -1.15, 4.15); I = (0.026, 0.0515, 0.0185)
    # u_roll  = 1*(0.1 + 0.026/0.5 + 0.1*-0.6)    = 0.092
    # u_pitch = 2*(0.2 + 0.0515/1  + 0.1*-1.15)   = 0.273
    # u_yaw   = 3*(0.3 + 0.0185/2  + 0.1*4.15)    = 2.17275
    u = pid.step(setpoint, np.zeros(3), Kp, Ti, Td, coupling)
    np.testing.assert_allclose(u, [0.092, 0.273, 2.17275], atol=1e-12)
    state = pid.get_state()
    np.testing.assert_allclose(state.integral, [0.026, 0.0515, 0.0185], atol=1e-12)
    pid.reset()
    assert pid.get_state().initialized is False
    pid.set_state(state)
    np.testing.assert_array_equal(pid.get_state().integral, state.integral)
