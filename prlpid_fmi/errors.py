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


class Interrupted(BaseException):
    """SIGTERM or SIGINT during a command: unwinds like KeyboardInterrupt (a training saves a checkpoint on the
    way); the CLI exits with 128 + the signal number. run_dir: the run being worked on, when known."""

    def __init__(self, signum: int, run_dir=None):
        super().__init__(signum)
        self.signum = signum
        self.run_dir = run_dir


class RunError(PrlPidError):
    """A run directory or an output file cannot be used as asked (exists, missing files, owned by a run)."""
