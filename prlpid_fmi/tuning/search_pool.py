"""A search's cost evaluations on all cores: worker processes, each with its own FMU instances.

Differential evolution asks for a whole generation at once (scipy's `vectorized`, deferred updating); `SearchPool.map`
hands its vectors out one at a time to whichever process is free: the worker processes (each built its evaluator
once from a picklable factory: its own loop cores on its own FMU instances) and this process, which evaluates on
the caller's own evaluator between hand-outs. The results come back in the order of the vectors, and each is what
the same evaluation gives in this process, so a search's result does not depend on the number of workers.

A worker that dies (an FMU that crashes it) or hangs (its step watchdog ends it) hands its vector back: it and
everything after are evaluated in this process, where the FMU behaves as it does without a pool. The crash is noted
(fmu.worker.note_crash), so loop cores made from then on run the plant in a worker process (plant.isolation auto); a
crash of this process's own cores ends it, and the CLI's supervising parent resumes the run isolated (run.supervise).

Workers fork from the fork server of prlpid_fmi.fmu.worker, the FMUs extracted once by this process.
"""
from __future__ import annotations

import os
from collections import deque
from pathlib import Path
from multiprocessing.connection import wait

from prlpid_fmi import runcontext
from prlpid_fmi.fmu.plant import FmuPlant, extracted_folders, reuse_extracted
from prlpid_fmi.fmu.watchdog import in_worker
from prlpid_fmi.fmu.worker import JOIN_TIMEOUT_S, become_worker, mp_context, note_crash, signal_name
from prlpid_fmi.loop.isolated import IsolatedCore

QUEUED = 2  # vectors handed to a worker at a time
WORKERS_ENV = "PRLPID_FMI_SEARCH_WORKERS"  # processes per search where set (a sweep's trial: 1), else one per core


def search_workers(requested: int | None, cores=()) -> int:
    """Processes a search evaluates on, this one included: `requested` (baseline.workers), else WORKERS_ENV, else
    the CPU cores this process may run on; 1 inside a worker process (its parent already uses the cores) and where
    one of the search's loop `cores` runs in a worker process already (plant.isolation "process", or an FMU that may
    be instantiated once per process)."""
    if in_worker() or any(isinstance(c, IsolatedCore) for c in cores):
        return 1
    if requested is not None:
        return max(1, int(requested))
    env = os.environ.get(WORKERS_ENV, "").strip()
    if env.isdigit():
        return max(1, int(env))
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def search_fmus(config) -> list:
    """The FMU files a search's loop cores on `config` open (its plant; the forecast is off in a search)."""
    from prlpid_fmi.fmu.resolve import resolve_fmu

    return [resolve_fmu(config.fmu, config.fmi_version)]


def _serve(conn, factory, args, extracted: dict, options: dict) -> None:
    """Worker main: evaluator = factory(*args), then answer (method, vector) with method(vector) until EOF. options:
    become_worker's (the parent's environment, step timeout and output check). No crumb file: a worker that dies
    hands its vectors back, so nothing reports its crash."""
    become_worker(conn, **options)
    reuse_extracted(extracted)
    try:
        evaluator = factory(*args)
    except Exception as exc:  # noqa: BLE001 - the parent evaluates everything itself then
        conn.send(("error", repr(exc)))
        return
    conn.send(("ok", None))
    try:
        while True:
            try:
                message = conn.recv()
            except (EOFError, OSError):
                break
            if message is None:
                break
            method, vector = message
            try:
                reply = ("ok", getattr(evaluator, method)(vector))
            except Exception as exc:  # noqa: BLE001 - the parent evaluates this vector itself and sees it
                reply = ("error", repr(exc))
            conn.send(reply)
    finally:
        close = getattr(evaluator, "close", None)
        if close is not None:
            close()


class SearchPool:
    """`workers` - 1 worker processes beside this one for the evaluations of one search.

    local: this process's evaluator (its methods are what `map` calls); factory(*args) builds a worker's (picklable,
    a module-level function); fmus: the FMU files the evaluator opens (extracted here once). With workers <= 1 no
    process is started and `map` evaluates on `local` alone. Close it (or use it as a context manager)."""

    def __init__(self, local, factory, args: tuple, workers: int, fmus=()):
        self.local = local
        self._fmus = list(fmus)
        self._workers: list = []  # (process, connection)
        if workers <= 1:
            return
        ctx = mp_context()
        extracted = extracted_folders(fmus)
        options = {"environ": dict(os.environ), "step_timeout_s": runcontext.current().step_timeout_s,
                   "check_outputs": FmuPlant.check_outputs}  # what this process's FMU calls run under
        for _ in range(workers - 1):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_serve, args=(child, factory, args, extracted, options), daemon=True)
            try:
                proc.start()
            except (OSError, RuntimeError):  # no process to be had (a main module without its __main__ guard)
                parent.close()
                break
            finally:
                child.close()
            self._workers.append((proc, parent))
        ready = []
        for worker in self._workers:  # a worker whose evaluator could not be built is not used
            try:
                ok = worker[1].recv()[0] == "ok"
            except (EOFError, OSError):
                ok = False
            if ok:
                ready.append(worker)
            else:
                self._end(worker)
        self._workers = ready

    @property
    def size(self) -> int:
        """Processes evaluating: the workers and this one."""
        return len(self._workers) + 1

    def map(self, method: str, vectors) -> list:
        """[getattr(evaluator, method)(v) for v in vectors], on the workers and here, in the order of `vectors`.

        Each worker has up to QUEUED vectors handed to it, so it starts the next the moment it sends a result, while
        this process is inside an evaluation of its own."""
        vectors = list(vectors)
        results = [None] * len(vectors)
        todo = deque(range(len(vectors)))
        queued = {worker[1]: (worker, deque()) for worker in self._workers}  # connection -> (worker, indices)
        local = getattr(self.local, method)

        def hand_out():
            for conn, (worker, indices) in list(queued.items()):
                while todo and len(indices) < QUEUED:
                    i = todo.popleft()
                    try:
                        conn.send((method, vectors[i]))
                    except (BrokenPipeError, OSError):
                        todo.appendleft(i)
                        lose(conn, "lost")
                        break
                    indices.append(i)

        def lose(conn, tag="error", payload=None):
            worker, indices = queued.pop(conn)
            todo.extendleft(reversed(indices))  # evaluated here (or by the others), in order
            self._lose(worker)
            if tag != "error":  # it died or hung: the FMU, not the evaluation, ended it
                names = ", ".join(Path(p).name for p in self._fmus) or "the FMU"
                note_crash(self._fmus, payload if tag == "hang" else
                           f"{names} crashed ({signal_name(worker[0].exitcode)}) in a worker process of a search")

        while todo or any(indices for _, indices in queued.values()):
            hand_out()
            busy = [conn for conn, (_, indices) in queued.items() if indices]
            if todo:  # this process takes the next one while the workers compute theirs
                i = todo.popleft()
                results[i] = local(vectors[i])
                ready = wait(busy, timeout=0) if busy else []
            else:
                ready = wait(busy)
            for conn in ready:
                while conn in queued and queued[conn][1] and conn.poll():
                    try:
                        tag, payload = conn.recv()
                    except (EOFError, OSError):
                        tag, payload = "lost", None
                    if tag != "ok":  # an error, a hang (the watchdog's line) or a crash: evaluated here
                        lose(conn, tag, payload)
                        break
                    results[queued[conn][1].popleft()] = payload
        return results

    def _lose(self, worker) -> None:
        if worker in self._workers:
            self._workers.remove(worker)
        self._end(worker)

    @staticmethod
    def _end(worker) -> None:
        proc, conn = worker
        try:
            conn.send(None)
        except (BrokenPipeError, OSError):
            pass
        conn.close()
        proc.join(JOIN_TIMEOUT_S)
        if proc.is_alive():
            proc.kill()
            proc.join(JOIN_TIMEOUT_S)

    def close(self) -> None:
        for worker in self._workers:
            self._end(worker)
        self._workers = []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
