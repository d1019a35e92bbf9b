"""The load experiment's approach to its operating point (tuning.load_experiment.approach), hand-computed."""
from __future__ import annotations

import pytest


def test_the_load_experiment_approaches_its_operating_point_by_a_ramp():
    """tuning.load_experiment.approach: from the start state to the point over the first half of the hold in
    APPROACH_STEPS equal steps (hand-computed), a step when there is no start or the hold is too short."""
    from prlpid_fmi.tuning.load_experiment import APPROACH_STEPS, approach

    schedule = approach([0.0, 5.0], [10.0, 5.0], 200)
    assert len(schedule) == APPROACH_STEPS == 25
    assert schedule[0] == (0, (0.4, 5.0)) and schedule[-1] == (96, (10.0, 5.0))
    steps = [k for k, _ in schedule]
    assert steps == sorted(set(steps)) and steps[-1] < 100
    assert all(r == pytest.approx((0.4 * (j + 1), 5.0)) for j, (_, r) in enumerate(schedule))
    assert approach(None, [10.0], 200) == ((0, (10.0,)),)
    assert approach([0.0], [10.0], 40) == ((0, (10.0,)),)
