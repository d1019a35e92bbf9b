"""The benchmark plants of benchmarks/plants/ (Astrom & Hagglund's PID benchmark families and two
drivetrains) built as FMUs, against their transfer functions written from the physics by hand.

Each plant starts in steady state at its start inputs; its open-loop response to a unit step and to a
seeded sequence of held steps over the input range is compared, in deviation variables, with the exact
zero-order-hold solution of the transfer function (scipy.signal.cont2discrete + dlsim), the dead time
as a shift by whole samples. The bound is the one each model.yaml states for its fixed_step: the output
error stays within 1e-9 of the loop's scale, and the next coarser step of the 1-2-5 series does not.

Transfer functions (s in 1/s):
- HeatExchanger: K e^(-sL)/(1 + sT) from the valve, 1/(1 + sT) from the inlet temperature;
- RCLadder4: 1/(1 + sRC)^4;
- InverseResponse: K (1 - alpha s)/(1 + tau s)^3;
- TwoMassDrive, by eliminating the motor speed and the twist phi = (w_m - w_l)/s from
  J_m s w_m = tau_m - (d + c/s)(w_m - w_l) - b_m w_m and J_l s w_l = (d + c/s)(w_m - w_l) - b_l w_l - tau_l:
  w_l/tau_m = (d s + c)/D and w_l/tau_l = -(J_m s^2 + (b_m + d) s + c)/D,
  D = s (J_m s + b_m)(J_l s + b_l) + (d s + c)((J_m + J_l) s + b_m + b_l);
- MotorInertia: 1/(J s + b).
"""
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from prlpid_fmi.fmu import FmuPlant, build_fmu

PLANTS = Path(__file__).parent.parent / "benchmarks" / "plants"
NAMES = ("HeatExchanger", "RCLadder4", "InverseResponse", "TwoMassDrive", "MotorInertia")
BOUND = 1e-9  # output error per unit of the loop's scale (docs/architecture.md, Internal step)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("benchmark_plants")
    return {name: build_fmu(name, out_dir=out, source_dir=PLANTS / name) for name in NAMES}


def _poly(*factors):
    """Product of polynomials given highest power first (numpy.polymul)."""
    out = np.array([1.0])
    for f in factors:
        out = np.polymul(out, f)
    return out


def _two_mass(Jm=0.01, Jl=0.02, c=50.0, d=0.05, bm=0.01, bl=0.01):
    den = np.polyadd(_poly([1.0, 0.0], [Jm, bm], [Jl, bl]), _poly([d, c], [Jm + Jl, bm + bl]))
    return (np.array([d, c]), den), (-np.array([Jm, bm + d, c]), den)


def _reference(tf, du, ts, delay_samples=0):
    """Exact ZOH response y[k] (k = 0..n) of tf = (num, den) to deviations du (n,) held per sample."""
    du = np.concatenate([np.zeros(delay_samples), du])[: len(du)]
    a, b, c, d, _ = signal.cont2discrete(signal.tf2ss(*tf), ts, method="zoh")
    _, y, _ = signal.dlsim((a, b, c, d, ts), np.append(du, 0.0))
    return y[:, 0]


def _fmu_response(path, inputs, output, u, ts, parameters=None):
    """Outputs y[0..n] of the FMU from its start, inputs u (n, n_inputs) held for one sample each."""
    with FmuPlant(path, inputs=inputs, outputs=[output], sample_time_s=ts, parameters=parameters) as plant:
        y = [plant.read_outputs()[0]]
        for row in u:
            y.append(plant.step(row)[0])
    return np.array(y)


def _held_steps(rng, low, high, n, hold):
    return np.repeat(rng.uniform(low, high, n // hold), hold)


# name, inputs (driven, other), start inputs, driven input range, output, ts [s], scale, (tf, delay [samples])
# per driven input, fixed parameters, fixed_step default and the next coarser step
CASES = {
    "heat_exchanger_lag": ("HeatExchanger", ["valve", "T_in"], [40.0, 20.0], (0.0, 100.0), "T_out", 1.0, 10.0,
                           [((np.array([0.5]), np.array([60.0, 1.0])), 6), ((np.array([1.0]), np.array([60.0, 1.0])), 0)],
                           {}, 0.1, None),
    "heat_exchanger_delay": ("HeatExchanger", ["valve", "T_in"], [40.0, 20.0], (0.0, 100.0), "T_out", 1.0, 10.0,
                             [((np.array([0.5]), np.array([10.0, 1.0])), 20), ((np.array([1.0]), np.array([10.0, 1.0])), 0)],
                             {"T": 10.0, "L": 20.0}, 0.1, 0.2),
    "rc_ladder4": ("RCLadder4", ["v_in"], [5.0], (0.0, 10.0), "v_out", 0.2, 1.0,
                   [((np.array([1.0]), _poly(*[[1.0, 1.0]] * 4)), 0)], {}, 0.01, 0.02),
    "inverse_response": ("InverseResponse", ["Q_steam"], [1.0], (0.0, 2.0), "T_tray", 1.0, 5.0,
                         [((np.array([-50.0, 10.0]), _poly(*[[10.0, 1.0]] * 3)), 0)], {}, 0.1, 0.2),
    "two_mass_drive": ("TwoMassDrive", ["tau_motor", "tau_load"], [1.0, 0.0], (-2.0, 2.0), "w_load", 0.01, 10.0,
                       [(_two_mass()[0], 0), (_two_mass()[1], 0)], {}, 0.0001, 0.0002),
    "motor": ("MotorInertia", ["tau", "tau_load"], [0.05, 0.0], (-0.1, 0.1), "w", 0.01, 10.0,
              [((np.array([1.0]), np.array([0.002, 0.001])), 0), ((np.array([-1.0]), np.array([0.002, 0.001])), 0)],
              {}, 0.01, None),
}


def _errors(fmus, case, fixed_step):
    """Max |y_fmu - y_ref| / scale over a unit step of each input and a held-step sequence of the driven one."""
    name, inputs, u0, (low, high), output, ts, scale, tfs, params, _, _ = CASES[case]
    params = {**params, "fixed_step": fixed_step}
    n = 600
    rng = np.random.default_rng(0)
    worst = 0.0
    sequences = [(0, np.ones(n))] + [(i, np.ones(n)) for i in range(1, len(inputs))]
    sequences.append((0, _held_steps(rng, low, high, n, 20) - u0[0]))
    for i, du in sequences:
        u = np.tile(u0, (n, 1))
        u[:, i] += du
        y = _fmu_response(fmus[name], inputs, output, u, ts, params)
        tf, delay = tfs[i]
        worst = max(worst, float(np.max(np.abs((y - y[0]) - _reference(tf, du, ts, delay)))) / scale)
    return worst


@pytest.mark.parametrize("case", list(CASES))
def test_open_loop_response_matches_the_transfer_function(fmus, case):
    *_, default, coarser = CASES[case]
    assert _errors(fmus, case, default) <= BOUND
    if coarser is not None:   # the default is the largest step of the 1-2-5 series that meets the bound
        assert _errors(fmus, case, coarser) > BOUND


def test_plants_start_in_steady_state(fmus):
    for name, inputs, u0, _, output, ts, scale, *_ in CASES.values():
        y = _fmu_response(fmus[name], inputs, output, np.tile(u0, (300, 1)), ts)
        assert np.max(np.abs(y - y[0])) <= 1e-12 * max(abs(y[0]), 1.0), name


def test_start_values_are_the_hand_computed_steady_states(fmus):
    """What a plant owner reads off model.yaml: 20 degC + 0.5 K/% * 40 %, 5 V, 70 degC + 10 K s/kg * 1 kg/s,
    1 N.m / (0.01 + 0.01) N.m.s/rad and 0.05 N.m / 0.001 N.m.s/rad."""
    start = {"HeatExchanger": ("T_out", 40.0), "RCLadder4": ("v_out", 5.0), "InverseResponse": ("T_tray", 80.0),
             "TwoMassDrive": ("w_load", 50.0), "MotorInertia": ("w", 50.0)}
    nonlinear = {"PhNeutralization", "ExothermicCSTR", "ConicalTank"}   # tests/test_nonlinear_plants.py
    assert sorted(p.name for p in PLANTS.iterdir() if (p / "model.yaml").is_file() and p.name not in nonlinear) \
        == sorted(start)
    for name, (output, value) in start.items():
        with FmuPlant(fmus[name], inputs=[], outputs=[output]) as plant:
            assert plant.read_outputs()[0] == pytest.approx(value, rel=1e-12), name


def test_dead_time_beyond_the_ring_gives_nan(fmus):
    with FmuPlant(fmus["HeatExchanger"], inputs=["valve"], outputs=["T_out"], sample_time_s=1.0,
                  parameters={"L": 30.0}) as plant:      # 300 sub-steps of 0.1 s > 256
        assert np.isnan(plant.read_outputs()[0])
    with FmuPlant(fmus["HeatExchanger"], inputs=["valve"], outputs=["T_out"], sample_time_s=1.0,
                  parameters={"L": 25.0}) as plant:
        assert plant.read_outputs()[0] == pytest.approx(40.0, abs=1e-12)
