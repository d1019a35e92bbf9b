"""Run directories: the names of the files a run owns, creating and reopening one, and atomic writes.

Layout of a run directory (every name below is owned by the run; nothing else may write there):
  scenario.yaml    the resolved scenario (every key, defaults filled in)
  run.json         seed, timesteps, command, start/end time, package versions, platform
  model.zip        the trained policy (+ vecnormalize.pkl), checkpoints/, tensorboard/, monitor/
  fixed_pid.json   the tuned fixed PID the policy is compared with
  metrics.json     adaptive policy vs the tuned fixed PID, overall and per interval
  gains.csv        time, setpoint, measurement, control signal, Kp, Ti, Td, ... at every step
  schedule.csv     the gain schedule (plain PID table, no neural network)
  report.md        the comparison as a table
  *.png            response, control signal, gains over time, learning curve
  evaluations/<n>/ re-evaluations (`prlpid-fmi evaluate`), each with its own scenario, metrics and plots
  .active          while `tune` works on the run: its process id (left behind only when that process
                   died abruptly, e.g. an FMU crashed it: `tune --resume` then isolates the plant)

Every file is written by `write_atomic`: a temporary file in the same folder, renamed over the target,
so a reader never sees half a file; files get mode 0666 minus the umask (0644 usually).
"""
from __future__ import annotations

import datetime as dt
import errno
import json
import os
import platform
import shutil
import tempfile
from importlib import metadata
from pathlib import Path
from typing import Callable, Union

import numpy as np

from prlpid_fmi.errors import ArgumentError, RunError

SCENARIO = "scenario.yaml"
RUN_INFO = "run.json"
MODEL = "model.zip"
VECNORMALIZE = "vecnormalize.pkl"
FIXED_PID = "fixed_pid.json"
FIXED_PID_CSV = "fixed_pid.csv"
CLASSICAL_SCHEDULE = "classical_schedule.csv"  # the classical gain schedule (nonlinear plants)
ADAPTIVE_SCHEDULE = "adaptive_schedule.csv"  # the policy's gain table, deployed or not
METRICS = "metrics.json"
GAINS = "gains.csv"
SCHEDULE = "schedule.csv"
REPORT = "report.md"
RESPONSE_PLOT = "response.png"
CONTROL_SIGNAL_PLOT = "control_signal.png"
GAINS_PLOT = "gains.png"
LEARNING_CURVE_PLOT = "learning_curve.png"
STEP_RESPONSE_PLOT = "step_response.png"  # the evaluation zoomed to its transients
LOAD_STEPS_PLOT = "load_steps.png"  # the design's load experiment, every plain PID
SCHEDULE_GAINS_PLOT = "schedule_gains.png"  # the gain tables over their scheduling variable
FREQUENCY = "frequency"  # per loop: the measured frequency responses (CSV) and their figures
CHECKPOINTS = "checkpoints"
TENSORBOARD = "tensorboard"
MONITOR = "monitor"
EVALUATIONS = "evaluations"
ACTIVE = ".active"
OWNED_FILES = frozenset({ACTIVE, SCENARIO, RUN_INFO, MODEL, VECNORMALIZE, FIXED_PID, FIXED_PID_CSV, CLASSICAL_SCHEDULE, ADAPTIVE_SCHEDULE, METRICS, GAINS, SCHEDULE, REPORT,
                         RESPONSE_PLOT, CONTROL_SIGNAL_PLOT, GAINS_PLOT, LEARNING_CURVE_PLOT, STEP_RESPONSE_PLOT,
                         LOAD_STEPS_PLOT, SCHEDULE_GAINS_PLOT})
OWNED_DIRS = frozenset({CHECKPOINTS, TENSORBOARD, MONITOR, EVALUATIONS, FREQUENCY})
PACKAGES = ("prlpid-fmi", "fmpy", "numpy", "scipy", "torch", "stable-baselines3", "gymnasium", "pyyaml", "matplotlib")

Content = Union[bytes, str, Callable[[Path], object]]


# -- atomic writes ---------------------------------------------------------------------------------
def _file_mode() -> int:
    """0666 minus the process umask: the mode open() would give a new file."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def write_atomic(path: str | Path, content: Content) -> Path:
    """Write `content` to `path` atomically (temporary file in the same folder, then rename).

    content: bytes; str (written as UTF-8, no newline translation); or a callback `write(tmp_path)`
    that writes the file itself (matplotlib's savefig, SB3's model.save, a ZipFile). The parent
    folder is created. An OSError (disk full, permission) is raised naming `path`, and leaves no
    temporary file behind.
    """
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        # the temporary name keeps the target's suffix last: SB3 appends ".zip" to names without it
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".part{path.suffix}", dir=path.parent)
        tmp = Path(name)
        if callable(content):
            os.close(fd)
            content(tmp)
        else:
            data = content.encode("utf-8") if isinstance(content, str) else bytes(content)
            with os.fdopen(fd, "wb") as f:
                f.write(data)
        os.chmod(tmp, _file_mode())
        os.replace(tmp, path)
        tmp = None
    except OSError as exc:
        raise OSError(exc.errno or errno.EIO, exc.strerror or str(exc), str(path)) from exc
    finally:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
    return path


def write_json(path: str | Path, data) -> Path:
    """`data` as indented JSON (numpy scalars and arrays as numbers and lists), atomically."""
    return write_atomic(path, json.dumps(data, indent=2, default=_json_default) + "\n")


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


# -- the run directory -----------------------------------------------------------------------------
def package_versions() -> dict[str, str]:
    """Python, platform and the versions of the packages a run depends on (for run.json)."""
    out = {"python": platform.python_version(), "platform": platform.platform()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def now() -> str:
    """UTC time, ISO 8601 to the second."""
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")


def _first_missing(path: Path) -> Path | None:
    """The outermost folder of `path` that does not exist yet (what mkdir(parents=True) would create)."""
    missing = None
    for p in (path, *path.parents):
        if p.exists():
            break
        missing = p
    return missing


def prepare_run_dir(out: str | Path | None, name: str, resume: bool) -> tuple[Path, Path | None]:
    """The run directory: new (default runs/<name>-<UTC time>) or, with resume, an existing one.

    Returns (run directory, outermost folder this call created or None), so that a start refused
    later can remove what it made (`discard_if_empty`).
    """
    if out is None:
        if resume:
            raise ArgumentError("{resume} needs {out} RUN_DIR naming the run to continue")
        stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y%m%d-%H%M%S")
        out = Path("runs") / f"{name}-{stamp}"
    run_dir = Path(out)
    if run_dir.exists() and not run_dir.is_dir():
        raise ArgumentError(f"{run_dir}: is a file, not a directory (got {{out}} {run_dir}; "
                            "expected a new directory for the run)")
    if resume:
        if not (run_dir / SCENARIO).is_file():
            raise RunError(f"{run_dir}: nothing to resume (no {SCENARIO}; expected a run directory from `tune`)")
        return run_dir, None
    if run_dir.exists() and any(run_dir.iterdir()):
        raise ArgumentError(f"{run_dir}: run directory exists and is not empty (got {{out}} {run_dir}; "
                            "expected a new directory, or {resume} to continue that run)")
    created = _first_missing(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir, created


def holds_results(run_dir: Path) -> bool:
    """True when the run directory holds work worth keeping: the tuned fixed PID, a trained model or a
    checkpoint (`--resume` continues from them)."""
    return any((run_dir / name).is_file() for name in (FIXED_PID, MODEL)) or any((run_dir / CHECKPOINTS).glob("*.zip"))


def discard_if_empty(run_dir: Path, created: Path | None) -> None:
    """Remove the folders a refused start created (`created` from prepare_run_dir), unless the run
    already produced results there (holds_results)."""
    if created is not None and created.is_dir() and not holds_results(run_dir):
        shutil.rmtree(created, ignore_errors=True)


def mark_active(run_dir: Path) -> bool:
    """Record that this process works on the run (ACTIVE holds its process id).

    Returns True when an earlier process left its mark behind, i.e. ended abruptly (a crash, SIGKILL).
    Raises RunError when that process is still alive (two commands on one run directory).
    """
    marker = Path(run_dir) / ACTIVE
    crashed = False
    if marker.is_file():
        try:
            pid = int(marker.read_text().strip() or 0)
        except ValueError:
            pid = 0
        if pid > 0 and pid != os.getpid() and _alive(pid):
            raise RunError(f"{run_dir}: in use by process {pid} (expected no other `tune` on this run directory)")
        crashed = True
    write_atomic(marker, f"{os.getpid()}\n")
    return crashed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def mark_inactive(run_dir: Path) -> None:
    """Remove this process's ACTIVE mark (the run ended normally, with an error or by a signal)."""
    (Path(run_dir) / ACTIVE).unlink(missing_ok=True)


def latest_checkpoint(run_dir: Path, trained_timesteps: int = 0) -> tuple[Path | None, int]:
    """(model file with the most timesteps, its timesteps): a checkpoint, or model.zip after a finished
    training (run.json's trained_timesteps), or (None, 0)."""
    best: tuple[Path | None, int] = (None, 0)
    for p in (run_dir / CHECKPOINTS).glob("model_*_steps.zip"):
        steps = int(p.stem.split("_")[1])
        if steps > best[1]:
            best = (p, steps)
    if (run_dir / MODEL).is_file() and trained_timesteps >= best[1]:
        best = (run_dir / MODEL, trained_timesteps)
    return best


def owned_name(run_dir: Path, path: Path) -> str | None:
    """The run-owned name `path` points at inside `run_dir` (e.g. "model.zip", "checkpoints"), or None.

    Paths are compared after resolving symbolic links and "..", so no spelling of a run's own file
    gets past.
    """
    try:
        rel = Path(os.path.realpath(path)).relative_to(os.path.realpath(run_dir))
    except ValueError:
        return None
    if not rel.parts:
        return "."
    if rel.parts[0] in OWNED_DIRS or (len(rel.parts) == 1 and rel.parts[0] in OWNED_FILES):
        return rel.parts[0]
    return None
