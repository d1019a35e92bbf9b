"""robustness.loop_models: the closed loop of several (coupled) PID loops on their local models, against
python-control's interconnection of the same blocks and against robustness.local_model for one loop."""
from __future__ import annotations

import math

import control
import numpy as np
import pytest
from scipy.signal import cont2discrete

from prlpid_fmi.control.pid import coupling_matrix
from prlpid_fmi.robustness.local_model import LocalModel, feedback_polynomials, load_responses
from prlpid_fmi.robustness.loop_models import closed_loop, loop_plants, stable, step_responses
from prlpid_fmi.robustness.margins import pid_frequency_response

TS = 0.1


def model(num, den) -> LocalModel:
    """The ZOH discretisation of num(s) / den(s) at TS as a LocalModel (powers of z^-1)."""
    b, a, _ = cont2discrete((num, den), TS, method="zoh")
    return LocalModel(np.ravel(b), np.ravel(a), TS, (0.0,), 0.0)


def q_tf(num, den):
    """num(q) / den(q), polynomials in ascending powers of q = z^-1, as python-control's discrete transfer function."""
    length = max(len(num), len(den))
    n, d = np.zeros(length), np.zeros(length)
    n[:len(num)], d[:len(den)] = num, den
    return control.tf(n, d, TS)


def reference(models, Kp, Ti, Td, N, tf, order, coupling):
    """python-control's closed loop d -> (y, u): P = diag(P_j), u = K y with K = diag(PD_i) M diag(F_j) + diag(I_i) M,
    M = C - I (the module docstring of robustness.loop_models, built from control.pid's sections by hand)."""
    n = len(models)
    P = control.append(*[control.ss(q_tf(m.numerator, m.denominator)) for m in models])
    filters, pds, integrals = [], [], []
    for i in range(n):
        num, den = np.array([1.0]), np.array([1.0])
        for _ in range(order if tf[i] > 0 else 0):
            T = tf[i] / order
            num, den = np.polymul(num, [TS / (T + TS)]), np.polymul(den, [1.0, -T / (T + TS)])
        filters.append(control.ss(q_tf(num, den)))
        Tdf = Td[i] / N
        dd = np.array([Tdf + TS, -Tdf])
        pds.append(control.ss(q_tf(Kp[i] * (dd + Td[i] * np.array([1.0, -1.0])), dd)))
        integrals.append(control.ss(q_tf([Kp[i] * TS / Ti[i]], [1.0, -1.0])))
    M = np.asarray(coupling) - np.eye(n)
    Mss = control.ss(np.zeros((0, 0)), np.zeros((0, n)), np.zeros((n, 0)), M, TS)
    K = control.append(*pds) * Mss * control.append(*filters) + control.append(*integrals) * Mss
    T = control.feedback(P, K, sign=1)
    return T, K * T, P, K


CASE = dict(Kp=[1.2, 0.9, 0.6], Ti=[3.0, 2.5, math.inf], Td=[0.6, 0.5, 0.4], N=10.0, tf=[0.0, 0.2, 0.1], order=2,
            coupling=coupling_matrix([0.1, -0.2, 0.05, 0.15, -0.1, 0.2]))
MODELS = [model([1.0], [0.4, 0.0, 0.0]), model([1.0], [0.4, 0.0, 0.0]), model([1.0], [0.8, 0.4, 0.0])]


def test_the_coupled_closed_loop_is_python_controls_interconnection():
    """Three loops (two double integrators like the quadrotor's roll and pitch, a lag and integrator), coupled,
    different filters, one loop without an integral term: the step responses at each plant input of y and u are
    python-control's (feedback of the same blocks), and both call the loop stable."""
    c = CASE
    A, B, Y, U = closed_loop(MODELS, c["Kp"], c["Ti"], c["Td"], TS, c["N"], c["tf"], c["order"], c["coupling"])
    dy, du = step_responses(A, B, Y, U, 200)
    T, KT, _, _ = reference(MODELS, c["Kp"], c["Ti"], c["Td"], c["N"], c["tf"], c["order"], c["coupling"])
    times = np.arange(200) * TS
    assert stable(A) and np.all(np.abs(control.poles(T)) < 1.0)
    y_ref = control.step_response(T, times).outputs  # (outputs, inputs, time)
    u_ref = control.step_response(KT, times).outputs
    np.testing.assert_allclose(dy, np.moveaxis(y_ref, 2, 0), atol=1e-9 * np.max(np.abs(y_ref)))
    np.testing.assert_allclose(du, np.moveaxis(u_ref, 2, 0), atol=1e-9 * np.max(np.abs(u_ref)))
    assert np.max(np.abs(dy[:, 0, 1])) > 1e-3  # the coupling moves roll on a pitch load: the test sees it


def test_an_unstable_gain_is_called_unstable_as_python_control_finds():
    c = dict(CASE, Kp=[40.0, 0.9, 0.6])
    A = closed_loop(MODELS, c["Kp"], c["Ti"], c["Td"], TS, c["N"], c["tf"], c["order"], c["coupling"])[0]
    T, *_ = reference(MODELS, c["Kp"], c["Ti"], c["Td"], c["N"], c["tf"], c["order"], c["coupling"])
    assert np.max(np.abs(control.poles(T))) > 1.0
    assert not stable(A)


def test_each_loops_sensitivity_is_the_input_sensitivity_of_python_controls_loop():
    """1 / (1 + C_i P_i) with the effective plants of loop_plants (the same filter on every loop) equals the diagonal of
    the input sensitivity (I - K P)^-1 of python-control's blocks, evaluated frequency by frequency."""
    c = dict(CASE, tf=[0.15, 0.15, 0.15])
    w = np.geomspace(0.01, math.pi / TS, 60)
    plants = loop_plants(MODELS, c["Kp"], c["Ti"], c["Td"], TS, c["N"], c["tf"], c["order"], c["coupling"], w)
    _, _, P, K = reference(MODELS, c["Kp"], c["Ti"], c["Td"], c["N"], c["tf"], c["order"], c["coupling"])
    KP = np.moveaxis(control.frequency_response(K * P, w).complex, 2, 0)  # (W, n, n)
    S_in = np.linalg.inv(np.eye(3)[None] - KP)
    for i in range(3):
        C = pid_frequency_response(c["Kp"][i], c["Ti"][i], c["Td"][i], TS, w, c["N"], c["tf"][i], c["order"])
        np.testing.assert_allclose(1.0 / (1.0 + C * plants[i]), S_in[:, i, i], rtol=1e-8)
    assert np.max(np.abs(plants[0] / MODELS[0].response(w) - 1.0)) > 0.01  # the other loops change what loop 1 sees


@pytest.mark.parametrize("Kp, Ti, Td, N, Tf, order", [(2.0, 1.5, 0.3, 10.0, 0.2, 2), (2.0, math.inf, 0.3, None, 0.0, 1),
                                                      (1.3, 0.7, 0.0, None, 0.5, 1)])
def test_one_uncoupled_loop_is_local_models_load_response(Kp, Ti, Td, N, Tf, order):
    m = model([1.0], [1.0, -1.0])
    Nc, Dc = feedback_polynomials(Kp, Ti, Td, TS, N, Tf, order)
    dy, du = load_responses(m, Nc, Dc, 150)
    A, B, Y, U = closed_loop([m], [Kp], [Ti], [Td], TS, N, [Tf], order)
    y, u = step_responses(A, B, Y, U, 150)
    np.testing.assert_allclose(y[:, 0, 0], dy, atol=1e-10)
    np.testing.assert_allclose(u[:, 0, 0], du, atol=1e-10)
