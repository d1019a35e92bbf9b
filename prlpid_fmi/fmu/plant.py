"""FmuPlant: one FMI 1.0, 2.0 or 3.0 co-simulation instance (or an FMI 2.0 model-exchange instance, integrated
by FMPy's CVode solver) driven step by step over FMPy.

The model description is read once, the FMU extracted once per file (instances of the same FMU
share the extraction), and value references are resolved at construction, so a step is one
set-inputs, one doStep and one get-outputs call on preallocated ctypes buffers.
It knows nothing about PID or RL.
"""
from __future__ import annotations

import atexit
import contextlib
import ctypes
import math
import shutil
import struct
import sys
import warnings
from ctypes import c_size_t
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu import verdicts, watchdog
from prlpid_fmi.fmu.adapters import adapter_class
from prlpid_fmi.fmu.description import FmuDescription, describe_fmu

_EXTRACTED: dict[tuple[str, float], str] = {}
STATUS_LABELS = ("ok", "warning", "discard", "error", "fatal", "pending")
RESET_CHECK_STEPS = 12          # steps of the once-per-FMU reset check (same inputs before and after a reset)
RESET_CHECK_RTOL = 1e-6         # the two runs agree to this fraction of the outputs' size
LONG_STOP_TIME_S = 1e7          # the stop time set up for an FMU known to stop at its default, where none is given
CALL_CODES = ("", "instantiate", "reset", "initialize", "step", "free")   # the worker's crumb.call
TINY = sys.float_info.min       # a nonzero |output| below this is a denormal: garbage, not a measurement
_warned_resets: set[str] = set()


class Crumb(ctypes.Structure):
    """The FMI call a process is in, in memory its parent reads after the process died (fmu.worker): busy (1 inside
    the call), call (index into CALL_CODES), plant (FmuPlant.crumb_id), role (index into CRUMB_ROLES: which instance
    of the loop, the plant or the forecast's prior), t [s]."""

    _fields_ = [("busy", ctypes.c_int32), ("call", ctypes.c_int32), ("plant", ctypes.c_int32),
                ("role", ctypes.c_int32), ("t", ctypes.c_double)]


CRUMB_ROLES = ("plant", "prior")  # Crumb.role: the FMI instance name of the loop's two instances (else 0)
crumb: Crumb | None = None      # set in a worker process, and in a supervised `tune` (fmu.worker.attach_crumb)
crumb_fmus: list[str] = []      # FMU file paths of this process's plants (each once), indexed by Crumb.plant
crumb_names = None              # where the worker's crumb file keeps them (fmu.worker.CrumbFile)


def extracted_folder(path: Path) -> str:
    """Extract an FMU once per (path, mtime); directories are removed at interpreter exit."""
    from fmpy import extract

    key = (str(path.resolve()), path.stat().st_mtime)
    if key not in _EXTRACTED:
        unzipdir = extract(str(path))
        atexit.register(shutil.rmtree, unzipdir, True)
        _EXTRACTED[key] = unzipdir
    return _EXTRACTED[key]


def extracted_folders(paths) -> dict:
    """{(path, mtime): folder} of these FMUs, extracted here once (a worker process reuses the folders through
    reuse_extracted; this process removes them at exit)."""
    return {(str(Path(p).resolve()), Path(p).stat().st_mtime): extracted_folder(Path(p)) for p in paths}


def reuse_extracted(folders: dict) -> None:
    """Use folders another process extracted (extracted_folders) instead of extracting the FMUs again."""
    _EXTRACTED.update(folders)


def rss_bytes() -> int | None:
    """This process's resident memory [bytes] now (Linux /proc; None elsewhere)."""
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * _PAGE_SIZE
    except (OSError, ValueError, IndexError):
        return None


try:
    import os as _os

    _PAGE_SIZE = _os.sysconf("SC_PAGE_SIZE")
except (AttributeError, ValueError, OSError):
    _PAGE_SIZE = 4096


class StepRejected(Exception):
    """doStep returned discard (or worse): the FMU kept its last good state. Not a user error."""


class GarbageOutput(PlantError):
    """An output that cannot be a measurement (non-finite or a denormal) where FmuPlant.check_outputs is on."""


garbage_seen: list[str] = []    # the first GarbageOutput's message of this process (a caller may swallow it)


class FmuPlant:
    """One co-simulation instance of an FMU, stepped at a fixed sample time.

    Args:
        fmu_path: the .fmu file.
        inputs: names of the inputs that `step(u)` sets, in order (default: all inputs).
        outputs: names of the variables that `step` returns, in order (default: all outputs).
        sample_time_s: communication step, s.
        parameters: start values applied at every reset {name: value}.
        instance_name: FMI instance name (for the FMU's log messages).
        step_timeout_s: a call into the FMU that does not return within this [s] ends the process (fmu.watchdog);
            None: 100 x the measured cost of a step, at least 10 s (watchdog.MIN_STEP_TIMEOUT_S).
        stop_time_s: the latest time [s] this plant will be stepped to after a reset, set up as the experiment's
            stop time (FMI stopTimeDefined); None: no stop time, unless the FMU showed it enforces its own.

    The first episode runs on the fresh instance; a later reset uses the FMU's reset only once a check
    showed it restores the start (check_reset, remembered per FMU file), else instantiates afresh.
    """

    check_outputs = False  # True: a non-finite or denormal output raises GarbageOutput (probe, init)

    def __init__(self, fmu_path: str | Path, inputs: Sequence[str] | None = None,
                 outputs: Sequence[str] | None = None, sample_time_s: float = 0.1,
                 parameters: Mapping[str, float] | None = None, instance_name: str = "plant",
                 step_timeout_s: float | None = None, stop_time_s: float | None = None):
        self.path = Path(fmu_path)
        self.description: FmuDescription = describe_fmu(self.path)
        d = self.description
        if not (d.co_simulation or d.model_exchange):
            raise PlantError(f"{self.path}: the FMU has neither a co-simulation nor a model-exchange interface")
        if not (sample_time_s > 0 and np.isfinite(sample_time_s)):
            raise PlantError(f"sample time must be a positive number of seconds, got {sample_time_s!r}")
        self.sample_time_s = float(sample_time_s)
        self.inputs = tuple(inputs) if inputs is not None else d.input_names
        self.outputs = tuple(outputs) if outputs is not None else d.output_names
        for name in self.inputs:
            d.require(name, ("input", "parameter"), "an input")
        for name in self.outputs:
            d.require(name, None, "an output")
        self.parameters = dict(parameters or {})
        for name in self.parameters:
            d.require(name, ("parameter", "input"), "a parameter")
        self._vr_by_name = {v.name: v.value_reference for v in d.variables}
        self._in_vr, self._in_val = self._buffers(self.inputs)
        self._out_vr, self._out_val = self._buffers(self.outputs)
        self._out_view = np.ctypeslib.as_array(self._out_val) if self.outputs else np.zeros(0)
        self._n_in = len(self.inputs)
        self.last_message = ""
        self.time = 0.0
        self._state = None          # FMU state handle reused by copy_state_to / get_state
        self._incoming = None       # deserialized state handle reused when receiving a copy
        self._leak_check = None     # [every_resets, limit_bytes, resets, bytes added] (guard_leaks)
        self.reinstantiations = 0   # fresh instances the leak guard made
        self.step_timeout_s = step_timeout_s
        self.stop_time_s = stop_time_s
        self._seq = 0               # FMI calls under watch, twice each: odd while one is under way (fmu.watchdog)
        self._call = "step"         # which one (a key of the adapter's call_names)
        self._strict = bool(self.check_outputs)
        self._crumb = crumb
        self.crumb_id = self.crumb_role = 0
        if crumb is not None:
            if str(self.path) not in crumb_fmus:
                crumb_fmus.append(str(self.path))
                crumb_names.names = "\n".join(crumb_fmus).encode("utf-8", "replace")[:1023]
            self.crumb_id = crumb_fmus.index(str(self.path))
            self.crumb_role = CRUMB_ROLES.index(instance_name) if instance_name in CRUMB_ROLES else 0
        self._fmi = None
        self._applied = None        # parameters of the fresh, unstepped instance (None once it moved)
        self._stop_defined = None   # the stop time the experiment was set up with [s] (None: none)
        watchdog.watch(self)
        self._start_fresh(instance_name)

    # -- watched calls ---------------------------------------------------------------------------
    @contextlib.contextmanager
    def _calling(self, call: str):
        """Mark a slow FMI call (instantiate, reset, initialize, free) for the watchdog and the crumb."""
        self._call = call
        self._seq += 1
        c = self._crumb
        if c is not None:
            c.call, c.plant, c.role, c.t, c.busy = CALL_CODES.index(call), self.crumb_id, self.crumb_role, self.time, 1
        try:
            yield
        finally:
            self._seq += 1
            self._call = "step"
            if c is not None:
                c.busy = 0

    @property
    def crumb(self) -> Crumb | None:
        """The crumb this plant's calls write (in a worker or a supervised `tune`; None elsewhere): a caller that
        runs the FMU's code in a call of its own (the native forecast) marks it there."""
        return self._crumb

    def call_name(self, call: str | None = None) -> str:
        """The FMI function(s) behind a watched call ('fmi2DoStep', 'fmi2Reset', ...)."""
        names = adapter_class(self.description.fmi_version, self.description.co_simulation).call_names
        return names.get(call or self._call, call or self._call)

    def describe_call(self) -> str:
        """'<fmu>: fmi2DoStep from t = 3 s' for the call under way (what the watchdog reports)."""
        return describe_call(self.path.name, self.call_name(), self._call, self.time)

    # -- setup ---------------------------------------------------------------------------------
    def _buffers(self, names):
        from fmpy.fmi2 import fmi2ValueReference
        vr = (fmi2ValueReference * len(names))(*[self._vr_by_name[n] for n in names])
        return vr, (ctypes.c_double * len(names))()

    def _instantiate(self, instance_name: str) -> None:
        d = self.description
        unzipdir = extracted_folder(self.path)
        self.instance_name = instance_name
        self.time = 0.0
        try:
            with self._calling("instantiate"):
                self._fmi = adapter_class(d.fmi_version, d.co_simulation).instantiate(d, unzipdir, instance_name, self)
        except Exception as exc:  # a broken binary or a platform without one
            from prlpid_fmi.fmu.archive import binary_problem

            hint = binary_problem(self.path)
            raise PlantError(f"{self.path}: cannot instantiate the FMU: {exc} {self.last_message}".strip()
                             + (f"; {hint}" if hint else "")) from None
        fmi = self._fmi
        self._set_inputs = fmi.real_setter(self._in_vr, self._in_val, len(self.inputs))
        self._get_outputs = fmi.real_getter(self._out_vr, self._out_val, len(self.outputs))
        self._do_step = fmi.stepper(self.sample_time_s)

    def value_reference(self, name: str) -> int:
        """The FMI value reference of variable `name` (KeyError for a name the FMU does not have)."""
        return self._vr_by_name[name]

    @property
    def library(self) -> ctypes.CDLL:
        """The FMU's loaded shared library (for plain C functions it exports beside the FMI API)."""
        return self._fmi.library

    @property
    def component(self):
        """The FMI instance pointer (fmi2Component / fmi3Instance) of this plant."""
        return self._fmi.component

    def _check(self, status: int, what: str) -> None:
        if status > 1:
            label = STATUS_LABELS[status] if 0 <= status < len(STATUS_LABELS) else str(status)
            when = "from" if what == self.call_name("step") else "at"
            raise PlantError(f"{self.path.name}: {what} {when} t = {self.time:g} s returned {label}: "
                             f"{self.last_message or '(the FMU logged no message)'}{self._stop_hint(what)}")

    def _stop_hint(self, what: str) -> str:
        """Why a step may be refused at the FMU's stop time, and what to do; remembers that it needs one."""
        stop = self.description.default_stop_time_s
        if what != self.call_name("step") or stop is None or self.time + self.sample_time_s <= stop * (1 + 1e-9):
            return ""
        if self._stop_defined is None:
            verdicts.put(self.path, "needs_stop_time", True)
            return (f" (the FMU's DefaultExperiment stopTime is {stop:g} s and the experiment was set up without "
                    "one: it may stop there; from now on its experiments are set up with a stop time)")
        if self._stop_defined > stop:
            return (f" (the experiment was set up to stop at {self._stop_defined:g} s, yet the FMU may keep its "
                    f"DefaultExperiment stopTime {stop:g} s: shorten the episodes (training/evaluation.episode_steps "
                    "x plant.sample_time) to end before it)")
        return ""

    def _check_garbage(self, values) -> None:
        """GarbageOutput for an output that is not finite or a denormal (check_outputs)."""
        for name, y in zip(self.outputs, values):
            if not math.isfinite(y) or (y != 0.0 and abs(y) < TINY):
                what = "not finite" if not math.isfinite(y) else "a denormal number"
                text = (f"{self.path.name}: {self.call_name('step')} returned garbage: {name} = {y:.3g} ({what}) at "
                        f"t = {self.time:g} s; the FMU's outputs cannot be trusted")
                if not garbage_seen:
                    garbage_seen.append(text)
                raise GarbageOutput(text)

    # -- values --------------------------------------------------------------------------------
    def set(self, values: Mapping[str, float]) -> None:
        """Set inputs or tunable parameters by name, now (e.g. a disturbance or a parameter change)."""
        self._applied = None
        names = list(values)
        vr, buf = self._buffers(names)
        for i, n in enumerate(names):
            buf[i] = float(values[n])
        self._check(self._fmi.real_setter(vr, buf, len(names))(), f"setting {', '.join(names)}")

    def get(self, names: Sequence[str]) -> np.ndarray:
        """Current values of any real variables, shape (len(names),)."""
        for name in names:
            self.description.require(name, None, "a variable")
        vr, buf = self._buffers(list(names))
        self._check(self._fmi.real_getter(vr, buf, len(names))(), "reading values")
        return np.array(buf[:], dtype=float)

    def read_outputs(self) -> np.ndarray:
        """The configured outputs now, shape (n_outputs,) (a new array)."""
        self._check(self._get_outputs(), "reading outputs")
        if self._strict:
            self._check_garbage(self._out_val[:])
        return self._out_view.copy()

    # -- simulation ----------------------------------------------------------------------------
    def guard_leaks(self, every_resets: int, limit_mb: float) -> None:
        """Watch the memory (RSS) each reset adds; every `every_resets` resets, when they added more than
        limit_mb [MB] together, free the instance and instantiate the FMU afresh (with a warning), which
        returns what a leaking reset kept. every_resets 0: no guard."""
        self._leak_check = [int(every_resets), float(limit_mb) * 2**20, 0, 0] if every_resets > 0 else None

    def _free_instance(self) -> None:
        self._release_states()
        if self._fmi is None:
            return
        with self._calling("free"):
            try:
                self._fmi.terminate()
            except Exception:
                pass
            self._fmi.free()
        self._fmi = None

    def _start_fresh(self, instance_name: str | None = None) -> None:
        """A new instance (the old one freed), this plant's parameters applied, initialised at t = 0."""
        name = instance_name or self.instance_name
        self._free_instance()
        self._instantiate(name)
        self._initialize()
        self._applied = dict(self.parameters)
        self._fresh_seq = self._seq

    def _initialize(self) -> None:
        """Parameters applied and the experiment set up (stop time where known) and initialised at t = 0."""
        self.time = 0.0
        if self.parameters:
            self.set(self.parameters)
        stop = self.stop_time_s
        if stop is None and self.description.default_stop_time_s is not None \
                and verdicts.get(self.path, "needs_stop_time"):
            stop = max(LONG_STOP_TIME_S, self.description.default_stop_time_s)
        self._stop_defined = stop
        try:
            with self._calling("initialize"):
                self._fmi.initialize(0.0, stop)
        except Exception as exc:
            raise PlantError(f"{self.path.name}: initialisation ({self.call_name('initialize')}) failed: {exc} "
                             f"{self.last_message}".strip()) from None

    def raw_reset(self) -> np.ndarray:
        """The FMU's own reset and initialisation, never a fresh instance (a diagnostic: inspect --probe).
        Returns the outputs at t = 0."""
        self._release_states()
        with self._calling("reset"):
            self._fmi.reset()
        self._initialize()
        return self.read_outputs()

    @property
    def reset_works(self) -> bool:
        """Whether the FMU's reset restores the start: checked once per FMU file (check_reset), remembered."""
        verdict = verdicts.get(self.path, "reset")
        if verdict is None:
            verdict = self.check_reset()
            verdicts.put(self.path, "reset", verdict)
        if verdict != "ok" and str(self.path) not in _warned_resets:
            _warned_resets.add(str(self.path))
            if not watchdog.in_worker():
                warnings.warn(f"{self.path.name}: its reset does not restore the start ({verdict}); every episode "
                              "instantiates the FMU afresh instead (checked once, remembered for this file)",
                              stacklevel=4)
        return verdict == "ok"

    def check_reset(self) -> str:
        """Run RESET_CHECK_STEPS steps of a fixed input sequence on a fresh instance, reset, run them again:
        "ok" when both runs agree (RESET_CHECK_RTOL), else what differs. An output that stays put after the
        reset while it moved before is "frozen" (judged by the outputs' change under the same inputs, so a
        slow plant whose outputs barely move is never called frozen). Leaves a used instance behind."""
        u = reset_check_inputs(self.description, self.inputs, RESET_CHECK_STEPS)
        self._start_fresh()
        try:
            first = np.array([self.step_values(row) for row in u])
        except (PlantError, StepRejected):
            return "ok"  # the check cannot run (the FMU rejects these inputs): the reset is not doubted
        try:
            self.raw_reset()
            second = np.array([self.step_values(row) for row in u])
        except (PlantError, StepRejected) as exc:
            return f"after {self.call_name('reset')} the same inputs fail: {' '.join(str(exc).split())}"
        except Exception as exc:  # noqa: BLE001 - FMPy raises on an error status
            return f"{self.call_name('reset')} failed: {exc}"
        return compare_runs(self.outputs, self.inputs, first, second, self.call_name("reset"))

    def reset(self, parameters: Mapping[str, float] | None = None) -> np.ndarray:
        """Back to t = 0 with start values, this plant's parameters (updated by `parameters`) applied.

        A fresh instance that has not moved is used as it is (never reset before it ran); otherwise uses the
        FMU's reset when check_reset found it restores the start, else instantiates afresh; re-instantiates
        too when the FMU's reset fails (or the leak guard finds the resets' memory growing, see guard_leaks).
        Returns the outputs at t = 0.
        """
        if parameters:
            for name in parameters:
                self.description.require(name, ("parameter", "input"), "a parameter")
            self.parameters.update(parameters)
        if self._applied is not None and self._applied == self.parameters and self._seq == self._fresh_seq:
            self.time = 0.0
            return self.read_outputs()  # the fresh instance has not moved: never reset a fresh instance
        check = self._leak_check
        before = rss_bytes() if check is not None else None
        self._release_states()
        if not self.reset_works:
            self._start_fresh()
            return self.read_outputs()
        try:
            with self._calling("reset"):
                self._fmi.reset()
        except Exception:
            self._start_fresh()
            return self.read_outputs()
        self._initialize()
        if before is not None:
            check[2] += 1
            check[3] += max(rss_bytes() - before, 0)
            if check[2] >= check[0]:
                grown, check[2], check[3] = check[3], 0, 0
                if grown > check[1]:
                    import warnings

                    warnings.warn(f"{self.path.name}: its last {check[0]} resets added {grown / 2**20:.0f} MB of "
                                  "memory; the FMU is instantiated afresh", stacklevel=2)
                    self.reinstantiations += 1
                    self._start_fresh()
        return self.read_outputs()

    def step(self, u: np.ndarray | Sequence[float]) -> np.ndarray:
        """Hold inputs u (shape (n_inputs,)) for one sample time; return the outputs after it.

        Raises StepRejected when the FMU discards the step (it keeps its last good state).
        """
        return np.array(self.step_values(u))

    def step_values(self, u: Sequence[float]) -> list[float]:
        """`step` on plain floats: u (n_inputs floats) -> outputs (list of n_outputs floats). The hot path."""
        c = self._crumb
        if c is not None:  # a worker: the parent reads which call and time after a crash
            c.call, c.plant, c.role, c.t, c.busy = 4, self.crumb_id, self.crumb_role, self.time, 1
        self._seq += 1
        try:
            if self._n_in:
                self._in_val[:] = u
                status = self._set_inputs()
                if status > 1:
                    self._check(status, "setting inputs")
            status = self._do_step(self.time)
            if status > 1:
                if status == 2:
                    raise StepRejected(f"{self.path.name} discarded the step at t = {self.time:g} s: "
                                       f"{self.last_message}")
                self._check(status, self.call_name("step"))
            self.time += self.sample_time_s
            status = self._get_outputs()
            if status > 1:
                self._check(status, "reading outputs")
        finally:
            self._seq += 1
            if c is not None:
                c.busy = 0
        if self._strict:
            self._check_garbage(self._out_val[:])
        return self._out_val[:]

    # -- state ---------------------------------------------------------------------------------
    def _capture(self):
        """Get the FMU state into a reused handle."""
        if self._state is None:
            self._state = ctypes.c_void_p()
        self._check(self._fmi.get_state(self._state), "getting the FMU state")
        return self._state

    def get_state(self) -> bytes:
        """Serialized FMU state with this instance's time (bytes, portable between instances)."""
        self._require_serialize()
        state = self._capture()
        size = c_size_t()
        self._check(self._fmi.serialized_size(state, size), "sizing the FMU state")
        buf = (self._fmi.byte_type * size.value)()
        self._check(self._fmi.serialize(state, buf, size), "serializing the FMU state")
        return struct.pack("d", self.time) + bytes(buf)

    def set_state(self, blob: bytes) -> None:
        """Restore a state produced by `get_state` of this or another instance of the same FMU."""
        self._require_serialize()
        (time,), raw = struct.unpack_from("d", blob), blob[8:]
        if self._incoming is None:
            self._incoming = ctypes.c_void_p()
        self._applied = None
        buf = (self._fmi.byte_type * len(raw)).from_buffer_copy(raw)
        self._check(self._fmi.deserialize(buf, len(raw), self._incoming), "deserializing the FMU state")
        self._check(self._fmi.set_state(self._incoming), "setting the FMU state")
        self.time = float(time)

    def hold_state(self) -> None:
        """Remember this instance's state and time in place (get FMU state, no serialization), for
        `restore_state`: what a single-instance rollback prior needs (canGetAndSetFMUstate)."""
        if not self.description.can_get_and_set_state:
            raise PlantError(f"{self.path.name} cannot get and set its state (canGetAndSetFMUstate is false)")
        self._capture()
        self._held_time = self.time

    def restore_state(self) -> None:
        """Back to the state and time of the last `hold_state`."""
        self._check(self._fmi.set_state(self._state), "setting the FMU state")
        self.time = self._held_time

    def copy_state_to(self, other: "FmuPlant") -> None:
        """Move this instance's full state (and time) into `other`, an instance of the same FMU."""
        if other.description.guid != self.description.guid:
            raise PlantError(f"cannot copy the state of {self.path.name} into {other.path.name}: different FMUs")
        other.set_state(self.get_state())

    def _require_serialize(self) -> None:
        if not self.description.can_serialize_state:
            raise PlantError(f"{self.path.name} cannot serialize its state (canSerializeFMUstate is false), "
                             "so it cannot serve as a predictive prior")

    def _release_states(self) -> None:
        for attr in ("_state", "_incoming"):
            handle = getattr(self, attr)
            if handle is not None and handle.value:
                self._fmi.free_state(handle)
            setattr(self, attr, None)

    def close(self) -> None:
        """Free the FMU instance (idempotent)."""
        if getattr(self, "_fmi", None) is None:
            return
        self._free_instance()
        watchdog.unwatch(self)

    def __enter__(self) -> "FmuPlant":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def describe_call(fmu_name: str, call_name: str, call: str, t: float) -> str:
    """'<fmu>: fmi2DoStep from t = 3 s' / '<fmu>: fmi2Reset at t = 0 s'."""
    return f"{fmu_name}: {call_name} {'from' if call == 'step' else 'at'} t = {t:g} s"


def reset_check_inputs(description: FmuDescription, inputs: Sequence[str], steps: int) -> np.ndarray:
    """The check's input sequence (steps, n_inputs): start values + 0.1 max(1, |start|) sin(0.7 k)."""
    start = []
    for name in inputs:
        v = description.variable(name).start
        start.append(float(v) if isinstance(v, (int, float)) else 0.0)
    start = np.array(start, float)
    k = np.arange(steps)[:, None]
    return start + 0.1 * np.maximum(1.0, np.abs(start)) * np.sin(0.7 * k + 0.3)


def compare_runs(outputs: Sequence[str], inputs: Sequence[str], first: np.ndarray, second: np.ndarray,
                 reset_name: str) -> str:
    """"ok" when the run after a reset agrees with the first one; else which output differs and how."""
    scale = np.maximum(np.nanmax(np.abs(first), axis=0, initial=0.0), 1e-300)
    same = (np.abs(first - second) <= RESET_CHECK_RTOL * scale) | (np.isnan(first) & np.isnan(second))
    if same.all():
        return "ok"
    for j, name in enumerate(outputs):
        if same[:, j].all():
            continue
        moved, stays = np.ptp(first[:, j]) > 0, np.ptp(second[:, j]) == 0
        if moved and stays:
            return (f"after {reset_name} {name} stays at {second[0, j]:.4g} while {', '.join(inputs) or 'time'} "
                    "moves: frozen")
        return f"after {reset_name} {name} differs from the first run by up to {np.nanmax(np.abs(first[:, j] - second[:, j])):.3g}"
    return "ok"
