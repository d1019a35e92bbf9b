"""The noise gains of a measured plant (robustness.plant_response) against python-control's impulse response.

std(u) / std(n) of white measurement noise n through u = -C S n is the H2 norm of C S, sqrt(sum h_k^2) over its
impulse response h; std(u_k - u_{k-1}) / std(n) is sqrt(sum (h_k - h_{k-1})^2). Both are computed here from
python-control's discrete transfer functions, independently of the frequency-domain integral under test.
"""
from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest

from prlpid_fmi.robustness.margins import pid_frequency_response
from prlpid_fmi.robustness.plant_response import MeasuredPlant

TS = 0.1


def _plant_and_pid(Kp, Ti, Td, Tf):
    z = ct.tf([1, 0], [1], TS)
    a = math.exp(-TS)
    P = (1 - a) / (z - a)  # ZOH of 1 / (s + 1)
    F = TS * z / ((Tf + TS) * z - Tf) if Tf > 0 else 1
    C = Kp * (F + (TS / Ti) * z / (z - 1) + Td * (z - 1) / (TS * z) * F)  # the PID law, derivative unfiltered
    return P, C


@pytest.mark.parametrize("Kp, Ti, Td, Tf", [(2.0, 1.0, 0.0, 0.0), (3.0, 0.8, 0.2, 0.05), (5.0, 1.5, 0.4, 0.3)])
def test_noise_and_increment_noise_gains_equal_the_impulse_response_norms(Kp, Ti, Td, Tf):
    P, C = _plant_and_pid(Kp, Ti, Td, Tf)
    CS = ct.minreal(C / (1 + C * P), verbose=False)
    # python-control's discrete impulse is a pulse of height 1/Ts: times Ts, the unit-sample response
    h = ct.impulse_response(CS, T=np.arange(4000) * TS).outputs.ravel() * TS
    std_u = math.sqrt(np.sum(h ** 2))
    std_du = math.sqrt(np.sum(np.diff(np.concatenate([[0.0], h])) ** 2))

    w = np.geomspace(1e-4, math.pi / TS, 400)
    plant = MeasuredPlant(w, np.asarray(P(np.exp(1j * w * TS))).ravel(), TS, (0.0,), (0.0,))
    controller = lambda omega: pid_frequency_response(Kp, Ti, Td, TS, omega, None, Tf, 1)  # noqa: E731
    assert plant.noise_gain(controller) == pytest.approx(std_u, rel=0.01)
    assert plant.noise_gain(controller, increments=True) == pytest.approx(std_du, rel=0.01)
    # the vectorised scan gives the same for every K (Kp scales C as a whole)
    shape = lambda omega: pid_frequency_response(1.0, Ti, Td, TS, omega, None, Tf, 1)  # noqa: E731
    _, noise, _, increments = plant.scan(np.array([Kp]), shape)
    assert noise[0] == pytest.approx(plant.noise_gain(controller), rel=1e-9)
    assert increments[0] == pytest.approx(plant.noise_gain(controller, increments=True), rel=1e-9)
    if Td > 0 and Tf < 0.1:  # a derivative on barely filtered noise: the increments dominate
        assert std_du > std_u

