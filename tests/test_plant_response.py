"""robustness.plant_response.MeasuredPlant.ms_forbidden, the exact Kp intervals where Ms exceeds its limit, against
python-control: the sensitivity peak of the PID with Kp = K on the same ZOH plant, 1/(s - 1) at Ts = 0.1 s, computed
from python-control's frequency response at the grid's frequencies. At the ends of each interval Ms equals the limit;
inside it Ms exceeds it; just outside, it does not (where no other interval begins)."""
from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest

from prlpid_fmi.robustness.margins import pid_frequency_response
from prlpid_fmi.robustness.plant_response import MeasuredPlant

TS = 0.1


def _ms_by_python_control(K: float, Ti: float, Td: float, w: np.ndarray) -> float:
    """max |1 / (1 + C P)| over w, with C and P as python-control discrete transfer functions."""
    z = ct.tf([1, 0], [1], TS)
    a = math.exp(TS)
    P = (a - 1) / (z - a)  # ZOH of 1 / (s - 1)
    C = K * (1 + (TS / Ti) * z / (z - 1) + Td * (z - 1) / (TS * z))
    L = (C * P)(np.exp(1j * w * TS))
    return float(np.max(np.abs(1.0 / (1.0 + np.asarray(L).ravel()))))


@pytest.mark.parametrize("Ti, Td, limit", [(2.0, 0.0, 2.0), (1.5, 0.3, 2.0), (4.0, 0.2, 1.6)])
def test_the_exact_ms_intervals_match_python_controls_sensitivity_peak(Ti, Td, limit):
    w = np.geomspace(1e-3, math.pi / TS, 300)
    a = math.exp(TS)
    P = (a - 1) / (np.exp(1j * w * TS) - a)
    plant = MeasuredPlant(w, P, TS, (0.0,), (0.0,))
    wg, _ = plant.grid()
    shape = lambda omega: pid_frequency_response(1.0, Ti, Td, TS, omega)  # noqa: E731
    forbidden = plant.ms_forbidden(shape, limit)
    assert len(forbidden) > 0 and np.all(forbidden[:, 0] > 0) and np.all(forbidden[:, 1] > forbidden[:, 0])
    # the union of the intervals: K where Ms > limit on the grid, by python-control, at log-spaced K
    ks = np.geomspace(1e-3, 1e3, 400)
    inside = np.any((ks[:, None] > forbidden[None, :, 0]) & (ks[:, None] < forbidden[None, :, 1]), axis=1)
    ms = np.array([_ms_by_python_control(k, Ti, Td, wg) for k in ks])
    assert np.array_equal(inside, ms > limit)
    # at the ends of the union's outermost interval Ms equals the limit (to 1e-4: between the measured frequencies the
    # grid's P is interpolated, python-control's exact)
    low, high = forbidden[:, 0].min(), forbidden[:, 1].max()
    assert _ms_by_python_control(low, Ti, Td, wg) == pytest.approx(limit, rel=1e-4)
    assert _ms_by_python_control(high, Ti, Td, wg) == pytest.approx(limit, rel=1e-4)
