"""Bundled plant FMUs against truths that do not come from our code: FMPy's validator,
analytic solutions, scipy.signal and scipy.integrate."""
import math
import zipfile

import numpy as np
import pytest
from fmpy.validation import validate_fmu
from scipy import signal
from scipy.integrate import solve_ivp

from prlpid_fmi.fmu import FmuPlant, describe_fmu
from conftest import PLANTS, fmu

TS = 0.1


def test_all_six_paper_plants_are_bundled():
    assert set(PLANTS) == {"FirstOrderUnstable", "SecondOrderUnstable", "TimeVaryingFirstOrder",
                           "TwoTank", "QuadrotorAttitude"}


@pytest.mark.parametrize("name", PLANTS)
def test_fmpy_validates_and_state_capabilities(name, fmi_version):
    path = fmu(name, fmi_version)
    assert validate_fmu(str(path)) == []
    d = describe_fmu(path)
    assert d.fmi_version == f"{fmi_version}.0"
    assert d.can_get_and_set_state and d.can_serialize_state
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
    assert "sources/model.c" in names and "sources/instance.c" in names
    assert any(n.startswith("binaries/") and n.endswith(".so") for n in names)
    assert any(n.startswith("documentation/") and n.endswith(".mo") for n in names)


@pytest.mark.parametrize("a", [1.0, 1.5])
def test_first_order_unit_step_is_analytic(a, fmi_version):
    with FmuPlant(fmu("FirstOrderUnstable", fmi_version), parameters={"a": a}, sample_time_s=TS) as plant:
        y = [plant.reset()[0]] + [plant.step([1.0])[0] for _ in range(20)]
    t = np.arange(21) * TS
    np.testing.assert_allclose(y, (np.exp(a * t) - 1.0) / a, rtol=0, atol=1e-8)


def test_second_order_matches_scipy_zoh_discretisation(fmi_version):
    num = [-0.2679 * -41.667, -0.2679]
    den = [279.03, -2.9781, 1.0]
    ad, bd, cd, dd, _ = signal.cont2discrete(signal.tf2ss(num, den), TS, method="zoh")
    u = np.random.default_rng(0).uniform(-1, 1, 200)
    _, y_ref, _ = signal.dlsim((ad, bd, cd, dd, TS), u)
    with FmuPlant(fmu("SecondOrderUnstable", fmi_version), sample_time_s=TS) as plant:
        y = [plant.reset()[0]] + [plant.step([uk])[0] for uk in u[:-1]]
    np.testing.assert_allclose(y, y_ref[:, 0], rtol=0, atol=1e-6)


def _zoh_solve(rhs, x0, u, n_steps):
    """Reference ZOH simulation with solve_ivp (DOP853, tight tolerances) sample by sample."""
    xs = [np.array(x0, float)]
    for k in range(n_steps):
        sol = solve_ivp(lambda t, x: rhs(t, x, u[k]), (k * TS, (k + 1) * TS), xs[-1],
                        method="DOP853", rtol=1e-12, atol=1e-12)
        xs.append(sol.y[:, -1])
    return np.array(xs)


def test_time_varying_matches_solve_ivp(fmi_version):
    u = np.random.default_rng(1).uniform(-1, 1, (60, 1))

    def rhs(t, x, uk):
        return [(0.5 + 0.25 * (math.sin(0.2 * math.pi * t) + 1.0)) * x[0] + uk[0]]

    ref = _zoh_solve(rhs, [0.0], u, 60)
    with FmuPlant(fmu("TimeVaryingFirstOrder", fmi_version), outputs=["y", "a_t"], sample_time_s=TS) as plant:
        out = [plant.reset()] + [plant.step(uk) for uk in u]
    out = np.array(out)
    np.testing.assert_allclose(out[:, 0], ref[:, 0], rtol=0, atol=1e-6)
    t = np.arange(61) * TS
    np.testing.assert_allclose(out[:, 1], 0.5 + 0.25 * (np.sin(0.2 * np.pi * t) + 1), atol=1e-12)


def test_quadrotor_matches_solve_ivp(fmi_version):
    ix, iy, iz = 0.4, 0.4, 0.8
    u = np.random.default_rng(2).uniform(-0.2, 0.2, (40, 3))

    def rhs(t, x, uk):
        p, q, r = x[3:]
        return [p, q, r, (iy - iz) / ix * q * r + uk[0] / ix, (iz - ix) / iy * p * r + uk[1] / iy,
                (ix - iy) / iz * p * q + uk[2] / iz]

    x0 = [0.1, -0.05, 0.2, 0.3, -0.2, 0.5]
    ref = _zoh_solve(rhs, x0, u, 40)
    names = ["phi0", "theta0", "psi0", "p0", "q0", "r0"]
    with FmuPlant(fmu("QuadrotorAttitude", fmi_version), parameters=dict(zip(names, x0)),
                  outputs=["phi", "theta", "psi", "p", "q", "r"], sample_time_s=TS) as plant:
        out = np.array([plant.reset()] + [plant.step(uk) for uk in u])
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-6)


def test_two_tank_settles_at_analytic_equilibrium(fmi_version):
    q_in, k1, k2 = 20.0, 10.74, 7.89
    with FmuPlant(fmu("TwoTank", fmi_version), inputs=["q_in"], outputs=["h1", "h2"], sample_time_s=TS) as plant:
        plant.reset()
        for _ in range(8000):
            h = plant.step([q_in])
    h2 = (q_in / k2) ** 2
    np.testing.assert_allclose(h, [h2 + (q_in / k1) ** 2, h2], rtol=1e-6)


def test_two_tank_levels_never_negative(fmi_version):
    with FmuPlant(fmu("TwoTank", fmi_version), inputs=["q_in"], outputs=["h1", "h2"],
                  parameters={"h1_0": 0.5, "h2_0": 0.2}, sample_time_s=TS) as plant:
        plant.reset()
        levels = np.array([plant.step([-50.0]) for _ in range(200)])
    assert levels.min() >= 0.0
    assert levels[-1, 0] == 0.0  # tank 1 drained by the negative inflow and stays empty
