"""Calls that load an FMU, run in a worker process: an FMU that crashes kills the worker, not the tool.

Workers are forked from multiprocessing's fork server (with the loop core and the margins preloaded), so a
worker costs a fork, not an interpreter start. The FMUs a call opens are extracted once, by the parent, and
the workers use those folders."""
from __future__ import annotations

import ctypes
import mmap
import multiprocessing
import os
import signal
import tempfile
from pathlib import Path

from prlpid_fmi import runcontext
from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu import plant as plant_module
from prlpid_fmi.fmu import watchdog
from prlpid_fmi.fmu.plant import extracted_folders, reuse_extracted

JOIN_TIMEOUT_S = 5.0


_context = None


in_worker = watchdog.in_worker  # True inside a worker process (call_in_worker's, or an isolated loop core's)


def become_worker(conn=None, crumb_path: str | None = None, step_timeout_s: float | None = None,
                  check_outputs: bool = False, environ: dict | None = None) -> None:
    """Mark this process as a worker (in_worker() is then True) that leaves Ctrl-C to its parent.

    Its stdout goes to stderr (an FMU's own printf never reaches the tool's results); a watchdog line
    (a call that does not return) goes to the parent over `conn` as ("hang", line); the FMI call under
    way is kept in the crumb file for the parent (crash_text); step_timeout_s: the watchdog's timeout
    for every plant [s] (None: each plant's own); check_outputs: garbage outputs raise (FmuPlant). environ: the
    parent's environment when it asked for the worker: workers fork from a server started once per process, so
    without it an FMU would see the environment of whenever that server started, not the caller's."""
    if environ is not None:
        for name in set(os.environ) - set(environ):
            del os.environ[name]
        for name, value in environ.items():
            if os.environ.get(name) != value:
                os.environ[name] = value
    watchdog.mark_worker()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        os.dup2(2, 1)
    except OSError:
        pass
    if conn is not None:
        watchdog.reporter = lambda line: conn.send(("hang", line))
    if crumb_path is not None:
        attach_crumb(crumb_path)
    runcontext.current().step_timeout_s = step_timeout_s  # this worker process's own context
    plant_module.FmuPlant.check_outputs = bool(check_outputs)


# -- the crumb: which FMI call a worker is in, readable after the worker died ------------------------
class CrumbFile(ctypes.Structure):
    """A worker's crumb (fmu.plant.Crumb) followed by the names of the FMUs it opened, one per line."""

    _fields_ = [("crumb", plant_module.Crumb), ("names", ctypes.c_char * 1024)]


_mapped = []


def new_crumb_file() -> str:
    """A zeroed crumb file for one worker (the parent removes it with remove_crumb_file)."""
    fd, path = tempfile.mkstemp(prefix="prlpid-fmi-crumb-")
    os.write(fd, bytes(ctypes.sizeof(CrumbFile)))
    os.close(fd)
    return path


def remove_crumb_file(path: str | None) -> None:
    if path:
        try:
            os.unlink(path)
        except OSError:
            pass


def attach_crumb(path: str) -> None:
    """In the worker: FmuPlant writes its calls into this file's memory."""
    with open(path, "r+b") as f:
        mm = mmap.mmap(f.fileno(), ctypes.sizeof(CrumbFile))
    shared = CrumbFile.from_buffer(mm)
    _mapped.append((mm, shared))
    plant_module.crumb = shared.crumb
    plant_module.crumb_names = shared


def read_crumb(path: str | None):
    """(busy, call, fmu name, t, fmu path, role) from a crumb file, or None (role: "plant" or "prior", the
    instance of the loop that was in the call)."""
    try:
        raw = Path(path).read_bytes()
    except (OSError, TypeError):
        return None
    if len(raw) < ctypes.sizeof(CrumbFile):
        return None
    c = CrumbFile.from_buffer_copy(raw)
    paths = c.names.decode("utf-8", "replace").splitlines()
    path = paths[c.crumb.plant] if 0 <= c.crumb.plant < len(paths) else None
    call = plant_module.CALL_CODES[c.crumb.call] if 0 <= c.crumb.call < len(plant_module.CALL_CODES) else ""
    roles = plant_module.CRUMB_ROLES
    role = roles[c.crumb.role] if 0 <= c.crumb.role < len(roles) else roles[0]
    return bool(c.crumb.busy), call, Path(path).name if path else None, float(c.crumb.t), path, role


def crash_text(fmus, crumb_path: str | None, how: str, what: str, process: str = "a worker process") -> str:
    """One line: which FMU crashed how, in which FMI call at which time (from the crumb), during what, in which
    process. fmus: the FMU files the process opened (() : those the crumb names)."""
    from prlpid_fmi.fmu.adapters import adapter_class
    from prlpid_fmi.fmu.description import describe_fmu

    found = read_crumb(crumb_path)
    if found and found[4] and not fmus:
        fmus = [found[4]]
    names = ", ".join(Path(p).name for p in fmus) or "the FMU"
    if not found or not found[1]:
        return f"{names} crashed ({how}) in {process} during {what}"
    busy, call, name, t = found[:4]
    path = next((p for p in fmus if Path(p).name == name), None)
    call_name = call
    if path is not None:
        d = describe_fmu(path)
        call_name = adapter_class(d.fmi_version, d.co_simulation).call_names.get(call, call)
    where = plant_module.describe_call(name or names, call_name, call, t).split(": ", 1)[1]
    if busy:
        of = " of the forecast's prior (the FMU's second instance)" if found[5] == "prior" else ""
        return f"{name or names} crashed ({how}) in {where}{of} (in {process} during {what})"
    return f"{name or names} crashed ({how}) in {process} during {what}, after {where}"


def mp_context():
    """The multiprocessing context of the workers: the fork server where the platform has one, else spawn."""
    global _context
    if _context is None:
        methods = multiprocessing.get_all_start_methods()
        _context = multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")
        if "forkserver" in methods:
            _context.set_forkserver_preload(["prlpid_fmi.loop.core", "prlpid_fmi.robustness.margins"])
    return _context


def signal_name(exitcode: int | None) -> str:
    """'SIGSEGV' for a worker killed by signal 11, 'exit code 3' otherwise."""
    if exitcode == watchdog.HANG_EXIT:
        return "hung: ended by the step watchdog"
    if exitcode is not None and exitcode < 0:
        try:
            return signal.Signals(-exitcode).name
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit code {exitcode}"


class WorkerCrashed(PlantError):
    """A worker process running an FMU died (the FMU crashed it)."""


class WorkerHung(WorkerCrashed):
    """A worker process running an FMU was ended by its step watchdog (an FMI call that did not return)."""


# -- crashes seen in this process's workers (loop.isolated.runs_isolated reads them) -----------------
_crashes: dict[str, str] = {}   # resolved FMU path -> the line of the first worker it crashed or hung


def note_crash(fmus, line: str) -> None:
    """Remember that a worker running these FMU files crashed or hung (`line`: what happened, one line); from
    then on, loop.isolated.runs_isolated puts a plant with isolation "auto" on them in a worker process."""
    for path in fmus:
        _crashes.setdefault(str(Path(path).resolve()), line)


def crash_seen(fmus) -> str | None:
    """The line of the first worker crash seen on any of these FMU files in this process, or None."""
    for path in fmus:
        line = _crashes.get(str(Path(path).resolve()))
        if line is not None:
            return line
    return None


def _run_one(conn, fn, args, extracted: dict, options: dict) -> None:
    become_worker(conn, **options)
    reuse_extracted(extracted)
    try:
        result = fn(*args)
        if plant_module.FmuPlant.check_outputs and plant_module.garbage_seen:
            raise PlantError(plant_module.garbage_seen[0])  # fn may have stopped quietly at the garbage
        message = ("ok", result)
    except Exception as exc:  # noqa: BLE001 - raised in the parent
        garbage = plant_module.FmuPlant.check_outputs and plant_module.garbage_seen
        message = ("error", PlantError(garbage[0]) if garbage else exc)  # the garbage, not what fn made of it
    try:
        conn.send(message)
    except (BrokenPipeError, ConnectionResetError, EOFError):
        return  # the parent is gone (a SIGTERM or Ctrl-C stopped it while this call finished): nobody to tell
    except Exception as exc:  # noqa: BLE001 - the result would not pickle: say so to the parent
        conn.send(("error", exc))
    conn.close()


def call_in_worker(fn, *args, fmus=(), what: str = "the call", step_timeout_s: float | None = None,
                   check_outputs: bool = False):
    """fn(*args) in a worker process (fn and the result picklable); its exceptions are raised here.

    fmus: FMU paths fn opens (extracted here first, once). step_timeout_s: the step watchdog's timeout in the
    worker [s] (None: the measured default); check_outputs: a non-finite or denormal output of any plant is a
    PlantError (FmuPlant.check_outputs). Raises WorkerCrashed naming the FMU, the FMI call, the time and how the
    worker ended when it dies (a crash) before answering, WorkerHung (a WorkerCrashed) when its watchdog ended it
    (a call that did not return).
    """
    ctx = mp_context()
    parent, child = ctx.Pipe()
    crumb = new_crumb_file()
    options = {"crumb_path": crumb, "step_timeout_s": step_timeout_s, "check_outputs": check_outputs,
               "environ": dict(os.environ)}
    proc = ctx.Process(target=_run_one, args=(child, fn, args, extracted_folders(fmus), options), daemon=True)
    proc.start()
    child.close()
    try:
        tag, payload = parent.recv()
    except (EOFError, OSError):
        proc.join(JOIN_TIMEOUT_S)
        line = crash_text(fmus, crumb, signal_name(proc.exitcode), what)
        note_crash(fmus, line)
        raise WorkerCrashed(line) from None
    finally:
        parent.close()
        proc.join(JOIN_TIMEOUT_S)
        remove_crumb_file(crumb)
    if tag == "hang":
        note_crash(fmus, f"{payload}, in a worker process during {what}")
        raise WorkerHung(f"{payload}, in a worker process during {what}")
    if tag == "error":
        raise payload
    return payload
