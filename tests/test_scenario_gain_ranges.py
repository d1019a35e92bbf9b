"""The bundled linear scenarios' gain ranges contain a stabilising PID (python-control reference).

The loop is the discrete PID of eq. 2 as implemented (u = Kp*(e + Ts/Ti*sum(e) + Td/Ts*(e - e_prev)),
the sum including the current error) with the plant discretised by zero-order hold at the scenario's
sample time. A grid over each gain range (log or linear, as the range says) must hold at least one
gain set whose closed-loop poles lie inside the unit circle; a scenario whose ranges hold none can
only ever end with "nothing safe to deploy".
"""
import itertools
from pathlib import Path

import control as ct
import numpy as np
import pytest

from prlpid_fmi.scenario.load import load_scenario
SCENARIOS_DIR = Path(__file__).resolve().parents[1] / "scenarios"

# The plants' transfer functions as the paper gives them (§4.1-4.3, eq. 17).
PLANTS = {
    "first_order": ct.tf([1.0], [1.0, -1.0]),
    "first_order_1p5": ct.tf([1.0], [1.0, -1.5]),
    "second_order": ct.tf([-0.2679 * -41.667, -0.2679], [279.03, -2.9781, 1.0]),
}


def _grid(r, n=15):
    if r.scale == "log":
        return np.geomspace(r.low, r.high, n)
    return np.linspace(r.low, r.high, n)


def _closed_loop_poles(plant_d, ts, kp, ti, td):
    """Roots of den_C*den_P + num_C*num_P, with C(z) = Kp*(z(z-1) + a*z^2 + b*(z-1)^2) / (z(z-1))."""
    num_p, den_p = (np.asarray(c[0][0], float) for c in (plant_d.num, plant_d.den))
    a, b = ts / ti, td / ts
    num_c = kp * (np.array([1.0, -1.0, 0.0]) + a * np.array([1.0, 0.0, 0.0]) + b * np.array([1.0, -2.0, 1.0]))
    den_c = np.array([1.0, -1.0, 0.0])
    return np.roots(np.polyadd(np.polymul(den_c, den_p), np.polymul(num_c, num_p)))


def _stabilising(plant, ts, loop):
    """Gain sets of the grid whose closed loop is stable (every pole inside |z| < 1)."""
    plant_d = ct.c2d(plant, ts, "zoh")
    return [(kp, ti, td) for kp, ti, td in itertools.product(_grid(loop.Kp), _grid(loop.Ti), _grid(loop.Td))
            if np.all(np.abs(_closed_loop_poles(plant_d, ts, kp, ti, td)) < 1.0)]


@pytest.mark.parametrize("name", sorted(PLANTS))
def test_gain_ranges_contain_a_stabilising_pid(name):
    scenario = load_scenario(SCENARIOS_DIR / f"{name}.yaml")
    tuning = scenario.tuning
    loop = tuning.loops[0]
    assert _stabilising(PLANTS[name], tuning.sample_time_s, loop), f"{name}: no stabilising PID in the gain ranges"


def test_the_old_second_order_ranges_held_none():
    """The check can fail: eq. 17 needs Td >= ~180 s, beyond the former range Td in [0, 60] s."""
    from prlpid_fmi.config import GainRange

    class Old:
        Kp, Ti, Td = GainRange(-1.0, -0.01, "linear"), GainRange(1.0, 200.0, "log"), GainRange(0.0, 60.0, "linear")

    assert _stabilising(PLANTS["second_order"], 0.1, Old) == []


def test_closed_loop_polynomial_matches_python_control():
    """The hand-expanded characteristic polynomial has python-control's closed-loop poles."""
    ts, kp, ti, td = 0.1, -0.0178, 30.0, 1000.0
    plant_d = ct.c2d(PLANTS["second_order"], ts, "zoh")
    z = ct.tf([1.0, 0.0], [1.0], ts)
    pid = kp * (1 + (ts / ti) * z / (z - 1) + (td / ts) * (z - 1) / z)
    reference = np.sort_complex(ct.feedback(pid * plant_d, 1).poles())
    ours = np.sort_complex(_closed_loop_poles(plant_d, ts, kp, ti, td))
    assert len(ours) == len(reference) == 4
    assert np.allclose(ours, reference, atol=1e-9)
