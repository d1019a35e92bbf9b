"""The search's evaluations on several processes (tuning.search_pool): the same results as in one, in the order asked.

Checked against the plain list comprehension the pool stands for, with workers that crash, raise or never start,
and end to end: the load design's search and the whole fixed-PID search on the bundled 1/(s - 1) give the same
gains, bit for bit, on one process and on two.
"""
from __future__ import annotations

import dataclasses
import math
import os

import numpy as np
import pytest

from prlpid_fmi.config import BaselineConfig
from prlpid_fmi.fmu.watchdog import in_worker
from prlpid_fmi.scenario.presets import preset
from prlpid_fmi.tuning.design_rule import tune_fixed_pid
from prlpid_fmi.tuning.load_design import LoadDesign
from prlpid_fmi.tuning.search_pool import WORKERS_ENV, SearchPool, search_fmus, search_workers


class Evaluator:
    """f(v) = sum of k * v_k**2 (a fixed function: any process gives the same float), with misbehaviour on demand:
    `crash_at` ends a worker process (never this one) at the first vector whose first entry is that value, `raise_at`
    raises there in every process."""

    def __init__(self, crash_at: float = math.nan, raise_at: float = math.nan):
        self.crash_at, self.raise_at = crash_at, raise_at
        self.pid = os.getpid()

    def value(self, vector) -> float:
        v = np.asarray(vector, float)
        if v[0] == self.crash_at and in_worker():
            os._exit(3)
        if v[0] == self.raise_at:
            raise ValueError(f"refused {v[0]}")
        return float(np.sum(np.arange(1, v.size + 1) * v ** 2))

    def where(self, vector) -> int:
        return os.getpid()


def broken_factory():
    raise RuntimeError("no evaluator here")


VECTORS = [np.array([0.1 * i, -0.3 * i, 1.0 / (i + 1)]) for i in range(23)]
EXPECTED = [float(np.sum(np.arange(1, 4) * v ** 2)) for v in VECTORS]


def test_map_returns_the_list_comprehensions_values_in_order_and_uses_every_process():
    with SearchPool(Evaluator(), Evaluator, (), workers=3) as pool:
        assert pool.size == 3
        assert pool.map("value", VECTORS) == EXPECTED
        where = pool.map("where", VECTORS * 4)
    assert len(set(where)) == 3  # this process and both workers took vectors
    assert os.getpid() in where


def test_one_worker_starts_no_process():
    pool = SearchPool(Evaluator(), Evaluator, (), workers=1)
    assert pool.size == 1
    assert set(pool.map("where", VECTORS)) == {os.getpid()}
    pool.close()


def test_a_worker_that_crashes_hands_its_vectors_back():
    crash = float(VECTORS[5][0])
    with SearchPool(Evaluator(crash_at=crash), Evaluator, (crash,), workers=2) as pool:
        assert pool.map("value", VECTORS) == EXPECTED  # the crashing vector is evaluated here, where it does not crash
        assert pool.size in (1, 2)
        assert pool.map("value", VECTORS[::-1]) == EXPECTED[::-1]


def test_an_exception_is_raised_here_as_without_a_pool():
    bad = float(VECTORS[7][0])
    with SearchPool(Evaluator(raise_at=bad), Evaluator, (math.nan, bad), workers=2) as pool:
        with pytest.raises(ValueError, match="refused"):
            pool.map("value", VECTORS)


def test_workers_whose_evaluator_cannot_be_built_leave_the_work_here():
    with SearchPool(Evaluator(), broken_factory, (), workers=3) as pool:
        assert pool.size == 1
        assert pool.map("value", VECTORS) == EXPECTED


def test_worker_count_rule(monkeypatch):
    monkeypatch.setenv(WORKERS_ENV, "1")
    assert search_workers(None) == 1
    assert search_workers(3) == 3  # baseline.workers wins over the environment
    monkeypatch.delenv(WORKERS_ENV)
    assert search_workers(None) == len(os.sched_getaffinity(0))


def first_order():
    """The bundled 1/(s - 1) tuning problem (TuningConfig)."""
    return preset("first_order")


def test_the_load_designs_search_gives_the_same_result_on_one_and_on_two_processes():
    config = first_order()
    results = []
    for workers in (1, 2):
        design = LoadDesign(config, 0.1, 2.0, 0.02, 4.0, 0.005, workers=workers)
        try:
            design.prepare(([6.0], [1.0], [0.0], None))
            result = design.search(seed=3, maxiter=3, popsize=6)
        finally:
            design.close()
        results.append((result.x.tolist(), float(result.fun), int(result.nfev)))
    assert results[0] == results[1]
    assert results[0][2] > 4 * 6 * 3  # the vectors evaluated are counted (scipy counts a vectorized call as one)


def test_the_fixed_pid_search_gives_the_same_controller_on_one_and_on_two_processes():
    config = first_order()
    out = []
    for workers in (1, 2):
        baseline = dataclasses.replace(BaselineConfig(), maxiter=2, popsize=5, episodes=1, workers=workers)
        fixed = tune_fixed_pid(config, seed=1, max_sensitivity=2.0, baseline=baseline)
        out.append((fixed.gains.values(), fixed.structure, fixed.cost, fixed.evaluations))
    assert out[0] == out[1]


def test_search_fmus_names_the_plant():
    assert [p.name for p in search_fmus(first_order())] == ["FirstOrderUnstable.fmu"]
