"""The fixed PID's search without the load limit (tuning.design_rule.follow_setpoints): where nothing within the load tolerance meets the
overshoot limit, the load IAE is minimised within the Ms, noise and overshoot limits without a load limit, and
kept where it meets them all. A fixed PID must follow the setpoint episodes it is chosen on: where the load-optimal
gains diverge on all of them whatever b, the search's best is kept where it follows them; where it does not, the
stabilising PID with its best b; where that diverges too, nothing is replaced.

Ms is checked against python-control's frequency response of the exactly sampled plant 1/(s - 1) (the bundled
first_order), not the tool's estimate; the search's reported setpoint response against a fresh simulation of the
same gains.
"""
from __future__ import annotations

import math

import control
import numpy as np
import pytest

from prlpid_fmi.config import DeployConfig
from prlpid_fmi.loop.gains import gains_from_values
from prlpid_fmi.progress import QUIET
from prlpid_fmi.scenario.presets import preset
from prlpid_fmi.tuning import design_rule
from prlpid_fmi.tuning.design_result import Trade
from prlpid_fmi.tuning.design_rule import follow_setpoints, follows_setpoints
from prlpid_fmi.tuning.fixed_pid import FixedPid
from prlpid_fmi.tuning.load_design import LoadDesign, SetpointDesign, setpoint_response, setpoint_weight

TS = 0.1  # first_order's sample time [s]
SEEDS = [0, 1, 2]
STABILISING = ([6.0], [1.0], [0.0], None)


def sensitivity_peak(Kp: float, Ti: float, Td: float) -> float:
    """max |1/(1 + C P)| to Nyquist; P: python-control's ZOH sampling of 1/(s - 1); C: Kp (1 + Ts/Ti z/(z - 1) +
    Td/Ts (z - 1)/z), the law's feedback part without filters (first_order has none)."""
    w = np.geomspace(1e-3, math.pi / TS, 4000)
    P = np.squeeze(control.frequency_response(control.c2d(control.tf([1.0], [1.0, -1.0]), TS, "zoh"), w).complex)
    z = np.exp(1j * w * TS)
    C = Kp * (1 + TS / Ti * z / (z - 1) + Td / TS * (z - 1) / z)
    return float(np.max(np.abs(1 / (1 + C * P))))


def test_follows_setpoints_reads_the_b_table_and_the_trade():
    inf = math.inf
    diverged = [{"b": 0.0, "ISE": inf, "Overshoot": inf}, {"b": 1.0, "ISE": inf, "Overshoot": inf}]
    assert not follows_setpoints(diverged, None)
    assert not follows_setpoints(diverged, Trade(feasible=False, ISE=inf))
    assert follows_setpoints(diverged, Trade(feasible=True, ISE=3.0))
    assert follows_setpoints(diverged[:1] + [{"b": 1.0, "ISE": 2.0, "Overshoot": 40.0}], None)
    assert not follows_setpoints([], None)  # b not tuned and nothing traded: nothing says the gains follow


@pytest.fixture(scope="module")
def design():
    config = preset("first_order")
    found = LoadDesign(config, 0.1, 2.0, 0.02, 4.0)
    found.prepare(STABILISING)
    yield config, found
    found.close()


def _first() -> FixedPid:
    return FixedPid(np.zeros(3), gains_from_values(*STABILISING), 0.0, 0, ([1.0], [0.0], [0.0]))


def test_the_search_without_a_load_limit_follows_the_episodes_within_the_limits(design):
    config, load_design = design
    best_load = 0.0252  # the Ms <= 2 load optimum of 1/(s - 1) (tests/test_load_design.py)
    found, keep = follow_setpoints(config, load_design, _first, best_load, DeployConfig(), SEEDS, 0, 4, 5, QUIET)
    assert found.source == "search" and keep is not None
    vector, gains, (b, c, tf) = keep
    Kp, Ti, Td, _ = gains
    assert sensitivity_peak(Kp[0], Ti[0], Td[0]) <= 2.0 * 1.01  # the tool's Ms limit, by python-control
    assert 0.0 <= b[0] <= 1.0 and c == list(load_design.c) and tf == [0.0]
    assert found.feasible and found.Overshoot <= 100.0 * DeployConfig().max_overshoot
    # what it reports is what these gains and this b do on the noise-free episodes, simulated afresh
    trade = SetpointDesign(load_design, best_load, math.inf, DeployConfig().max_overshoot, SEEDS)
    try:
        trade.core.set_structure(b, c, tf)
        ise, overshoot = setpoint_response(trade.core, gains, SEEDS)
    finally:
        trade.close()
    assert (ise, overshoot) == pytest.approx((found.ISE, found.Overshoot), rel=1e-12)
    assert found.load_cost == pytest.approx(load_design.load_cost(gains, tf), rel=1e-12)
    # the least load IAE within the limits: well below what the least setpoint ISE's search finds with the same budget
    ise_search = SetpointDesign(load_design, best_load, math.inf, DeployConfig().max_overshoot, SEEDS)
    try:
        other = ise_search.search(None, 0, 4, 5)
        assert np.max(ise_search.constraint_values(other.x)) <= 0
        assert found.load_cost < 0.9 * ise_search.evaluate(other.x)[0]
    finally:
        ise_search.close()


def test_where_the_search_diverges_the_stabilising_pid_is_kept_and_where_it_diverges_too_nothing(design, monkeypatch):
    config, load_design = design
    monkeypatch.setattr(SetpointDesign, "evaluate", lambda self, vector: (1.0, math.inf, math.inf))
    found, keep = follow_setpoints(config, load_design, _first, 0.0252, DeployConfig(), SEEDS, 0, 1, 3, QUIET)
    weight, rows = setpoint_weight(config, STABILISING, ([1.0], [0.0], [0.0]), SEEDS, DeployConfig().max_overshoot)
    assert found.source == "stabilising PID"
    _, gains, (b, c, tf) = keep
    assert gains == STABILISING and b == [weight] and c == [0.0] and tf == [0.0]
    assert found.ISE == next(r["ISE"] for r in rows if r["b"] == weight) and math.isfinite(found.ISE)
    # where the gains of steps 2-4 follow the episodes (only the overshoot limit unmet), nothing replaces them
    found, keep = follow_setpoints(config, load_design, _first, 0.0252, DeployConfig(), SEEDS, 0, 1, 3, QUIET,
                                   diverged=False)
    assert found.source is None and keep is None and not found.load_optimal_diverged

    inf = math.inf
    monkeypatch.setattr(design_rule, "setpoint_weight", lambda *a: (0.0, [{"b": 0.0, "ISE": inf, "Overshoot": inf}]))
    found, keep = follow_setpoints(config, load_design, _first, 0.0252, DeployConfig(), SEEDS, 0, 1, 3, QUIET)
    assert found.source is None and keep is None


def test_on_the_local_models_the_search_is_verified_on_the_fmu_and_rejects_loads_no_worse(design):
    """With identified local models the search runs on them (unit setpoint steps, load cost on the models), its
    choice kept where the FMU's episodes meet the overshoot limit with b chosen again: what it reports is the FMU's
    (a fresh simulation), Ms within the limit by python-control, and its load IAE no worse than the search on the
    FMU's episodes with the same budget (the models afford more candidates)."""
    config, fmu_design = design
    best_load = 0.0252
    identified = LoadDesign(config, 0.1, 2.0, 0.02, 4.0, design_model="identified")
    try:
        identified.prepare(STABILISING)
        assert identified.models is not None, identified.model_note
        found, keep = follow_setpoints(config, identified, _first, best_load, DeployConfig(), SEEDS, 0, 4, 5, QUIET)
        record = found.on_models
        assert found.source == "search" and record.kept and keep is not None
        vector, gains, (b, c, tf) = keep
        Kp, Ti, Td, _ = gains
        assert sensitivity_peak(Kp[0], Ti[0], Td[0]) <= 2.0 * 1.01
        assert found.Overshoot <= 100.0 * DeployConfig().max_overshoot and b == [record.b]
        trade = SetpointDesign(identified, best_load, math.inf, DeployConfig().max_overshoot, SEEDS)
        try:
            trade.core.set_structure(b, c, tf)
            assert setpoint_response(trade.core, gains, SEEDS) == pytest.approx((found.ISE, found.Overshoot),
                                                                                 rel=1e-12)
        finally:
            trade.close()
        assert found.load_cost == pytest.approx(fmu_design.load_cost(gains, tf), rel=1e-12)
        assert record.model_load_cost == pytest.approx(found.load_cost, rel=0.01)  # the models predict it
        on_fmu, _ = follow_setpoints(config, fmu_design, _first, best_load, DeployConfig(), SEEDS, 0, 4, 5, QUIET)
        assert on_fmu.on_models is None and on_fmu.feasible
        assert found.load_cost <= 1.02 * on_fmu.load_cost
    finally:
        identified.close()


def test_where_the_least_load_iae_leaves_range_steps_unsettled_the_least_setpoint_ise_is_kept(design, monkeypatch):
    """Requirement 1 ranks first: where the least load IAE within the limits does not settle the range episode (here
    every PID the load objective returns is said not to), the least setpoint ISE within the same limits is kept if it
    settles it; where neither settles, the least load IAE stays."""
    from prlpid_fmi.tuning.design_result import Following

    config, load_design = design
    by_load, _ = follow_setpoints(config, load_design, _first, 0.0252, DeployConfig(), SEEDS, 0, 4, 5, QUIET)
    unsettled = by_load.load_cost

    def following(config, gains, structure):
        settles = load_design.load_cost(gains, list(structure[2])) != unsettled
        return Following(12, 0 if settles else 3, 0, False, 0.0, 1.0)

    monkeypatch.setattr(design_rule, "following", following)
    found, keep = follow_setpoints(config, load_design, _first, 0.0252, DeployConfig(), SEEDS, 0, 4, 5, QUIET)
    assert found.objective == "setpoint" and keep is not None and found.load_cost != unsettled
    assert found.feasible and found.Overshoot <= 100.0 * DeployConfig().max_overshoot
    monkeypatch.setattr(design_rule, "following", lambda *a: Following(12, 3, 0, False, 0.0, 1.0))
    found, keep = follow_setpoints(config, load_design, _first, 0.0252, DeployConfig(), SEEDS, 0, 4, 5, QUIET)
    assert found.objective == "load" and found.load_cost == unsettled and keep is not None
