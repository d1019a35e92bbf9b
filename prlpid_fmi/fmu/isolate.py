"""FMU work of a command in a worker process (`probe`, `init`: probe.isolated, scenario.draft): a crash, a call
that never returns or garbage outputs end the command with one line naming the FMU, the FMI call and the time
(a PlantError: exit 2), and the FMU's own stdout (a banner printed by its C code) goes to stderr, never into
the results."""
from __future__ import annotations

import functools
from pathlib import Path

from prlpid_fmi.fmu.description import describe_fmu


def run_isolated(fn, fmu: str | Path, what: str, step_timeout_s: float | None = None, **kwargs):
    """fn(fmu, **kwargs) in a worker process with garbage outputs checked (FmuPlant.check_outputs); the FMU is
    described here first, so a file that is no FMU is its usual one line. step_timeout_s: the watchdog's
    timeout for each FMU call [s] (None: 100 x the measured step cost, at least 10 s)."""
    from prlpid_fmi.fmu.worker import call_in_worker

    path = Path(fmu)
    describe_fmu(path)
    return call_in_worker(functools.partial(fn, path, **kwargs), fmus=[path], what=what,
                          step_timeout_s=step_timeout_s, check_outputs=True)
