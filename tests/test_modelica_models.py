"""Each bundled plant's Modelica model (.mo) against independent truths, and against its FMU.

The .mo files are parsed with pymoca and simulated with CasADi (tests/modelica_reference.py). They are
checked against analytic solutions, scipy's transfer-function simulation and scipy's ODE solver on
equations written out again here; then each FMU (built from the C sources) is checked against its .mo.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from modelica_reference import load_modelica, modelica_interface, simulate_modelica  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PLANTS = ["FirstOrderUnstable", "SecondOrderUnstable", "TimeVaryingFirstOrder", "TwoTank", "QuadrotorAttitude"]
TOL = 1e-6


def mo(plant: str) -> Path:
    return ROOT / "plant_sources" / plant / f"{plant}.mo"


def zoh_truth(rhs, x0, inputs: np.ndarray, ts: float) -> np.ndarray:
    """Integrate der(x) = rhs(t, x, u) with u = inputs[k] held over [k ts, (k+1) ts]; states at the grid."""
    xs = [np.asarray(x0, dtype=float)]
    for k, u in enumerate(inputs):
        sol = solve_ivp(lambda t, x: rhs(t, x, u), (k * ts, (k + 1) * ts), xs[-1],
                        method="DOP853", rtol=1e-12, atol=1e-12)
        assert sol.success, sol.message
        xs.append(sol.y[:, -1])
    return np.array(xs)


# -- the models as pymoca sees them ------------------------------------------------------------------
@pytest.mark.parametrize("plant", PLANTS)
def test_model_matches_plant_interface(plant):
    """Same public variables as the C plant's model.yaml: names, causality, defaults, units."""
    yaml = pytest.importorskip("yaml")
    spec = yaml.safe_load((ROOT / "plant_sources" / plant / "model.yaml").read_text())
    iface = modelica_interface(mo(plant))
    assert iface["description"]
    expected = {v["name"]: v for v in spec["variables"]}
    assert set(iface["variables"]) == set(expected)
    for name, var in iface["variables"].items():
        want = expected[name]
        assert var["causality"] == want["causality"], name
        assert var["unit"] == want.get("unit"), name
        assert var["description"], f"{name} has no description string"
        if want["causality"] in ("input", "parameter"):
            assert var["start"] == pytest.approx(float(want["start"]), abs=0), name
    model = load_modelica(mo(plant))
    assert model.output_names == [v["name"] for v in spec["variables"] if v["causality"] == "output"]
    assert model.input_names == [v["name"] for v in spec["variables"] if v["causality"] == "input"]
    assert len(model.state_names) == len(spec["states"])


def test_simulate_modelica_rejects_unknown_names_and_bad_shapes():
    with pytest.raises(KeyError):
        simulate_modelica(mo("FirstOrderUnstable"), {"nope": 1.0}, {}, 0.1, 3)
    with pytest.raises(KeyError):
        simulate_modelica(mo("FirstOrderUnstable"), {}, {"v": np.zeros(3)}, 0.1, 3)
    with pytest.raises(ValueError):
        simulate_modelica(mo("FirstOrderUnstable"), {}, {"u": np.zeros(4)}, 0.1, 3)


# -- against independent truths ------------------------------------------------------------------------
@pytest.mark.parametrize("a, b, x0", [(1.0, 1.0, 0.0), (1.5, 1.0, 0.0), (1.5, 0.7, 0.2)])
def test_first_order_unstable_step_response_is_analytic(a, b, x0):
    ts, n = 0.1, 50
    params = {"a": a, "b": b} if x0 == 0.0 else {"a": a, "b": b, "x0": x0}
    y = simulate_modelica(mo("FirstOrderUnstable"), params, {"u": np.ones(n)}, ts, n)["y"]
    t = ts * np.arange(n + 1)
    exact = x0 * np.exp(a * t) + b * (np.exp(a * t) - 1.0) / a
    assert y.shape == (n + 1,)
    np.testing.assert_allclose(y, exact, rtol=0, atol=TOL)


def test_first_order_defaults_are_one_over_s_minus_one():
    y = simulate_modelica(mo("FirstOrderUnstable"), None, {"u": np.ones(10)}, 0.1, 10)["y"]
    np.testing.assert_allclose(y, np.expm1(0.1 * np.arange(11)), rtol=0, atol=TOL)


def test_second_order_unstable_realises_the_transfer_function():
    K, Tn, a2, a1, a0 = -0.2679, 41.667, 279.03, -2.9781, 1.0
    ts, n = 0.5, 400
    u = np.repeat(np.random.default_rng(1).uniform(-1.0, 1.0, n // 20), 20)  # random steps, 10 s each
    y = simulate_modelica(mo("SecondOrderUnstable"), {}, {"u": u}, ts, n)["y"]
    # scipy's own realisation of K (1 - Tn s) / (a2 s^2 + a1 s + a0), discretised exactly for a ZOH input.
    A, B, C, D = signal.tf2ss([-K * Tn, K], [a2, a1, a0])
    _, y_ref, _ = signal.dlsim(signal.cont2discrete((A, B, C, D), ts, method="zoh"), np.append(u, 0.0))
    y_ref = np.ravel(y_ref)
    assert np.abs(y_ref).max() > 0.5  # a non-trivial response
    np.testing.assert_allclose(y, y_ref, rtol=0, atol=TOL)


def test_second_order_unstable_initial_states():
    ts, n = 0.5, 40
    K, Tn, a2, a1, a0 = -0.2679, 41.667, 279.03, -2.9781, 1.0
    u = np.random.default_rng(2).uniform(-1.0, 1.0, n)
    y = simulate_modelica(mo("SecondOrderUnstable"), {"x1_0": 0.4, "x2_0": -0.02}, {"u": u}, ts, n)["y"]
    xs = zoh_truth(lambda t, x, v: [x[1], (v - a1 * x[1] - a0 * x[0]) / a2], [0.4, -0.02], u, ts)
    np.testing.assert_allclose(y, K * (xs[:, 0] - Tn * xs[:, 1]), rtol=0, atol=TOL)


@pytest.mark.parametrize("params", [{}, {"a_offset": -0.3, "a_amplitude": 0.6, "a_frequency": 0.35, "x0": 0.5}])
def test_time_varying_first_order_matches_ode_solver(params):
    p = {"a_offset": 0.5, "a_amplitude": 0.25, "a_frequency": 0.1, "x0": 0.0} | params
    ts, n = 0.1, 60
    u = np.random.default_rng(3).uniform(-1.0, 1.0, n)
    out = simulate_modelica(mo("TimeVaryingFirstOrder"), params, {"u": u}, ts, n)

    def pole(t):
        return p["a_offset"] + p["a_amplitude"] * (math.sin(2.0 * math.pi * p["a_frequency"] * t) + 1.0)

    xs = zoh_truth(lambda t, x, v: [pole(t) * x[0] + v], [p["x0"]], u, ts)
    t = ts * np.arange(n + 1)
    np.testing.assert_allclose(out["y"], xs[:, 0], rtol=0, atol=TOL)
    np.testing.assert_allclose(out["a_t"], [pole(ti) for ti in t], rtol=0, atol=1e-12)


def test_quadrotor_attitude_matches_ode_solver():
    p = {"Ix": 0.3, "Iy": 0.5, "Iz": 0.8, "phi0": 0.1, "theta0": -0.2, "psi0": 0.3, "p0": 0.5, "q0": -0.4, "r0": 0.7}
    ts, n = 0.1, 50
    U = np.random.default_rng(4).uniform(-0.1, 0.1, (n, 3))
    out = simulate_modelica(mo("QuadrotorAttitude"), p, dict(zip(["U_phi", "U_theta", "U_psi"], U.T)), ts, n)
    Ix, Iy, Iz = p["Ix"], p["Iy"], p["Iz"]

    def rhs(t, s, v):
        _, _, _, wp, wq, wr = s
        return [wp, wq, wr,
                (Iy - Iz) / Ix * wq * wr + v[0] / Ix,
                (Iz - Ix) / Iy * wp * wr + v[1] / Iy,
                (Ix - Iy) / Iz * wp * wq + v[2] / Iz]

    xs = zoh_truth(rhs, [p[k] for k in ("phi0", "theta0", "psi0", "p0", "q0", "r0")], U, ts)
    for i, name in enumerate(["phi", "theta", "psi", "p", "q", "r"]):
        np.testing.assert_allclose(out[name], xs[:, i], rtol=0, atol=TOL, err_msg=name)


def test_quadrotor_attitude_defaults_decouple_roll_and_pitch():
    """With Ix = Iy the yaw rate is constant; a pure roll torque gives phi = U t^2 / (2 Ix)."""
    ts, n = 0.1, 20
    out = simulate_modelica(mo("QuadrotorAttitude"), {}, {"U_phi": np.full(n, 0.2)}, ts, n)
    t = ts * np.arange(n + 1)
    np.testing.assert_allclose(out["phi"], 0.2 * t**2 / (2 * 0.4), rtol=0, atol=TOL)
    np.testing.assert_allclose(out["p"], 0.2 * t / 0.4, rtol=0, atol=TOL)
    for name in ("theta", "psi", "q", "r"):
        assert np.all(out[name] == 0.0), name


TANK = {"A1": 15.52, "A2": 15.52, "k1": 10.74, "k2": 7.89}


@pytest.mark.parametrize("q_in", [10.0, 30.0])
def test_two_tank_settles_to_analytic_equilibrium(q_in):
    n = 600
    out = simulate_modelica(mo("TwoTank"), {}, {"q_in": np.full(n, q_in)}, 1.0, n)
    h2 = (q_in / TANK["k2"]) ** 2
    h1 = h2 + (q_in / TANK["k1"]) ** 2
    assert out["h1"][-1] == pytest.approx(h1, abs=1e-4)
    assert out["h2"][-1] == pytest.approx(h2, abs=1e-4)


def test_two_tank_matches_ode_solver_in_the_smooth_region():
    ts, n = 0.1, 50
    rng = np.random.default_rng(5)
    U = np.column_stack([rng.uniform(20.0, 40.0, n), rng.uniform(0.0, 5.0, n), rng.uniform(0.8, 1.2, n)])
    out = simulate_modelica(mo("TwoTank"), {"h1_0": 15.4, "h2_0": 10.0},
                            dict(zip(["q_in", "q_d", "valve_factor"], U.T)), ts, n)

    def rhs(t, h, v):
        q12 = v[2] * TANK["k1"] * math.sqrt(max(h[0] - h[1], 0.0))
        return [(v[0] + v[1] - q12) / TANK["A1"], (q12 - TANK["k2"] * math.sqrt(max(h[1], 0.0))) / TANK["A2"]]

    xs = zoh_truth(rhs, [15.4, 10.0], U, ts)
    np.testing.assert_allclose(out["h1"], xs[:, 0], rtol=0, atol=TOL)
    np.testing.assert_allclose(out["h2"], xs[:, 1], rtol=0, atol=TOL)


@pytest.mark.parametrize("q_d", [0.0, -5.0])
def test_two_tank_empty_tanks_stay_exactly_empty(q_d):
    """No inflow (or a draining disturbance on tank 1): the levels stay exactly 0, never negative."""
    n = 100
    out = simulate_modelica(mo("TwoTank"), {}, {"q_in": np.zeros(n), "q_d": np.full(n, q_d)}, 0.1, n)
    assert np.all(out["h1"] == 0.0)
    assert np.all(out["h2"] == 0.0)


def _vec(dm) -> np.ndarray:
    return np.array(dm.full(), dtype=float).ravel()


def test_two_tank_empty_tank_rule_in_the_equations():
    """der(h) is clamped to 0 only when the level is <= 0 and the unclamped rate is negative."""
    m = load_modelica(mo("TwoTank"))
    p = [15.52, 15.52, 10.74, 7.89, 0.0, 0.0]
    assert m.parameter_names == ["A1", "A2", "k1", "k2", "h1_0", "h2_0"]
    # Empty tank 1 with a draining disturbance: clamped. A level of 0.5 with the same inputs: not.
    assert _vec(m.rhs(0.0, [0.0, 0.0], [0.0, -5.0, 1.0], p)).tolist() == [0.0, 0.0]
    dh = _vec(m.rhs(0.0, [0.5, 0.5], [0.0, -5.0, 1.0], p))
    assert dh[0] == pytest.approx(-5.0 / 15.52)
    # Empty tank 2 fed from tank 1: positive rate, not clamped.
    dh = _vec(m.rhs(0.0, [4.0, 0.0], [0.0, 0.0, 1.0], p))
    assert dh[1] == pytest.approx(10.74 * 2.0 / 15.52)
    # Empty tank 2 with a reversed valve (negative flow): clamped.
    dh = _vec(m.rhs(0.0, [4.0, 0.0], [0.0, 0.0, -1.0], p))
    assert dh[1] == 0.0


# -- against the FMUs ----------------------------------------------------------------------------------
FMU_CASES = {
    "FirstOrderUnstable": dict(inputs={"u": (-1.0, 1.0)}, outputs=["y"],
                               parameters={"a": 1.5, "b": 0.8, "x0": 0.2}),
    "SecondOrderUnstable": dict(inputs={"u": (-1.0, 1.0)}, outputs=["y"],
                                parameters={"x1_0": 0.5, "x2_0": -0.01}),
    "TimeVaryingFirstOrder": dict(inputs={"u": (-1.0, 1.0)}, outputs=["y", "a_t"],
                                  parameters={"x0": 0.3, "a_frequency": 0.25}),
    "TwoTank": dict(inputs={"q_in": (20.0, 40.0), "q_d": (0.0, 5.0), "valve_factor": (0.8, 1.2)},
                    outputs=["h1", "h2"], parameters={"h1_0": 15.4, "h2_0": 10.0}),
    "QuadrotorAttitude": dict(inputs={"U_phi": (-0.05, 0.05), "U_theta": (-0.05, 0.05), "U_psi": (-0.05, 0.05)},
                              outputs=["phi", "theta", "psi", "p", "q", "r"],
                              parameters={"Iz": 0.7, "p0": 0.2, "r0": 0.5, "theta0": 0.1}),
}


@pytest.mark.parametrize("plant", PLANTS)
def test_fmu_matches_modelica(plant):
    fmu = pytest.importorskip("prlpid_fmi.fmu")
    case = FMU_CASES[plant]
    ts, n = 0.1, 50
    rng = np.random.default_rng(sum(map(ord, plant)))
    names = list(case["inputs"])
    U = np.column_stack([rng.uniform(lo, hi, n) for lo, hi in case["inputs"].values()])
    ref = simulate_modelica(mo(plant), case["parameters"], dict(zip(names, U.T)), ts, n)

    plant_fmu = fmu.FmuPlant(fmu.bundled_fmu(plant, fmi_version=2), inputs=names, outputs=case["outputs"],
                             sample_time_s=ts, parameters=case["parameters"])
    try:
        ys = [plant_fmu.reset()]
        ys += [plant_fmu.step(u) for u in U]
    finally:
        plant_fmu.close()
    ys = np.array(ys)
    assert ys.shape == (n + 1, len(case["outputs"]))
    for i, name in enumerate(case["outputs"]):
        np.testing.assert_allclose(ys[:, i], ref[name], rtol=0, atol=TOL, err_msg=f"{plant}.{name}")
