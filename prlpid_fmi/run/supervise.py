"""`tune` under a supervising parent: a crash of the tool's own process never ends the run with a bare signal.

The command line forks before the work starts (the parent has imported little: a fork costs about a millisecond and
no second interpreter start). The child runs the work; the parent waits, forwards SIGTERM and SIGINT to it and
reads what it left:

- the child exits (0, 2, 128 + a signal it handled, ...): the parent exits with the same code;
- the child dies by a crash signal (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGSYS, SIGTRAP), i.e. an FMU crashed the
  tool's process: once, when the child had announced a run directory holding its scenario.yaml, a new child resumes
  that run from its last checkpoint with the crash's line (what `tune --resume` does after an abrupt end: with
  plant.isolation auto the plant then runs in a worker process); otherwise, or when the resumed child crashes too,
  one line naming the FMU, the FMI call and the simulation time (read from the crumb the child's FMU calls write,
  fmu.worker) and the run directory kept, exit 2;
- the child dies by another signal (SIGKILL, e.g. out of memory): one line, exit 128 + the signal.

The child ends with the parent (Linux: PR_SET_PDEATHSIG, SIGTERM), so a parent killed with SIGKILL leaves no run
going on unseen. Cost: the fork (the parent has imported the command line only), a waiting parent of about 40 MB,
and in the child the crumb's stores on every FMU step (0.2-0.4 us idle, about 1 us on a loaded machine:
benchmarks/bench_supervise.py); a resumed child starts afresh (its
imports again), only after a crash.
"""
from __future__ import annotations

import os
import signal
import sys
from pathlib import Path
from typing import Callable, Optional

CRASH_SIGNALS = frozenset({signal.SIGSEGV, signal.SIGBUS, signal.SIGFPE, signal.SIGILL, signal.SIGABRT,
                           signal.SIGSYS, signal.SIGTRAP})
FORWARDED = (signal.SIGTERM, signal.SIGINT)
PROG = "prlpid-fmi"

# work(announce, restart) -> exit code, run in the child. announce(run_dir) tells the parent the run directory as soon
# as it exists; restart: None on the first attempt, else (run_dir, the crash's line) to resume from.
Work = Callable[[Callable[[Path], None], Optional[tuple]], int]


def supervised(work: Work) -> int:
    """Run `work` in a child process and survive its crash (module docstring). Returns the exit code in the parent;
    in the child, returns work's result (the caller returns it as the child's exit code: the child unwinds
    normally, so its atexit handlers run)."""
    from prlpid_fmi.fmu.worker import new_crumb_file, remove_crumb_file

    restart = None
    for attempt in (1, 2):
        crumb = new_crumb_file()
        read_end, write_end = os.pipe()
        for stream in (sys.stdout, sys.stderr):  # nothing buffered here is printed twice
            stream.flush()
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, FORWARDED)
        pid = os.fork()
        if pid == 0:  # the child: the work, with the crumb its FMU calls write
            from prlpid_fmi.fmu.worker import attach_crumb

            os.close(read_end)
            _end_with_parent()
            attach_crumb(crumb)
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
            return work(_announcer(write_end), restart)
        os.close(write_end)
        status = _wait(pid, blocked)
        run_dir = _announced(read_end)
        code = os.waitstatus_to_exitcode(status)
        if code >= 0:
            remove_crumb_file(crumb)
            return code
        signum = -code
        line = _crash_line(crumb, signum)
        remove_crumb_file(crumb)
        kept = run_dir is not None and (run_dir / "scenario.yaml").is_file()
        if signum in CRASH_SIGNALS and attempt == 1 and kept:
            restart = (run_dir, line)
            continue
        where = (f"; the run directory {run_dir} is kept with what finished; continue it with `{PROG} tune "
                 f"{run_dir}/scenario.yaml --out {run_dir} --resume`" if kept else "")
        again = " again after the resume" if attempt == 2 else ""
        print(f"{PROG}: error: {line}{again}{where}", file=sys.stderr, flush=True)
        return 2 if signum in CRASH_SIGNALS else 128 + signum
    raise AssertionError("unreachable")


def _end_with_parent() -> None:
    """Linux: SIGTERM to this child when the parent dies (kill -9 of the parent): the run stops as interrupted,
    its checkpoint saved, instead of running on unseen."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _announcer(fd: int) -> Callable[[Path], None]:
    def announce(run_dir: Path) -> None:
        try:
            os.write(fd, f"{Path(run_dir).resolve()}\n".encode())
        except OSError:
            pass
    return announce


def _announced(fd: int) -> Path | None:
    """The last run directory the child announced (None: none)."""
    data = b""
    with os.fdopen(fd, "rb") as pipe:
        data = pipe.read()
    lines = [line for line in data.decode("utf-8", "replace").splitlines() if line]
    return Path(lines[-1]) if lines else None


def _wait(pid: int, blocked) -> int:
    """waitpid(pid) with SIGTERM and SIGINT forwarded to the child meanwhile; its wait status."""
    def forward(signum, frame):
        try:
            os.kill(pid, signum)
        except ProcessLookupError:
            pass

    previous = {s: signal.signal(s, forward) for s in FORWARDED}
    signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    try:
        return os.waitpid(pid, 0)[1]  # retried after a forwarded signal (PEP 475)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _crash_line(crumb: str, signum: int) -> str:
    """One line: the FMU, the FMI call and the time the child was in when the signal ended it (its crumb)."""
    from prlpid_fmi.fmu.worker import crash_text, signal_name

    how = signal_name(-signum)
    text = crash_text((), crumb, how, "tune", process="the tool's process")
    return text if not text.startswith("the FMU crashed") else f"the tool's process ended by {how} during tune"
