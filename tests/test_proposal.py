"""What `probe` identifies and what `init` chooses, on analytic plants built here with pythonfmu (a PyPI exporter):
the mechanism of each plant kind against its transfer function, the loop an engineer would choose (a free
inertia's speed, a mass on a spring's position, a levitated ball's gap through its coil voltage with a negative
Kp), and the gain ranges of a plant with inverse response against an independent python-control design.

Plants (tests/data/pythonfmu/): TransferFunction, y = (b2 s² + b1 s + b0)/(a3 s³ + a2 s² + a1 s + a0) u e^(-L s),
stepped exactly (zero-order hold); FreeInertia, J dw/dt = M - d w, dphi/dt = w (J = 0.002 kg m², d = 0.001 N m s:
torque -> speed 1000/(2 s + 1), torque -> angle 1000/(s (2 s + 1))); MagLev, m x'' = m g - k (V/R)² / x² + F_d
between stops, linearised x'' = (2 g/x0) Δx - (2 g/V0) ΔV (poles ±44.3 1/s, b = -3.924 m/s² per V);
MassSpringDamper (m = 1, k = 30, c = 1.1).
"""
import importlib.util
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from prlpid_fmi.cli import main
from prlpid_fmi.probe.proposal import choose_loop, propose_loop
from prlpid_fmi.probe.open_loop import probe_outputs
from prlpid_fmi.scenario.draft import init_scenario

DATA = Path(__file__).parent / "data" / "pythonfmu"
ZERO = {name: 0.0 for name in ("b0", "b1", "b2", "a0", "a1", "a2", "a3", "L", "x2_0")}
G, X0, V0 = 9.81, 0.01, 5.0


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    pytest.importorskip("pythonfmu")
    out = tmp_path_factory.mktemp("mechanisms")
    built = {}
    for name in ("TransferFunction", "FreeInertia", "MagLev", "MassSpringDamper"):
        subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(DATA / f"{name}.py"), "-d", str(out)],
                       check=True, capture_output=True)
        built[name] = out / f"{name}.fmu"
    if importlib.util.find_spec("pythonfmu3"):                       # the same inertia from the FMI 3.0 exporter
        subprocess.run([sys.executable, "-m", "pythonfmu3", "build", "-f", str(DATA.parent / "pythonfmu3" /
                        "FreeInertia3.py"), "-d", str(out)], check=True, capture_output=True)
        built["FreeInertia3"] = out / "FreeInertia3.fmu"
    return built


# (parameters, the mechanism, the poles and zeros of the transfer function, the low-frequency gain, dead time)
KINDS = {
    "lag": ({"b0": 2.0, "a1": 5.0, "a0": 1.0}, "lag", [-0.2], [], 2.0, 0.0),
    "lag with delay": ({"b0": 2.0, "a1": 5.0, "a0": 1.0, "L": 2.0}, "lag with delay", [-0.2], [], 2.0, 2.0),
    "delay": ({"b0": 2.0, "a0": 1.0, "L": 1.0}, "delay", None, None, 2.0, 1.0),
    "pure integrator": ({"b0": 0.5, "a1": 1.0}, "pure integrator", [0.0], [], 0.5, 0.0),
    "integrator with lag": ({"b0": 0.5, "a2": 3.0, "a1": 1.0}, "integrator with lag", [0.0, -1 / 3], [], 0.5, 0.0),
    "double integrator": ({"b0": 0.5, "a2": 1.0}, "double integrator", [0.0, 0.0], [], 0.5, 0.0),
    "oscillator": ({"b0": 4.0, "a2": 1.0, "a1": 0.4, "a0": 4.0}, "oscillator",
                   [complex(-0.2, math.sqrt(3.96)), complex(-0.2, -math.sqrt(3.96))], [], 1.0, 0.0),
    "inverse response": ({"b0": 2.0, "b1": -10.0, "a2": 450.0, "a1": 45.0, "a0": 1.0}, "inverse response",
                         [-1 / 30, -1 / 15], [0.2], 2.0, 0.0),
    "unstable": ({"b0": 1.0, "a1": 1.0, "a0": -0.5}, "unstable", [0.5], [], -2.0, 0.0),
}


@pytest.mark.parametrize("kind", list(KINDS))
def test_the_probe_names_each_mechanism_with_its_transfer_function(fmus, kind):
    parameters, mechanism, poles, zeros, gain, dead = KINDS[kind]
    result = probe_outputs(fmus["TransferFunction"], start_values={**ZERO, **parameters})["y"]
    r = result.response("u")
    assert r.mechanism == mechanism
    assert mechanism.upper() in r.summary()                       # said in the probe's output
    assert r.dead_time_s == pytest.approx(dead, abs=r.sample_time_s)    # a static output moves a sample late
    if poles is None:                                              # a gain behind a delay: no dynamics
        assert r.kind == "static" and r.gain == pytest.approx(gain, rel=1e-9)
        return
    model = r.model
    assert model.low_frequency_gain == pytest.approx(gain, rel=2e-3)
    assert sorted(model.poles, key=lambda p: (p.real, p.imag)) == pytest.approx(
        sorted(poles, key=lambda p: (p.real, p.imag)), abs=2e-3 * max(1.0, max(abs(p) for p in poles)))
    assert sorted(z.real for z in model.zeros if z.real > 0) == pytest.approx(zeros, rel=2e-3)


@pytest.mark.parametrize("name", ["FreeInertia", "FreeInertia3"])
def test_free_inertia_init_tunes_the_speed_loop(fmus, tmp_path, capsys, name):
    """Torque -> angle is an integrator with the speed's 2 s lag: a free mechanism, so init measures the speed,
    with a sample time from the speed loop's bandwidth (not microseconds); FMI 2.0 (pythonfmu) and 3.0
    (pythonfmu3) alike."""
    if name not in fmus:
        pytest.skip("pythonfmu3 is not installed")
    results = probe_outputs(fmus[name])
    phi, w = results["phi"].response("M"), results["w"].response("M")
    assert phi.mechanism == "integrator with lag" and w.mechanism == "lag" and w.rate_of == "phi"
    assert phi.model.low_frequency_gain == pytest.approx(1 / 0.001, rel=2e-3)       # 1/d rad/s per N m
    assert -1 / max(p.real for p in w.model.poles) == pytest.approx(0.002 / 0.001, rel=2e-3)   # J/d
    assert main(["init", str(fmus[name])]) == 0
    text = capsys.readouterr().out
    (tmp_path / "inertia.yaml").write_text(text)
    loop = yaml.safe_load(text)["plant"]["loops"][0]
    assert (loop["input"], loop["output"]) == ("M", "w")
    assert "free mechanism" in text
    ts = yaml.safe_load(text)["plant"]["sample_time"]
    assert 1e-4 <= ts <= 2.0 / 10                                   # at least 10 samples per speed time constant
    assert main(["validate", str(tmp_path / "inertia.yaml")]) == 0


def test_mass_on_a_spring_init_measures_the_position(fmus):
    results = probe_outputs(fmus["MassSpringDamper"])
    assert results["x"].response("F").mechanism == "oscillator" and results["v"].response("F").rate_of == "x"
    chosen, why = choose_loop(results)
    assert chosen.output == "x" and "v: the rate of x" in why


def test_levitation_init_finds_the_coil_and_its_negative_gain(fmus):
    """Every constant voltage parks the ball on a stop; the probe reads the growth rate before the stop and
    init drives the gap with the coil voltage, a negative Kp (more voltage, smaller gap), not the disturbance
    force and not an on/off input."""
    results = probe_outputs(fmus["MagLev"])
    v = results["x"].response("V")
    assert v.kind == "unstable" and v.mechanism == "unstable"
    assert v.growth_rate_per_s == pytest.approx(math.sqrt(2 * G / X0), rel=0.03)
    assert v.model.high_frequency_gain == pytest.approx(-2 * G / V0, rel=0.03)
    chosen, why = choose_loop(results)
    loop = propose_loop(chosen, why)
    assert (loop.input, loop.output) == ("V", "x") and "on/off" not in loop.why["input"]
    kp_low, kp_high, _ = loop.gains["Kp"]
    assert kp_low < kp_high < 0
    # the PD at the centre stabilises the linearised plant: s² + b Kp Td s + (b Kp - λ²) with b = -2 g / V0
    b, lam2 = -2 * G / V0, 2 * G / X0
    assert b * loop.design["Kp"] > lam2 and b * loop.design["Kp"] * loop.design["Td"] > 0
    assert 1e-4 <= loop.sample_time_s <= 0.1 / math.sqrt(lam2)


def _independent_pid(num, den):
    """Kp, Ti, Td (ideal form, derivative filter Td/10) that minimise the IAE of a unit load step at the plant
    input under a maximum sensitivity of 1.6, by python-control simulation and Nelder-Mead from a neutral start."""
    control = pytest.importorskip("control")
    from scipy.optimize import minimize

    plant = control.tf(num, den)
    w, t = np.logspace(-3, 1, 200), np.linspace(0, 400, 801)

    def cost(x):
        kp, ti, td = np.exp(x)
        c = control.tf([kp * ti * td * 1.1, kp * (ti + 0.1 * td), kp], [0.1 * ti * td, ti, 0])
        ms = np.max(np.abs(1 / (1 + (c * plant)(1j * w))))
        loop = control.feedback(plant, c)
        if np.any(np.real(loop.poles()) >= 0):
            return 1e6
        _, y = control.step_response(loop, t)
        return float(np.sum(np.abs(y)) * (t[1] - t[0])) + 1e6 * max(ms - 1.6, 0.0) ** 2

    best = minimize(cost, np.log([0.5, 30.0, 5.0]), method="Nelder-Mead",
                    options={"xatol": 1e-2, "fatol": 1e-3, "maxiter": 300})
    return np.exp(best.x)


def test_inverse_response_gain_ranges_contain_an_independent_design(fmus):
    """G = 2 (1 - 5 s)/((30 s + 1)(15 s + 1)): init's ranges contain the PID an optimiser finds with
    python-control (about Kp 1.2, Ti 18 s, Td 13 s), Kp centred within a factor 2 of it, and a setpoint held
    longer than that design takes to settle."""
    parameters = {**ZERO, **KINDS["inverse response"][0]}
    text = init_scenario(fmus["TransferFunction"], start_values=parameters)
    doc = yaml.safe_load(text)
    gains = doc["plant"]["loops"][0]["gains"]
    kp, ti, td = _independent_pid([-10.0, 2.0], [450.0, 45.0, 1.0])
    assert gains["Kp"][0] < kp < gains["Kp"][1] and gains["Kp"][0] > 0
    assert gains["Ti"][0] < ti < gains["Ti"][1]
    assert gains["Td"][0] <= td < gains["Td"][1]
    assert math.sqrt(gains["Kp"][0] * gains["Kp"][1]) == pytest.approx(kp, rel=1.0)   # within 2x
    control = pytest.importorskip("control")
    c = control.tf([kp * ti * td * 1.1, kp * (ti + 0.1 * td), kp], [0.1 * ti * td, ti, 0])
    settling = control.step_info(control.feedback(c * control.tf([-10.0, 2.0], [450.0, 45.0, 1.0]), 1))["SettlingTime"]
    assert doc["training"]["setpoint_hold_steps"] * doc["plant"]["sample_time"] >= settling


def test_a_lag_the_first_grid_misses_is_re_probed_before_the_sample_time_is_chosen(fmus):
    """1000/(s (0.005 s + 1)) looks like a pure integrator on the probe's first 0.1 s grid, and the actuator's
    range alone would allow a closed loop in microseconds. init re-probes on a finer grid, finds the 5 ms lag
    (the model's pole within 5 %) and designs on it: at most a fifth of the lag, and a sample time below 1e-4 s
    only with the line saying why."""
    parameters = {**ZERO, "b0": 1000.0, "a2": 0.005, "a1": 1.0}
    results = probe_outputs(fmus["TransferFunction"], start_values=parameters)
    first = results["y"].response("u")
    assert first.kind == "integrating"
    loop = propose_loop(*choose_loop(results))
    assert "re-probed" in loop.why["sample_time"] and "integrator with lag" in loop.why["sample_time"]
    assert 1e-5 <= loop.sample_time_s <= 0.005 / 5
    assert loop.sample_time_s >= 1e-4 or "below 0.0001 s because" in loop.why["sample_time"]
    tau2 = float(loop.why["gains"].split("τ2 = ")[1].split(" s")[0])
    assert tau2 == pytest.approx(0.005, rel=0.05)


def test_a_pure_integrator_at_every_grid_bounds_the_loop_by_the_finest_grid_probed(fmus):
    """1000/s shows no lag on any grid: the closed-loop time constant is bounded by twice the finest grid the
    re-probe measured (faster dynamics are unknown), so the sample time says why it is below 1e-4 s."""
    results = probe_outputs(fmus["TransferFunction"], start_values={**ZERO, "b0": 1000.0, "a1": 1.0})
    loop = propose_loop(*choose_loop(results))
    assert "re-probed" in loop.why["sample_time"] and "showed no lag or delay" in loop.why["sample_time"]
    assert loop.sample_time_s >= 1e-5


def test_an_integrating_plant_started_off_equilibrium_is_operated_where_its_free_response_settles(fmus):
    """1/(s (s + 1)) started with its second state at 2 coasts from y = 0 to y = 2 (x1(∞) = x2(0) τ) with the
    input at its start value 0: that value holds the output there, so the trim input is 0 (not the input that
    would hold the transient's start) and the setpoint range is centred on 2."""
    results = probe_outputs(fmus["TransferFunction"], start_values={**ZERO, "b0": 1.0, "a2": 1.0, "a1": 1.0,
                                                                    "x2_0": 2.0})
    loop = propose_loop(*choose_loop(results))
    assert loop.trim_input == 0.0
    lo, hi = loop.setpoint_range
    assert (lo + hi) / 2 == pytest.approx(2.0, rel=0.01)
    assert "where its free response settles" in loop.why["setpoint_range"]
