"""`prlpid-fmi probe` and the scenario `init` proposes from it, against hand-derived references.

References: FirstOrderUnstable dx/dt = a x + b u (a = 1: grows as e^t, formal G(0) = -b/a);
SecondOrderUnstable's poles (2.9781 ± j sqrt(4·279.03 - 2.9781²)) / (2·279.03); TwoTank (TwoTank.mo)
linearised by hand around its steady state for q_in = 25 cm³/s; two plants with unusual scales built
from tests/plants/: a motor inertia J = 0.002 kg·m² with a +10 N·m load (an integrator, 1/J = 500 rad/s²
per N·m; holding any speed needs -10 N·m) and a room with an hour-long time constant (R C = 3600 s,
gain R = 0.01 K/W, starting at 16 °C, 5 °C outside, the outside temperature being its first input), and a
valve without dynamics (q = 2.5 x opening: the output follows the input within one step).
"""
import dataclasses
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest
import yaml

from prlpid_fmi.tuning.design_rule import tune_fixed_pid
from prlpid_fmi.cli import main
from prlpid_fmi.loop.evaluation import evaluate_gains
from prlpid_fmi.fmu import build_fmu
from prlpid_fmi.fmu.build import bundled_fmu
from prlpid_fmi.probe.open_loop import probe
from prlpid_fmi.probe.proposal import propose_loop
from prlpid_fmi.scenario.draft import init_scenario
from prlpid_fmi.scenario.load import load_scenario

PLANTS = Path(__file__).parent / "plants"


@pytest.fixture(scope="module")
def unusual(tmp_path_factory):
    out = tmp_path_factory.mktemp("plants")
    names = ("Inertia", "RoomHeating", "StaticValve")
    return {name: build_fmu(name, out_dir=out, source_dir=PLANTS / name) for name in names}


def test_first_order_unstable_growth_rate_and_gain():
    r = probe(bundled_fmu("FirstOrderUnstable")).response("u")
    assert r.kind == "unstable"
    assert r.growth_rate_per_s == pytest.approx(1.0, rel=1e-4)   # a = 1
    assert r.time_constant_s == pytest.approx(1.0, rel=1e-4)
    assert r.gain == pytest.approx(-1.0, rel=1e-4)               # G(0) = -b/a
    stable = probe(bundled_fmu("FirstOrderUnstable"), start_values={"a": -0.5, "b": 2.0}).response("u")
    assert stable.kind == "stable"
    assert stable.time_constant_s == pytest.approx(2.0, rel=1e-4) and stable.gain == pytest.approx(4.0, rel=1e-4)


def test_second_order_unstable_oscillating_growth():
    r = probe(bundled_fmu("SecondOrderUnstable")).response("u")
    assert r.kind == "unstable"
    assert r.growth_rate_per_s == pytest.approx(2.9781 / (2 * 279.03), rel=1e-3)
    assert r.gain == pytest.approx(-0.2679, rel=1e-3)


def test_two_tank_matches_the_hand_linearisation():
    k1, k2, area, q = 10.74, 7.89, 15.52, 25.0
    h2 = (q / k2) ** 2                  # outflow k2 sqrt(h2) = q
    h1 = h2 + (q / k1) ** 2             # k1 sqrt(h1 - h2) = q
    g1, g2 = k1 / (2 * np.sqrt(h1 - h2)), k2 / (2 * np.sqrt(h2))   # d(flow)/d(level difference)
    a = np.array([[-g1 / area, g1 / area], [g1 / area, -(g1 + g2) / area]])
    slow = -1 / max(np.linalg.eigvals(a).real)                      # about 28.7 s
    result = probe(bundled_fmu("TwoTank"), output="h2", start_values={"q_in": q, "h1_0": h1, "h2_0": h2})
    r = result.response("q_in")
    assert r.kind == "stable" and r.dead_time_s == 0
    assert r.gain == pytest.approx(1 / g2, rel=0.01)                # 0.803 cm per cm³/s (a 1 % step: nonlinear)
    assert r.time_constant_s == pytest.approx(slow, rel=0.015)
    assert result.response("q_d").disturbance_like and not r.disturbance_like
    assert abs(result.response("valve_factor").gain) < 2e-3           # h2 is set by the outflow alone


def test_inertia_integrator_init_holds_the_load(unusual, tmp_path):
    r = probe(unusual["Inertia"]).response("tau")
    assert r.kind == "integrating" and r.rate == pytest.approx(1 / 0.002, rel=1e-6)
    loop = propose_loop(probe(unusual["Inertia"]))
    assert loop.input == "tau" and loop.trim_input == pytest.approx(-10.0, rel=1e-6)
    assert loop.u_limits[0] < -10 < loop.u_limits[1]
    # one sample at full authority moves the speed by a small part of the setpoint range, not 500 rad/s
    authority = 500 * max(loop.u_limits[1] + 10, -10 - loop.u_limits[0])
    assert authority * loop.sample_time_s < 0.2 * (loop.setpoint_range[1] - loop.setpoint_range[0])
    text = init_scenario(unusual["Inertia"])
    assert "tau_load: looks like a disturbance" in text
    _settles(text, tmp_path / "inertia.yaml")


def test_room_hour_long_time_constant_init_chooses_the_heater(unusual, tmp_path):
    result = probe(unusual["RoomHeating"])
    heater = result.response("P_heat")
    assert heater.kind == "stable"
    assert heater.time_constant_s == pytest.approx(3600.0, rel=1e-4) and heater.gain == pytest.approx(0.01, rel=1e-4)
    assert result.response("T_outside").disturbance_like
    loop = propose_loop(result)
    assert loop.input == "P_heat" and loop.u_limits == (0.0, 2000.0)       # declared min and max
    assert loop.trim_input == pytest.approx(1100.0, rel=1e-3)             # (16 - 5) K / 0.01 K/W
    lo, hi = loop.setpoint_range                                          # held: 5 to 25 °C
    assert 5.0 < lo < 16.0 < hi < 25.0
    assert 60.0 <= loop.sample_time_s <= 600.0
    text = init_scenario(unusual["RoomHeating"])
    assert "T_outside: looks like a disturbance" in text and "input: P_heat" in text
    _settles(text, tmp_path / "room.yaml")


def test_a_plant_without_dynamics_is_static_and_init_gives_a_working_integral_controller(unusual, tmp_path):
    """Before, the probe fitted ever faster lags to a feedthrough and proposed a 1 µs sample time."""
    r = probe(unusual["StaticValve"]).response("opening")
    assert r.kind == "static" and r.gain == pytest.approx(2.5, rel=1e-9) and r.time_constant_s is None
    loop = propose_loop(probe(unusual["StaticValve"]))
    assert loop.sample_time_s == pytest.approx(0.1)                     # the FMU's default step, not 1e-6 s
    assert loop.trim_input == pytest.approx(0.4) and loop.u_limits == (0.0, 1.0)
    # one-step delay, u = Kp e + integral: 0.3 / Kv and Ti = Ts put the closed-loop poles at 0.78 and -0.38
    kp_low, kp_high, _ = loop.gains["Kp"]
    ti_low, ti_high, _ = loop.gains["Ti"]
    assert kp_low < 0.3 / 2.5 < kp_high and ti_low < loop.sample_time_s < ti_high
    text = init_scenario(unusual["StaticValve"])
    # those gains on the FMU: the error decays as the dominant root of z^2 - 0.4 z - 0.3, derived by hand from
    # y_(k+1) = 2.5 u_k, u_k = Kp e_k + (Kp Ts / Ti) sum_(j<=k) e_j
    (tmp_path / "valve.yaml").write_text(text)
    s = load_scenario(tmp_path / "valve.yaml")
    _, traj = evaluate_gains(lambda core: ([0.12], [0.1], [0.0], None), s.evaluation_config(),
                             intervals=s.evaluation.intervals)
    e = traj["setpoint"][:20, 0] - traj["measurement"][:20, 0]
    assert e[15] / e[14] == pytest.approx(max(np.roots([1.0, -0.4, -0.3]).real), rel=1e-3)
    _settles(text, tmp_path / "valve.yaml")


def _settles(text: str, path: Path) -> None:
    """The proposed scenario is tunable as written: its tuned fixed PID settles at every evaluation setpoint."""
    path.write_text(text)
    s = load_scenario(path)
    b = s.baseline                                  # the scenario's own search budget, as `tune` runs it
    fixed = tune_fixed_pid(s.tuning, max_sensitivity=s.deploy.max_sensitivity, baseline=b, deploy=s.deploy)
    tuned = dataclasses.replace(s.evaluation_config(), tuned_structure=tuple(zip(*fixed.structure)))  # b, c, Tf too
    metrics, traj = evaluate_gains(lambda core: fixed.gains_values(), tuned, intervals=s.evaluation.intervals)
    assert not metrics["terminated"]
    y, r = traj["measurement"][:, 0], traj["setpoint"][:, 0]
    for start, end in s.evaluation.intervals:
        step = abs(r[end - 1] - (r[start - 1] if start else y[0]))
        assert np.max(np.abs(y[end - 10:end] - r[end - 10:end])) < 0.02 * step


def test_probe_command_writes_a_plot(unusual, tmp_path, capsys):
    png = tmp_path / "room.png"
    assert main(["probe", str(unusual["RoomHeating"]), "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "P_heat" in out and "time constant 3600 s" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and np.var(mpimg.imread(str(png))) > 1e-4
    assert main(["probe", str(unusual["RoomHeating"]), "--set", "C"]) == 2
    assert capsys.readouterr().err.strip().count("\n") == 0


def test_init_writes_the_operating_point(tmp_path):
    text = init_scenario(bundled_fmu("TwoTank"), output="h2", start_values={"q_in": 25.0, "h1_0": 15.46, "h2_0": 10.04})
    doc = yaml.safe_load(text)
    assert doc["plant"]["parameters"] == {"h1_0": 15.46, "h2_0": 10.04}
    assert doc["plant"]["loops"][0]["input"] == "q_in"


def test_a_delayed_static_response_is_static_with_its_dead_time():
    """Δy = 0 for three samples, then 2.5 per input unit for good: a gain behind a transport delay. The
    delay is counted from the sample before the first move (the step acts over one sample): 2 samples."""
    from prlpid_fmi.probe.open_loop import _analyse

    dt, du = 0.1, 0.004
    dy = np.r_[np.zeros(3), np.full(97, 2.5 * du)]
    kind, gain, tau, _, _, dead = _analyse(dt * np.arange(100), dy, dt, du, 1.0)
    assert (kind, tau) == ("static", None)
    assert gain == pytest.approx(2.5) and dead == pytest.approx(2 * dt)
