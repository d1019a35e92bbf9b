"""The one-call C forecast equals the FMI-path forecast bit for bit, and neither moves the plant.

Truth: FmiForecast, which runs the Python PID (control/pid.py), the Python reward (control/reward.py)
and the FMU through the standard FMI calls. Every comparison is `==` on floats (no tolerance): the
mean reward, every step's reward, every predicted measurement and the prior's full serialized state
afterwards. States, gains, setpoints and overrides are random; the anti-windup modes, the derivative
filter, the 2-DOF structure (setpoint weights b, c, the measurement filter Tf of order 1 and 2, changed by
set_structure between calls), the output rate limit (per loop, from the preset's output, from no previous output
and from a warmed-up one), the coupled PID, divergence, a discarded step and the error paths are all covered.
"""
import dataclasses
import math

import numpy as np
import pytest

from prlpid_fmi.control import PID, CoupledPID, RewardWeights
from prlpid_fmi.loop.forecast.fmi import FmiForecast
from prlpid_fmi.loop.forecast import make_forecast
from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu import FmuPlant
from prlpid_fmi.loop.core import LoopCore
from prlpid_fmi.loop.forecast.native import NativeForecast, native_unavailable
from prlpid_fmi.scenario.presets import preset
from conftest import PLANTS, fmu

TS = 0.1


class Plant:
    """A bundled plant's loops as a scenario would set them up, plus how to randomise and override it."""

    def __init__(self, inputs, outputs, u_limits, scale, bound, setpoints, gains, parameters, overrides,
                 input_range, extra_inputs=()):
        self.inputs, self.outputs = inputs, outputs
        self.u_limits, self.scale, self.bound = u_limits, scale, bound
        self.setpoints, self.gains = setpoints, gains  # (low, high); gains: Kp, Ti, Td (low, high) each
        self.parameters = parameters        # plant's (randomised / disturbed) values
        self.overrides = overrides          # the prior's nominal values of those
        self.input_range = input_range      # random inputs while warming the plant up
        self.extra_inputs = extra_inputs    # disturbance inputs set on the plant: (name, value)


SPECS = {
    "FirstOrderUnstable": Plant(["u"], ["y"], (-10.0, 10.0), [1.0], [5.0], (-1.0, 1.0),
                                ((0.5, 30.0), (0.2, 20.0), (0.0, 0.2)), {"a": 1.3, "b": 0.9},
                                {"a": 1.0, "b": 1.0}, (-1.0, 1.0)),
    "SecondOrderUnstable": Plant(["u"], ["y"], (-5.0, 5.0), [1.0], [10.0], (-1.0, 1.0),
                                 ((-1.0, -0.01), (1.0, 200.0), (0.0, 60.0)), {"K": -0.3}, {"K": -0.2679},
                                 (-1.0, 1.0)),
    "TimeVaryingFirstOrder": Plant(["u"], ["y"], (-10.0, 10.0), [1.0], [5.0], (-1.0, 1.0),
                                   ((0.5, 30.0), (0.2, 20.0), (0.0, 0.2)), {"a_offset": 0.6}, {"a_offset": 0.5},
                                   (-1.0, 1.0)),
    "TwoTank": Plant(["q_in"], ["h2"], (0.0, 50.0), [10.0], [10.0], (5.0, 15.0),
                     ((0.5, 50.0), (1.0, 200.0), (0.0, 5.0)), {"h1_0": 15.4, "h2_0": 10.0, "k1": 11.5},
                     {"k1": 10.74, "q_d": 0.0, "valve_factor": 1.0}, (20.0, 30.0),
                     extra_inputs=(("q_d", 4.0), ("valve_factor", 0.8))),
    "QuadrotorAttitude": Plant(["U_phi", "U_theta", "U_psi"], ["phi", "theta", "psi"], (-2.0, 2.0), [0.5] * 3,
                               [6.0] * 3, (-0.5, 0.5), ((0.1, 20.0), (0.5, 100.0), (0.05, 2.0)),
                               {"Ix": 0.45, "Iz": 0.7}, {"Ix": 0.4, "Iz": 0.8}, (-0.3, 0.3)),
}


def _log_uniform(rng, lo, hi, n):
    if lo > 0:
        return np.exp(rng.uniform(math.log(lo), math.log(hi), n)).tolist()
    return rng.uniform(lo, hi, n).tolist()


def _pair(name, version, pid, horizon, weights, overrides=True, prior_parameters=None):
    """plant, prior, native and FMI-path forecasts over the same objects."""
    spec = SPECS[name]
    path = fmu(name, version)
    plant = FmuPlant(path, spec.inputs, spec.outputs, TS, spec.parameters, "plant")
    prior = FmuPlant(path, spec.inputs, spec.outputs, TS, prior_parameters or spec.parameters, "prior")
    n = len(spec.inputs)
    kw = dict(horizon=horizon, scale=spec.scale, bound=spec.bound, penalty=-100.0, weights=weights,
              u_scale=[spec.u_limits[1] - spec.u_limits[0]] * n, overrides=spec.overrides if overrides else None)
    native = make_forecast(plant, prior, pid, **kw)
    fmi = make_forecast(plant, prior, pid, path="fmi", **kw)
    assert isinstance(native, NativeForecast) and isinstance(fmi, FmiForecast)
    return plant, prior, native, fmi


def _warm_up(plant, pid, spec, rng, steps, coupling=None):
    """Random inputs for a few samples, with the PID stepping too (its state becomes non-trivial)."""
    n = len(spec.inputs)
    for name, value in spec.extra_inputs:
        plant.set({name: value})
    y = plant.read_outputs().tolist()
    for _ in range(steps):
        r = rng.uniform(*spec.setpoints, n).tolist()
        gains = [_log_uniform(rng, lo, hi, n) for lo, hi in spec.gains]
        if coupling is not None:
            pid.step_values(r, y, *gains, coupling)
        else:
            pid.step_values(r, y, *gains)
        y = plant.step_values(rng.uniform(*spec.input_range, n).tolist())
    return y


def _pid_state(pid):
    s = pid.get_state()
    return (s.integral.tolist(), s.last_error.tolist(), s.derivative.tolist(), s.initialized, s.filtered.tolist(),
            s.filter_stage.tolist(), str(s.last_output.tolist()), s.last_p_error.tolist(),
            str(s.last_gains.tolist()))  # str: NaN == NaN


def _compare(plant, prior, native, fmi, args):
    """Both forecasts from the same plant state: equal bit for bit; the plant and the PID untouched."""
    before = plant.get_state(), plant.time, plant.read_outputs().tolist()
    pid_before = _pid_state(native.pid)
    a = native.mean_reward(*args)
    native_prior = prior.get_state(), prior.time
    native_rewards, native_measurements = native.last_rewards, native.last_measurements
    b = fmi.mean_reward(*args)
    assert a == b or (math.isnan(a) and math.isnan(b))
    assert native_rewards == fmi.last_rewards
    assert native_measurements == fmi.last_measurements
    assert native_prior == (prior.get_state(), prior.time)  # the prior ends in the same state, time included
    assert (plant.get_state(), plant.time, plant.read_outputs().tolist()) == before
    assert _pid_state(native.pid) == pid_before
    return a, native_rewards


@pytest.mark.parametrize("filter_N", [None, 8.0], ids=["unfiltered", "filtered"])
@pytest.mark.parametrize("anti_windup", ["clamping", "back_calculation", "none"])
@pytest.mark.parametrize("name", PLANTS)
def test_native_equals_fmi_path_bit_for_bit(name, fmi_version, anti_windup, filter_N):
    spec = SPECS[name]
    n = len(spec.inputs)
    rng = np.random.default_rng([PLANTS.index(name), fmi_version, len(anti_windup), filter_N is None])
    pid = PID(TS, n, spec.u_limits[0], spec.u_limits[1], anti_windup, derivative_filter_N=filter_N)
    weights = RewardWeights(control_variation_weight=0.3)
    plant, prior, native, fmi = _pair(name, fmi_version, pid, 10, weights)
    saturated = []
    step_values = pid.step_values

    def counting(*args):  # the Python PID of the FMI path: record whether u hit a limit
        u = step_values(*args)
        saturated.append(any(v in spec.u_limits for v in u))
        return u

    with plant, prior:
        y = _warm_up(plant, pid, spec, rng, 5)
        pid.step_values = counting
        lengths = set()
        for call in range(8):
            r = rng.uniform(*spec.setpoints, n).tolist()
            Kp, Ti, Td = [_log_uniform(rng, lo, hi, n) for lo, hi in spec.gains]
            if call == 0:
                Ti = [math.inf] * n  # no integral action
            u_prev = rng.uniform(*spec.u_limits, n).tolist()
            _, rewards = _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, None, u_prev))
            lengths.add(len(rewards))
            y = _warm_up(plant, pid, spec, rng, 1)
        assert 10 in lengths  # at least one full roll-out
        assert any(saturated) and not all(saturated)  # the anti-windup mode mattered


def test_quadrotor_coupled_pid(fmi_version):
    spec = SPECS["QuadrotorAttitude"]
    rng = np.random.default_rng(11)
    pid = CoupledPID(TS, -2.0, 2.0, "back_calculation", Tt=[0.3, 0.5, 0.7], derivative_filter_N=10.0)
    plant, prior, native, fmi = _pair("QuadrotorAttitude", fmi_version, pid, 10, RewardWeights(control_variation_weight=1.0))
    with plant, prior:
        coupling = rng.uniform(-0.5, 0.5, 6).tolist()
        y = _warm_up(plant, pid, spec, rng, 4, coupling)
        for _ in range(10):
            r = rng.uniform(-0.5, 0.5, 3).tolist()
            Kp, Ti, Td = [_log_uniform(rng, lo, hi, 3) for lo, hi in spec.gains]
            coupling = rng.uniform(-0.5, 0.5, 6).tolist()
            _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, coupling, rng.uniform(-2, 2, 3).tolist()))
            y = _warm_up(plant, pid, spec, rng, 1, coupling)


# (b, c, Tf in samples, filter order) of the 2-DOF law (control/pid.py); the tests above run b = c = 1, Tf = 0,
# the paper's eq. 2
STRUCTURES = {"b0.5-c0": (0.5, 0.0, 0.0, 1), "b0.3-c1-Tf2Ts": (0.3, 1.0, 2.0, 1),
              "b0.7-c0-Tf3Ts-order2": (0.7, 0.0, 3.0, 2)}


def _random_call(rng, spec, n, coupled=False):
    """(setpoint, Kp, Ti, Td, coupling, u_prev) for one forecast call."""
    r = rng.uniform(*spec.setpoints, n).tolist()
    Kp, Ti, Td = [_log_uniform(rng, lo, hi, n) for lo, hi in spec.gains]
    coupling = rng.uniform(-0.5, 0.5, 6).tolist() if coupled else None
    return r, Kp, Ti, Td, coupling, rng.uniform(*spec.u_limits, n).tolist()


@pytest.mark.parametrize("structure", list(STRUCTURES.values()), ids=list(STRUCTURES))
@pytest.mark.parametrize("anti_windup", ["clamping", "back_calculation"])
@pytest.mark.parametrize("name", PLANTS)
def test_2dof_structure_native_equals_fmi_path_bit_for_bit(name, fmi_version, anti_windup, structure):
    """Setpoint weights and the measurement filter: native == FMI path from a fresh PID (the filter starts at
    y(0)) and from a warmed-up one; set_structure between calls is read by the next native call."""
    spec = SPECS[name]
    n = len(spec.inputs)
    b, c, tf, order = structure
    rng = np.random.default_rng([PLANTS.index(name), fmi_version, len(anti_windup), order, int(10 * b)])
    filter_N = 8.0 if anti_windup == "back_calculation" else None
    pid = PID(TS, n, spec.u_limits[0], spec.u_limits[1], anti_windup, derivative_filter_N=filter_N,
              setpoint_weight=b, derivative_weight=c, measurement_filter_s=tf * TS, measurement_filter_order=order)
    plant, prior, native, fmi = _pair(name, fmi_version, pid, 10, RewardWeights(control_variation_weight=0.3))
    with plant, prior:
        for extra, value in spec.extra_inputs:
            plant.set({extra: value})
        y = plant.step_values(rng.uniform(*spec.input_range, n).tolist())  # y != 0: the filter's start shows
        r, Kp, Ti, Td, _, u_prev = _random_call(rng, spec, n)
        _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, None, u_prev))  # fresh PID
        y = _warm_up(plant, pid, spec, rng, 5)
        assert pid.raw_state()[3] and (tf == 0 or pid.raw_state()[4] != [0.0] * n)
        mattered = []
        for call in range(6):
            r, Kp, Ti, Td, _, u_prev = _random_call(rng, spec, n)
            if call == 0:
                Ti = [math.inf] * n
            args = (r, y, Kp, Ti, Td, None, u_prev)
            weighted, _ = _compare(plant, prior, native, fmi, args)
            pid.set_structure(1.0, 1.0, 0.0)  # the paper's law, the filter state kept
            paper, _ = _compare(plant, prior, native, fmi, args)
            pid.set_structure(b, c, tf * TS)
            assert _compare(plant, prior, native, fmi, args)[0] == weighted
            mattered.append(paper != weighted)
            y = _warm_up(plant, pid, spec, rng, 1)
        assert any(mattered)


@pytest.mark.parametrize("order", [1, 2])
def test_quadrotor_coupled_pid_with_2dof_structure(fmi_version, order):
    """Eq. 27 on (r, y), (b*r, yf) and (c*r, yf) with b != 1 and Tf > 0 (one loop unfiltered)."""
    spec = SPECS["QuadrotorAttitude"]
    rng = np.random.default_rng([13, order, fmi_version])
    pid = CoupledPID(TS, -2.0, 2.0, "clamping" if order == 1 else "back_calculation",
                     derivative_filter_N=None if order == 1 else 10.0, setpoint_weight=[0.5, 0.8, 0.2],
                     derivative_weight=[0.0, 1.0, 0.0], measurement_filter_s=[2 * TS, 0.0, 3 * TS],
                     measurement_filter_order=order)
    plant, prior, native, fmi = _pair("QuadrotorAttitude", fmi_version, pid, 10,
                                      RewardWeights(control_variation_weight=1.0))
    with plant, prior:
        y = plant.step_values(rng.uniform(*spec.input_range, 3).tolist())
        r, Kp, Ti, Td, coupling, u_prev = _random_call(rng, spec, 3, coupled=True)
        _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, coupling, u_prev))  # fresh PID
        y = _warm_up(plant, pid, spec, rng, 4, coupling)
        for _ in range(8):
            r, Kp, Ti, Td, coupling, u_prev = _random_call(rng, spec, 3, coupled=True)
            _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, coupling, u_prev))
            y = _warm_up(plant, pid, spec, rng, 1, coupling)


@pytest.mark.parametrize("scenario, structure, order, gains", [
    ("first_order", ((0.3, 1.0, 2 * TS),), 1, ([3.0], [1.0], [0.05])),
    ("two_tank", ((0.7, 0.0, 3 * TS),), 2, ([4.0], [40.0], [1.0])),
    ("quadrotor", ((0.5, 0.0, 2 * TS), (0.8, 1.0, 0.0), (0.2, 0.0, 3 * TS)), 2, ([2.0] * 3, [5.0] * 3, [0.3] * 3)),
], ids=["first_order", "two_tank", "quadrotor"])
def test_loop_core_forecast_with_a_tuned_structure(fmi_version, scenario, structure, order, gains):
    """A preset with tuned_structure: the loop's forecast rewards, native and FMI path, equal over episodes,
    also after LoopCore.set_structure (as the fixed-PID search does between episodes)."""
    config = dataclasses.replace(preset(scenario), fmi_version=fmi_version, tuned_structure=structure,
                                 measurement_filter_order=order, episode_steps=40)
    assert config.sample_time_s == TS
    coupling = [0.1, -0.05, 0.2, 0.0, -0.1, 0.15] if config.coupled else None
    cores = LoopCore(config), LoopCore(config, forecast_path="fmi")
    assert isinstance(cores[0].forecast, NativeForecast) and isinstance(cores[1].forecast, FmiForecast)
    paper = [1.0] * config.n_loops, [1.0] * config.n_loops, [0.0] * config.n_loops
    runs = []
    try:
        for core in cores:
            runs.append([])
            for episode, change in enumerate((None, paper, [list(v) for v in zip(*structure)])):
                if change is not None:
                    core.set_structure(*change)
                core.reset(np.random.default_rng(7))  # the same episode, only the structure changes
                for _ in range(25):
                    core.step(*gains, coupling)
                    runs[-1].append((episode, core.forecast_reward, list(core.measurement)))
    finally:
        for core in cores:
            core.close()
    assert runs[0] == runs[1]
    assert [r for e, r, _ in runs[0] if e == 0] == [r for e, r, _ in runs[0] if e == 2]
    assert [r for e, r, _ in runs[0] if e == 0] != [r for e, r, _ in runs[0] if e == 1]


def _rate_limits(spec, n):
    """Per loop, a rate limit that binds for the spec's gains: 5 % of the control span per sample; the middle loop
    of three without one."""
    span = spec.u_limits[1] - spec.u_limits[0]
    return [math.inf if n == 3 and i == 1 else 0.05 * span / TS for i in range(n)]


def _rate_bound(pid, spec):
    """Wrap pid.step_values (the FMI path's Python PID): record per step whether some rate-limited loop's output sat
    on its rate band inside the limits (the rate limit, not saturation, clipped it)."""
    core = pid.pid if isinstance(pid, CoupledPID) else pid
    rates, step_values, bound = core.u_rate_limit.tolist(), pid.step_values, []

    def counting(*args):
        previous = list(core.last_output)
        u = step_values(*args)
        bound.append(any(r != math.inf and p == p and u[i] not in spec.u_limits and u[i] in (p - r * TS, p + r * TS)
                         for i, (r, p) in enumerate(zip(rates, previous))))
        return u

    pid.step_values = counting
    return bound


@pytest.mark.parametrize("anti_windup", ["clamping", "back_calculation", "none"])
@pytest.mark.parametrize("name", PLANTS)
def test_rate_limit_native_equals_fmi_path_bit_for_bit(name, fmi_version, anti_windup):
    """The rate limit (control/pid.py): native == FMI path from a fresh PID with no previous output (the first
    sample not rate limited), from the bumpless preset (the band around u0), and from warmed-up PIDs; the band
    binds inside the limits on both paths."""
    spec = SPECS[name]
    n = len(spec.inputs)
    rng = np.random.default_rng([PLANTS.index(name), fmi_version, len(anti_windup), 17])
    rates = _rate_limits(spec, n)
    pid = PID(TS, n, spec.u_limits[0], spec.u_limits[1], anti_windup, setpoint_weight=0.6,
              derivative_filter_N=8.0 if anti_windup == "back_calculation" else None, u_rate_limit=rates)
    assert pid.u_rate_limit.tolist() == rates
    plant, prior, native, fmi = _pair(name, fmi_version, pid, 10, RewardWeights(control_variation_weight=0.3))
    with plant, prior:
        for extra, value in spec.extra_inputs:
            plant.set({extra: value})
        y = plant.step_values(rng.uniform(*spec.input_range, n).tolist())
        r, Kp, Ti, Td, _, u_prev = _random_call(rng, spec, n)
        assert all(v != v for v in pid.last_output)  # NaN: no previous output yet
        _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, None, u_prev))
        u0 = rng.uniform(*spec.u_limits, n).tolist()
        pid.preset_output(u0, y, Kp, Ti)  # as LoopCore before its first step: the band starts around u0
        assert pid.last_output == u0
        _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, None, u0))
        y = _warm_up(plant, pid, spec, rng, 5)
        bound = _rate_bound(pid, spec)
        for call in range(6):
            r, Kp, Ti, Td, _, u_prev = _random_call(rng, spec, n)
            if call == 0:
                Ti = [math.inf] * n
            _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, None, u_prev))
            y = _warm_up(plant, pid, spec, rng, 1)
        assert any(bound)  # the rate limit clipped u in the roll-outs


@pytest.mark.parametrize("anti_windup", ["clamping", "back_calculation", "none"])
@pytest.mark.parametrize("name", PLANTS)
def test_bumpless_gain_change_native_equals_fmi_path_bit_for_bit(name, fmi_version, anti_windup):
    """gain_change "bumpless" (control/pid.py): the forecast's first step rescales the error sum from the previous
    sample's gains (copied in with the state, ABI 4) to the call's; native == FMI path, with the 2-DOF structure,
    the derivative filter, rate limits (with clamping), Ti = inf (Ki = 0: no rescale) and the last sample's gains
    (no rescale); the first step's error sum differs from the positional law's where a rescale happens, not elsewhere."""
    spec = SPECS[name]
    n = len(spec.inputs)
    rng = np.random.default_rng([PLANTS.index(name), fmi_version, len(anti_windup), 23])
    kw = dict(anti_windup=anti_windup, setpoint_weight=0.5, derivative_weight=0.0, measurement_filter_s=2 * TS,
              derivative_filter_N=8.0 if anti_windup != "none" else None,
              u_rate_limit=_rate_limits(spec, n) if anti_windup == "clamping" else math.inf)
    pid = PID(TS, n, spec.u_limits[0], spec.u_limits[1], gain_change="bumpless", **kw)
    twin = PID(TS, n, spec.u_limits[0], spec.u_limits[1], gain_change="positional", **kw)
    plant, prior, native, fmi = _pair(name, fmi_version, pid, 10, RewardWeights(control_variation_weight=0.3))
    differs = []
    with plant, prior:
        y = _warm_up(plant, pid, spec, rng, 5)
        for call in range(6):
            r, Kp, Ti, Td, _, u_prev = _random_call(rng, spec, n)
            if call == 1:
                Ti = [math.inf] * n
            if call == 2:  # the last sample's gains: nothing to rescale
                _, Kp, Ti, Td = (list(v) for v in pid.raw_gain_state())
            _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, None, u_prev))
            twin.set_state(pid.get_state())  # the first step of the roll-out, on both laws
            bumpless = pid.copy()
            bumpless.step_values(r, y, Kp, Ti, Td)
            twin.step_values(r, y, Kp, Ti, Td)
            differs.append(bumpless.raw_state()[0] != twin.raw_state()[0])
            y = _warm_up(plant, pid, spec, rng, 1)
    assert any(differs[i] for i in (0, 3, 4, 5)) and not differs[1] and not differs[2]  # Ki = 0, equal gains: none


def test_quadrotor_coupled_pid_bumpless(fmi_version):
    spec = SPECS["QuadrotorAttitude"]
    rng = np.random.default_rng(29)
    pid = CoupledPID(TS, -2.0, 2.0, "back_calculation", derivative_filter_N=10.0, setpoint_weight=0.7,
                     gain_change="bumpless")
    plant, prior, native, fmi = _pair("QuadrotorAttitude", fmi_version, pid, 10, RewardWeights(control_variation_weight=1.0))
    with plant, prior:
        coupling = rng.uniform(-0.5, 0.5, 6).tolist()
        y = _warm_up(plant, pid, spec, rng, 4, coupling)
        for _ in range(6):
            r, Kp, Ti, Td, coupling, u_prev = _random_call(rng, spec, 3, coupled=True)
            _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, coupling, u_prev))
            y = _warm_up(plant, pid, spec, rng, 1, coupling)


@pytest.mark.parametrize("anti_windup", ["clamping", "back_calculation"])
def test_quadrotor_coupled_pid_with_rate_limits(fmi_version, anti_windup):
    """Eq. 26-27 with rate limits on roll and yaw (none on pitch), b != 1 and a measurement filter on one loop."""
    spec = SPECS["QuadrotorAttitude"]
    rng = np.random.default_rng([19, fmi_version, len(anti_windup)])
    rates = _rate_limits(spec, 3)
    pid = CoupledPID(TS, -2.0, 2.0, anti_windup, derivative_filter_N=10.0, setpoint_weight=[0.5, 1.0, 0.8],
                     derivative_weight=0.0, measurement_filter_s=[2 * TS, 0.0, 0.0], u_rate_limit=rates)
    plant, prior, native, fmi = _pair("QuadrotorAttitude", fmi_version, pid, 10,
                                      RewardWeights(control_variation_weight=1.0))
    with plant, prior:
        y = plant.step_values(rng.uniform(*spec.input_range, 3).tolist())
        r, Kp, Ti, Td, coupling, u_prev = _random_call(rng, spec, 3, coupled=True)
        pid.preset_output(u_prev, y, Kp, Ti)
        _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, coupling, u_prev))  # from the preset
        y = _warm_up(plant, pid, spec, rng, 4, coupling)
        bound = _rate_bound(pid, spec)
        for _ in range(8):
            r, Kp, Ti, Td, coupling, u_prev = _random_call(rng, spec, 3, coupled=True)
            _compare(plant, prior, native, fmi, (r, y, Kp, Ti, Td, coupling, u_prev))
            y = _warm_up(plant, pid, spec, rng, 1, coupling)
        assert any(bound)


@pytest.mark.parametrize("scenario, rates, gains", [
    ("first_order", (5.0,), ([8.0], [1.0], [0.05])),
    ("two_tank", (10.0,), ([4.0], [40.0], [1.0])),
    ("quadrotor", (3.0, math.inf, 2.0), ([2.0] * 3, [5.0] * 3, [0.3] * 3)),
], ids=["first_order", "two_tank", "quadrotor"])
def test_loop_core_forecast_with_rate_limits(fmi_version, scenario, rates, gains):
    """The scenario's plant.loops[i].u_rate_limit through make_pid: the loop's forecast rewards, native and FMI path,
    equal over an episode that starts with the bumpless preset (LoopCore always presets, the band around u0)."""
    config = preset(scenario)
    config = dataclasses.replace(config, fmi_version=fmi_version, episode_steps=40, tuned_structure=None,
                                 loops=tuple(dataclasses.replace(l, u_rate_limit=r) for l, r in zip(config.loops, rates)))
    coupling = [0.1, -0.05, 0.2, 0.0, -0.1, 0.15] if config.coupled else None
    cores = LoopCore(config), LoopCore(config, forecast_path="fmi")
    assert isinstance(cores[0].forecast, NativeForecast) and isinstance(cores[1].forecast, FmiForecast)
    runs, bound = [], 0
    try:
        for core in cores:
            pid = core.pid.pid if config.coupled else core.pid
            assert pid.u_rate_limit.tolist() == list(rates)
            runs.append([])
            core.reset(np.random.default_rng(7))
            for _ in range(25):
                previous = list(core.pid_output)
                core.step(*gains, coupling)
                runs[-1].append((core.forecast_reward, list(core.measurement), list(core.pid_output)))
                steps = [abs(u - p) for u, p in zip(core.pid_output, previous)]
                assert all(s <= r * TS * (1 + 1e-12) for s, r in zip(steps, rates))
                bound += sum(r != math.inf and math.isclose(s, r * TS, rel_tol=1e-9) for s, r in zip(steps, rates))
    finally:
        for core in cores:
            core.close()
    assert runs[0] == runs[1] and bound > 0  # the rate limit moved u at its most in some samples


def test_fresh_pid_and_no_overrides_and_zero_control_weight(fmi_version):
    """First step after reset (no derivative kick), prior without overrides, reward without the u term."""
    pid = PID(TS, 1, -10.0, 10.0)
    plant, prior, native, fmi = _pair("FirstOrderUnstable", fmi_version, pid, 3, RewardWeights(), overrides=False)
    with plant, prior:
        assert not pid.raw_state()[3]
        for y0 in ([0.0], [0.2], [-0.4]):
            reward, rewards = _compare(plant, prior, native, fmi, ([1.0], y0, [2.0], [1.5], [0.1], None, [0.0]))
            assert len(rewards) == 3 and math.isfinite(reward)
            plant.step_values([1.0])


def test_divergence_ends_the_roll_out_with_the_penalty(fmi_version):
    pid = PID(TS, 1, -0.5, 0.5)  # too weak to hold the unstable pole
    plant, prior, native, fmi = _pair("FirstOrderUnstable", fmi_version, pid, 10, RewardWeights(), overrides=False,
                                      prior_parameters={"a": 1.3, "b": 0.9})
    with plant, prior:
        for _ in range(3):
            y = plant.step_values([10.0])  # x = 9/1.3 (e^(1.3*0.3) - 1) = 3.3 (a = 1.3, b = 0.9)
        assert 3.0 < y[0] < 4.0
        reward, rewards = _compare(plant, prior, native, fmi, ([0.0], y, [1.0], [5.0], [0.0], None, [0.0]))
        assert 1 < len(rewards) < 10 and rewards[-1] == -100.0
        assert native._result.stopped == 1
        assert abs(native.last_measurements[-1][0]) > 5.0  # the step that crossed the bound is recorded


def test_discarded_step_ends_the_roll_out_with_the_penalty(fmi_version):
    pid = PID(TS, 1, -1e308, 1e308)  # u near 1e308 overflows the RK4 stages: the FMU discards the step
    plant, prior, native, fmi = _pair("FirstOrderUnstable", fmi_version, pid, 5, RewardWeights(), overrides=False)
    with plant, prior:
        plant.step_values([0.1])
        reward, rewards = _compare(plant, prior, native, fmi, ([1.0], [0.1], [1e308], [1.0], [0.0], None, [0.0]))
        assert rewards == [-100.0] and reward == -100.0
        assert native._result.stopped == 2 and native.last_measurements == []


def test_errors_are_the_same_on_both_paths(fmi_version):
    pid = PID(TS, 1, -10.0, 10.0)
    plant, prior, native, fmi = _pair("FirstOrderUnstable", fmi_version, pid, 3, RewardWeights())
    with plant, prior:
        for forecast in (native, fmi):  # Ti = 0: Python's float division raises
            with pytest.raises(ZeroDivisionError):
                forecast.mean_reward([1.0], [0.0], [1.0], [0.0], [0.0], None, [0.0])
        assert pid.raw_state()[3] is False
    # back-calculation with Ti*Td < 0 while saturated: math.sqrt raises ValueError
    pid = PID(TS, 1, -0.1, 0.1, "back_calculation")
    plant, prior, native, fmi = _pair("FirstOrderUnstable", fmi_version, pid, 3, RewardWeights())
    with plant, prior:
        for forecast in (native, fmi):
            with pytest.raises(ValueError, match="math domain error"):
                forecast.mean_reward([1.0], [0.0], [1.0], [-2.0], [0.5], None, [0.0])
    # an override the prior cannot take once initialised (a fixed parameter): PlantError on both
    pid = PID(TS, 1, -10.0, 10.0)
    path = fmu("FirstOrderUnstable", fmi_version)
    with FmuPlant(path, ["u"], ["y"], TS) as plant, FmuPlant(path, ["u"], ["y"], TS, instance_name="prior") as prior:
        for where in ("auto", "fmi"):
            forecast = make_forecast(plant, prior, pid, horizon=2, scale=[1.0], bound=[5.0], penalty=-100.0,
                                     weights=RewardWeights(), u_scale=[20.0], overrides={"x0": 0.5}, path=where)
            with pytest.raises(PlantError):
                forecast.mean_reward([1.0], [0.0], [1.0], [1.0], [0.0], None, [0.0])


def test_native_keeps_prior_time_for_later_fmi_calls(fmi_version):
    """After a native roll-out, the prior's Python time matches its C time: FMI calls on it still work."""
    pid = PID(TS, 1, -10.0, 10.0)
    plant, prior, native, fmi = _pair("FirstOrderUnstable", fmi_version, pid, 4, RewardWeights())
    with plant, prior:
        plant.step_values([0.5])
        native.mean_reward([1.0], [0.05], [2.0], [1.0], [0.0], None, [0.0])
        assert prior.time == plant.time + 4 * TS
        prior.step_values([0.0])  # doStep at prior.time is accepted only if it is the FMU's time


def test_raw_state_is_the_live_state():
    pid = PID(TS, 2, -1.0, 1.0, setpoint_weight=0.5, measurement_filter_s=[0.2, 0.0], measurement_filter_order=2)
    for y in ([0.1, 0.4], [0.3, -0.2]):
        pid.step_values([0.5, -2.0], y, [1.0, 3.0], [2.0, 1.0], [0.1, 0.0])
    integral, last_error, derivative, initialized, filtered, filter_stage = pid.raw_state()
    state = pid.get_state()
    assert (integral, last_error, derivative, initialized, filtered, filter_stage) == (
        state.integral.tolist(), state.last_error.tolist(), state.derivative.tolist(), True, state.filtered.tolist(),
        state.filter_stage.tolist())
    assert filtered[0] != filter_stage[0]  # the second-order filter's two sections differ after a step
    coupled = CoupledPID(TS)
    assert coupled.raw_state() == coupled.pid.raw_state()


def test_make_forecast_picks_native_only_for_the_same_bundled_fmu():
    path2, path3 = fmu("FirstOrderUnstable", 2), fmu("FirstOrderUnstable", 3)
    pid = PID(TS, 1)
    kw = dict(horizon=2, scale=[1.0], bound=[5.0], penalty=-100.0, weights=RewardWeights(), u_scale=[1.0])
    with FmuPlant(path2, ["u"], ["y"]) as plant, FmuPlant(path2, ["u"], ["y"]) as prior, \
            FmuPlant(path3, ["u"], ["y"]) as other:
        assert native_unavailable(plant, prior) is None
        assert isinstance(make_forecast(plant, prior, pid, **kw), NativeForecast)
        assert isinstance(make_forecast(plant, prior, pid, path="fmi", **kw), FmiForecast)
        assert isinstance(make_forecast(plant, prior, pid, state_map={"x0": "y"}, **kw), FmiForecast)
        assert "not the plant's FMU" in native_unavailable(plant, other)
        assert isinstance(make_forecast(plant, other, pid, **kw), FmiForecast)
        with pytest.raises(PlantError, match="not available"):
            make_forecast(plant, other, pid, path="native", **kw)
        with pytest.raises(ValueError, match="path"):
            make_forecast(plant, prior, pid, path="fast", **kw)
