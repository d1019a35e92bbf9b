"""robustness.local_model: the local models identified from the measured frequency responses, the PID's feedback
law as polynomials, and the load search on those models (tuning.load_design, baseline.design_model)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import differential_evolution
from scipy.signal import cont2discrete, lfilter

from prlpid_fmi.control.pid import PID
from prlpid_fmi.robustness.local_model import (LocalModel, closed_loop_stable, feedback_polynomials, identify,
                                              load_responses, reference_polynomial, setpoint_response)
from prlpid_fmi.robustness.margins import pid_frequency_response, setpoint_range_points
from prlpid_fmi.robustness.plant_response import MeasuredPlant
from prlpid_fmi.scenario.presets import preset
from prlpid_fmi.tuning.load_design import LoadDesign
from prlpid_fmi.tuning.load_experiment import plant_responses

STABILISING = ([4.0], [1.0], [0.05], None)  # Kp, Ti, Td, coupling: stabilises 1/(s - 1) and 1/(s - 1.5) at Ts 0.1


def zoh(num, den, Ts):
    """(numerator, denominator) in powers of z^-1 of the ZOH discretisation (scipy.signal.cont2discrete)."""
    b, a, _ = cont2discrete((num, den), Ts, method="zoh")
    return np.ravel(b), np.ravel(a)


@pytest.mark.parametrize("name, pole", [("first_order", 1.0), ("first_order_1p5", 1.5)])
def test_identified_model_of_an_unstable_first_order_plant_is_its_zoh_discretisation(name, pole):
    """1/(s - a) measured on the FMU at each operating point: the identified model is of order 1 and its
    coefficients are scipy's ZOH discretisation's within 1e-4 (the multisine estimate converges to 1e-3 of |1 + L|;
    a linear plant's is far closer)."""
    config = preset(name)
    b_ref, a_ref = zoh([1.0], [1.0, -pole], config.sample_time_s)
    for plants in plant_responses(config, STABILISING, setpoint_range_points(config)):
        model = identify(plants[0])
        assert model.order == 1
        np.testing.assert_allclose(model.denominator, a_ref, rtol=0, atol=1e-4)
        np.testing.assert_allclose(model.numerator, b_ref, rtol=0, atol=1e-4)
        assert model.fit_error < 1e-3


def test_identify_picks_the_lowest_order_that_fits_a_second_order_response():
    """A ZOH-discretised 2/((s + 1)(s + 3)) sampled at 60 frequencies: order 2, coefficients within 1e-8; the order-1
    fit would miss it by far more than the fit tolerance."""
    Ts = 0.05
    b, a = zoh([2.0], [1.0, 4.0, 3.0], Ts)
    w = np.geomspace(0.01, math.pi / Ts, 60)
    q = np.exp(-1j * w * Ts)
    P = np.polyval(b[::-1], q) / np.polyval(a[::-1], q)
    model = identify(MeasuredPlant(w, P, Ts, (0.0,), ()))
    assert model.order == 2
    np.testing.assert_allclose(model.denominator, a, atol=1e-8)
    np.testing.assert_allclose(model.numerator, b, atol=1e-8)
    assert identify(MeasuredPlant(w, P, Ts, (0.0,), ()), max_order=1, high_order=1).fit_error > 0.05


def test_a_pole_zero_pair_below_the_lowest_measured_octave_is_not_identified():
    """Two tanks' 0.005 / ((s + 0.05)(s + 0.5)) at Ts 0.1 s, its response at the two lowest of 60 frequencies 9 % off
    (a closed-loop estimate at high loop gain): order 2 misses a tolerance of 0.5 %, and the higher orders that meet
    or approach it follow the error with a pole and a zero below 2x the lowest frequency (without the rule an order-5
    fit was taken). The model taken is of order 2, its poles scipy's ZOH discretisation's within 0.2 % (stable)."""
    Ts = 0.1
    b, a = zoh([0.005], [1.0, 0.55, 0.025], Ts)
    w = np.geomspace(0.004, math.pi / Ts, 60)
    q = np.exp(-1j * w * Ts)
    P = np.polyval(b[::-1], q) / np.polyval(a[::-1], q)
    P[:2] *= 1.09
    model = identify(MeasuredPlant(w, P, Ts, (0.0,), ()), tolerance=0.005)
    assert model.order == 2 and len(model.numerator) == 3
    np.testing.assert_allclose(np.sort(np.roots(model.denominator)), np.sort(np.roots(a)), rtol=2e-3)
    assert np.max(np.abs(np.roots(model.denominator))) < 1.0


def test_identify_finds_the_dead_time_of_a_delayed_lag():
    """A ZOH-discretised e^(-0.35 s)/(2 s + 1) at Ts = 0.05 (7 samples of delay, the ZOH's sample on top): no order
    1..4 without dead time fits it within the tolerance; with it, order 1 and d = 7, the coefficients within 1e-8 of
    scipy's discretisation, and its unit step response is scipy's delayed by 7 samples."""
    from scipy.signal import dlsim

    Ts, delay = 0.05, 7
    b, a = zoh([1.0], [2.0, 1.0], Ts)
    w = np.geomspace(0.01, math.pi / Ts, 120)
    q = np.exp(-1j * w * Ts)
    P = q ** delay * np.polyval(b[::-1], q) / np.polyval(a[::-1], q)
    assert identify(MeasuredPlant(w, P, Ts, (0.0,), ()), max_delay=0, high_order=4).fit_error > 0.05
    model = identify(MeasuredPlant(w, P, Ts, (0.0,), ()))
    assert model.order == 1 and model.fit_error < 1e-6
    np.testing.assert_allclose(model.numerator, np.concatenate([np.zeros(delay), b]), atol=1e-8)
    np.testing.assert_allclose(model.denominator, a, atol=1e-8)
    _, y_ref = dlsim((b[1:], a, Ts), np.ones(60))  # b_1 q / (1 + a_1 q) = b_1 / (z + a_1)
    y = lfilter(model.numerator, model.denominator, np.ones(60 + delay))
    np.testing.assert_allclose(y[delay:], y_ref[:, 0], atol=1e-8)


def test_identify_fits_a_sixth_order_lag_after_the_low_orders_and_dead_times_fail():
    """A ZOH-discretised 1/(s + 1)^6 at Ts = 0.1 (scipy) sampled at 120 frequencies: no order 1..4, with or without dead
    time, fits it within the tolerance; the high-order stage returns order 6 without dead time, its coefficients
    within 1e-6 of scipy's."""
    Ts = 0.1
    b, a = zoh([1.0], np.poly([-1.0] * 6), Ts)
    w = np.geomspace(0.01, math.pi / Ts, 120)
    q = np.exp(-1j * w * Ts)
    plant = MeasuredPlant(w, np.polyval(b[::-1], q) / np.polyval(a[::-1], q), Ts, (0.0,), ())
    assert identify(plant, high_order=4).fit_error > 0.02
    model = identify(plant)
    assert model.order == 6 and len(model.numerator) == 7 and model.fit_error < 1e-6
    np.testing.assert_allclose(model.denominator, a, atol=1e-6)
    np.testing.assert_allclose(model.numerator, b, atol=1e-6)


@pytest.mark.parametrize("Kp, Ti, Td, N, Tf, order", [(2.0, 1.5, 0.3, 10.0, 0.2, 2), (2.0, math.inf, 0.3, None, 0.0, 1),
                                                      (1.3, 0.7, 0.0, None, 0.5, 1), (0.8, 2.0, 0.1, 5.0, 0.0, 1)])
def test_feedback_polynomials_are_the_pid_law(Kp, Ti, Td, N, Tf, order):
    """u = -C y at a constant setpoint: the polynomials filter a random measurement exactly as control.pid.PID steps
    it (from rest at 0, no limits), and equal margins.pid_frequency_response on the unit circle."""
    Ts = 0.1
    Nc, Dc = feedback_polynomials(Kp, Ti, Td, Ts, N, Tf, order)
    y = np.concatenate([[0.0], np.random.default_rng(3).normal(size=300)])
    pid = PID(Ts, derivative_filter_N=N, setpoint_weight=1.0, derivative_weight=0.0, measurement_filter_s=Tf,
              measurement_filter_order=order, anti_windup="none")
    u = np.array([pid.step_values([0.0], [v], [Kp], [Ti], [Td])[0] for v in y])
    np.testing.assert_allclose(lfilter(-Nc, Dc, y), u, rtol=1e-9, atol=1e-9)
    w = np.geomspace(0.01, math.pi / Ts, 50)
    q = np.exp(-1j * w * Ts)
    C = np.polyval(Nc[::-1], q) / np.polyval(Dc[::-1], q)
    R = pid_frequency_response(Kp, Ti, Td, Ts, w, N, Tf, order)
    np.testing.assert_allclose(C, R, rtol=1e-9)


@pytest.mark.parametrize("Kp, Ti, Td, N, Tf, order, b, c", [(2.0, 1.5, 0.3, 10.0, 0.2, 2, 0.4, 0.0),
                                                            (2.0, math.inf, 0.3, None, 0.0, 1, 1.0, 0.0),
                                                            (1.3, 0.7, 0.2, 8.0, 0.5, 1, 0.0, 1.0),
                                                            (0.8, 2.0, 0.1, 5.0, 0.0, 1, 0.7, 0.5)])
def test_setpoint_response_is_the_pid_law_in_closed_loop(Kp, Ti, Td, N, Tf, order, b, c):
    """A random setpoint sequence through control.pid.PID (setpoint weights b, c; from rest, no limits) in closed loop
    with y_{k+1} = 0.8 y_k + 0.3 u_k: u = Cr r - C y with Cr = Nr / Dc (`reference_polynomial`) gives the same u to
    1e-9, and a unit step gives `setpoint_response`'s y. (The PID's derivative starts from ed(-1) := ed(0), so both
    sequences start at r = 0 for a sample: a step at k = 0 from rest would skip the c-weighted derivative kick.)"""
    Ts = 0.1
    model = LocalModel(np.array([0.0, 0.3]), np.array([1.0, -0.8]), Ts, (0.0,), 0.0)
    Nc, Dc = feedback_polynomials(Kp, Ti, Td, Ts, N, Tf, order)
    Nr = reference_polynomial(Kp, Ti, Td, Ts, b, c, N, Tf, order)

    def run(r):
        pid = PID(Ts, derivative_filter_N=N, setpoint_weight=b, derivative_weight=c, measurement_filter_s=Tf,
                  measurement_filter_order=order, anti_windup="none")
        y, ys, us = 0.0, [], []
        for rk in r:
            u = pid.step_values([float(rk)], [y], [Kp], [Ti], [Td])[0]
            ys.append(y)
            us.append(u)
            y = 0.8 * y + 0.3 * u
        return np.array(ys), np.array(us)

    r = np.concatenate([[0.0], np.repeat(np.random.default_rng(5).normal(size=20), 10)])
    y, u = run(r)
    np.testing.assert_allclose(lfilter(Nr, Dc, r) - lfilter(Nc, Dc, y), u, rtol=1e-9, atol=1e-9)
    step = np.concatenate([[0.0], np.ones(80)])
    y, _ = run(step)
    np.testing.assert_allclose(np.concatenate([[0.0], setpoint_response(model, Nc, Dc, Nr, 80)]), y, rtol=1e-9,
                               atol=1e-9)


def test_load_response_of_a_p_controller_on_a_first_order_lag_by_hand():
    """y_{k+1} = 0.5 y_k + u_k + d_k with u = -y (P control, Kp 1) and d a unit step from k = 0: y_0 = 0 and
    y_{k+1} = -0.5 y_k + 1 (0, 1, 0.5, 0.75, ...); the PID output -y. Kp 2 puts the closed-loop pole at -1.5."""
    from prlpid_fmi.robustness.local_model import LocalModel

    model = LocalModel(np.array([0.0, 1.0]), np.array([1.0, -0.5]), 1.0, (0.0,), 0.0)
    Nc, Dc = feedback_polynomials(1.0, math.inf, 0.0, 1.0)
    dy, du = load_responses(model, Nc, Dc, 6)
    expected = [0.0]
    for _ in range(5):
        expected.append(-0.5 * expected[-1] + 1.0)
    np.testing.assert_allclose(dy, expected, atol=1e-12)
    np.testing.assert_allclose(du, -np.array(expected), atol=1e-12)
    assert closed_loop_stable(model, Nc, Dc)
    assert not closed_loop_stable(model, *feedback_polynomials(2.0, math.inf, 0.0, 1.0))  # pole at -1.5


def test_the_schur_cohn_test_agrees_with_the_roots_numpy_finds():
    """schur_stable against np.roots' largest |root| on random real polynomials of degree 1-8 whose roots lie at
    least 1e-6 from the unit circle (both sides), scaled by a random leading coefficient of either sign."""
    from prlpid_fmi.robustness.local_model import schur_stable

    rng = np.random.default_rng(1)
    stable = unstable = 0
    for _ in range(5000):
        degree = int(rng.integers(1, 9))
        pairs = rng.uniform(0.0, 1.3, degree // 2) * np.exp(1j * rng.uniform(0.0, math.pi, degree // 2))
        roots = np.concatenate([pairs, pairs.conj(), rng.uniform(-1.3, 1.3, degree % 2)])
        if np.any(np.abs(np.abs(roots) - 1.0) < 1e-6):
            continue
        c = np.real(np.poly(roots)) * rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 10.0)
        expected = bool(np.max(np.abs(np.roots(c))) < 1.0)
        assert schur_stable(c.tolist()) == expected, roots
        stable, unstable = stable + expected, unstable + (not expected)
    assert stable > 500 and unstable > 500  # both answers were asked for
    assert schur_stable([3.0]) and not schur_stable([1.0, -1.0])  # a constant; a root on the circle is not inside


def test_nonlinear_plants_model_matches_the_fmus_small_load_step():
    """The two tanks (nonlinear: outflow ~ sqrt(h)): the load IAE and chatter of a PID on the identified local
    models equal the FMU's load experiment with a small load (2 % of the span) within 5 %, at every point."""
    config = preset("two_tank")
    design = LoadDesign(config, 0.02, 2.0, math.inf, 4.0, design_model="identified")
    try:
        design.prepare(([5.0], [40.0], [1.0], None))
        assert design.models is not None, design.model_note
        for gains in (([5.0], [40.0], [1.0], None), ([10.0], [20.0], [0.0], None)):
            model, _ = design.model_load_response(gains, list(design.tf))
            fmu, _ = design.load_response(gains, list(design.tf))
            assert model == pytest.approx(fmu, rel=0.05)
    finally:
        design.close()


def load_search(config, design_model: str, maxiter: int = 6, popsize: int = 8):
    """The load search (tuning.load_design) of config on design_model's path: (vector, its load cost on the FMU,
    the design's model note)."""
    design = LoadDesign(config, 0.1, 2.0, math.inf, 4.0, workers=1, design_model=design_model)
    try:
        design.prepare(STABILISING)
        result = design.search(0, maxiter, popsize)
        return result.x, design.load_cost(design.gains(result.x), design.filters(result.x)), design.models
    finally:
        design.close()


def test_model_based_design_on_the_unstable_plant_equals_the_fmu_simulation_design():
    """1/(s - 1): the load search on the identified models finds a design whose load IAE on the FMU is within 2 % of
    the design found by simulating every candidate on the FMU (same budget, same seed)."""
    config = preset("first_order")
    _, on_models, models = load_search(config, "identified")
    _, on_fmu, none = load_search(config, "fmu")
    assert models is not None and none is None
    assert on_models == pytest.approx(on_fmu, rel=0.02)


BUDGET = dict(seed=0, episodes=1, maxiter=3, popsize=5, max_sensitivity=2.0)  # a small fixed-PID design


def fixed_pid(design_model: str):
    """tune_fixed_pid of first_order on a small budget with baseline.design_model = design_model, one worker."""
    from prlpid_fmi.tuning import design_rule

    return design_rule.tune_fixed_pid(preset("first_order"), baseline=dataclasses.replace(
        design_rule.BaselineConfig(), design_model=design_model, workers=1), **BUDGET)


@pytest.fixture(scope="module")
def on_fmu():
    """The small design of first_order with every candidate simulated on the FMU."""
    return fixed_pid("fmu")


def test_the_fixed_pid_on_local_models_is_no_worse_than_the_fmu_paths_on_the_unstable_plant(on_fmu):
    """1/(s - 1) (linear: its local models are exact): the whole fixed-PID rule on the identified models, the load
    search and the setpoint search within the load tolerance, keeps a design no worse than the FMU path's on both
    the load IAE and the setpoint ISE on the FMU (2 % slack; the setpoint search on the models affords more
    generations), and its report says which path it took and how well the models predicted the FMU."""
    result = fixed_pid("identified")
    record = result.report.details.design_model
    assert record.path == "identified" and record.agrees and record.validation_error < 1e-6
    assert [m["order"] for m in record.models] == [1, 1, 1]
    traded = result.report.details.traded_for_overshoot
    assert traded is not None and traded.on_models.kept  # searched on the models, verified on the FMU
    assert record.setpoint_search == "identified"
    assert traded.on_models.model_load_cost == pytest.approx(traded.load_cost, rel=1e-6)
    assert on_fmu.report.details.design_model.path == "fmu"

    def ise(r):
        return next(q.value for q in r.report.requirements if q.name == "setpoint ISE")
    assert result.cost <= 1.02 * on_fmu.cost and ise(result) <= 1.02 * ise(on_fmu)


def test_a_model_that_disagrees_with_the_fmu_sends_the_search_to_the_fmu(monkeypatch, on_fmu):
    """A local model with twice the plant's gain: the validation on the FMU finds the disagreement (> 10 %), the
    design report says the FMU path was used and why, and the design is the FMU path's."""
    from prlpid_fmi.robustness import local_model
    from prlpid_fmi.tuning import load_design

    def doubled(plant, *args, **kwargs):
        m = local_model.identify(plant, *args, **kwargs)
        return dataclasses.replace(m, numerator=2.0 * m.numerator)

    monkeypatch.setattr(load_design, "identify", doubled)
    result = fixed_pid("identified")
    record = result.report.details.design_model
    assert record.path == "fmu" and record.requested == "identified"
    assert record.validation_error > 0.1 and not record.agrees
    assert "differs" in record.note
    np.testing.assert_allclose(result.gains.values()[0], on_fmu.gains.values()[0])
    assert result.cost == pytest.approx(on_fmu.cost)


def test_the_vectorised_kp_scan_equals_the_per_controller_estimates():
    """MeasuredPlant.scan (what the Kp interval of every candidate uses) against sensitivity_peak, winding and
    noise_gains of each PID alone, on 1/(s - 1)'s exact ZOH response: the same Ms, winding and noise gains."""
    Ts = 0.1
    b, a = zoh([1.0], [1.0, -1.0], Ts)
    w = np.geomspace(2 * math.pi / (4096 * Ts), math.pi / Ts, 120)
    q = np.exp(-1j * w * Ts)
    plant = MeasuredPlant(w, np.polyval(b[::-1], q) / np.polyval(a[::-1], q), Ts, (0.0,), ())
    Ti, Td, N, Tf = 0.8, 0.05, 10.0, 0.2
    kps = np.geomspace(0.1, 40.0, 9)
    shape = lambda x: pid_frequency_response(1.0, Ti, Td, Ts, x, N, Tf)  # noqa: E731
    (ms, winding), (noise, increments) = plant.scan(kps, shape), plant.noise_scan(kps, shape)
    for j, kp in enumerate(kps):
        C = lambda x, kp=kp: pid_frequency_response(kp, Ti, Td, Ts, x, N, Tf)  # noqa: E731
        assert ms[j] == pytest.approx(plant.sensitivity_peak(C), rel=1e-9)
        assert winding[j] == pytest.approx(plant.winding(C), abs=1e-9)
        assert (noise[j], increments[j]) == pytest.approx(plant.noise_gains(C), rel=1e-9)
    assert len(set(np.round(winding / math.pi))) > 1  # the scan crosses from unstable to stable gains


# The setpoint optimum of 1/(s - 1) at Ts 0.1 s by benchmarks/bench_pid_design.py (its own law and optimiser: least
# unit-step ISE over Kp, Ti, Td and a continuous b subject to Ms <= 2, load IAE <= 1.15 x the Ms <= 2 load optimum
# 0.02515 and overshoot <= 5 %): Kp 8.246, Ti 0.234, Td 0, b 0.375.
SETPOINT_OPTIMUM = dict(Kp=8.246, Ti=0.234, Td=0.0, b=0.375)
LOAD_OPTIMUM = 0.02515


def _first_order_loop(Kp, Ti, Td, b, r, load, steps=3000, Ts=0.1):
    """y (steps,) of 1/(s - 1) (ZOH at Ts: y_{k+1} = e^Ts y_k + (e^Ts - 1)(u_k + load)) under the 2-DOF PID written
    out here: e = r - y, I_k = I_{k-1} + e_k Ts, D on -y by backward difference (D = 0 at k = 0),
    u = Kp (b r - y + I / Ti + Td D); from rest."""
    a, g = math.exp(Ts), math.exp(Ts) - 1.0
    y, integral, y_prev, out = 0.0, 0.0, 0.0, []
    for k in range(steps):
        out.append(y)
        integral += (r - y) * Ts
        derivative = 0.0 if k == 0 else -(y - y_prev) / Ts
        u = Kp * (b * r - y + integral / Ti + Td * derivative)
        y_prev, y = y, a * y + g * (u + load)
    return np.array(out)


def _first_order_figures(Kp, Ti, Td, b, Ts=0.1):
    """(unit-step ISE, overshoot [%], unit-load IAE, Ms on 2000 frequencies) of the loop above."""
    y = _first_order_loop(Kp, Ti, Td, b, 1.0, 0.0)
    y_load = _first_order_loop(Kp, Ti, Td, b, 0.0, 1.0)
    z = np.exp(1j * np.linspace(1e-4, math.pi, 2000))
    P = (math.exp(Ts) - 1.0) / (z - math.exp(Ts))
    C = Kp * (1.0 + Ts / Ti * z / (z - 1.0) + Td / Ts * (z - 1.0) / z)
    return (float(np.sum((1.0 - y) ** 2) * Ts), 100.0 * max(0.0, float(np.max(y)) - 1.0),
            float(np.sum(np.abs(y_load)) * Ts), float(np.max(np.abs(1.0 / (1.0 + C * P)))))


def test_the_setpoint_search_on_the_local_models_reaches_the_independent_setpoint_optimum():
    """1/(s - 1), no b meets the overshoot limit with the load optimum: the setpoint search on the local models
    (tuning.design_rule requirement 5, verified on the FMU) keeps gains whose unit-step ISE, computed by this file's own
    loop, is within 5 % of the independent setpoint optimum's, with overshoot <= 5 % (+0.3 for the episodes' steps
    against this unit step), load IAE <= 1.15 x the design's load optimum and Ms <= 2 (+1 %)."""
    result = fixed_pid("identified")
    traded = result.report.details.traded_for_overshoot
    assert traded.feasible and traded.on_models.kept
    b = result.structure[0][0]
    ise, overshoot, load_iae, ms = _first_order_figures(result.gains.Kp[0], result.gains.Ti[0], result.gains.Td[0], b)
    ise_opt, overshoot_opt, load_opt, ms_opt = _first_order_figures(**SETPOINT_OPTIMUM)
    assert overshoot_opt <= 5.0 + 1e-2 and ms_opt <= 2.0 + 1e-2 and load_opt <= 1.15 * LOAD_OPTIMUM * 1.001
    assert ise <= 1.05 * ise_opt
    # within the tolerance of the load optimum the tool found at this small budget (1.2x the independent one here)
    assert overshoot <= 5.3 and load_iae <= 1.15 * result.report.details.load_optimum * 1.001 and ms <= 2.02


def test_where_no_gains_within_the_load_tolerance_meet_the_overshoot_limit_the_nearest_are_kept_from_the_models():
    """1/(s - 1) with baseline.load_tolerance 1.01: no gains within 1 % of the load optimum keep a setpoint step's
    overshoot within 5 % (the setpoint optimum needs about 1.15x); the search on the models ranks by violation and the
    gains nearest the tolerance that meet the overshoot limit are kept (requirement 3 above 4), verified on the FMU:
    this file's own loop gives overshoot <= 5 % (+0.3) and a load IAE above 1.01x the design's optimum."""
    from prlpid_fmi.tuning import design_rule

    # a load search that reaches the optimum (1.005x the benchmark's 0.02515), so that nothing within 1 % meets 5 %
    result = design_rule.tune_fixed_pid(preset("first_order"), baseline=dataclasses.replace(
        design_rule.BaselineConfig(), workers=1, load_tolerance=1.01), **{**BUDGET, "maxiter": 12, "popsize": 8})
    traded = result.report.details.traded_for_overshoot
    assert traded.nearest_load_tolerance and not traded.feasible
    assert traded.on_models.kept and traded.on_models.nearest_on_models
    _, overshoot, load_iae, ms = _first_order_figures(result.gains.Kp[0], result.gains.Ti[0], result.gains.Td[0],
                                                      result.structure[0][0])
    assert overshoot <= 5.3 and ms <= 2.02
    assert load_iae > 1.01 * result.report.details.load_optimum


def test_the_quadrotors_loop_models_are_its_double_integrators_and_predict_the_fmu_with_coupling():
    """Three loops (the quadrotor, linear about rest: P_j = 1 / (I_j s^2)): measured with a coupled PID, each loop's
    local model is the ZOH discretisation of its double integrator (1 % over the measured frequencies: the loop's own
    measurement's response, not the coupled error's effective plant); for another coupled
    PID the load IAE on the models (robustness.loop_models' closed loop of the three) equals the FMU's load experiment
    within 5 %, and so does each loop's Ms with the coupled loops closed (models_ms) the margin experiment on the FMU."""
    from prlpid_fmi.robustness.margins import margins_of

    config = preset("quadrotor")
    design = LoadDesign(config, 0.1, 2.0, math.inf, 4.0, design_model="identified")
    try:
        # roll and pitch coupled to each other and to yaw, yaw to neither: the yaw rate stays 0 while roll or pitch is
        # excited, so the gyroscopic terms q r, p r stay 0 and each experiment is linear
        design.prepare(([1.5] * 3, [8.0] * 3, [0.8] * 3, [0.3, 0.2, -0.25, 0.15, 0.0, 0.0]))
        assert design.models is not None, design.model_note
        for models, plants in zip(design.models, design.plants):
            for model, plant, inertia in zip(models, plants, (0.4, 0.4, 0.8)):
                w = plant.frequencies_rad_s[:-1]  # the Nyquist frequency: the ZOH's zero
                b, a = zoh([1.0], [inertia, 0.0, 0.0], 0.1)
                q = np.exp(-1j * w * 0.1)
                exact = np.polyval(b[::-1], q) / np.polyval(a[::-1], q)
                assert np.max(np.abs(model.response(w) / exact - 1.0)) < 0.01
        gains = ([1.2, 1.0, 1.5], [10.0, 12.0, 15.0], [0.7, 0.8, 1.0], [0.1, -0.1, 0.05, 0.1, -0.05, 0.1])
        tf = list(design.tf)
        model, _ = design.model_load_response(gains, tf)
        fmu, _ = design.load_response(gains, tf)
        assert model == pytest.approx(fmu, rel=0.05)
        measured = max(margins_of(config, gains, p).Ms for p in design.points)
        assert design.models_ms(gains, tf) == pytest.approx(measured, rel=0.05)
        # decoupled PIDs (the fixed PID's) take each loop on its own model; a 1e-12 coupling takes the coupled
        # state-space loop: both give the same load IAE, chatter and Ms
        decoupled = (*gains[:3], [0.0] * 6)
        barely = (*gains[:3], [1e-12] * 6)
        assert design.model_load_response(decoupled, tf) == pytest.approx(design.model_load_response(barely, tf),
                                                                           rel=1e-7, abs=1e-12)
        assert design.models_ms(decoupled, tf) == pytest.approx(design.models_ms(barely, tf), rel=1e-9)
        # on diag(models) decoupled loops are separable: J_load is the loops' shares summed, chatter and Ms their worst
        shares = [design.loop_load_response(i, decoupled, tf) for i in range(3)]
        joint, chatter = design.model_load_response(decoupled, tf)
        assert sum(j for j, _ in shares) == pytest.approx(joint, rel=1e-12)
        assert max(c for _, c in shares) == pytest.approx(chatter, abs=1e-15)
        assert max(design.loop_models_ms(i, decoupled, tf) for i in range(3)) == design.models_ms(decoupled, tf)
        # so the search one loop at a time reaches a joint cost no worse than DE over all nine entries with at least
        # as many evaluations, and no small step of any entry lowers it (a local optimum of the joint cost)
        found = design.search(seed=2, maxiter=8, popsize=8)
        assert found.fun == pytest.approx(design.cost(found.x), rel=1e-12) and found.fun < 1.0
        joint_de = differential_evolution(lambda v: design.cost(v), [(-1.0, 1.0)] * design.n, maxiter=8,
                                          popsize=int(np.ceil(found.nfev / (9 * design.n))), seed=2, polish=False)
        assert joint_de.nfev >= found.nfev and found.fun <= joint_de.fun
        for k in range(design.n):
            for step in (-0.02, 0.02):
                moved = found.x.copy()
                moved[k] = np.clip(moved[k] + step, -1.0, 1.0)
                assert design.cost(moved) >= found.fun * (1.0 - 1e-3)
    finally:
        design.close()


def test_frequencies_where_the_measuring_loop_has_high_gain_weigh_less_in_the_fit():
    """A closed-loop estimate is a ratio of small signals where |S| of the measuring loop is small: here two tanks'
    0.005 / ((s + 0.05)(s + 0.5)) at Ts 0.1 s measured with a PI (Kp 5, Ti 10 s), each frequency's estimate off by
    0.1 % / |S| (rotating phase). Unweighted, no order fits within FIT_TOLERANCE; with the measuring loop's |S|
    (MeasuredPlant.sensitivity) order 2 fits and its poles are scipy's ZOH discretisation's within 0.2 %."""
    from prlpid_fmi.robustness.local_model import FIT_TOLERANCE

    Ts = 0.1
    b, a = zoh([0.005], [1.0, 0.55, 0.025], Ts)
    w = np.geomspace(0.0005, math.pi / Ts, 120)
    q = np.exp(-1j * w * Ts)
    P = np.polyval(b[::-1], q) / np.polyval(a[::-1], q)
    S = np.abs(1.0 / (1.0 + pid_frequency_response(5.0, 10.0, 0.0, Ts, w) * P))
    assert S.min() < 0.01  # high loop gain at the lowest frequencies
    measured = P * (1.0 + 0.001 / S * np.exp(1j * np.arange(len(w))))
    plain = identify(MeasuredPlant(w, measured, Ts, (0.0,), ()))
    assert plain.order != 2 or plain.fit_error > FIT_TOLERANCE
    model = identify(MeasuredPlant(w, measured, Ts, (0.0,), (), None, S))
    assert model.order == 2 and model.fit_error <= FIT_TOLERANCE
    np.testing.assert_allclose(np.sort(np.roots(model.denominator)), np.sort(np.roots(a)), rtol=2e-3)
