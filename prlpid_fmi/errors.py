"""User-facing errors: the CLI prints their message on one line and exits with code 2."""


class PrlPidError(Exception):
    """An error the user can cause and fix (bad input, unusable FMU). Not a bug."""


class ScenarioError(PrlPidError):
    """A scenario file is invalid: the message names the file, the key, the value and what was expected."""


class PlantError(PrlPidError):
    """An FMU cannot be loaded or used as a plant or prior."""


class RunError(PrlPidError):
    """A run directory or an output file cannot be used as asked (exists, missing files, owned by a run)."""
