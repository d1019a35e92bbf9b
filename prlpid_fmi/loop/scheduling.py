"""The scheduling variable of a gain table, read from a loop core before each step (as a table lookup would).

Names: ``setpoint[<loop>]``, ``measurement[<loop>]``, ``error[<loop>]`` (the loop's output name) or an FMU
variable. The replay of a table (tuning.schedule.replay) and the anchored gain map on a table
(loop.actions.ScheduledActionMap, in loop.env) both read it here, so both see the same value at every step.
"""
from __future__ import annotations

import re

LOOP_SIGNALS = ("setpoint", "measurement", "error")  # scheduling variables read from a loop, not the FMU
LOOP_VARIABLE = re.compile(r"^(setpoint|measurement|error)\[(.+)\]$")  # <signal>[<loop output>]


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
