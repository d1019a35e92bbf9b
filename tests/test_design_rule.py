"""The fixed PID's design rule (tuning.design_rule): requirements by priority, noise limits relaxed before they may
cost following or settling.

Independent truths: the priority order on hand-built candidates whose requirements conflict; the relaxation ladder
written out by hand; and, on the bundled 1/(s - 1) FMU, whether a PI settles the range episode's steps, checked by
an exact ZOH recursion of the sampled loop written here (scipy's cont2discrete), not by the tool's metrics.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.signal import cont2discrete

from prlpid_fmi.config import BaselineConfig, DeployConfig
from prlpid_fmi.loop.gains import gains_from_values
from prlpid_fmi.progress import QUIET
from prlpid_fmi.scenario.presets import preset
from prlpid_fmi.tuning import design_rule
from prlpid_fmi.tuning.design_result import DesignDetails, Following, Relaxation
from prlpid_fmi.tuning.design_rule import (RANGE_HOLD, RANGE_ORDER, RELAX_FACTORS, Candidate, NoiseLimits, following,
                                           priority, relaxations)

TS = 0.1  # first_order: 1/(s - 1), Ts 0.1 s, setpoint range [-1, 1], setpoint_hold_steps 100
STRICT = ([1.05], [50.0], [0.0], None)  # what a strict noise limit leaves: barely stabilising, almost no integral
RELAXED = ([4.0], [1.0], [0.0], None)  # what the relaxed limit allows


def settles_by_recursion(Kp: float, Ti: float, hold: int, band: float = 0.02) -> bool:
    """Whether the PI u = Kp (r - y + I/Ti), I += (r - y) Ts on 1/(s - 1) sampled with a ZOH settles every step of
    -1 -> 0 -> 1 -> 0 -> -1 (RANGE_ORDER over the range's low, middle, high) into band x the step by the
    end of each hold, starting at rest at -1 (the integral preset to hold it)."""
    A, B, _, _, _ = cont2discrete((np.array([[1.0]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]])), TS,
                                  "zoh")
    a, b = float(A[0, 0]), float(B[0, 0])
    levels = [-1.0, 0.0, 1.0]
    x = -1.0
    integral = Ti / Kp  # at r = y = -1, u = 1 holds it (dx/dt = x + u = 0): Kp I / Ti = 1
    for previous, index in zip(RANGE_ORDER, RANGE_ORDER[1:]):
        r, step = levels[index], abs(levels[index] - levels[previous])
        errors = []
        for _ in range(hold):
            e = r - x
            integral += e * TS
            u = Kp * (e + integral / Ti)
            if abs(u) > 10.0 or not math.isfinite(x):  # the actuator's limit: the linear check does not apply
                return False
            errors.append(abs(e))
            x = a * x + b * u
        beyond = np.flatnonzero(np.array(errors) > band * step)
        if beyond.size and beyond[-1] == hold - 1:
            return False
    return True


def test_the_range_episode_on_the_fmu_agrees_with_an_independent_recursion():
    config = preset("first_order")
    hold = RANGE_HOLD * config.setpoint_hold_steps
    assert not settles_by_recursion(*STRICT[0], *STRICT[1], hold)  # the premise: one that does not settle ...
    assert settles_by_recursion(*RELAXED[0], *RELAXED[1], hold)  # ... and one that does
    structure = ([1.0], [0.0], [0.0])
    assert not following(config, STRICT, structure).settles
    found = following(config, RELAXED, structure)
    assert found.settles and found.steps == len(RANGE_ORDER) - 1 and not found.diverged


def _candidate(gains, relaxed=(), *, unsettled=0, diverged=False, ms_met=True, overshoot=1.0, load=1.0, ise=1.0,
               active=()):
    details = DesignDetails(load_cost=load, load_optimum=1.0, active_limits=[{"limit": a} for a in active],
                            noise={"std_u": 0.0, "std_du": 0.0})
    c = Candidate(np.zeros(3), gains, ([1.0], [0.0], [0.0]), details, NoiseLimits(0.02, 0.005, True), relaxed,
                  ms_met, overshoot, ise, load)
    c.following = Following(4, unsettled, 0, diverged, overshoot, ise)
    return c


def test_the_priority_order_on_conflicting_requirements():
    deploy, load_limit = DeployConfig(max_overshoot=0.05), 1.15
    key = lambda c: priority(c, deploy, load_limit)  # noqa: E731
    settles = _candidate(RELAXED, overshoot=30.0, load=3.0, ise=9.0, ms_met=False)
    # 1 before everything: a candidate leaving a step unsettled, or diverging, is never kept over one that settles
    assert min([_candidate(STRICT, unsettled=1, ise=0.1), settles], key=key) is settles
    assert min([_candidate(STRICT, diverged=True, ise=0.1), settles], key=key) is settles
    # fewer unsettled steps first among those that do not settle
    two, one = _candidate(STRICT, unsettled=2, ise=0.1), _candidate(STRICT, unsettled=1, ise=5.0)
    assert min([two, one], key=key) is one
    # 2 (Ms) before 3 (overshoot) before 4 (load) before 5 (ISE) before the noise relaxations
    ms = _candidate(RELAXED, overshoot=20.0, load=2.0, ise=5.0)
    assert min([settles, ms], key=key) is ms
    overshoot = _candidate(RELAXED, overshoot=4.0, load=2.0, ise=5.0)
    assert min([ms, overshoot], key=key) is overshoot
    load = _candidate(RELAXED, overshoot=4.9, load=1.1, ise=6.0)
    assert min([overshoot, load], key=key) is load
    ise = _candidate(RELAXED, overshoot=4.9, load=1.14, ise=2.0)
    assert min([load, ise], key=key) is ise
    relaxed = _candidate(RELAXED, (Relaxation("max_noise_increment", 0.005, 0.01),), overshoot=4.9, load=1.14,
                         ise=2.0)
    assert min([relaxed, ise], key=key) is ise


def test_the_relaxation_ladder_filters_first_then_raises_the_limits_that_held():
    deploy = DeployConfig(max_noise_gain=0.02, max_noise_increment=0.005)
    config = dataclasses.replace(preset("first_order"), measurement_noise_std=0.1, measurement_filter=0.0)
    ladder = relaxations(config, deploy, {"max_noise_increment"})
    assert ladder[0] == (NoiseLimits(0.02, 0.005, True), (Relaxation("measurement_filter", 0.0, 1.0),))
    assert [limits for limits, _ in ladder[1:]] == [NoiseLimits(0.02, 0.005 * f, True) for f in RELAX_FACTORS]
    assert [r[-1] for _, r in ladder[1:]] == [Relaxation("max_noise_increment", 0.005, 0.005 * f)
                                               for f in RELAX_FACTORS]
    tuned = dataclasses.replace(config, measurement_filter="tuned")  # the filter searched already: limits at once
    ladder = relaxations(tuned, deploy, set())  # none held: both are raised together
    assert [limits for limits, _ in ladder] == [NoiseLimits(0.02 * f, 0.005 * f, True) for f in RELAX_FACTORS]


class _Designer:
    """design_rule.Designer with the searches replaced: under the requested (strict) increment limit the gains a
    strict noise limit leaves, under any relaxed one the faster PI; every call recorded."""

    calls: list = []

    def __init__(self, config, seed, episodes, maxiter, popsize, progress, max_sensitivity, baseline, deploy):
        self.deploy, self.load_optimum, self.evaluations, self.measured = deploy, 1.0, 0, None

    def design_under(self, limits, relaxed=()):
        _Designer.calls.append(limits)
        strict = limits.increment <= self.deploy.max_noise_increment and not relaxed
        return _candidate(STRICT if strict else RELAXED, relaxed, active=("max_noise_increment",) if strict else ())


def test_a_design_that_does_not_settle_under_a_strict_noise_limit_is_relaxed_until_it_settles(monkeypatch):
    monkeypatch.setattr(design_rule, "Designer", _Designer)
    _Designer.calls = []
    config = dataclasses.replace(preset("first_order"), measurement_noise_std=0.05, measurement_filter="tuned")
    deploy = DeployConfig(max_noise_increment=0.005)
    result = design_rule.design_load_pid(config, 0, 1, 1, 2, QUIET, 2.0, BaselineConfig(), deploy)
    # the first relaxation (the increment limit, which held the strict design, x 2) settles: the ladder stops there
    assert _Designer.calls == [NoiseLimits(0.02, 0.005, True), NoiseLimits(0.02, 0.01, True)]
    assert result.gains.as_dict() == {k: np.asarray(v) for k, v in gains_from_values(*RELAXED).as_dict().items()}
    report = result.report
    assert report.relaxed == (Relaxation("max_noise_increment", 0.005, 0.01),)
    assert report.bound == "follows and settles the setpoint steps" and report.following.settles
    assert settles_by_recursion(RELAXED[0][0], RELAXED[1][0], RANGE_HOLD * config.setpoint_hold_steps)
    kept = [c["kept"] for c in report.as_json()["candidates"]]
    assert kept == [False, True]


def test_the_report_says_how_the_steps_settled_what_was_relaxed_and_what_bound_the_design():
    from prlpid_fmi.report.markdown import design_section

    fixed = {"gains": {"Kp": [4.0], "Ti": [1.0], "Td": [0.0]},
             "structure": {"setpoint_weight": [1.0], "derivative_weight": [0.0], "measurement_filter_s": [0.0]},
             "design": {"objective": "load", "load_step": 0.1, "load_cost": 1.0, "load_optimum": 1.0,
                        "following": {"steps": 4, "unsettled": 1, "slow": 2, "diverged": False, "overshoot": 3.0,
                                      "ise": 1.0},
                        "relaxed": [{"limit": "measurement_filter", "requested": 0.0, "used": 1.0},
                                    {"limit": "max_noise_increment", "requested": 0.005, "used": 0.01},
                                    {"limit": "max_noise_gain", "requested": 0.02, "used": math.inf}],
                        "bound": "follows and settles the setpoint steps"}}
    text = design_section(design_rule.DesignResult.from_json(fixed), ["y"])
    assert "it settles 3 of 4 (2 slowly, after training.setpoint_hold_steps), worst overshoot 3 %." in text
    assert ("a measurement filter was searched (controller.measurement_filter was not tuned); "
            "deploy.max_noise_increment 0.50% raised to 1.00%; deploy.max_noise_gain 2.00% raised to no limit.") in text
    assert "The requirement that bound this design: follows and settles the setpoint steps" in text
    older = design_section(design_rule.DesignResult.from_json(
        {**fixed, "design": {k: v for k, v in fixed["design"].items() if k not in ("following", "relaxed", "bound")}}),
        ["y"])
    assert "settles" not in older and "relaxed" not in older  # a fixed_pid.json written before the rule


class _Unsettled(_Designer):
    """No design settles, whatever the noise limits; the stabilising PID does."""

    def design_under(self, limits, relaxed=()):
        _Designer.calls.append(limits)
        return _candidate(STRICT, relaxed, active=("max_noise_gain",), ise=0.01)

    def stabilising(self, limits):
        return _candidate(RELAXED, ise=50.0, load=30.0, overshoot=20.0)


def test_where_no_relaxation_settles_the_stabilising_pid_that_settles_is_kept(monkeypatch):
    monkeypatch.setattr(design_rule, "Designer", _Unsettled)
    _Designer.calls = []
    config = dataclasses.replace(preset("first_order"), measurement_noise_std=0.05, measurement_filter="tuned")
    result = design_rule.design_load_pid(config, 0, 1, 1, 2, QUIET, 2.0, BaselineConfig(), DeployConfig())
    # every rung tried (the filter is searched already: the held limit x each factor), none settles ...
    assert _Designer.calls[1:] == [NoiseLimits(0.02 * f, DeployConfig().max_noise_increment, True)
                                   for f in RELAX_FACTORS]
    # ... so the stabilising PID, which settles (the FMU's range episode and the recursion agree), is kept over
    # designs of lower ISE, load and overshoot
    assert result.gains.as_dict()["Kp"] == [RELAXED[0][0]] and result.report.following.settles
    assert [c["kept"] for c in result.report.as_json()["candidates"]] == [False] * (1 + len(RELAX_FACTORS)) + [True]
    assert result.report.bound == "overshoot [%]"  # the first requirement it misses: 20 % against 5 %


def test_the_design_report_is_json():
    import json

    from prlpid_fmi.tuning.design_result import DesignReport
    from prlpid_fmi.tuning.design_rule import requirements

    c = _candidate(RELAXED, overshoot=np.float64(4.0))
    reqs = requirements(c, DeployConfig(), 2.0, 1.15)
    text = json.dumps(DesignReport("Ms", (), reqs, c.following, c.details).as_json())
    assert [r["rank"] for r in json.loads(text)["requirements"]] == [1, 2, 3, 4, 5, 6, 6]


def reversals_by_hand(u, span: float) -> float:
    """deploy.max_chatter's definition written out as a loop: the fraction of k = 3 .. n-1 at which the moves
    u_k - u_(k-1), u_(k-1) - u_(k-2), u_(k-2) - u_(k-3) alternate in sign, each above 1 % of the span, plus the
    one-sample pulses (two such moves of opposite sign) between moves under half the pulse's smaller move."""
    du = [u[k] - u[k - 1] for k in range(1, len(u))]
    big = [abs(d) > 0.01 * span for d in du]
    count = 0
    for k in range(3, len(u)):
        a, b, c = du[k - 3], du[k - 2], du[k - 1]
        if big[k - 3] and big[k - 2] and big[k - 1] and a * b < 0 and b * c < 0:
            count += 1
    for j in range(1, len(du) - 2):  # a pulse of moves j, j + 1 between moves j - 1 and j + 2
        if big[j] and big[j + 1] and du[j] * du[j + 1] < 0:
            small = 0.5 * min(abs(du[j]), abs(du[j + 1]))
            if abs(du[j - 1]) < small and abs(du[j + 2]) < small:
                count += 1
    return count / (len(u) - 3)


def command_by_recursion(Kp: float, Ti: float, setpoints) -> list[float]:
    """The PI's command on first_order over the setpoints r_k (n,): 1/(s - 1) sampled exactly (ZOH), x(0) = 0,
    |u| <= 10 with clamping; the PID is the frozen eq. 2 law (tests/eq2_pid_reference.py; b = c = 1, Tf = 0,
    u0 = 0)."""
    from eq2_pid_reference import PID as Eq2PID

    A, B, _, _, _ = cont2discrete((np.array([[1.0]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]])), TS,
                                  "zoh")
    a, b = float(A[0, 0]), float(B[0, 0])
    pid = Eq2PID(TS, 1, u_min=-10.0, u_max=10.0, anti_windup="clamping")
    x, out = 0.0, []
    for r in setpoints:
        u = float(pid.step(float(r), x, Kp, Ti, 0.0)[0])
        out.append(u)
        x = a * x + b * u
    return out


def test_a_pi_that_rings_after_setpoint_steps_is_detuned_until_it_does_not():
    """1/(s - 1) at Ts 0.1 s with Kp 19: the sampled loop's pole a - b Kp = -0.89 rings at the sample rate after
    every step. quiet_command must detune it by the first lambda = 1.15**k whose ring, by the independent recursion
    on the same setpoints (the full-range episodes: -1 and 1 alternating every 100 samples, from either end; the
    quiet training episodes: the setpoints the core drew for seeds 0 .. 7), is within the design's margin, and
    report the ring before it as the recursion computes it."""
    from prlpid_fmi.tuning.full_range import full_range_episodes, quiet
    from prlpid_fmi.tuning.load_experiment import open_core
    from prlpid_fmi.loop.evaluation import gains_rollout

    config = preset("first_order")
    span, Ti = 20.0, 20.0
    sequences = [[(-1.0, 1.0)[(first + k // 100) % 2] for k in range(200)] for first in (0, 1)]
    random = quiet(dataclasses.replace(config, forecast_horizon=0))
    core = open_core(random)
    try:
        sequences += [gains_rollout(lambda _: ([1.0], [1.0], [0.0], None), random, seed=s, core=core).setpoint[:200, 0]
                      for s in range(design_rule.CHATTER_EPISODES)]
    finally:
        core.close()
    assert len(full_range_episodes(config, 0)) == 2

    def worst(Kp):
        return max(reversals_by_hand(command_by_recursion(Kp, Ti, r), span) for r in sequences)

    target = design_rule.CHATTER_MARGIN * 0.05
    assert worst(19.0) > 2 * target  # the premise: it rings
    check, found = design_rule.quiet_command(config, ([19.0], [Ti], [0.0], None), ([1.0], [1.0], [0.0]), 0.05, 0)
    assert check.before == pytest.approx(worst(19.0), abs=1e-12)
    assert check.detuned_by > 1 and check.met and check.after <= target
    k = round(math.log(check.detuned_by) / math.log(design_rule.DETUNE_STEP))
    assert found[0][0] == pytest.approx(19.0 / check.detuned_by) and found[1][0] == Ti  # Ti x lambda, clipped at 20
    assert check.after == pytest.approx(worst(found[0][0]), abs=1e-12) and worst(found[0][0]) <= target
    assert worst(19.0 / design_rule.DETUNE_STEP ** (k - 1)) > target  # the k before did not meet it
    quiet_check, same = design_rule.quiet_command(config, ([4.0], [1.0], [0.0], None), ([1.0], [1.0], [0.0]), 0.05, 0)
    assert quiet_check.detuned_by == 1 and same == ([4.0], [1.0], [0.0], None) and quiet_check.before <= target
