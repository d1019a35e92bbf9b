"""User-facing errors: the CLI prints their message on one line and exits with code 2."""


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


class RunError(PrlPidError):
    """A run directory or an output file cannot be used as asked (exists, missing files, owned by a run)."""
