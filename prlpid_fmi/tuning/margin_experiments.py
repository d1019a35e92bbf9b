"""Margin experiments measured ahead on all cores: the closed-loop frequency-response experiments of a batch of
(gains, operating point) requests, each in a worker process with its own FMU instance (tuning.search_pool).

The stages after training ask for many independent experiments whose list is known before the first is measured
(every row of a gain table at its operating points, every point of the evidence, the halfway checks between
breakpoints). `measure_ahead` measures those that robustness.margins.margins_of does not keep yet, on
`search_workers` processes, and hands them to margins_of's store (robustness.margins.keep_margins); the code that
asks for them then finds them there, in its own order. Each experiment is deterministic and runs on a fresh FMU
instance, so what it measures in a worker is what it measures here, and what the stages decide does not depend on
the number of processes (tests/test_margin_experiments.py). One process (baseline.workers 1, the variable
PRLPID_FMI_SEARCH_WORKERS=1, a sweep's trial, a worker process, plant.isolation "process"): nothing is measured
ahead, margins_of measures each when asked.
"""
from __future__ import annotations

from prlpid_fmi.loop.isolated import runs_isolated
from prlpid_fmi.robustness.margins import keep_margins, measure_margins, measured_margins, measurement_key
from prlpid_fmi.tuning.search_pool import SearchPool, search_fmus, search_workers


class MarginExperiments:
    """A SearchPool evaluator: measure((gains, point)) -> robustness.margins.Margins of config's plant."""

    def __init__(self, config):
        self.config = config

    def measure(self, request: tuple):
        gains, point = request
        return measure_margins(self.config, gains, point)


def measure_ahead(config, requests, workers: int | None = None) -> int:
    """Measure the (gains, point) requests that margins_of does not keep yet, on all cores (module docstring), and
    keep them; returns how many were measured (0 with one process or fewer than two to measure). gains: (Kp, Ti,
    Td, coupling) lists as margins_of takes them; point: setpoints per loop; workers: baseline.workers."""
    todo, seen = [], set()
    for gains, point in requests:
        key = measurement_key(config, gains, point)
        if key in seen or measured_margins(config, gains, point) is not None:
            continue
        seen.add(key)
        todo.append((gains, list(point)))
    processes = 1 if runs_isolated(config) else min(search_workers(workers), len(todo))
    if processes <= 1:
        return 0
    with SearchPool(MarginExperiments(config), MarginExperiments, (config,), processes,
                    fmus=search_fmus(config)) as pool:
        found = pool.map("measure", todo)
    for (gains, point), margins in zip(todo, found):
        keep_margins(config, gains, point, margins)
    return len(todo)
