"""Crash isolation: the closed loop (plant FMU, prior, PID, reward) in a worker process.

`IsolatedCore` has LoopCore's interface for its drivers (the agent's env, the fixed-PID search, the
schedule replay, evaluation): `reset`, `step`, `step_control`, `begin_step`, `close` and the signals
they read after each call. Each call is one message over a pipe to a worker process that holds a
real LoopCore. When the FMU kills the worker (a segmentation fault, an abort) or hangs in a call (the
worker's step watchdog ends it, or it does not answer within twice its step timeout and is killed),
the episode ends with the divergence penalty and a Termination of kind "crash" naming the FMU, the FMI
call and the time (read from the worker's crumb file, fmu.worker); the next `reset` starts a fresh
worker. A worker that crashes while resetting twice in a row is a PlantError naming the call.

Workers come from prlpid_fmi.fmu.worker (the fork server, FMUs extracted once by the parent), so a
restart costs a fork and the FMU's instantiation, not an interpreter start.

`plant.isolation` in a scenario: "none" runs LoopCore in this process (the fast path, unchanged);
"process" runs IsolatedCore; "auto" is "none" until an FMU of the loop has crashed (or hung) a worker process of
this process (any worker: the loop check, a margin experiment, a search pool's, an isolated core's;
fmu.worker.note_crash), or `tune --resume` finds the run ended abruptly; from then on it is "process".
"""
from __future__ import annotations

import dataclasses
import os
import statistics
import time
import warnings
from collections import deque
from pathlib import Path

import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu.plant import extracted_folders, reuse_extracted
from prlpid_fmi.fmu.resolve import resolve_fmu
from prlpid_fmi.fmu.watchdog import MIN_STEP_TIMEOUT_S, STEP_TIMEOUT_FACTOR
from prlpid_fmi.fmu.worker import (JOIN_TIMEOUT_S, become_worker, crash_seen, crash_text, mp_context,
                                   new_crumb_file, note_crash, read_crumb, remove_crumb_file, signal_name)
from prlpid_fmi.loop.core import LoopConstants, LoopCore, Termination

_SNAPSHOT = ("k", "setpoint", "measurement", "previous_error", "applied_setpoint", "control_signal", "pid_output",
             "forecast_reward", "step_reward", "termination")
_warned: set[str] = set()


_switched: dict[str, str] = {}  # plant FMU file -> the crash line that put it in a worker process (auto)


def loop_fmus(config: TuningConfig) -> list[Path]:
    """The FMU files a loop core on `config` opens: the plant, and a prior FMU of its own when it forecasts."""
    paths = [resolve_fmu(config.fmu, config.fmi_version)]
    if config.prior.fmu and config.forecast_horizon:
        paths.append(resolve_fmu(config.prior.fmu, config.fmi_version))
    return paths


def runs_isolated(config: TuningConfig) -> bool:
    """Whether `config` puts the plant in a worker process: isolation "process", or "auto" once one of its FMUs
    crashed a worker process of this process (said once per FMU, in one warning; crash_isolation)."""
    if config.isolation != "auto":
        return config.isolation == "process"
    return crash_isolation(config) is not None


def crash_isolation(config: TuningConfig) -> str | None:
    """For isolation "auto": the line of the worker crash that put the plant in a worker process for the rest of
    this process's run (None: none seen). The first time, one warning says so."""
    paths = loop_fmus(config)
    line = crash_seen(paths)
    if line is not None and str(paths[0]) not in _switched:
        _switched[str(paths[0])] = line
        warnings.warn(f"{line}; the plant runs in a worker process for the rest of this run (plant.isolation: "
                      "process)", stacklevel=3)
    return line


def make_core(config: TuningConfig, forecast_path: str = "auto"):
    """The loop core `config` asks for: LoopCore in this process, or IsolatedCore in a worker."""
    if runs_isolated(config):
        return IsolatedCore(config, forecast_path)
    return LoopCore(config, forecast_path)


def _step_alone(config: TuningConfig, steps: int) -> int:
    """In a worker: the plant FMU as the only instance, its inputs held at their start values, `steps` samples."""
    from prlpid_fmi.loop.core import plant_limits
    from prlpid_fmi.fmu import FmuPlant

    inputs, outputs = [l.input for l in config.loops], [l.output for l in config.loops]
    with FmuPlant(resolve_fmu(config.fmu, config.fmi_version), inputs, outputs, config.sample_time_s,
                  config.plant_parameters, "plant", **plant_limits(config)) as plant:
        u = plant.get(inputs).tolist()
        for _ in range(steps):
            plant.step_values(u)
    return steps


def plant_alone_survives(config: TuningConfig, until_s: float) -> bool:
    """Whether the plant FMU alone (one instance in a worker process, no prior, its inputs held at their start
    values) steps past until_s [s] plus the forecast's horizon without crashing or failing: the test that tells a
    crash of the forecast's prior (its second instance) from one the plant meets at that time anyway."""
    from prlpid_fmi.fmu.worker import call_in_worker

    steps = int(np.ceil(until_s / config.sample_time_s - 1e-9)) + config.forecast_horizon + 1
    path = resolve_fmu(config.fmu, config.fmi_version)
    try:
        call_in_worker(_step_alone, config, steps, fmus=[path], what="the check of the plant without its prior",
                       step_timeout_s=config.step_timeout_s)
    except Exception:  # noqa: BLE001 - a crash, a hang or a failed step: the plant fails alone too
        return False
    return True


# -- the worker ------------------------------------------------------------------------------------
def _snapshot(core: LoopCore) -> tuple:
    return tuple(getattr(core, name, None) for name in _SNAPSHOT)


SETUP_ALLOWANCE_S = 30.0  # a reset or start message may take this much longer than a step one [s]


def _serve(conn, config: TuningConfig, forecast_path: str, extracted: dict, crumb_path: str,
           environ: dict | None = None) -> None:
    """Worker main: build a LoopCore, then answer (operation, arguments) messages until "close" or EOF; environ: the
    parent's environment (fmu.worker.become_worker)."""
    become_worker(conn, crumb_path, environ=environ)  # the parent decides when to stop
    reuse_extracted(extracted)
    try:
        core = LoopCore(config, forecast_path)
    except Exception as exc:  # noqa: BLE001 - sent to the parent, raised there
        conn.send(("error", exc))
        return
    conn.send(("ok", None))
    rng = None
    while True:
        try:
            op, args = conn.recv()
        except (EOFError, OSError):
            break
        try:
            if op == "step":
                reward, terminated = core.step(*args)
                conn.send(("ok", (reward, terminated, _snapshot(core))))
            elif op == "step_control":
                reward, terminated = core.step_control(args)
                conn.send(("ok", (reward, terminated, _snapshot(core))))
            elif op == "reset":
                state, schedule = args
                if state is not None or rng is None:
                    rng = np.random.Generator(np.random.PCG64())
                    rng.bit_generator.state = state
                core.reset(rng, schedule)
                conn.send(("ok", _snapshot(core)))
            elif op == "set_structure":
                core.set_structure(*args)
                conn.send(("ok", None))
            elif op == "begin_step":
                core.begin_step()
                conn.send(("ok", None))
            elif op == "get":
                conn.send(("ok", core.plant.get(args)))
            elif op == "set":
                core.plant.set(args)
                conn.send(("ok", None))
            elif op == "close":
                core.close()
                conn.send(("ok", None))
                break
            else:
                conn.send(("error", ValueError(f"unknown operation {op!r}")))
        except Exception as exc:  # noqa: BLE001
            conn.send(("error", exc))
    conn.close()


class _WorkerDied(Exception):
    """The worker process ended while a call was under way (args: the watchdog's line, when it sent one)."""


class _RemotePlant:
    """The plant as the drivers see it through IsolatedCore: its description, and get/set by name."""

    def __init__(self, core: "IsolatedCore", path: Path):
        from prlpid_fmi.fmu import describe_fmu

        self._core = core
        self.path = path
        self.description = describe_fmu(path)
        self.inputs = tuple(l.input for l in core.config.loops)
        self.outputs = tuple(l.output for l in core.config.loops)

    def get(self, names) -> np.ndarray:
        return np.asarray(self._core._call("get", list(names)), dtype=float)

    def set(self, values) -> None:
        self._core._call("set", dict(values))


class IsolatedCore(LoopConstants):
    """LoopCore's interface with the loop in a worker process (see the module docstring).

    Args: as LoopCore. Attributes read after reset/step: as LoopCore (setpoint, measurement,
    previous_error, applied_setpoint, control_signal, pid_output, forecast_reward, step_reward, k,
    termination), plus `crashes` (worker processes lost to the FMU so far).
    """

    def __init__(self, config: TuningConfig, forecast_path: str = "auto"):
        c = config
        self.set_loop_constants(c)
        self.forecast_path = forecast_path
        path = resolve_fmu(c.fmu, c.fmi_version)
        paths = [path] + ([resolve_fmu(c.prior.fmu, c.fmi_version)] if c.prior.fmu and c.forecast_horizon else [])
        self._extracted = extracted_folders(paths)
        self.plant = _RemotePlant(self, path)
        self.prior = self.forecast = self.pid = None  # in the worker
        self.crashes = 0
        self._proc = self._conn = None
        self._crumb = None
        self._hang = None           # the line of a worker that hung (its watchdog's, or the parent's)
        self._round_trips = deque(maxlen=15)  # [s] of step messages, for the default step timeout
        self._rng = None
        self.k = 0
        self.termination: Termination | None = None
        self.forecast_reward = self.step_reward = None
        self._start()

    # -- the worker's life --------------------------------------------------------------------
    def _start(self) -> None:
        ctx = mp_context()
        parent, child = ctx.Pipe()
        remove_crumb_file(self._crumb)
        self._crumb = new_crumb_file()
        proc = ctx.Process(target=_serve, args=(child, self.config, self.forecast_path, self._extracted, self._crumb,
                                                dict(os.environ)),
                           name=f"prlpid-fmi plant {self.plant.path.name}", daemon=True)
        proc.start()
        child.close()
        self._proc, self._conn, self._rng = proc, parent, None
        try:
            self._receive(self._backstop_s(setup=True))
        except _WorkerDied:
            raise PlantError(self._lost("the loop's start")) from None

    def _backstop_s(self, setup: bool = False) -> float:
        """How long the parent waits for an answer before it kills the worker [s]: twice the step timeout (the
        worker's own watchdog ends it first), plus SETUP_ALLOWANCE_S for a reset or the start."""
        timeout = self.config.step_timeout_s
        if timeout is None:
            measured = STEP_TIMEOUT_FACTOR * statistics.median(self._round_trips) if self._round_trips else 0.0
            timeout = max(MIN_STEP_TIMEOUT_S, measured)
        return 2.0 * timeout + 1.0 + (SETUP_ALLOWANCE_S if setup else 0.0)

    def _receive(self, wait_s: float):
        try:
            if not self._conn.poll(wait_s):
                self._hang = (f"{self.plant.path.name}: the worker process running the FMU did not answer within "
                              f"{wait_s:g} s (a call that never returns; plant.step_timeout_s) and was killed")
                self._proc.kill()
                self._proc.join(JOIN_TIMEOUT_S)
                raise _WorkerDied()
            tag, payload = self._conn.recv()
        except (EOFError, OSError):
            self._proc.join(JOIN_TIMEOUT_S)
            raise _WorkerDied() from None
        if tag == "hang":
            self._hang = payload
            self._proc.join(JOIN_TIMEOUT_S)
            raise _WorkerDied()
        if tag == "error":
            raise payload
        return payload

    def _call(self, op: str, args=None):
        if self._proc is None:
            self._start()
        try:
            self._conn.send((op, args))
        except (BrokenPipeError, OSError):
            self._proc.join(JOIN_TIMEOUT_S)
            raise _WorkerDied() from None
        if op not in ("step", "step_control"):
            return self._receive(self._backstop_s(setup=True))
        started = time.perf_counter()
        answer = self._receive(self._backstop_s())
        self._round_trips.append(time.perf_counter() - started)
        return answer

    def _lost(self, during: str = "the loop") -> str:
        """Forget the dead worker; returns one line: which FMU, how it ended, in which FMI call at what time."""
        how = signal_name(self._proc.exitcode)
        paths = [self.plant.path] + ([resolve_fmu(self.config.prior.fmu, self.config.fmi_version)]
                                     if self.config.prior.fmu and self.config.forecast_horizon else [])
        text = self._hang or crash_text(paths, self._crumb, how, during)
        note_crash(paths, text)
        found = read_crumb(self._crumb)
        if found and found[0] and found[1] == "reset":  # the next worker instantiates afresh instead
            from prlpid_fmi.fmu import verdicts

            verdicts.put(self.plant.path, "reset", f"it crashed the worker: {text}")
            warnings.warn(f"{text}; every episode instantiates the FMU afresh instead (remembered for this file)",
                          stacklevel=4)
        self._hang = None
        self._conn.close()
        self._proc = self._conn = None
        self.crashes += 1
        return text

    def _apply(self, snapshot: tuple) -> None:
        for name, value in zip(_SNAPSHOT, snapshot):
            setattr(self, name, value)

    # -- LoopCore's interface -----------------------------------------------------------------
    def reset(self, rng: np.random.Generator, setpoint_schedule=None) -> None:
        """As LoopCore.reset; a crashed worker is started afresh first (twice at most)."""
        for attempt in (1, 2):
            # the worker keeps drawing from its copy of `rng` over consecutive episodes of the same generator
            state = None if rng is self._rng and self._proc is not None else rng.bit_generator.state
            try:
                self._apply(self._call("reset", (state, setpoint_schedule)))
                self._rng = rng
                return
            except _WorkerDied:
                how = self._lost("a reset")
                if attempt == 2:
                    raise PlantError(f"{how}, while resetting to t = 0 s, twice; it cannot be run") from None

    def step(self, Kp, Ti, Td, coupling=None) -> tuple[float, bool]:
        """As LoopCore.step; a crash of the FMU ends the episode with the divergence penalty."""
        return self._step("step", (Kp, Ti, Td, coupling))

    def step_control(self, u) -> tuple[float, bool]:
        """As LoopCore.step_control."""
        return self._step("step_control", [float(x) for x in u])

    def _step(self, op: str, args) -> tuple[float, bool]:
        try:
            reward, terminated, snapshot = self._call(op, args)
        except _WorkerDied:
            return self._crashed()
        self._apply(snapshot)
        return reward, terminated

    def _crashed(self) -> tuple[float, bool]:
        found = read_crumb(self._crumb)
        instance = found[5] if found and found[0] else ""  # the instance inside an FMI call when it died
        how = self._lost()
        t = self.k * self.config.sample_time_s
        self.k += 1
        self.forecast_reward = self.step_reward = None
        name = self.plant.path.name
        self.termination = Termination("crash", self.k, t, f"{how} (the loop's step from t = {t:g} s)", instance)
        if name not in _warned:
            _warned.add(name)
            warnings.warn(f"{how}: the episode ends with the divergence penalty at t = {t:g} s and a fresh worker "
                          "starts the next one", stacklevel=3)
        return self.penalty, True

    def set_structure(self, setpoint_weight, derivative_weight, measurement_filter_s) -> None:
        """As LoopCore.set_structure; a restarted worker is built with it too."""
        structure = tuple(zip(map(float, setpoint_weight), map(float, derivative_weight), map(float, measurement_filter_s)))
        self.config = dataclasses.replace(self.config, tuned_structure=structure)
        if self._proc is not None:
            try:
                self._call("set_structure", (list(setpoint_weight), list(derivative_weight), list(measurement_filter_s)))
            except _WorkerDied:
                self._lost()

    def begin_step(self) -> None:
        self._call("begin_step")

    def close(self) -> None:
        """Stop the worker (idempotent)."""
        proc, conn = self._proc, self._conn
        self._proc = self._conn = None
        remove_crumb_file(self._crumb)
        self._crumb = None
        if proc is None:
            return
        try:
            conn.send(("close", None))
            conn.recv()
        except (EOFError, OSError):
            pass
        conn.close()
        proc.join(JOIN_TIMEOUT_S)
        if proc.is_alive():
            proc.kill()
            proc.join()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
