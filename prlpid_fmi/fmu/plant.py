"""FmuPlant: one FMI 1.0, 2.0 or 3.0 co-simulation instance (or an FMI 2.0 model-exchange instance, integrated
by FMPy's CVode solver) driven step by step over FMPy.

The model description is read once, the FMU extracted once per file (instances of the same FMU
share the extraction), and value references are resolved at construction, so a step is one
set-inputs, one doStep and one get-outputs call on preallocated ctypes buffers.
It knows nothing about PID or RL.
"""
from __future__ import annotations

import atexit
import ctypes
import shutil
import struct
from ctypes import c_size_t
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu.adapters import adapter_class
from prlpid_fmi.fmu.description import FmuDescription, describe_fmu

_EXTRACTED: dict[tuple[str, float], str] = {}
STATUS_LABELS = ("ok", "warning", "discard", "error", "fatal", "pending")


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


class FmuPlant:
    """One co-simulation instance of an FMU, stepped at a fixed sample time.

    Args:
        fmu_path: the .fmu file.
        inputs: names of the inputs that `step(u)` sets, in order (default: all inputs).
        outputs: names of the variables that `step` returns, in order (default: all outputs).
        sample_time_s: communication step, s.
        parameters: start values applied at every reset {name: value}.
        instance_name: FMI instance name (for the FMU's log messages).
    """

    def __init__(self, fmu_path: str | Path, inputs: Sequence[str] | None = None,
                 outputs: Sequence[str] | None = None, sample_time_s: float = 0.1,
                 parameters: Mapping[str, float] | None = None, instance_name: str = "plant"):
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
        self._instantiate(instance_name)
        self.reset()

    # -- setup ---------------------------------------------------------------------------------
    def _buffers(self, names):
        from fmpy.fmi2 import fmi2ValueReference
        vr = (fmi2ValueReference * len(names))(*[self._vr_by_name[n] for n in names])
        return vr, (ctypes.c_double * len(names))()

    def _instantiate(self, instance_name: str) -> None:
        d = self.description
        unzipdir = extracted_folder(self.path)
        try:
            self._fmi = adapter_class(d.fmi_version, d.co_simulation).instantiate(d, unzipdir, instance_name, self)
        except Exception as exc:  # a broken binary or a platform without one
            raise PlantError(f"{self.path}: cannot instantiate the FMU: {exc} {self.last_message}".strip()) from None
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
            raise PlantError(f"{self.path.name}: {what} returned {label}: {self.last_message}")

    # -- values --------------------------------------------------------------------------------
    def set(self, values: Mapping[str, float]) -> None:
        """Set inputs or tunable parameters by name, now (e.g. a disturbance or a parameter change)."""
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
        return self._out_view.copy()

    # -- simulation ----------------------------------------------------------------------------
    def guard_leaks(self, every_resets: int, limit_mb: float) -> None:
        """Watch the memory (RSS) each reset adds; every `every_resets` resets, when they added more than
        limit_mb [MB] together, free the instance and instantiate the FMU afresh (with a warning), which
        returns what a leaking reset kept. every_resets 0: no guard."""
        self._leak_check = [int(every_resets), float(limit_mb) * 2**20, 0, 0] if every_resets > 0 else None

    def _reinstantiate(self) -> None:
        name = self._fmi.instance_name
        self._free_instance()
        self._instantiate(name)

    def _free_instance(self) -> None:
        self._release_states()
        try:
            self._fmi.terminate()
        except Exception:
            pass
        self._fmi.free()

    def reset(self, parameters: Mapping[str, float] | None = None) -> np.ndarray:
        """Back to t = 0 with start values, this plant's parameters (updated by `parameters`) applied.

        Uses the FMU's reset; re-instantiates when the FMU's reset fails (or the leak guard finds the
        resets' memory growing, see guard_leaks). Returns the outputs at t = 0.
        """
        if parameters:
            for name in parameters:
                self.description.require(name, ("parameter", "input"), "a parameter")
            self.parameters.update(parameters)
        check = self._leak_check
        before = rss_bytes() if check is not None else None
        self._release_states()
        try:
            self._fmi.reset()
        except Exception:
            name = self._fmi.instance_name
            self._fmi.free()
            self._instantiate(name)
        self.time = 0.0
        if self.parameters:
            self.set(self.parameters)
        try:
            self._fmi.initialize(0.0)
        except Exception as exc:
            raise PlantError(f"{self.path.name}: initialisation failed: {exc} {self.last_message}".strip()) from None
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
                    self._reinstantiate()
                    return self.reset()
        return self.read_outputs()

    def step(self, u: np.ndarray | Sequence[float]) -> np.ndarray:
        """Hold inputs u (shape (n_inputs,)) for one sample time; return the outputs after it.

        Raises StepRejected when the FMU discards the step (it keeps its last good state).
        """
        return np.array(self.step_values(u))

    def step_values(self, u: Sequence[float]) -> list[float]:
        """`step` on plain floats: u (n_inputs floats) -> outputs (list of n_outputs floats). The hot path."""
        if self._n_in:
            self._in_val[:] = u
            status = self._set_inputs()
            if status > 1:
                self._check(status, "setting inputs")
        status = self._do_step(self.time)
        if status > 1:
            if status == 2:
                raise StepRejected(f"{self.path.name} discarded the step at t = {self.time:g} s: {self.last_message}")
            self._check(status, "doStep")
        self.time += self.sample_time_s
        status = self._get_outputs()
        if status > 1:
            self._check(status, "reading outputs")
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
        self._fmi = None

    def __enter__(self) -> "FmuPlant":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
