"""Calls that load an FMU, run in a worker process: an FMU that crashes kills the worker, not the tool.

Workers are forked from multiprocessing's fork server (with the loop core and the margins preloaded), so a
worker costs a fork, not an interpreter start. The FMUs a call opens are extracted once, by the parent, and
the workers use those folders."""
from __future__ import annotations

import multiprocessing
import signal
from pathlib import Path

from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu.plant import extracted_folders, reuse_extracted

JOIN_TIMEOUT_S = 5.0


_context = None


_in_worker = False


def in_worker() -> bool:
    """True inside a worker process (call_in_worker's, or an isolated loop core's)."""
    return _in_worker


def become_worker() -> None:
    """Mark this process as a worker (in_worker() is then True) that leaves Ctrl-C to its parent."""
    global _in_worker
    _in_worker = True
    signal.signal(signal.SIGINT, signal.SIG_IGN)


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
    if exitcode is not None and exitcode < 0:
        try:
            return signal.Signals(-exitcode).name
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit code {exitcode}"


class WorkerCrashed(PlantError):
    """A worker process running an FMU died (the FMU crashed it)."""


def _run_one(conn, fn, args, extracted: dict) -> None:
    become_worker()
    reuse_extracted(extracted)
    try:
        conn.send(("ok", fn(*args)))
    except Exception as exc:  # noqa: BLE001 - raised in the parent
        conn.send(("error", exc))
    conn.close()


def call_in_worker(fn, *args, fmus=(), what: str = "the call"):
    """fn(*args) in a worker process (fn and the result picklable); its exceptions are raised here.

    fmus: FMU paths fn opens (extracted here first, once). Raises WorkerCrashed naming the FMU and how
    the worker ended when it dies before answering.
    """
    ctx = mp_context()
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_run_one, args=(child, fn, args, extracted_folders(fmus)), daemon=True)
    proc.start()
    child.close()
    try:
        tag, payload = parent.recv()
    except (EOFError, OSError):
        proc.join(JOIN_TIMEOUT_S)
        names = ", ".join(Path(p).name for p in fmus) or "the FMU"
        raise WorkerCrashed(f"{names} crashed ({signal_name(proc.exitcode)}) in a worker process during {what}") from None
    finally:
        parent.close()
    proc.join(JOIN_TIMEOUT_S)
    if tag == "error":
        raise payload
    return payload
