"""Margin experiments measured ahead on two processes (tuning.margin_experiments) are the experiments measured here,
bit for bit, and margins_of then decides what it decides without them (its plant-response references included)."""
import numpy as np
import pytest

from prlpid_fmi.robustness.margins import margins_of, measure_margins, measured_margins, predicted_ms
from prlpid_fmi.scenario.load import load_scenario
from prlpid_fmi.scenario.presets import scenario_path
from prlpid_fmi.tuning.margin_experiments import measure_ahead

# 1/(s - 1) at Ts 0.05 s: three PIs that hold it (Ms between 1.3 and 2.5) and one that cannot (Kp below 1: unstable)
GAINS = [([3.0], [1.0], [0.0], None), ([8.0], [0.3], [0.0], None), ([2.0], [2.0], [0.05], None),
         ([0.5], [1.0], [0.0], None)]


@pytest.fixture
def config(run_context):
    return load_scenario(scenario_path("first_order")).tuning


def _same(a, b) -> bool:
    return (a.Ms == b.Ms or (np.isnan(a.Ms) and np.isnan(b.Ms))) and a.note == b.note and \
        np.array_equal(a.frequencies_rad_s, b.frequencies_rad_s) and \
        np.array_equal(a.plant_response, b.plant_response, equal_nan=True) and a.reliable == b.reliable


def test_measured_ahead_on_two_processes_equals_measured_here(config, run_context, monkeypatch):
    from prlpid_fmi.tuning import margin_experiments

    sizes = []

    class Recorded(margin_experiments.SearchPool):  # the pool really has a worker process beside this one
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            sizes.append(self.size)
    monkeypatch.setattr(margin_experiments, "SearchPool", Recorded)
    points = [[0.0], [0.5]]
    requests = [(g, p) for g in GAINS for p in points]
    here = [measure_margins(config, g, p) for g, p in requests]
    assert sorted({round(m.Ms, 1) for m in here})[0] < 2.0 and any(np.isinf(m.Ms) for m in here)
    # a duplicate is measured once; nothing is a reference before margins_of returns it
    assert measure_ahead(config, requests + requests[:2], workers=2) == len(requests)
    assert sizes == [2] and run_context.references == {}
    for (g, p), m in zip(requests, here):
        assert _same(measured_margins(config, g, p), m)
    assert measure_ahead(config, requests, workers=2) == 0 and sizes == [2]  # kept: nothing left, no pool


def test_one_process_measures_nothing_ahead(config):
    assert measure_ahead(config, [(g, [0.0]) for g in GAINS], workers=1) == 0
    assert all(measured_margins(config, g, [0.0]) is None for g in GAINS)


def test_references_are_the_first_returned_as_without_measuring_ahead(config, run_context):
    """predicted_ms predicts from the first verified measurement margins_of returned at a point: measuring ahead
    in another order (here all four at once) leaves the same reference as asking one by one."""
    point = [0.0]
    for g in GAINS[1:]:  # one by one: the second PI's measurement becomes the reference
        margins_of(config, g, point)
    one_by_one = predicted_ms(config, GAINS[0], point)
    run_context.measured.clear()
    run_context.references.clear()
    assert measure_ahead(config, [(g, point) for g in reversed(GAINS)], workers=2) == len(GAINS)
    assert predicted_ms(config, GAINS[0], point) is None  # no reference yet
    for g in GAINS[1:]:
        margins_of(config, g, point)
    assert predicted_ms(config, GAINS[0], point) == one_by_one
    assert abs(one_by_one - margins_of(config, GAINS[0], point).Ms) <= 1e-3 * one_by_one  # a linear plant
