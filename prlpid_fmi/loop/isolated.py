"""Crash isolation: the closed loop (plant FMU, prior, PID, reward) in a worker process.

`IsolatedCore` has LoopCore's interface for its drivers (the agent's env, the fixed-PID search, the
schedule replay, evaluation): `reset`, `step`, `step_control`, `begin_step`, `close` and the signals
they read after each call. Each call is one message over a pipe to a worker process that holds a
real LoopCore. When the FMU kills the worker (a segmentation fault, an abort), the episode ends with
the divergence penalty and a Termination of kind "crash" naming the FMU and the time; the next
`reset` starts a fresh worker. A worker that crashes while resetting twice in a row is a PlantError.

Workers come from prlpid_fmi.fmu.worker (the fork server, FMUs extracted once by the parent), so a
restart costs a fork and the FMU's instantiation, not an interpreter start.

`plant.isolation` in a scenario: "none" runs LoopCore in this process (the fast path, unchanged);
"process" runs IsolatedCore; "auto" is "none" until `tune --resume` finds the run ended in a crash.
"""
from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu.plant import extracted_folders, reuse_extracted
from prlpid_fmi.fmu.resolve import resolve_fmu
from prlpid_fmi.fmu.worker import JOIN_TIMEOUT_S, become_worker, mp_context, signal_name
from prlpid_fmi.loop.core import LoopConstants, LoopCore, Termination

_SNAPSHOT = ("k", "setpoint", "measurement", "previous_error", "applied_setpoint", "control_signal", "pid_output",
             "forecast_reward", "step_reward", "termination")
_warned: set[str] = set()


def runs_isolated(config: TuningConfig) -> bool:
    """Whether `config` puts the plant in a worker process (isolation "process")."""
    return config.isolation == "process"


def make_core(config: TuningConfig, forecast_path: str = "auto"):
    """The loop core `config` asks for: LoopCore in this process, or IsolatedCore in a worker."""
    if runs_isolated(config):
        return IsolatedCore(config, forecast_path)
    return LoopCore(config, forecast_path)


# -- the worker ------------------------------------------------------------------------------------
def _snapshot(core: LoopCore) -> tuple:
    return tuple(getattr(core, name, None) for name in _SNAPSHOT)


def _serve(conn, config: TuningConfig, forecast_path: str, extracted: dict) -> None:
    """Worker main: build a LoopCore, then answer (operation, arguments) messages until "close" or EOF."""
    become_worker()  # the parent decides when to stop
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
    """The worker process ended while a call was under way."""


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
        self._rng = None
        self.k = 0
        self.termination: Termination | None = None
        self.forecast_reward = self.step_reward = None
        self._start()

    # -- the worker's life --------------------------------------------------------------------
    def _start(self) -> None:
        ctx = mp_context()
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_serve, args=(child, self.config, self.forecast_path, self._extracted),
                           name=f"prlpid-fmi plant {self.plant.path.name}", daemon=True)
        proc.start()
        child.close()
        self._proc, self._conn, self._rng = proc, parent, None
        try:
            self._receive()
        except _WorkerDied:
            raise PlantError(f"{self.plant.path.name}: the FMU crashed ({signal_name(proc.exitcode)}) in its worker "
                             "process while being instantiated") from None

    def _receive(self):
        try:
            tag, payload = self._conn.recv()
        except (EOFError, OSError):
            self._proc.join(JOIN_TIMEOUT_S)
            raise _WorkerDied() from None
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
        return self._receive()

    def _lost(self) -> str:
        """Forget the dead worker; returns how it ended ('SIGSEGV', ...)."""
        how = signal_name(self._proc.exitcode)
        self._conn.close()
        self._proc = self._conn = None
        self.crashes += 1
        return how

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
                how = self._lost()
                if attempt == 2:
                    raise PlantError(f"{self.plant.path.name}: the FMU crashed ({how}) in its worker process while "
                                     "resetting to t = 0 s, twice; it cannot be run") from None

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
        how = self._lost()
        t = self.k * self.config.sample_time_s
        self.k += 1
        self.forecast_reward = self.step_reward = None
        name = self.plant.path.name
        self.termination = Termination("crash", self.k, t, f"{name} crashed ({how}) in the step from t = {t:g} s")
        if name not in _warned:
            _warned.add(name)
            warnings.warn(f"{name} crashed ({how}) in its worker process at t = {t:g} s: the episode ends with the "
                          "divergence penalty and a fresh worker starts the next one", stacklevel=3)
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
