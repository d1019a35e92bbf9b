"""One small adapter per FMI version: the function pointers and call shapes of a co-simulation instance.

FmuPlant talks to an adapter only, so the hot path has no FMI-version branches, and FMPy's private
attributes (`_functions`, `dll`, `component`) are touched here and nowhere else. Setters, getters and
the stepper are returned as zero-argument (or one-argument) closures over preallocated ctypes
buffers: one Python call and one ctypes call each.

FMPy is pinned to the version range tested here (pyproject.toml).
"""
from __future__ import annotations

import ctypes
import weakref
from ctypes import byref, c_size_t
from typing import Callable

FMI_OK, FMI_WARNING, FMI_DISCARD, FMI_ERROR = 0, 1, 2, 3

# FMPy's varargs logger proxy keeps one FMI 2.0 logger per process: route messages by componentEnvironment.
_FMI2_SINKS: "weakref.WeakValueDictionary[int, object]" = weakref.WeakValueDictionary()
_FMI2_LOGGER = []


def _fmi2_logger(logger_type):
    if not _FMI2_LOGGER:
        def dispatch(env, instance_name, status, category, message):
            sink = _FMI2_SINKS.get(env or 0)
            if sink is not None:
                sink.last_message = message.decode("utf-8", "replace") if message else ""

        _FMI2_LOGGER.append(logger_type(dispatch))
    return _FMI2_LOGGER[0]


class FmiAdapter:
    """The calls FmuPlant needs, on one instantiated FMU. Subclasses fill in the version's shapes.

    Attributes: library (ctypes.CDLL of the FMU binary), component (the instance pointer),
    byte_type (ctypes type of a serialized-state byte).
    """

    byte_type = ctypes.c_char
    prefix = ""

    def __init__(self, fmu):
        self._fmu = fmu                      # the FMPy slave object
        self._f = fmu._functions             # FMPy keeps the ctypes function objects here
        self.library = fmu.dll
        self.component = fmu.component

    def function(self, name: str):
        """A raw FMI function by its version-neutral name, e.g. 'GetFMUstate'."""
        return self._f[self.prefix + name]

    # -- values and stepping: closures over fixed buffers ---------------------------------------
    def real_setter(self, vr, values, n: int) -> Callable[[], int]:
        raise NotImplementedError

    def real_getter(self, vr, values, n: int) -> Callable[[], int]:
        raise NotImplementedError

    def stepper(self, step_size_s: float) -> Callable[[float], int]:
        """A callable(t) doing one doStep of `step_size_s` from communication point t; returns the status."""
        raise NotImplementedError

    # -- lifecycle --------------------------------------------------------------------------------
    def reset(self) -> None:
        self._fmu.reset()

    def initialize(self, start_time: float) -> None:
        raise NotImplementedError

    def terminate(self) -> None:
        self._fmu.terminate()

    def free(self) -> None:
        self._fmu.freeInstance()

    @property
    def instance_name(self) -> str:
        return self._fmu.instanceName

    # -- FMU state ------------------------------------------------------------------------------
    def get_state(self, handle) -> int:
        return self.function(self.state_names[0])(self.component, byref(handle))

    def set_state(self, handle) -> int:
        return self.function(self.state_names[1])(self.component, handle)

    def free_state(self, handle) -> int:
        return self.function(self.state_names[2])(self.component, byref(handle))

    def serialized_size(self, handle, size: c_size_t) -> int:
        return self.function(self.state_names[3])(self.component, handle, byref(size))

    def serialize(self, handle, buffer, size: int) -> int:
        return self.function(self.state_names[4])(self.component, handle, buffer, size)

    def deserialize(self, buffer, size: int, handle) -> int:
        return self.function(self.state_names[5])(self.component, buffer, size, byref(handle))


class Fmi2Adapter(FmiAdapter):
    """FMI 2.0 co-simulation: fmi2SetReal(c, vr, n, v), fmi2DoStep(c, t, h, noSetPrior)."""

    prefix = "fmi2"
    byte_type = ctypes.c_char
    state_names = ("GetFMUstate", "SetFMUstate", "FreeFMUstate", "SerializedFMUstateSize",
                   "SerializeFMUstate", "DeSerializeFMUstate")

    def real_setter(self, vr, values, n):
        f, c = self.function("SetReal"), self.component
        return lambda: f(c, vr, n, values)

    def real_getter(self, vr, values, n):
        f, c = self.function("GetReal"), self.component
        return lambda: f(c, vr, n, values)

    def stepper(self, step_size_s):
        f, c, h = self.function("DoStep"), self.component, float(step_size_s)
        return lambda t: f(c, t, h, 1)

    @classmethod
    def instantiate(cls, description, unzipdir: str, instance_name: str, sink) -> "Fmi2Adapter":
        """Instantiate with a logger that stores each message as `sink.last_message`."""
        from fmpy.fmi2 import FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE
        from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free
        from fmpy.logging import addLoggerProxy

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = _fmi2_logger(fmi2CallbackLoggerTYPE)
        key = max(_FMI2_SINKS.keys(), default=0) + 1
        _FMI2_SINKS[key] = sink
        callbacks.componentEnvironment = key
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(callbacks))
        fmu = FMU2Slave(guid=description.guid, unzipDirectory=unzipdir,
                        modelIdentifier=description.model_identifier, instanceName=instance_name)
        fmu.instantiate(callbacks=callbacks)
        adapter = cls(fmu)
        adapter._callbacks = callbacks  # keep the callback structure alive with the instance
        return adapter

    def initialize(self, start_time):
        self._fmu.setupExperiment(startTime=start_time)
        self._fmu.enterInitializationMode()
        self._fmu.exitInitializationMode()


class Fmi3Adapter(FmiAdapter):
    """FMI 3.0 co-simulation: fmi3SetFloat64(c, vr, nvr, v, nv), fmi3DoStep(c, t, h, noSetPrior, flags...)."""

    prefix = "fmi3"
    byte_type = ctypes.c_uint8
    state_names = ("GetFMUState", "SetFMUState", "FreeFMUState", "SerializedFMUStateSize",
                   "SerializeFMUState", "DeserializeFMUState")

    def real_setter(self, vr, values, n):
        f, c = self.function("SetFloat64"), self.component
        return lambda: f(c, vr, n, values, n)

    def real_getter(self, vr, values, n):
        f, c = self.function("GetFloat64"), self.component
        return lambda: f(c, vr, n, values, n)

    def stepper(self, step_size_s):
        f, c, h = self.function("DoStep"), self.component, float(step_size_s)
        flags = (ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double())
        refs = tuple(byref(x) for x in flags)
        return lambda t: f(c, t, h, True, *refs)

    @classmethod
    def instantiate(cls, description, unzipdir: str, instance_name: str, sink) -> "Fmi3Adapter":
        """Instantiate with a logger that stores each message as `sink.last_message`."""
        from fmpy.fmi3 import FMU3Slave

        def log(env, status, category, message):
            sink.last_message = message.decode("utf-8", "replace") if message else ""

        fmu = FMU3Slave(guid=description.guid, unzipDirectory=unzipdir,
                        modelIdentifier=description.model_identifier, instanceName=instance_name)
        fmu.instantiate(logMessage=log)  # FMPy keeps the callback alive
        return cls(fmu)

    def initialize(self, start_time):
        self._fmu.enterInitializationMode(startTime=start_time)
        self._fmu.exitInitializationMode()


def adapter_class(fmi_version: str) -> type[FmiAdapter]:
    """The adapter for a modelDescription's fmiVersion ("2.0", "3.0", ...)."""
    return Fmi3Adapter if fmi_version.startswith("3") else Fmi2Adapter
