"""The noise gains of a measured plant (robustness.plant_response) against python-control's impulse response.

std(u) / std(n) of white measurement noise n through u = -C S n is the H2 norm of C S, sqrt(sum h_k^2) over its
impulse response h; std(u_k - u_{k-1}) / std(n) is sqrt(sum (h_k - h_{k-1})^2). Both are computed here from
python-control's discrete transfer functions, independently of the frequency-domain integral under test.
"""
from __future__ import annotations

import math

import control as ct
import numpy as np
import pytest

from prlpid_fmi.robustness.margins import pid_frequency_response
from prlpid_fmi.robustness.plant_response import MeasuredPlant

TS = 0.1


def _plant_and_pid(Kp, Ti, Td, Tf):
    z = ct.tf([1, 0], [1], TS)
    a = math.exp(-TS)
    P = (1 - a) / (z - a)  # ZOH of 1 / (s + 1)
    F = TS * z / ((Tf + TS) * z - Tf) if Tf > 0 else 1
    C = Kp * (F + (TS / Ti) * z / (z - 1) + Td * (z - 1) / (TS * z) * F)  # the PID law, derivative unfiltered
    return P, C


@pytest.mark.parametrize("Kp, Ti, Td, Tf", [(2.0, 1.0, 0.0, 0.0), (3.0, 0.8, 0.2, 0.05), (5.0, 1.5, 0.4, 0.3)])
def test_noise_and_increment_noise_gains_equal_the_impulse_response_norms(Kp, Ti, Td, Tf):
    P, C = _plant_and_pid(Kp, Ti, Td, Tf)
    CS = ct.minreal(C / (1 + C * P), verbose=False)
    # python-control's discrete impulse is a pulse of height 1/Ts: times Ts, the unit-sample response
    h = ct.impulse_response(CS, T=np.arange(4000) * TS).outputs.ravel() * TS
    std_u = math.sqrt(np.sum(h ** 2))
    std_du = math.sqrt(np.sum(np.diff(np.concatenate([[0.0], h])) ** 2))

    w = np.geomspace(1e-4, math.pi / TS, 400)
    plant = MeasuredPlant(w, np.asarray(P(np.exp(1j * w * TS))).ravel(), TS, (0.0,), (0.0,))
    controller = lambda omega: pid_frequency_response(Kp, Ti, Td, TS, omega, None, Tf, 1)  # noqa: E731
    assert plant.noise_gain(controller) == pytest.approx(std_u, rel=0.01)
    assert plant.noise_gain(controller, increments=True) == pytest.approx(std_du, rel=0.01)
    # the vectorised scan gives the same for every K (Kp scales C as a whole)
    shape = lambda omega: pid_frequency_response(1.0, Ti, Td, TS, omega, None, Tf, 1)  # noqa: E731
    noise, increments = plant.noise_scan(np.array([Kp]), shape)
    assert noise[0] == pytest.approx(plant.noise_gain(controller), rel=1e-9)
    assert increments[0] == pytest.approx(plant.noise_gain(controller, increments=True), rel=1e-9)
    if Td > 0 and Tf < 0.1:  # a derivative on barely filtered noise: the increments dominate
        assert std_du > std_u



# -- the design drops the increment limit only where no Kp can meet it (tuning.load_design) ----------------------
def _independent_feasibility(sigma: float, kps: np.ndarray, Ti: float, span: float, max_ms: float,
                             max_noise: float, max_increment: float, tfs=(0.0,)) -> tuple[bool, bool]:
    """(some Kp meets Ms, std(u) and std(du) limits, some Kp meets Ms and std(u)) for the PI (Kp, Ti) on the ZOH
    of 1 / (s + 1): Ms from python-control's frequency response on a dense unit-circle grid, the noise gains from
    its impulse response."""
    with_increment = without = False
    theta = np.linspace(1e-4, math.pi, 4000)
    for Kp, Tf in ((k, f) for f in tfs for k in kps):
        P, C = _plant_and_pid(Kp, Ti, 0.0, Tf)
        L = C * P
        ms = float(np.max(np.abs(1.0 / (1.0 + np.asarray(L(np.exp(1j * theta))).ravel()))))
        CS = ct.minreal(C / (1 + C * P), verbose=False)
        h = ct.impulse_response(CS, T=np.arange(3000) * TS).outputs.ravel() * TS
        std_u = math.sqrt(np.sum(h ** 2))
        std_du = math.sqrt(np.sum(np.diff(np.concatenate([[0.0], h])) ** 2))
        ok = ms <= max_ms and sigma * std_u / span <= max_noise
        without |= ok
        with_increment |= ok and sigma * std_du / span <= max_increment
    return with_increment, without


@pytest.mark.parametrize("sigma", [0.1, 1.0])
def test_the_increment_limit_is_dropped_exactly_where_no_kp_meets_it(sigma):
    import dataclasses

    from prlpid_fmi.scenario.presets import preset
    from prlpid_fmi.tuning.load_design import LoadDesign

    config = dataclasses.replace(preset("first_order"), measurement_noise_std=sigma, measurement_filter=0.0)
    design = LoadDesign(config, 0.1, 2.0, 0.02, 4.0, 0.005)
    w = np.geomspace(1e-3, math.pi / TS, 400)
    P, _ = _plant_and_pid(1.0, 1.0, 0.0, 0.0)
    plant = MeasuredPlant(w, np.asarray(P(np.exp(1j * w * TS))).ravel(), TS, (0.0,), (0.0,))
    design.plants = [[plant]]  # the stable 1/(s + 1) measured at one point, instead of the FMU's experiment
    gains = ([0.5], [1.0], [0.0], None)
    design.reference = [[plant.winding(design.controller(gains, [0.0], 0))]]
    design.relax_increment_limit(gains)
    r = design.search_config.loops[0].Kp
    span = 20.0  # first_order: u_limits [-10, 10]
    with_increment, without = _independent_feasibility(sigma, np.geomspace(r.low, r.high, 60), 1.0, span, 2.0,
                                                       0.02, 0.005)
    assert design.increment_relaxed == (not with_increment and without)
    assert design.increment_relaxed == (sigma == 1.0)  # the premise: one case on each side
    interval = design.kp_interval(0, 1.0, 0.0, 0.0)
    assert interval is not None  # with the limit dropped (sigma 1) or met (sigma 0.1) a Kp range remains
    if not design.increment_relaxed:
        _, _, kp_high = interval  # the increment limit still bounds Kp: the top of the range meets it
        P, C = _plant_and_pid(kp_high, 1.0, 0.0, 0.0)
        h = ct.impulse_response(ct.minreal(C / (1 + C * P), verbose=False), T=np.arange(3000) * TS).outputs.ravel() * TS
        assert sigma * math.sqrt(np.sum(np.diff(np.concatenate([[0.0], h])) ** 2)) / span <= 0.005 * 1.02


def test_a_searched_measurement_filter_that_meets_the_increment_limit_keeps_it():
    """With the filter searched (controller.measurement_filter "tuned"), the limit is dropped only where no Tf the
    search may choose admits a Kp: with sigma = 1 no unfiltered PI on 1/(s + 1) meets it (the case above), but a
    filtered one does, by python-control's responses of the PI with a first-order filter on P, so it stays."""
    import dataclasses

    from prlpid_fmi.scenario.presets import preset
    from prlpid_fmi.tuning.load_design import FILTER_PROBES, TF_RANGE, LoadDesign

    sigma, span = 1.0, 20.0
    config = dataclasses.replace(preset("first_order"), measurement_noise_std=sigma, measurement_filter="tuned")
    design = LoadDesign(config, 0.1, 2.0, 0.02, 4.0, 0.005)
    assert design.tune_filter
    w = np.geomspace(1e-3, math.pi / TS, 400)
    P, _ = _plant_and_pid(1.0, 1.0, 0.0, 0.0)
    plant = MeasuredPlant(w, np.asarray(P(np.exp(1j * w * TS))).ravel(), TS, (0.0,), (0.0,))
    design.plants = [[plant]]
    gains = ([0.5], [1.0], [0.0], None)
    design.reference = [[plant.winding(design.controller(gains, [0.0], 0))]]
    design.relax_increment_limit(gains)
    r = design.search_config.loops[0].Kp
    tfs = [0.0] + list(np.geomspace(TF_RANGE[0] * TS, TF_RANGE[1] * TS, FILTER_PROBES))
    unfiltered, _ = _independent_feasibility(sigma, np.geomspace(r.low, r.high, 60), 1.0, span, 2.0, 0.02, 0.005)
    filtered, _ = _independent_feasibility(sigma, np.geomspace(r.low, r.high, 60), 1.0, span, 2.0, 0.02, 0.005,
                                           tfs=tfs)
    assert not unfiltered and filtered  # the premise: only a filter meets it
    assert not design.increment_relaxed and math.isfinite(design.max_increment)


@pytest.mark.parametrize("held", ["max_sensitivity", "max_noise_gain"])
def test_the_limits_that_hold_a_design_are_those_within_1_percent(held):
    """LoadDesign.active_limits (fixed_pid.json design.active_limits, the report's "Limits that hold this design")
    names the limit whose estimate lies within 1 % of it: Ms and std(u) of a PI on 1/(s + 1) from python-control's
    frequency and impulse responses, each limit set 0.5 % above its value (held) or 5 % above (free)."""
    import dataclasses

    from prlpid_fmi.scenario.presets import preset
    from prlpid_fmi.tuning.load_design import LoadDesign

    sigma, span, (Kp, Ti) = 0.1, 20.0, (4.0, 0.5)
    P, C = _plant_and_pid(Kp, Ti, 0.0, 0.0)
    theta = np.linspace(1e-4, math.pi, 20000)
    ms = float(np.max(np.abs(1.0 / (1.0 + np.asarray((C * P)(np.exp(1j * theta))).ravel()))))
    h = ct.impulse_response(ct.minreal(C / (1 + C * P), verbose=False), T=np.arange(3000) * TS).outputs.ravel() * TS
    share = sigma * math.sqrt(np.sum(h ** 2)) / span
    near = {name: (1.005 if name == held else 1.05) for name in ("max_sensitivity", "max_noise_gain")}
    config = dataclasses.replace(preset("first_order"), measurement_noise_std=sigma)
    design = LoadDesign(config, 0.1, ms * near["max_sensitivity"], share * near["max_noise_gain"], 4.0, math.inf)
    w = np.geomspace(1e-3, math.pi / TS, 400)
    design.plants = [[MeasuredPlant(w, np.asarray(P(np.exp(1j * w * TS))).ravel(), TS, (0.0,), (0.0,))]]
    design.points = [[0.5]]
    (active,) = design.active_limits(([Kp], [Ti], [0.0], None), [0.0])
    assert active["limit"] == held and active["point"] == [0.5] and active["loop"] == 0
    assert active["value"] == pytest.approx(ms if held == "max_sensitivity" else share, rel=0.01)
    assert active["bound"] == pytest.approx(active["value"] * 1.005, rel=0.01)
