"""User-facing errors: the CLI prints their message on one line and exits with code 2."""
from __future__ import annotations

import re


class PrlPidError(Exception):
    """An error the user can cause and fix (bad input, unusable FMU). Not a bug."""


class ScenarioError(PrlPidError):
    """A scenario file is invalid: one line per mistake, each naming the file, the key, the value and what was
    expected (the CLI prints every line)."""

    @property
    def lines(self) -> list[str]:
        """The mistakes, one message line each, in file order."""
        return str(self).splitlines()


class PlantError(PrlPidError):
    """An FMU cannot be loaded or used as a plant or prior."""


class Interrupted(BaseException):
    """SIGTERM or SIGINT during a command: unwinds like KeyboardInterrupt (a training saves a checkpoint on the
    way); the CLI exits with 128 + the signal number. run_dir: the run being worked on, when known."""

    def __init__(self, signum: int, run_dir=None):
        super().__init__(signum)
        self.signum = signum
        self.run_dir = run_dir


class RunError(PrlPidError):
    """A run directory or an output file cannot be used as asked (exists, missing files, owned by a run)."""


class ArgumentError(RunError):
    """An argument of a library call that cannot be used as given, worded in the library's terms.

    template: the message with each parameter it names written as {parameter} (e.g. "{points}: must be at least
    1 (got 0; ...)"); str() shows the parameter names, `worded(flags)` shows the names the caller knows them by
    (the CLI's options: {"points": "--points"}).
    """

    _FIELD = re.compile(r"\{([a-z_]+)\}")

    def __init__(self, template: str):
        self.template = template
        super().__init__(self.worded({}))

    def worded(self, names: dict[str, str]) -> str:
        """The message with each {parameter} replaced by names[parameter] (the parameter's own name if absent)."""
        return self._FIELD.sub(lambda m: names.get(m.group(1), m.group(1)), self.template)
