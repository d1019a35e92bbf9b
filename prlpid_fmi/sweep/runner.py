"""Running a sweep's trials: local processes (default) or Ray tasks; each trial is an ordinary run directory.

Layout of a sweep's output folder::

    <out>/sweep.yaml                  the sweep file as given
    <out>/sweep.json                  the sweep, its variants and one record per invocation (command, wall time)
    <out>/<variant>/scenario.yaml     the variant's resolved scenario (what every trial of it runs)
    <out>/<variant>/seed<k>/          a run directory made by run.tune (scenario.yaml, run.json, metrics.json, ...)
    <out>/summary.csv, summary.md, trials.csv, learning_curves.png, metrics.png   (summary.py)

A trial whose run.json says "finished" is never run again; one that started and did not finish resumes
from its latest checkpoint (`tune --resume`); a trial folder without run.json holds nothing of value and
starts over. Before anything runs, every existing trial's scenario is compared with the sweep's: a sweep
file edited since the folder was made is refused (one line per differing trial), never mixed in.

Local execution: a ProcessPoolExecutor with the spawn start method, one trial per process at a time,
torch on one thread. Ray: one Ray task per trial (1 CPU each) on the cluster `ray.init` connects to;
several machines need `--out` on a file system every node sees, and prlpid-fmi installed on each.
"""
from __future__ import annotations

import dataclasses
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Optional

from prlpid_fmi import rundir as rd
from prlpid_fmi.errors import ArgumentError, Interrupted, PrlPidError
from prlpid_fmi.run.record import RunRecord
from prlpid_fmi.rundir import write_atomic, write_json
from prlpid_fmi.sweep.spec import Sweep

SWEEP_COPY = "sweep.yaml"
SWEEP_INFO = "sweep.json"
NEW, UNFINISHED, FINISHED, STALE = "new", "unfinished", "finished", "stale"
STOP_TIMEOUT_S = 60.0  # how long a stopped sweep waits for its workers to save their checkpoints
CONNECT_TIMEOUT_S = 5.0  # how long `--ray host:port` may take to answer before the sweep gives up


@dataclass(frozen=True)
class Trial:
    """One variant at one seed: the scenario file it runs and its run directory (absolute paths)."""

    variant: str
    seed: int
    scenario_file: str
    run_dir: str
    timesteps: Optional[int]

    @property
    def label(self) -> str:
        return f"{self.variant}/seed{self.seed}"


def variant_dir(out: Path, variant: str) -> Path:
    return out / variant


def trial_dir(out: Path, variant: str, seed: int) -> Path:
    return out / variant / f"seed{seed}"


def plan(sweep: Sweep, out: Path) -> list[Trial]:
    """Every trial of the sweep, variant by variant, seed by seed."""
    out = out.resolve()
    return [Trial(v.name, s, str(variant_dir(out, v.name) / rd.SCENARIO), str(trial_dir(out, v.name, s)),
                  sweep.timesteps)
            for v in sweep.variants for s in sweep.seeds]


def trial_status(run_dir: str | Path) -> str:
    """new (no folder or empty), finished (run.json has "finished"), unfinished (resumable) or stale (a folder
    without run.json: a start that never got going)."""
    d = Path(run_dir)
    if not d.is_dir() or not any(d.iterdir()):
        return NEW
    if not (d / rd.RUN_INFO).is_file():
        return STALE
    record = RunRecord.read(d)
    if record is None:
        return STALE
    return FINISHED if record.finished else UNFINISHED


def _first_difference(a, b, path: str = "") -> Optional[tuple[str, object, object]]:
    """(key path, value in a, value in b) of the first place two YAML-like documents differ, or None."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in list(a) + [k for k in b if k not in a]:
            d = _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else str(k))
            if d:
                return d
        return None
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            d = _first_difference(x, y, f"{path}[{i}]")
            if d:
                return d
        return None
    return None if a == b else (path or "(top level)", a, b)


def expected_scenario(sweep: Sweep, trial: Trial):
    """The Scenario a trial's run directory must hold: its variant's, with the trial's seed and budget."""
    variant = next(v for v in sweep.variants if v.name == trial.variant)
    s = variant.scenario
    agent = dataclasses.replace(s.agent, seed=trial.seed, total_timesteps=trial.timesteps or s.agent.total_timesteps)
    return dataclasses.replace(s, agent=agent)


def check_existing(sweep: Sweep, trials: list[Trial]) -> list[str]:
    """One line per existing trial whose scenario differs from what the sweep asks for now."""
    from prlpid_fmi.scenario.load import load_scenario, scenario_to_dict
    from prlpid_fmi.schema.messages import show

    lines = []
    for t in trials:
        file = Path(t.run_dir) / rd.SCENARIO
        if trial_status(t.run_dir) not in (UNFINISHED, FINISHED) or not file.is_file():
            continue
        try:
            have = scenario_to_dict(load_scenario(file))
        except PrlPidError as exc:
            lines.append(f"{file}: cannot be read ({str(exc).splitlines()[0]}; expected the scenario `tune` wrote)")
            continue
        diff = _first_difference(have, scenario_to_dict(expected_scenario(sweep, t)))
        if diff:
            key, got, want = diff
            lines.append(f"{file}: {key}: differs from the sweep's variant {t.variant} (got {show(got)}; expected "
                         f"{show(want)}: the sweep file changed since this trial ran; use another {{out}})")
    return lines


# -- one trial, in a worker ------------------------------------------------------------------------
def _one_thread() -> None:
    """A worker's math libraries on one thread (set before torch or numpy start their pools), and its fixed-PID
    search in its own process (tuning.search_pool): the sweep runs one trial per core already."""
    from prlpid_fmi.tuning.search_pool import WORKERS_ENV

    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", WORKERS_ENV):
        os.environ[var] = "1"


_WORKER = {"in_trial": False, "stopping": False}  # a local worker's state, read by its SIGTERM handler


def _local_worker() -> None:
    """Initializer of a local worker process: one thread; Ctrl-C is for the sweep's process, which stops the
    workers with SIGTERM. During a trial, SIGTERM raises Interrupted once, so the trial unwinds as `tune` does on
    Ctrl-C (the training saves a checkpoint, the run is marked as ended cleanly) and `--resume` continues it; a
    second SIGTERM while it unwinds is ignored. Outside a trial (idle, or sending a finished trial's result back)
    the worker exits at once: there is nothing to unwind, and an Interrupted raised inside the executor's own
    code would be caught there and leave a worker that no longer listens, running the next trial to its end."""
    import signal

    from prlpid_fmi.errors import Interrupted

    def stop(signum, frame):
        if not _WORKER["in_trial"]:
            os._exit(128 + signum)
        if not _WORKER["stopping"]:
            _WORKER["stopping"] = True
            raise Interrupted(signum)

    _one_thread()
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, stop)


def run_trial(trial: Trial) -> dict:
    """Run (or resume) one trial with run.tune; never raises for a failed trial.

    Returns {"status": "finished earlier" | "done" | "failed", "wall_s": seconds, "error": one line}.
    """
    _one_thread()
    import torch

    from prlpid_fmi.run.tune import tune

    torch.set_num_threads(1)
    status = trial_status(trial.run_dir)
    if status == FINISHED:
        return {"status": "finished earlier", "wall_s": 0.0}
    start = time.perf_counter()
    _WORKER["in_trial"] = True
    try:
        if status == STALE:
            shutil.rmtree(trial.run_dir)
        tune(trial.scenario_file, timesteps=trial.timesteps, seed=trial.seed, out=trial.run_dir,
             resume=status == UNFINISHED, progress_bar=False)
    except Exception as exc:  # a failed trial is a result of the sweep, not the end of it
        text = " ".join(str(exc).split())
        error = text if isinstance(exc, PrlPidError) else f"{type(exc).__name__}: {text}"
        return {"status": "failed", "wall_s": time.perf_counter() - start, "error": error}
    except Interrupted as exc:  # the sweep is stopping: the trial has unwound; this worker takes no further trial
        os._exit(128 + exc.signum)
    finally:
        _WORKER["in_trial"] = False
    return {"status": "resumed" if status == UNFINISHED else "done", "wall_s": time.perf_counter() - start}


# -- backends --------------------------------------------------------------------------------------
def run_local(trials: list[Trial], workers: int) -> Iterator[tuple[Trial, dict]]:
    """Trials in `workers` spawned processes; yields (trial, result) as each one ends."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_local_worker)
    try:
        futures = {pool.submit(run_trial, t): t for t in trials}
        for fut in as_completed(futures):
            try:
                result = fut.result()
            except Exception as exc:  # the worker process died (killed, out of memory, a crash in native code)
                result = {"status": "failed", "wall_s": 0.0, "error": f"{type(exc).__name__}: {exc}"}
            yield futures[fut], result
    except BaseException:  # Ctrl-C or an error here: stop the running trials (they resume on the next start)
        workers_now = list((pool._processes or {}).values())  # ProcessPoolExecutor has no public kill before 3.14
        pool.shutdown(wait=False, cancel_futures=True)
        for process in workers_now:
            process.terminate()
        for process in workers_now:
            process.join(STOP_TIMEOUT_S)
        raise
    pool.shutdown()


def _unreachable(address: str) -> Optional[str]:
    """Why a "host:port" or "ray://host:port" address cannot be reached (None: it can, or another form such as
    "auto"). ray.init retries an unreachable address for minutes; this answers in seconds."""
    import socket

    host, sep, port = address.removeprefix("ray://").rpartition(":")
    if not sep or not port.isdigit():
        return None
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        return exc.strerror or str(exc) or type(exc).__name__
    return None


def connect_ray(address: Optional[str]) -> bool:
    """ray.init on the cluster at `address` (None: Ray's default: RAY_ADDRESS, else a new local instance without
    dashboard). Returns True when this call initialised Ray (then run_ray shuts it down); a Ray already
    initialised in this process is used as it is."""
    try:
        import ray
    except ImportError:
        raise ArgumentError("{ray}: Ray is not installed (got no module 'ray'; expected `pip install "
                            "\"prlpid-fmi[ray]\"` or `pip install \"ray[default]\"`)") from None
    if ray.is_initialized():
        return False
    expected = "expected the address of a running Ray cluster: host:6379, ray://host:10001 or auto"
    reason = _unreachable(address) if address else None
    if reason:
        raise ArgumentError(f"{{ray}} {address}: cannot reach a Ray cluster there (got {reason}; {expected})")
    import logging

    kwargs: dict = {"address": address, "log_to_driver": False, "logging_level": logging.WARNING}
    if address is None and not os.environ.get("RAY_ADDRESS"):
        kwargs["include_dashboard"] = False  # a new local instance: no web dashboard
    try:
        ray.init(**kwargs)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise ArgumentError(f"{{ray}} {address or ''}: cannot connect (got {' '.join(str(exc).split())}; "
                            f"{expected})") from None
    return True


def run_ray(trials: list[Trial], started: bool) -> Iterator[tuple[Trial, dict]]:
    """Trials as Ray tasks (1 CPU each) on the cluster connect_ray joined; yields (trial, result) as each one
    ends. started: connect_ray's answer (Ray is shut down at the end when this sweep started it)."""
    import ray

    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(run_trial)
        pending = {remote.remote(t): t for t in trials}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                trial = pending.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception as exc:  # the task's worker died or the node was lost
                    result = {"status": "failed", "wall_s": 0.0,
                              "error": f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}"}
                yield trial, result
    finally:
        if started:
            ray.shutdown()


# -- the sweep -------------------------------------------------------------------------------------
@dataclass
class SweepRun:
    """What run_sweep did: the output folder, the summary files, and the trials that failed ((label, error))."""

    out: Path
    summary_files: list[Path]
    failed: list[tuple[str, str]]
    wall_s: float


def default_out(sweep: Sweep) -> Path:
    """runs/sweeps/<name>: the same folder every time, so running the command again continues the sweep."""
    return Path("runs") / "sweeps" / sweep.name


def run_sweep(path: str | Path, out: str | Path | None = None, workers: Optional[int] = None,
              ray: bool = False, ray_address: Optional[str] = None,
              log: Callable[[str], None] = lambda line: None) -> SweepRun:
    """Validate the sweep, run its unfinished trials (locally in `workers` processes, default one per core, or
    on Ray), then write the summary. `log` gets one progress line per event."""
    from prlpid_fmi.sweep.spec import load_sweep
    from prlpid_fmi.sweep.summary import write_summary

    if workers is not None and workers < 1:
        raise ArgumentError(f"{{workers}}: must be at least 1 (got {workers}; expected a number of processes >= 1)")
    if ray and workers is not None:
        raise ArgumentError(f"{{workers}}: not used with {{ray}} (got {{workers}} {workers}; expected no {{workers}}: "
                            "Ray runs one trial per free CPU of the cluster)")
    started, t0 = rd.now(), time.perf_counter()
    sweep = load_sweep(path)
    out = Path(out) if out is not None else default_out(sweep)
    if out.exists() and not out.is_dir():
        raise ArgumentError(f"{out}: is a file, not a folder (got {{out}} {out}; expected a folder for the sweep)")
    trials = plan(sweep, out)
    mismatched = check_existing(sweep, trials)
    if mismatched:
        raise ArgumentError("\n".join(mismatched))

    status = {t: trial_status(t.run_dir) for t in trials}
    todo = [t for t in trials if status[t] != FINISHED]
    ray_started = connect_ray(ray_address) if ray and todo else False  # before anything is written

    from prlpid_fmi.scenario.load import scenario_to_yaml

    write_atomic(out / SWEEP_COPY, Path(path).read_text(encoding="utf-8"))
    for v in sweep.variants:
        write_atomic(variant_dir(out, v.name) / rd.SCENARIO, scenario_to_yaml(v.scenario))
    n_workers = min(workers or os.cpu_count() or 1, max(len(todo), 1))
    where = f"Ray ({ray_address or 'default address'})" if ray else f"{n_workers} local process(es)"
    log(f"sweep {sweep.name}: {len(sweep.variants)} variant(s) x {len(sweep.seeds)} seed(s) = {len(trials)} trials; "
        f"{len(trials) - len(todo)} finished earlier, " + (f"{len(todo)} to run on {where}" if todo else "none to run")
        + f"; output {out}")

    failed: list[tuple[str, str]] = []
    record = {"started": started, "command": sys.argv, "backend": "ray" if ray else "local",
              "ray_address": ray_address, "workers": None if ray else n_workers, "trials_run": 0}
    interrupted: BaseException | None = None
    if todo:
        results = run_ray(todo, ray_started) if ray else run_local(todo, n_workers)
        try:
            for i, (trial, result) in enumerate(results, 1):
                record["trials_run"] = i
                line = f"[{i}/{len(todo)}] {trial.label}: {result['status']} in {result['wall_s']:.1f} s"
                if result["status"] == "failed":
                    failed.append((trial.label, result["error"]))
                    line += f": {result['error']}"
                log(line)
        except (KeyboardInterrupt, Interrupted) as exc:  # Ctrl-C or SIGTERM: the running trials were stopped
            interrupted = exc
    record.update(finished=rd.now(), wall_s=round(time.perf_counter() - t0, 3), failed=dict(failed),
                  interrupted=interrupted is not None)
    _append_invocation(out, sweep, record)
    files = write_summary(sweep, out, trials, [f"{label}: {error}" for label, error in failed])
    wall = time.perf_counter() - t0
    if interrupted is not None:
        log(f"sweep {sweep.name}: interrupted after {wall:.1f} s; summary of the finished trials in "
            f"{out / 'summary.md'}; the same command continues the sweep")
        raise interrupted
    log(f"sweep {sweep.name}: done in {wall:.1f} s; summary in {out / 'summary.md'}")
    return SweepRun(out, files, failed, wall)


def _append_invocation(out: Path, sweep: Sweep, record: dict) -> None:
    info_path = out / SWEEP_INFO
    info = json.loads(info_path.read_text()) if info_path.is_file() else {}
    info.update(name=sweep.name, sweep_file=str(Path(sweep.path).resolve()), base_scenario=str(sweep.base),
                seeds=list(sweep.seeds), timesteps=sweep.timesteps,
                set={k: val for k, val, origin in sweep.variants[0].overrides if origin == "set"},
                variants={v.name: {k: val for k, val, origin in v.overrides if origin != "set"} for v in sweep.variants},
                versions=rd.package_versions())
    info.setdefault("invocations", []).append(record)
    write_json(info_path, info)
