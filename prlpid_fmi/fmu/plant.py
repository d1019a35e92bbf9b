"""FmuPlant: one FMI 2.0 or 3.0 co-simulation instance driven step by step over FMPy.

The model description is read once, the FMU extracted once per file (instances of the same FMU
share the extraction), and value references are resolved at construction, so a step is one
set-inputs, one doStep and one get-outputs call on preallocated ctypes buffers.
It knows nothing about PID or RL.
"""
from __future__ import annotations

import atexit
import ctypes
import shutil
import weakref
from ctypes import byref, c_size_t
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import PlantError
from .description import FmuDescription, describe_fmu

_EXTRACTED: dict[tuple[str, float], str] = {}
STATUS_LABELS = ("ok", "warning", "discard", "error", "fatal", "pending")


def _extract(path: Path) -> str:
    """Extract an FMU once per (path, mtime); directories are removed at interpreter exit."""
    from fmpy import extract

    key = (str(path.resolve()), path.stat().st_mtime)
    if key not in _EXTRACTED:
        unzipdir = extract(str(path))
        atexit.register(shutil.rmtree, unzipdir, True)
        _EXTRACTED[key] = unzipdir
    return _EXTRACTED[key]


_FMI2_PLANTS: "weakref.WeakValueDictionary[int, FmuPlant]" = weakref.WeakValueDictionary()
_FMI2_LOGGER = []


def _register_fmi2_plant(plant: "FmuPlant") -> int:
    key = max(_FMI2_PLANTS.keys(), default=0) + 1
    _FMI2_PLANTS[key] = plant
    return key


def _fmi2_logger(logger_type):
    """One process-wide FMI 2.0 logger that hands each message to the instance it came from."""
    if not _FMI2_LOGGER:
        def dispatch(env, instance_name, status, category, message):
            plant = _FMI2_PLANTS.get(env or 0)
            if plant is not None:
                plant.last_message = message.decode("utf-8", "replace") if message else ""

        _FMI2_LOGGER.append(logger_type(dispatch))
    return _FMI2_LOGGER[0]


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
        if not d.co_simulation:
            raise PlantError(f"{self.path}: the FMU has no co-simulation interface (FMI {d.fmi_version}, model exchange only)")
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
        self._fmi3 = d.fmi_version.startswith("3")
        self._in_vr, self._in_val = self._buffers(self.inputs)
        self._out_vr, self._out_val = self._buffers(self.outputs)
        self._out_view = np.ctypeslib.as_array(self._out_val) if self.outputs else np.zeros(0)
        self.last_message = ""
        self.time = 0.0
        self._state = None          # FMU state handle reused by copy_state_to / get_state
        self._incoming = None       # deserialized state handle reused when receiving a copy
        self._instantiate(instance_name)
        self.reset()

    # -- setup ---------------------------------------------------------------------------------
    def _buffers(self, names):
        from fmpy.fmi2 import fmi2ValueReference
        vr = (fmi2ValueReference * len(names))(*[self._vr_by_name[n] for n in names])
        return vr, (ctypes.c_double * len(names))()

    def _instantiate(self, instance_name: str) -> None:
        d = self.description
        unzipdir = _extract(self.path)
        try:
            if self._fmi3:
                from fmpy.fmi3 import FMU3Slave

                self._fmu = FMU3Slave(guid=d.guid, unzipDirectory=unzipdir, modelIdentifier=d.model_identifier,
                                      instanceName=instance_name)
                self._fmu.instantiate(logMessage=self._log3)  # FMPy keeps the callback alive
            else:
                from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
                from fmpy.fmi2 import fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE
                from fmpy.fmi2 import calloc, free
                from fmpy.logging import addLoggerProxy

                callbacks = fmi2CallbackFunctions()
                # FMPy's varargs proxy keeps one logger per process: route by componentEnvironment.
                callbacks.logger = _fmi2_logger(fmi2CallbackLoggerTYPE)
                callbacks.componentEnvironment = _register_fmi2_plant(self)
                callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
                callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
                addLoggerProxy(byref(callbacks))
                self._callbacks = callbacks
                self._fmu = FMU2Slave(guid=d.guid, unzipDirectory=unzipdir, modelIdentifier=d.model_identifier,
                                      instanceName=instance_name)
                self._fmu.instantiate(callbacks=callbacks)
        except Exception as exc:  # a broken binary or a platform without one
            raise PlantError(f"{self.path}: cannot instantiate the FMU: {exc} {self.last_message}".strip()) from None
        f = self._fmu._functions
        self._c = self._fmu.component
        p = "fmi3" if self._fmi3 else "fmi2"
        self._set_real = f[f"{p}SetFloat64" if self._fmi3 else "fmi2SetReal"]
        self._get_real = f[f"{p}GetFloat64" if self._fmi3 else "fmi2GetReal"]
        self._do_step = f[f"{p}DoStep"]
        self._flags = (ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double())
        self._byte = ctypes.c_uint8 if self._fmi3 else ctypes.c_char  # fmi3Byte / fmi2Byte

    @property
    def library(self) -> ctypes.CDLL:
        """The FMU's loaded shared library (for plain C functions it exports beside the FMI API)."""
        return self._fmu.dll

    @property
    def component(self):
        """The FMI instance pointer (fmi2Component / fmi3Instance) of this plant."""
        return self._c

    def _log3(self, env, status, category, message):
        self.last_message = message.decode("utf-8", "replace") if message else ""

    def _check(self, status: int, what: str) -> None:
        if status > 1:
            label = STATUS_LABELS[status] if 0 <= status < len(STATUS_LABELS) else str(status)
            raise PlantError(f"{self.path.name}: {what} returned {label}: {self.last_message}")

    # -- values --------------------------------------------------------------------------------
    def _write(self, vr, values, n: int) -> int:
        if self._fmi3:
            return self._set_real(self._c, vr, n, values, n)
        return self._set_real(self._c, vr, n, values)

    def _read(self, vr, values, n: int) -> int:
        if self._fmi3:
            return self._get_real(self._c, vr, n, values, n)
        return self._get_real(self._c, vr, n, values)

    def set(self, values: Mapping[str, float]) -> None:
        """Set inputs or tunable parameters by name, now (e.g. a disturbance or a parameter change)."""
        names = list(values)
        vr, buf = self._buffers(names)
        for i, n in enumerate(names):
            buf[i] = float(values[n])
        self._check(self._write(vr, buf, len(names)), f"setting {', '.join(names)}")

    def get(self, names: Sequence[str]) -> np.ndarray:
        """Current values of any real variables, shape (len(names),)."""
        for name in names:
            self.description.require(name, None, "a variable")
        vr, buf = self._buffers(list(names))
        self._check(self._read(vr, buf, len(names)), "reading values")
        return np.array(buf[:], dtype=float)

    def read_outputs(self) -> np.ndarray:
        """The configured outputs now, shape (n_outputs,) (a new array)."""
        self._check(self._read(self._out_vr, self._out_val, len(self.outputs)), "reading outputs")
        return self._out_view.copy()

    # -- simulation ----------------------------------------------------------------------------
    def reset(self, parameters: Mapping[str, float] | None = None) -> np.ndarray:
        """Back to t = 0 with start values, this plant's parameters (updated by `parameters`) applied.

        Uses the FMU's reset; re-instantiates when the FMU's reset fails. Returns the outputs at t = 0.
        """
        if parameters:
            for name in parameters:
                self.description.require(name, ("parameter", "input"), "a parameter")
            self.parameters.update(parameters)
        self._release_states()
        try:
            self._fmu.reset()
        except Exception:
            name = self._fmu.instanceName
            self._fmu.freeInstance()
            self._instantiate(name)
        self.time = 0.0
        if self.parameters:
            self.set(self.parameters)
        try:
            if self._fmi3:
                self._fmu.enterInitializationMode(startTime=0.0)
            else:
                self._fmu.setupExperiment(startTime=0.0)
                self._fmu.enterInitializationMode()
            self._fmu.exitInitializationMode()
        except Exception as exc:
            raise PlantError(f"{self.path.name}: initialisation failed: {exc} {self.last_message}".strip()) from None
        return self.read_outputs()

    def step(self, u: np.ndarray | Sequence[float]) -> np.ndarray:
        """Hold inputs u (shape (n_inputs,)) for one sample time; return the outputs after it.

        Raises StepRejected when the FMU discards the step (it keeps its last good state).
        """
        n_in = len(self.inputs)
        for i in range(n_in):
            self._in_val[i] = u[i]
        if n_in:
            self._check(self._write(self._in_vr, self._in_val, n_in), "setting inputs")
        if self._fmi3:
            e, t, r, last = self._flags
            status = self._do_step(self._c, self.time, self.sample_time_s, True, byref(e), byref(t), byref(r), byref(last))
        else:
            status = self._do_step(self._c, self.time, self.sample_time_s, 1)
        if status >= 2:
            if status == 2:
                raise StepRejected(f"{self.path.name} discarded the step at t = {self.time:g} s: {self.last_message}")
            self._check(status, "doStep")
        self.time += self.sample_time_s
        self._check(self._read(self._out_vr, self._out_val, len(self.outputs)), "reading outputs")
        return self._out_view.copy()

    # -- state ---------------------------------------------------------------------------------
    def _capture(self):
        """Get the FMU state into a reused handle."""
        f = self._fmu._functions
        name = "fmi3GetFMUState" if self._fmi3 else "fmi2GetFMUstate"
        if self._state is None:
            self._state = ctypes.c_void_p()
        self._check(f[name](self._c, byref(self._state)), "getting the FMU state")
        return self._state

    def get_state(self) -> bytes:
        """Serialized FMU state with this instance's time (bytes, portable between instances)."""
        self._require_serialize()
        f = self._fmu._functions
        p = "fmi3" if self._fmi3 else "fmi2"
        state = self._capture()
        size = c_size_t()
        self._check(f[f"{p}SerializedFMUStateSize" if self._fmi3 else "fmi2SerializedFMUstateSize"](
            self._c, state, byref(size)), "sizing the FMU state")
        buf = (self._byte * size.value)()
        self._check(f[f"{p}SerializeFMUState" if self._fmi3 else "fmi2SerializeFMUstate"](
            self._c, state, buf, size), "serializing the FMU state")
        return np.float64(self.time).tobytes() + bytes(buf)

    def set_state(self, blob: bytes) -> None:
        """Restore a state produced by `get_state` of this or another instance of the same FMU."""
        self._require_serialize()
        f = self._fmu._functions
        time, raw = np.frombuffer(blob[:8], dtype=np.float64)[0], blob[8:]
        if self._incoming is None:
            self._incoming = ctypes.c_void_p()
        buf = (self._byte * len(raw)).from_buffer_copy(raw)
        name = "fmi3DeserializeFMUState" if self._fmi3 else "fmi2DeSerializeFMUstate"
        self._check(f[name](self._c, buf, len(raw), byref(self._incoming)), "deserializing the FMU state")
        self._check(f["fmi3SetFMUState" if self._fmi3 else "fmi2SetFMUstate"](self._c, self._incoming),
                    "setting the FMU state")
        self.time = float(time)

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
        f = self._fmu._functions
        name = "fmi3FreeFMUState" if self._fmi3 else "fmi2FreeFMUstate"
        for attr in ("_state", "_incoming"):
            handle = getattr(self, attr)
            if handle is not None and handle.value:
                f[name](self._c, byref(handle))
            setattr(self, attr, None)

    def close(self) -> None:
        """Free the FMU instance (idempotent)."""
        if getattr(self, "_fmu", None) is None:
            return
        self._release_states()
        try:
            self._fmu.terminate()
        except Exception:
            pass
        self._fmu.freeInstance()
        self._fmu = None

    def __enter__(self) -> "FmuPlant":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
