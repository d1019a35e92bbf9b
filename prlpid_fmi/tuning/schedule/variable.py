"""The scheduling variable: its name for a run's loops, and reading it from the loop core before each step."""
from __future__ import annotations

from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.tuning.schedule.table import LOOP_SIGNALS, LOOP_VARIABLE


def variable_name(schedule_by: str, loop_names: list[str]) -> str:
    """The table's variable for `schedule_by`: "setpoint" -> "setpoint[<loop 0>]", "<signal>[<loop>]" checked
    against loop_names (PrlPidError), an FMU variable as it is."""
    if schedule_by in LOOP_SIGNALS:
        return f"{schedule_by}[{loop_names[0]}]"
    m = LOOP_VARIABLE.match(schedule_by)
    if m and m.group(2) not in loop_names:
        raise PrlPidError(f"{schedule_by!r}: no loop measures {m.group(2)!r} (loops: {', '.join(loop_names)})")
    return schedule_by


class SchedulingVariable:
    """Reads the scheduling variable from a loop core (before a step, as the lookup would): setpoint,
    measurement or error of a loop, or an FMU variable (checked to exist). unit(): its unit from the FMU."""

    def __init__(self, variable: str, env):
        self.env = env
        m = LOOP_VARIABLE.match(variable)
        if m:
            self.kind, self.index = m.group(1), env.loop_names.index(m.group(2))
        else:
            env.plant.description.require(variable, None, "a scheduling variable")
            self.kind, self.name = "fmu", variable

    def __call__(self) -> float:
        if self.kind == "setpoint":
            return float(self.env.setpoint[self.index])
        if self.kind == "measurement":
            return float(self.env.measurement[self.index])
        if self.kind == "error":
            return float(self.env.setpoint[self.index]) - float(self.env.measurement[self.index])
        return float(self.env.plant.get([self.name])[0])

    def unit(self) -> str:
        name = self.env.loop_names[self.index] if self.kind != "fmu" else self.name
        return self.env.plant.description.unit_of(name)
