"""The scheduling variable's name for a run's loops (reading it before each step: prlpid_fmi.loop.scheduling)."""
from __future__ import annotations

from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.loop.scheduling import LOOP_SIGNALS, LOOP_VARIABLE


def variable_name(schedule_by: str, loop_names: list[str]) -> str:
    """The table's variable for `schedule_by`: "setpoint" -> "setpoint[<loop 0>]", "<signal>[<loop>]" checked
    against loop_names (PrlPidError), an FMU variable as it is."""
    if schedule_by in LOOP_SIGNALS:
        return f"{schedule_by}[{loop_names[0]}]"
    m = LOOP_VARIABLE.match(schedule_by)
    if m and m.group(2) not in loop_names:
        raise PrlPidError(f"{schedule_by!r}: no loop measures {m.group(2)!r} (loops: {', '.join(loop_names)})")
    return schedule_by
