"""FMU work of a command in a worker process (`probe`, `init`: probe.isolated, scenario.draft): a call that never
returns or garbage outputs end the command with one line naming the FMU, the FMI call and the time (a PlantError:
exit 2), and the FMU's own stdout (a banner printed by its C code) goes to stderr, never into the results.

A crash of that worker is survived: the work runs again in this process with each of its FMU runs in a worker
process of its own (probe.open_loop runs them so once fmu.worker.crash_seen names the FMU), a run that crashes
keeping the samples before the crash; what it still cannot do is one line as above."""
from __future__ import annotations

import functools
from pathlib import Path

from prlpid_fmi.errors import PlantError, PrlPidError
from prlpid_fmi.fmu.description import describe_fmu


def run_isolated(fn, fmu: str | Path, what: str, step_timeout_s: float | None = None, **kwargs):
    """fn(fmu, **kwargs) in a worker process with garbage outputs checked (FmuPlant.check_outputs); the FMU is
    described here first, so a file that is no FMU is its usual one line. step_timeout_s: the watchdog's
    timeout for each FMU call [s] (None: 100 x the measured step cost, at least 10 s). A crash of the worker (not a
    hang): fn(fmu, **kwargs) again here, its FMU runs each in a worker (fmu.worker.crash_seen is set by then)."""
    from prlpid_fmi.fmu.worker import WorkerCrashed, WorkerHung, call_in_worker

    path = Path(fmu)
    describe_fmu(path)
    try:
        return call_in_worker(functools.partial(fn, path, **kwargs), fmus=[path], what=what,
                              step_timeout_s=step_timeout_s, check_outputs=True)
    except WorkerHung:
        raise
    except WorkerCrashed as exc:
        crash = str(exc)
    try:
        return fn(path, **kwargs)  # the crash is noted: each FMU run of fn in a worker process of its own
    except PrlPidError as exc:
        raise PlantError(f"{exc} (each run in a worker process of its own, cut at its crash, after: {crash})") from None
