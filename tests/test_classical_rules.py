"""tuning.classical_rules against hand-computed truths: the tangent-method FOPDT of 1/(s + 1)^2 and of a delayed lag,
the ramp asymptote of 1/(s (s + 1)), AMIGO's and SIMC's published formulas, and the bound's interpolation."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import cont2discrete

from prlpid_fmi.robustness.local_model import LocalModel
from prlpid_fmi.tuning.classical_rules import fopdt, integrating, load_bound, rules

TS = 0.02


def model(num, den, Ts=TS, delay_samples=0) -> LocalModel:
    """The ZOH discretisation of num/den (descending powers of s) as a LocalModel in powers of q = z^-1, with
    delay_samples more samples of dead time."""
    b, a, _ = cont2discrete((num, den), Ts, method="zoh")
    b, a = np.ravel(b), np.ravel(a)
    b = np.concatenate([np.zeros(len(a) - len(b)), b])  # same length as a: b[0] = 0 for a strictly proper plant
    return LocalModel(np.concatenate([np.zeros(delay_samples), b / a[0]]), a / a[0], Ts, (0.0,), 0.0)


def test_tangent_method_on_a_double_lag_by_hand():
    """1/(s + 1)^2: y = 1 - (1 + t) e^-t is steepest at t = 1 (slope 1/e, y = 1 - 2/e), so the tangent crosses zero at
    L = 1 - (1 - 2/e) e = 3 - e; y(t63) = 1 - 1/e at (1 + t) e^-t = 1/e, t63 = 2.1462; T = t63 - L; then L + Ts/2 for
    the hold."""
    K, T, L = fopdt(model([1.0], [1.0, 2.0, 1.0]))
    L_hand = 3.0 - math.e
    t63 = 2.146193220620583  # the root of (1 + t) e^-t = e^-1 (by hand: Newton from 2)
    assert K == pytest.approx(1.0, abs=1e-3)
    assert L == pytest.approx(L_hand + TS / 2, abs=2e-3)  # the step between samples on a Ts/20 grid
    assert T == pytest.approx(t63 - L_hand, abs=2e-3)


def test_a_delayed_lag_is_read_back_and_the_rules_are_the_published_formulas():
    """2 e^(-0.5 s) / (3 s + 1), the delay a whole number of samples: the tangent is steepest at t = 0.5, so L = 0.5
    (+ Ts/2), T = 3, K = 2; AMIGO (Astrom & Hagglund 2004) and SIMC (Skogestad 2003, tc = L) from those by hand."""
    K, T, L = fopdt(model([2.0], [3.0, 1.0], delay_samples=25))
    assert (K, T, L) == pytest.approx((2.0, 3.0, 0.5 + TS / 2), abs=2e-3)
    amigo = rules(model([2.0], [3.0, 1.0], delay_samples=25))["AMIGO"](1.0)
    assert amigo == pytest.approx(((0.2 + 0.45 * T / L) / K, (0.4 * L + 0.8 * T) / (L + 0.1 * T) * L,
                                   0.5 * L * T / (0.3 * L + T)), rel=1e-9)
    simc = rules(model([2.0], [3.0, 1.0], delay_samples=25))["SIMC"](1.0)
    assert simc == pytest.approx((T / (K * 2 * L), min(T, 8 * L), 0.0), rel=1e-9)


def test_an_integrator_with_a_lag_is_read_by_its_ramp_asymptote():
    """-0.5 / (s (s + 1)): the ramp's asymptote is -0.5 (t - 1): kv = -0.5, L = 1 (+ Ts/2); AMIGO's integrating PID
    0.45 / (kv L), 8 L, 0.5 L with the sign of kv."""
    m = model([-0.5], [1.0, 1.0, 0.0])
    assert fopdt(m) is None
    kv, L = integrating(m)
    assert (kv, L) == pytest.approx((-0.5, 1.0 + TS / 2), abs=2e-3)
    Kp, Ti, Td = rules(m)["AMIGO"](1.0)
    assert (Kp, Ti, Td) == pytest.approx((0.45 / (kv * L), 8 * L, 0.5 * L), rel=1e-9)
    assert Kp < 0


@pytest.mark.parametrize("den", [[1.0, -1.0], [1.0, 0.4, 4.0], [1.0, 0.0, 0.0]])
def test_no_rule_for_unstable_oscillatory_or_double_integrating_models(den):
    assert rules(model([1.0], den)) == {}


def test_the_bound_is_the_least_load_at_or_below_each_ms_interpolated():
    """A made-up sweep of AMIGO's knob k where Ms = 1.2 + 0.5 ln(k + 1) rises and the load 10 / k falls, SIMC's
    points all dominated (load 100 at Ms interleaved with AMIGO's): the bound at Ms m is AMIGO's least load over
    Ms <= m, linear between its sweep's points, inf below its least Ms; SIMC's points change nothing."""
    m = model([2.0], [3.0, 1.0], delay_samples=25)
    K, T, L = fopdt(m)
    amigo_kp = (0.2 + 0.45 * T / L) / K

    def assess(pid):
        if pid[2] == 0.0:  # SIMC's PI
            return 1.2 + 0.5 * math.log(pid[0] / amigo_kp + 1.0) + 1e-3, 100.0
        k = pid[0] / amigo_kp
        return 1.2 + 0.5 * math.log(k + 1.0), 10.0 / k
    bound = load_bound(m, assess)
    from prlpid_fmi.tuning.classical_rules import KNOBS
    ms = 1.2 + 0.5 * np.log(KNOBS + 1.0)
    assert bound(1.0) == math.inf
    assert bound(ms[0]) == pytest.approx(10.0 / KNOBS[0])
    mid = 0.5 * (ms[10] + ms[11])
    assert bound(mid) == pytest.approx(0.5 * (10.0 / KNOBS[10] + 10.0 / KNOBS[11]))
    assert bound(10.0) == pytest.approx(10.0 / KNOBS[-1])
    assert load_bound(model([1.0], [1.0, -1.0]), assess) is None
    assert load_bound(m, lambda pid: None) is None  # every rule's gains refused


# -- the design rule's requirement 5 against AMIGO at equal Ms, computed here with python-control ---------------

def _pid_z(Kp, Ti, Td, Tf, Ts):
    """The tool's feedback law (control.pid) as a python-control transfer function: C = Kp (F (1 + Td (z - 1) / (Ts z))
    + Ts z / (Ti (z - 1))), F the backward-Euler measurement filter Ts z / ((Tf + Ts) z - Tf) (1 without)."""
    import control

    z = control.tf([1.0, 0.0], [1.0], Ts)
    F = Ts * z / ((Tf + Ts) * z - Tf) if Tf > 0 else 1
    return Kp * (F * (1 + Td * (z - 1) / (Ts * z)) + Ts * z / (Ti * (z - 1)))


def _loop_figures(P, C, Ts):
    """(Ms on 4000 frequencies, IAE of a unit load step at the plant input over 300 s) of the loop P, C."""
    import control

    w = np.geomspace(1e-4, math.pi / Ts, 4000)
    L = np.asarray(control.frequency_response(P * C, w).complex).ravel()
    t = np.arange(int(300.0 / Ts)) * Ts
    _, y = control.forced_response(control.feedback(P, C), t, np.ones_like(t))
    return float(np.max(np.abs(1.0 / (1.0 + L)))), float(np.sum(np.abs(y)) * Ts)


def test_the_setpoint_search_never_rejects_loads_worse_than_amigo_at_the_same_ms(tmp_path):
    """e^(-s) / (s + 1)^2 (the zoo's sopdt_T1, LinearBatch FMU): the fixed PID the rule keeps after requirement 5 (the
    least setpoint ISE within the load tolerance, searched on the local models) has a load IAE no worse than AMIGO's
    PID, its Kp scaled to the same Ms, both computed here on the exact ZOH plant with python-control; AMIGO from the
    analytic tangent-method FOPDT of the plant: L = 1 + (3 - e) + Ts/2, T = t63 - (3 - e), K = 1."""
    import dataclasses

    import control
    import yaml

    from prlpid_fmi.fmu import build_fmu
    from prlpid_fmi.scenario.load import load_scenario
    from prlpid_fmi.tuning import design_rule

    zoo = Path(__file__).resolve().parents[1] / "benchmarks" / "zoo"
    fmu = build_fmu("LinearBatch", out_dir=tmp_path, source_dir=zoo / "plants" / "LinearBatch")
    scenario = yaml.safe_load((zoo / "scenarios" / "sopdt_T1.yaml").read_text())
    scenario["plant"]["fmu"] = str(fmu)
    (tmp_path / "sopdt.yaml").write_text(yaml.safe_dump(scenario))
    config = load_scenario(tmp_path / "sopdt.yaml").tuning
    result = design_rule.tune_fixed_pid(config, baseline=dataclasses.replace(design_rule.BaselineConfig(), workers=1),
                                        seed=0, episodes=1, maxiter=6, popsize=6, max_sensitivity=2.0)
    refined = result.report.details.setpoint_refined
    assert refined.classical_bound and refined.kept  # the bound was in force and the search moved the gains

    Ts = config.sample_time_s
    P = control.sample_system(control.tf([1.0], [1.0, 2.0, 1.0]), Ts, method="zoh") * \
        control.tf([1.0], [1.0] + [0.0] * round(1.0 / Ts), Ts)
    g, tf = result.gains, result.structure[2][0]
    ms, load = _loop_figures(P, _pid_z(g.Kp[0], g.Ti[0], g.Td[0], tf, Ts), Ts)
    tangent = 3.0 - math.e
    L, T = 1.0 + tangent + Ts / 2, 2.146193220620583 - tangent
    amigo = ((0.2 + 0.45 * T / L), (0.4 * L + 0.8 * T) / (L + 0.1 * T) * L, 0.5 * L * T / (0.3 * L + T))
    lo, hi = 0.2, 3.0  # AMIGO's Kp factor: Ms rises with it; bisection to the tool's Ms
    for _ in range(30):
        k = 0.5 * (lo + hi)
        if _loop_figures(P, _pid_z(k * amigo[0], amigo[1], amigo[2], 0.0, Ts), Ts)[0] < ms:
            lo = k
        else:
            hi = k
    amigo_ms, amigo_load = _loop_figures(P, _pid_z(lo * amigo[0], amigo[1], amigo[2], 0.0, Ts), Ts)
    assert amigo_ms == pytest.approx(ms, abs=2e-3)
    assert load <= 1.01 * amigo_load
