"""The run context: what a run keeps in its process while it runs, owned by the run.

`tune` opens one (`opened`) for its run and closes it at the end, so two runs in one process share nothing. It holds:
- step_timeout_s: every FMU call's timeout [s] where the plant sets none (fmu.watchdog; the scenario's
  tuning.step_timeout_s, the CLI's --step-timeout); None: measured per plant;
- run_dir: where the run keeps its finished work, said in the one line a hung FMU call ends the process with;
- measured: robustness.margins' measurements, (config, FMU file, point, gains) -> Margins;
- references: the plant responses robustness.margins predicts Ms from, (config, FMU file, point) -> (gains,
  MeasuredPlant).
The caches keep at most CACHE_LIMIT entries each (`keep`: the oldest dropped). Outside a run (a library call, a worker
process) the process's own context is current.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

CACHE_LIMIT = 512  # entries per cache


@dataclass
class RunContext:
    """What one run keeps (module docstring)."""

    step_timeout_s: float | None = None
    run_dir: Path | None = None
    measured: dict = field(default_factory=dict)
    references: dict = field(default_factory=dict)

    @staticmethod
    def keep(cache: dict, key, value) -> None:
        """cache[key] = value, the oldest entry dropped first where the cache holds CACHE_LIMIT."""
        if key not in cache and len(cache) >= CACHE_LIMIT:
            cache.pop(next(iter(cache)))
        cache[key] = value


_current = RunContext()


def current() -> RunContext:
    """The context of the run under way (the process's own outside one)."""
    return _current


@contextlib.contextmanager
def opened(**values) -> Iterator[RunContext]:
    """A fresh RunContext(**values) current for the block; the one before is current again after it."""
    global _current
    before, _current = _current, RunContext(**values)
    try:
        yield _current
    finally:
        _current = before
