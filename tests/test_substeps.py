"""Each bundled plant's internal RK4 step (`fixed_step` in its model.yaml) is accurate to 1e-9.

Truth does not come from our code: the exact zero-order-hold solution for the linear plants
(exponential / matrix exponential) and scipy's DOP853 at rtol 1e-13 for the nonlinear and the
time-varying ones. Each plant runs closed loops with a PID (paper eq. 2, our PID class: it is the
same on both sides) over a bundled scenario's evaluation horizon and setpoints, plus the setpoint
range's extremes where they matter, with a few gain sets that settle the loop. The error is the
largest |y_fmu - y_reference| / measurement_scale over the run, so "1e-9" means 1e-9 of a
normalised output of order 1 (the units the reward sees).

The next coarser step of the 1-2-5 series that divides the 0.1 s sample misses 1e-9 on at least
one of the loops: the default is the largest such step that meets it (docs/architecture.md,
"Internal step").
"""
import math
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import yaml
from scipy.integrate import solve_ivp
from scipy.linalg import expm

from prlpid_fmi.control import PID
from prlpid_fmi.fmu import FmuPlant
from prlpid_fmi.fmu.build import load_spec
from conftest import PLANTS, fmu

TS = 0.1
TOLERANCE = 1e-9
# 1-2-5 steps that divide the sample time, coarse to fine (s)
STEPS_S = (0.1, 0.05, 0.025, 0.02, 0.01, 0.005, 0.004, 0.002, 0.001)


def _closed_loop(step, y0, setpoints, gains, u_limits):
    """Positional PID (clamping) around `step(k, u) -> y`; returns outputs, shape (len(setpoints) + 1, n_loops)."""
    n = len(y0)
    pid = PID(TS, n, u_limits[0], u_limits[1])
    ys = [np.asarray(y0, float)]
    for k, r in enumerate(setpoints):
        u = pid.step(r, ys[-1], *gains)
        ys.append(np.asarray(step(k, u), float))
    return np.array(ys)


def _zoh_ivp(rhs, x0, output):
    """A `step(k, u)` that integrates rhs(t, x, u) over one sample with scipy (DOP853, rtol 1e-13)."""
    x = np.array(x0, float)

    def step(k, u):
        nonlocal x
        sol = solve_ivp(lambda t, z: rhs(t, z, u), (k * TS, (k + 1) * TS), x, method="DOP853", rtol=1e-13, atol=1e-14)
        x = sol.y[:, -1]
        return output(x)
    return step


def _first_order(a, b=1.0):
    ead = math.exp(a * TS)
    x = [0.0]

    def step(k, u):  # exact: x+ = e^(aT) x + (e^(aT) - 1)/a b u
        x[0] = ead * x[0] + (ead - 1.0) / a * b * u[0]
        return [x[0]]
    return step


def _second_order():
    K, Tn, a2, a1, a0 = -0.2679, 41.667, 279.03, -2.9781, 1.0
    M = np.zeros((3, 3))
    M[:2, :2] = [[0.0, 1.0], [-a0 / a2, -a1 / a2]]
    M[1, 2] = 1.0 / a2
    E = expm(M * TS)  # exact ZOH discretisation of the augmented system
    Ad, Bd, C = E[:2, :2], E[:2, 2], np.array([K, -K * Tn])
    x = np.zeros(2)

    def step(k, u):
        nonlocal x
        x = Ad @ x + Bd * u[0]
        return [C @ x]
    return step


def _time_varying(t, x, u):
    return [(0.5 + 0.25 * (math.sin(0.2 * math.pi * t) + 1.0)) * x[0] + u[0]]


def _quadrotor(t, x, u, ix=0.4, iy=0.4, iz=0.8):
    p, q, r = x[3:]
    return [p, q, r, (iy - iz) / ix * q * r + u[0] / ix, (iz - ix) / iy * p * r + u[1] / iy,
            (ix - iy) / iz * p * q + u[2] / iz]


def _two_tank(t, x, u, A1=15.52, A2=15.52, k1=10.74, k2=7.89):
    q12 = k1 * math.sqrt(max(x[0] - x[1], 0.0))
    return [(u[0] - q12) / A1, (q12 - k2 * math.sqrt(max(x[1], 0.0))) / A2]


def _hold(*segments):
    """[(n_samples, setpoint (n_loops,)), ...] -> setpoint per sample."""
    return [list(r) for n, r in segments for _ in range(n)]


ONE_STEP = _hold((100, [1.0]), (100, [-0.5]))
# plant -> (inputs, outputs, FMU parameters, measurement_scale, u_limits, reference factory, [(setpoints, (Kp, Ti, Td))])
CASES = {
    "FirstOrderUnstable": [
        (["u"], ["y"], {"a": a}, 1.0, ([-10.0], [10.0]), lambda a=a: _first_order(a), ONE_STEP, gains)
        for a in (1.0, 1.5) for gains in (([3.0], [1.0], [0.05]), ([8.0], [0.7], [0.1]))],
    "SecondOrderUnstable": [
        (["u"], ["y"], {}, 1.0, ([-20.0], [20.0]), _second_order, _hold((500, [1.0]), (500, [-0.5])), gains)
        for gains in (([-0.2], [40.0], [10.0]), ([-0.5], [20.0], [30.0]))],
    "TimeVaryingFirstOrder": [
        (["u"], ["y"], {}, 1.0, ([-10.0], [10.0]), lambda: _zoh_ivp(_time_varying, [0.0], lambda x: [x[0]]),
         ONE_STEP, gains)
        for gains in (([3.0], [1.0], [0.05]), ([8.0], [0.7], [0.1]))],
    "QuadrotorAttitude": [
        (["U_phi", "U_theta", "U_psi"], ["phi", "theta", "psi"], {}, 0.5, ([-2.0] * 3, [2.0] * 3),
         lambda: _zoh_ivp(_quadrotor, [0.0] * 6, lambda x: x[:3]), setpoints, gains)
        for setpoints, gains in (
            (_hold((150, [0.2, -0.1, 0.3]), (150, [-0.2, 0.2, 0.0])), ([2.0] * 3, [20.0] * 3, [0.5] * 3)),
            (_hold((150, [0.5, -0.5, 0.5]), (150, [-0.5, 0.5, -0.5])), ([4.0] * 3, [10.0] * 3, [0.4] * 3)))],
    "TwoTank": [
        (["q_in"], ["h2"], {"h1_0": 15.4, "h2_0": 10.0}, 10.0, ([0.0], [50.0]),
         lambda: _zoh_ivp(_two_tank, [15.4, 10.0], lambda x: [x[1]]),
         _hold((50, [10.0]), (300, [14.0]), (300, [6.0]), (350, [10.0])), gains)
        for gains in (([10.0], [30.0], [0.5]), ([5.0], [50.0], [0.0]))],
}


def _fixed_step(name: str) -> float:
    """The FMU's start value of fixed_step (what a user gets without setting it)."""
    with zipfile.ZipFile(fmu(name)) as zf:
        root = ET.fromstring(zf.read("modelDescription.xml"))
    [var] = [v for v in root.iter("ScalarVariable") if v.get("name") == "fixed_step"]
    return float(var.find("Real").get("start"))


def _worst_error(name: str, fixed_step_s: float | None) -> float:
    """Largest normalised output error over the plant's loops at `fixed_step_s` (None: the FMU's default)."""
    worst = 0.0
    for inputs, outputs, parameters, scale, limits, reference, setpoints, gains in CASES[name]:
        if fixed_step_s is not None:
            parameters = {**parameters, "fixed_step": fixed_step_s}
        with FmuPlant(fmu(name), inputs, outputs, TS, parameters) as plant:
            y = _closed_loop(lambda k, u: plant.step(u), plant.reset(), setpoints, gains, limits)
        y_ref = _closed_loop(reference(), y[0], setpoints, gains, limits)
        worst = max(worst, float(np.max(np.abs(y - y_ref))) / scale)
    return worst


def test_every_bundled_plant_has_cases():
    assert set(CASES) == set(PLANTS)


@pytest.mark.parametrize("name", PLANTS)
def test_default_fixed_step_meets_1e_9_and_the_next_coarser_does_not(name):
    default = load_spec(name).variables[1].start
    assert _fixed_step(name) == default
    assert default in STEPS_S
    assert _worst_error(name, None) <= TOLERANCE
    coarser = STEPS_S.index(default) - 1
    if coarser >= 0:
        assert _worst_error(name, STEPS_S[coarser]) > TOLERANCE


def test_bundled_scenarios_sample_at_a_multiple_of_the_fixed_step():
    paths = sorted((Path(__file__).resolve().parents[1] / "scenarios").glob("*.yaml"))
    assert paths
    for path in paths:
        plant = yaml.safe_load(path.read_text())["plant"]
        if plant["fmu"] in PLANTS:
            ratio = plant["sample_time"] / load_spec(plant["fmu"]).variables[1].start
            assert abs(ratio - round(ratio)) < 1e-9, path
