"""`probe` with its FMU in a worker process (fmu.isolate.run_isolated): a crash, a hang or garbage outputs are one
line, and an output that never moves while the inputs step (frozen) is refused as well."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu.isolate import run_isolated


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
    """probe.open_loop.probe(fmu, **kwargs) in a worker process; a frozen output is a PlantError too."""
    from prlpid_fmi.probe.open_loop import probe

    result = run_isolated(probe, fmu, "the probe", step_timeout_s, **kwargs)
    frozen = frozen_output(result)
    if frozen:
        raise PlantError(frozen)
    return result
