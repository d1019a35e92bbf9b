"""The plant zoo of benchmarks/zoo/ (benchmarks/bench_zoo.py) built as FMUs, against scipy.

- LinearBatch, with the parameters of every linear zoo scenario (Astrom & Hagglund's PID test batch): the
  open-loop response to a seeded sequence of held steps against the exact zero-order-hold solution of the
  transfer function N(s)/D(s) (scipy.signal.cont2discrete + dlsim), the dead time a shift by whole samples.
- The nonlinear plants (Van de Vusse CSTR, ball and beam, bioreactor, spherical tank, distillation-like column):
  the response to held steps of the input against scipy's DOP853 (rtol 1e-12) on the equations of
  benchmarks/zoo/models.py, written from the cited physics, not from the C code; their start states against
  the steady states computed by hand in the model files.
Bound: the output error stays within BOUND of the loop's measurement scale (RK4 at each scenario's fixed_step).
"""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import signal
from scipy.integrate import solve_ivp

from prlpid_fmi.fmu import FmuPlant, build_fmu

ROOT = Path(__file__).resolve().parents[1]
ZOO = ROOT / "benchmarks" / "zoo"
_spec = importlib.util.spec_from_file_location("zoo_models", ZOO / "models.py")
models = importlib.util.module_from_spec(_spec)
sys.modules["zoo_models"] = models
_spec.loader.exec_module(models)

BOUND = 1e-7
SCENARIOS = {p.stem: yaml.safe_load(p.read_text()) for p in sorted((ZOO / "scenarios").glob("*.yaml"))}
LINEAR = [n for n, s in SCENARIOS.items() if s["plant"]["fmu"].endswith("LinearBatch.fmu")]
NONLINEAR = [n for n in SCENARIOS if n not in LINEAR]


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("zoo_plants")
    return {d.name: build_fmu(d.name, out_dir=out, source_dir=d) for d in sorted((ZOO / "plants").iterdir())
            if (d / "model.yaml").is_file()}


def _fmu_response(path, inp, out, u, ts, params):
    with FmuPlant(path, inputs=[inp], outputs=[out], sample_time_s=ts, parameters=params) as plant:
        y = [plant.read_outputs()[0]]
        for v in u:
            y.append(plant.step([v])[0])
    return np.array(y)


def test_the_zoo_is_split_into_a_development_and_a_check_set():
    index = yaml.safe_load((ZOO / "zoo.yaml").read_text())["plants"]
    assert sorted(p["name"] for p in index) == sorted(SCENARIOS)
    sets = {p["name"]: p["set"] for p in index}
    assert set(sets.values()) == {"dev", "check"} and len(sets) >= 20
    assert sum(v == "dev" for v in sets.values()) >= 10 and sum(v == "check" for v in sets.values()) >= 10


@pytest.mark.parametrize("name", LINEAR)
def test_linear_batch_matches_the_transfer_function(fmus, name):
    sc = SCENARIOS[name]["plant"]
    ts, params = float(sc["sample_time"]), sc["parameters"]
    num, den, delay = models.linear_model(params)
    d = delay / ts
    assert abs(d - round(d)) < 1e-9, "the dead time is a whole number of samples"
    n = 150
    u = np.repeat(np.random.default_rng(1).uniform(-1.0, 1.0, n // 15), 15)
    y = _fmu_response(fmus["LinearBatch"], "u", "y", u, ts, params)
    a, b, c, dd, _ = signal.cont2discrete(signal.tf2ss(num, den), ts, method="zoh")
    shifted = np.concatenate([np.zeros(int(round(d))), u])[:n]
    _, ref, _ = signal.dlsim((a, b, c, dd, ts), np.append(shifted, 0.0))
    assert np.max(np.abs(y - ref[:, 0])) <= BOUND * max(1.0, np.max(np.abs(ref)))


def test_linear_batch_refuses_an_improper_model_and_a_dead_time_beyond_its_ring(fmus):
    nan = _fmu_response(fmus["LinearBatch"], "u", "y", [1.0], 0.1, {"num1": 1.0, "den1": 1.0, "den0": 1.0})
    assert np.all(np.isnan(nan))
    ok = _fmu_response(fmus["LinearBatch"], "u", "y", [1.0], 0.1, {"L": 2.56})
    assert np.all(np.isfinite(ok))
    assert np.all(np.isnan(_fmu_response(fmus["LinearBatch"], "u", "y", [1.0], 0.1, {"L": 2.6})))


def _zoh_truth(plant, p, x0, u, ts, delay_samples, u0):
    held = np.concatenate([np.full(delay_samples, u0), u])[:len(u)]
    xs = [np.asarray(x0, float)]
    for v in held:
        sol = solve_ivp(lambda t, x: plant.f(x, v, p), (0.0, ts), xs[-1], method="DOP853", rtol=1e-12, atol=1e-12)
        assert sol.success
        xs.append(sol.y[:, -1])
    return np.array([plant.output_of(x, p) for x in xs])


# per plant: input levels of the held steps (within the actuator range, on the scenario's branch) and samples
STEPS = {"VanDeVusse": ([0.3, 0.9, 2.0, 0.5], 40), "BallBeam": ([0.02, -0.03, 0.01, 0.0], 15),
         "Bioreactor": ([0.34, 0.3, 0.36, 0.2], 25), "SphericalTank": ([1.8, 0.4, 1.2, 0.0], 40),
         "Distillation": ([2.5, 1.6, 2.2, 1.9], 40)}


@pytest.mark.parametrize("name", NONLINEAR)
def test_nonlinear_plant_matches_scipy(fmus, name):
    sc = SCENARIOS[name]["plant"]
    fmu = Path(sc["fmu"]).stem
    plant = models.NONLINEAR[fmu]
    loop = sc["loops"][0]
    p = {**plant.defaults, **(sc.get("parameters") or {})}
    ts = float(sc["sample_time"])
    levels, hold = STEPS[fmu]
    u = np.repeat(levels, hold)
    assert np.all((u >= loop["u_limits"][0]) & (u <= loop["u_limits"][1]))
    y = _fmu_response(fmus[fmu], loop["input"], loop["output"], u, ts, sc.get("parameters"))
    d = int(round(plant.delay(p) / ts))
    ref = _zoh_truth(plant, p, plant.x_ss(p["u0"], p), u, ts, d, p["u0"])
    assert np.max(np.abs(y - ref)) <= BOUND * float(loop["measurement_scale"])
    assert np.ptp(ref) > 10 * float(loop["measurement_scale"]) * 1e-2   # the steps move the output


def test_start_states_are_the_hand_computed_steady_states(fmus):
    """Bioreactor: S = 0.2418, X = 0.4 (4 - S) = 1.5033 g/L at D = 0.33 1/h; Van de Vusse: Ca = 3, Cb = 1.117 at
    D = 4/7 1/min (Bequette's nominal point); spherical tank (1 / sqrt 2)^2 = 0.5 m; distillation x_D =
    100 / (1 + e^(-(-3.8 + 4 * 2))) = 98.52 %; ball and beam at rest at 0."""
    expected = {"Bioreactor": ("X_out", 1.50325, 1e-4), "VanDeVusse": ("Cb", 1.117021, 1e-5),
                "SphericalTank": ("h", 0.5, 1e-12), "Distillation": ("x_D", 98.522597, 1e-5), "BallBeam": ("p", 0.0, 0)}
    for name, (out, value, tol) in expected.items():
        with FmuPlant(fmus[name], inputs=[], outputs=[out]) as plant:
            assert plant.read_outputs()[0] == pytest.approx(value, abs=tol), name
    vdv = models.NONLINEAR["VanDeVusse"]
    assert vdv.x_ss(4 / 7, vdv.defaults) == pytest.approx([3.0, 1.117021], abs=1e-5)
