"""The 2-DOF PID law (control/pid.py) against outside truth: the old eq. 2 code, python-control, invariants.

- b = c = 1, Tf = 0 is the paper's eq. 2 exactly: bit for bit the PID before the 2-DOF law (tests/
  eq2_pid_reference.py, a frozen copy), on random signals with gain changes, saturation, every anti-windup
  mode, a derivative filter and the bumpless start, and the coupled PID too;
- the closed loop of the 2-DOF law with a measurement filter equals python-control's: Y = P C_r / (1 + P C_y) R
  with C_y the feedback part (robustness.margins.pid_transfer_function is NOT used: C_r and C_y are written
  here from the equations) for a sampled first-order plant;
- the setpoint weight b does not change the load response (the preset absorbs b's kick: the output is
  u0 + Kp (r - y) + Ki sum e dt whatever b), and it does change a setpoint step (so the first check cannot
  pass by ignoring b).
"""
from __future__ import annotations

import math

import control
import numpy as np
import pytest

from eq2_pid_reference import PID as Eq2PID, CoupledPID as Eq2CoupledPID
from prlpid_fmi.control.pid import PID, CoupledPID

TS = 0.1


@pytest.mark.parametrize("mode", ["clamping", "back_calculation", "none"])
@pytest.mark.parametrize("N", [None, 5.0])
def test_b_c_1_and_no_filter_is_the_old_eq2_pid_bit_for_bit(mode, N):
    rng = np.random.default_rng(7)
    kw = dict(u_min=[-1.5, -2.0], u_max=[1.5, 2.0], anti_windup=mode, derivative_filter_N=N)
    new, old = PID(TS, 2, **kw), Eq2PID(TS, 2, **kw)
    assert not new._weighted
    for episode in range(3):
        new.reset(), old.reset()
        r = rng.uniform(-1, 1, 2).tolist()
        u0 = rng.uniform(-1, 1, 2).tolist()
        Kp, Ti = rng.uniform(0.5, 5, 2).tolist(), rng.uniform(0.2, 3, 2).tolist()
        new.preset_output(u0, r, Kp, Ti)
        old.preset_integral(u0, Kp, Ti)
        for k in range(200):
            if k % 50 == 0:
                r = rng.uniform(-1, 1, 2).tolist()
            y = rng.normal(0, 0.7, 2).tolist()
            Kp, Ti, Td = rng.uniform(0.5, 5, 2).tolist(), rng.uniform(0.2, 3, 2).tolist(), rng.uniform(0, 0.3, 2).tolist()
            a = new.step_values(r, y, Kp, Ti, Td)
            b = old.step_values([r[i] - y[i] for i in range(2)], Kp, Ti, Td)
            assert a == b, (episode, k)
            assert new.unsaturated_u.tolist() == old.unsaturated_u.tolist()


def test_the_coupled_pid_with_b_c_1_is_the_old_one_bit_for_bit():
    rng = np.random.default_rng(3)
    new, old = CoupledPID(TS, u_min=-2, u_max=2), Eq2CoupledPID(TS, u_min=-2, u_max=2)
    coupling = rng.uniform(-0.5, 0.5, 6).tolist()
    for k in range(300):
        r, y = rng.uniform(-1, 1, 3).tolist(), rng.normal(0, 0.5, 3).tolist()
        Kp, Ti, Td = rng.uniform(0.5, 4, 3).tolist(), rng.uniform(0.3, 3, 3).tolist(), rng.uniform(0, 0.2, 3).tolist()
        assert new.step_values(r, y, Kp, Ti, Td, coupling) == old.step_values(r, y, Kp, Ti, Td, coupling), k


def _closed_loop(pid: PID, r, load=None, x0=0.0, u0=0.0, gains=(2.0, 1.5, 0.2)):
    """y (N+1,) of the first-order plant x+ = phi x + gamma (u + load), y = x, with `pid` (u from y(k))."""
    phi = math.exp(-TS)
    gamma = 1 - phi
    Kp, Ti, Td = gains
    x, ys = x0, []
    pid.reset()
    if u0:
        pid.preset_output([u0], [r[0]], [Kp], [Ti])
    for k in range(len(r)):
        ys.append(x)
        u = pid.step_values([r[k]], [x], [Kp], [Ti], [Td])[0]
        x = phi * x + gamma * (u + (0.0 if load is None else load[k]))
    ys.append(x)
    return np.array(ys)


@pytest.mark.parametrize("b, c, Tf, order", [(0.5, 0.0, 0.3, 1), (0.3, 1.0, 0.25, 2), (1.0, 1.0, 0.0, 1)])
def test_the_2dof_closed_loop_matches_python_control(b, c, Tf, order):
    Kp, Ti, Td = 2.0, 1.5, 0.2
    n = 120
    r = np.ones(n)
    y = _closed_loop(PID(TS, setpoint_weight=b, derivative_weight=c, measurement_filter_s=Tf,
                         measurement_filter_order=order), r, gains=(Kp, Ti, Td))
    z = control.tf([1, 0], [1], TS)
    P = control.c2d(control.tf([1.0], [1.0, 1.0]), TS, "zoh")
    F = 1 if Tf == 0 else (TS * z / ((Tf / order + TS) * z - Tf / order)) ** order
    D = (z - 1) / (TS * z)                      # backward difference
    I = TS * z / (z - 1)                        # the error sum includes the current error
    C_y = Kp * (F + I / Ti + Td * D * F)        # on y: u = C_r r - C_y y
    C_r = Kp * (b + I / Ti + c * Td * D)
    T = control.minreal(P * C_r / (1 + P * C_y), verbose=False)
    # the law's first sample has no derivative kick (ed(-1) := ed(0)); python-control starts from zero state, so
    # compare a step applied from rest after one quiet sample: r = 0 at k = 0
    r[0] = 0.0
    y = _closed_loop(PID(TS, setpoint_weight=b, derivative_weight=c, measurement_filter_s=Tf,
                         measurement_filter_order=order), r, gains=(Kp, Ti, Td))
    ref = control.forced_response(T, T=np.arange(n) * TS, U=r).outputs
    assert np.max(np.abs(y[:n] - ref)) < 1e-6  # transfer-function round-off of the order-2 filter case: ~1e-8


def test_the_setpoint_weight_leaves_the_load_response_unchanged_and_acts_on_setpoint_steps():
    n, r0 = 200, 1.0
    load = np.zeros(n)
    load[40:] = 0.5
    r = np.full(n, r0)
    # start at the steady state of setpoint 1: x = 1, u0 = 1; the preset holds it whatever b
    runs = [_closed_loop(PID(TS, setpoint_weight=b, derivative_weight=0.0), r, load=load, x0=r0, u0=r0)
            for b in (0.0, 0.4, 1.0)]
    assert np.max(np.abs(runs[0][:40] - r0)) < 1e-12  # no kick at t = 0 with b != 1
    for y in runs[1:]:
        assert np.max(np.abs(y - runs[0])) < 1e-12
    assert np.max(np.abs(runs[0] - r0)) > 0.05  # the load does move y
    step = np.where(np.arange(n) >= 10, 1.0, 0.0)
    y0, y1 = (_closed_loop(PID(TS, setpoint_weight=b, derivative_weight=0.0), step) for b in (0.0, 1.0))
    assert np.max(np.abs(y1 - y0)) > 0.05
