"""Step watchdog: an FMU call that never returns ends the process (or its worker) with one line.

Python signal handlers, SIGALRM included, never run while the main thread is inside a C call, so a
thread watches. Every FmuPlant counts its FMI calls in `_seq` (odd while a call is under way: two
integer increments per step, ~35 ns) and registers here; the thread wakes every `interval_s` and,
when a plant's counter has stood still on an odd value for its timeout, ends the process:

- in the tool's own process: one line on stderr naming the FMU, the call and the time, what is kept
  (the run context's run directory, prlpid_fmi.runcontext, and the `--resume` command), then os._exit(2) after flushing;
  files already written (fixed_pid.json, checkpoints, logs) stay, and `tune` leaves its `.active`
  marker, so `--resume` runs the plant in a worker process (plant.isolation: auto);
- in a worker process (fmu.worker, loop.isolated): `reporter(line)` sends the line to the parent,
  then os._exit(HANG_EXIT); the parent reports it like a crash.

The timeout of a plant is its `step_timeout_s` when set (plant.step_timeout_s), else
STEP_TIMEOUT_FACTOR x the median cost of its calls as this thread measured them (the time between
polls over the calls made in it; nothing is timed in the hot path), at least MIN_STEP_TIMEOUT_S.

SIGTERM and SIGINT during a call that does not return: the signal's wakeup byte (signal.set_wakeup_fd)
reaches this thread; when the same call is still under way SIGNAL_GRACE_S later, the thread prints one
line and ends the process with 128 + the signal number (the Python handler would never run).
"""
from __future__ import annotations

import os
import select
import signal
import statistics
import sys
import threading
import time
import weakref
from collections import deque

from prlpid_fmi import runcontext

MIN_STEP_TIMEOUT_S = 10.0     # the measured default is never below this [s]
STEP_TIMEOUT_FACTOR = 100.0   # default timeout = this x the median measured cost of a call
HANG_EXIT = 86                # exit code of a worker the watchdog ended (worker.signal_name says "hung")
SIGNAL_GRACE_S = 2.0          # SIGTERM/SIGINT during a call: end the process when it is still under way then
_MAX_INTERVAL_S, _MIN_INTERVAL_S = 1.0, 0.02
_COST_SAMPLES = 15

reporter = None               # in a worker: callable(line) that hands the line to the parent


_worker_process = False  # set by fmu.worker.become_worker (here, below both worker and plant: no import cycle)


def in_worker() -> bool:
    """True inside a worker process (fmu.worker.call_in_worker's, or an isolated loop core's)."""
    return _worker_process


def mark_worker() -> None:
    """This process is a worker from now on (fmu.worker.become_worker)."""
    global _worker_process
    _worker_process = True


class _Watch:
    """What the thread knows of one plant: the counter it saw last, since when [monotonic s], and the
    measured costs of its calls [s]."""

    __slots__ = ("seq", "since", "costs")

    def __init__(self, seq: int, now: float):
        self.seq, self.since, self.costs = seq, now, deque(maxlen=_COST_SAMPLES)


def timeout_of(plant) -> tuple[float, str]:
    """(timeout [s], where it comes from) for a plant: its step_timeout_s, else the measured default."""
    if plant.step_timeout_s is not None:
        return float(plant.step_timeout_s), "plant.step_timeout_s"
    run_timeout = runcontext.current().step_timeout_s
    if run_timeout is not None:
        return float(run_timeout), "--step-timeout"
    watch = _state.watches.get(id(plant))
    costs = list(watch[1].costs) if watch else []
    measured = STEP_TIMEOUT_FACTOR * statistics.median(costs) if costs else 0.0
    return (max(MIN_STEP_TIMEOUT_S, measured),
            f"the default: {STEP_TIMEOUT_FACTOR:g} x the measured step cost, at least {MIN_STEP_TIMEOUT_S:g} s; "
            "set plant.step_timeout_s")


class _State:
    def __init__(self):
        self.pid = None
        self.thread = None
        self.wake = threading.Event()
        self.watches: dict[int, tuple] = {}   # id(plant) -> (weakref, _Watch)
        self.wakeup_r = self.wakeup_w = None
        self.pending = None                   # (signum, when, id(plant), seq) of a signal during a call
        self.lock = threading.Lock()


_state = _State()


def watch(plant) -> None:
    """Watch this FmuPlant's calls (starts the thread in this process on first use)."""
    s = _state
    with s.lock:
        if s.pid != os.getpid():   # first use, or a forked child: no thread of the parent survives a fork
            s.pid, s.thread, s.watches, s.pending = os.getpid(), None, {}, None
            _install_wakeup(s)
        s.watches[id(plant)] = (weakref.ref(plant), _Watch(plant._seq, time.monotonic()))
        if s.thread is None:
            s.thread = threading.Thread(target=_run, name="prlpid-fmi step watchdog", daemon=True)
            s.thread.start()
    s.wake.set()  # a new plant may need a shorter interval


def unwatch(plant) -> None:
    """Stop watching a plant (it was closed)."""
    _state.watches.pop(id(plant), None)


def _install_wakeup(s: _State) -> None:
    """Signal wakeup bytes to this thread (main thread only; never over someone else's wakeup fd)."""
    if threading.current_thread() is not threading.main_thread():
        return
    try:
        r, w = os.pipe()
        os.set_blocking(r, False)
        os.set_blocking(w, False)
        old = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except (ValueError, OSError):
        return
    if old not in (-1, s.wakeup_w):  # another owner: give it back
        signal.set_wakeup_fd(old)
        os.close(r)
        os.close(w)
        return
    s.wakeup_r, s.wakeup_w = r, w


def _interval(s: _State) -> float:
    shortest = min((timeout_of(ref())[0] for ref, _ in list(s.watches.values()) if ref() is not None),
                   default=MIN_STEP_TIMEOUT_S)
    return min(max(shortest / 4.0, _MIN_INTERVAL_S), _MAX_INTERVAL_S)


def _wait(s: _State, seconds: float) -> list[int]:
    """Sleep up to `seconds`; the signal numbers that arrived meanwhile."""
    if s.wakeup_r is None:
        s.wake.wait(seconds)
        s.wake.clear()
        return []
    try:
        ready, _, _ = select.select([s.wakeup_r], [], [], seconds)
        return list(os.read(s.wakeup_r, 64)) if ready else []
    except (OSError, ValueError, BlockingIOError):
        time.sleep(seconds)
        return []


def _run() -> None:
    s = _state
    while True:
        signals = _wait(s, _interval(s))
        now = time.monotonic()
        for key, (ref, w) in list(s.watches.items()):
            plant = ref()
            if plant is None:
                s.watches.pop(key, None)
                continue
            seq = plant._seq
            if seq != w.seq:
                calls = (seq - w.seq) // 2
                if calls > 0 and not w.seq % 2:
                    w.costs.append((now - w.since) / calls)
                w.seq, w.since = seq, now
                continue
            if seq % 2:
                limit, source = timeout_of(plant)
                if now - w.since >= limit:
                    _end(f"{plant.describe_call()} did not return within {limit:g} s ({source})", 2)
        for signum in signals:
            if signum in (signal.SIGTERM, signal.SIGINT):
                busy = _busy_plant(s)
                if busy is not None:
                    s.pending = (signum, now, id(busy), busy._seq)
        if s.pending is not None:
            signum, since, key, seq = s.pending
            entry = s.watches.get(key)
            plant = entry[0]() if entry else None
            if plant is None or plant._seq != seq:
                s.pending = None      # the call returned: the Python handler takes over
            elif now - since >= SIGNAL_GRACE_S:
                _end(f"interrupted by {signal.Signals(signum).name} while {plant.describe_call()} had not "
                     f"returned for {SIGNAL_GRACE_S:g} s", 128 + signum)


def _busy_plant(s: _State):
    for ref, _ in list(s.watches.values()):
        plant = ref()
        if plant is not None and plant._seq % 2:
            return plant
    return None


def _end(text: str, code: int) -> None:
    """End this process with one line: to the parent (a worker), or on stderr with what is kept."""
    if reporter is not None:
        try:
            reporter(text)
        finally:
            os._exit(HANG_EXIT)
    run_dir = runcontext.current().run_dir
    if run_dir is not None:
        text += (f"; the run directory {run_dir} is kept with what finished; continue it with "
                 f"`prlpid-fmi tune {run_dir}/scenario.yaml --out {run_dir} --resume` (with plant.isolation: auto "
                 "the plant then runs in a worker process)")
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:  # noqa: BLE001 - ending anyway
            pass
    try:
        os.write(2, f"\nprlpid-fmi: error: {text}\n".encode("utf-8", "replace"))
    finally:
        os._exit(code)
