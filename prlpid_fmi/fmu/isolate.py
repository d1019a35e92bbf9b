"""`probe` and `init` with their FMU in a worker process: a crash, a call that never returns or garbage
outputs end the command with one line naming the FMU, the FMI call and the time (a PlantError: exit 2),
and the FMU's own stdout (a banner printed by its C code) goes to stderr, never into the results."""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from prlpid_fmi.errors import PlantError
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


def frozen_output(result) -> str:
    """'' or why the probed output is frozen: it never moved in any run (trim and every input's step) although
    the inputs were stepped (judged against the inputs' change, so a slow output that moves a little passes)."""
    runs = [r for r in result.responses if r.du != 0]
    if not runs:
        return ""
    values = np.concatenate([np.concatenate([r.trim, r.stepped]) for r in runs])
    if values.size < 2 or np.ptp(values) > 0:
        return ""
    steps = ", ".join(f"{r.input} by {r.du:+.3g}" for r in runs)
    return (f"{Path(result.fmu).name}: {result.output} stays at {values[0]:.6g} in every run while the inputs step "
            f"({steps}): a frozen output (the FMU computes nothing, or not this output)")


def probe_isolated(fmu: str | Path, step_timeout_s: float | None = None, **kwargs):
    """probe.step_test.probe(fmu, **kwargs) in a worker process; a frozen output is a PlantError too."""
    from prlpid_fmi.probe.step_test import probe

    result = run_isolated(probe, fmu, "the probe", step_timeout_s, **kwargs)
    frozen = frozen_output(result)
    if frozen:
        raise PlantError(frozen)
    return result


def init_isolated(fmu: str | Path, step_timeout_s: float | None = None, **kwargs) -> str:
    """scenario.draft.init_scenario(fmu, **kwargs) in a worker process: the scenario's text."""
    from prlpid_fmi.scenario.draft import init_scenario

    return run_isolated(init_scenario, fmu, "init (the probe of the FMU)", step_timeout_s, **kwargs)
