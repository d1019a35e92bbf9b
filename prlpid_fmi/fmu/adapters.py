"""One small adapter per FMI version and interface: the function pointers and call shapes of an instance.

FMI 1.0, 2.0 and 3.0 co-simulation step with the FMU's own doStep; FMI 2.0 model exchange is integrated
over each communication step by FMPy's CVode solver (sundials), with the FMU's events handled between steps.

FmuPlant talks to an adapter only, so the hot path has no FMI-version branches, and FMPy's private
attributes (`_functions`, `dll`, `component`) are touched here and nowhere else. Setters, getters and
the stepper are returned as zero-argument (or one-argument) closures over preallocated ctypes
buffers: one Python call and one ctypes call each.

FMPy is pinned to the version range tested here (pyproject.toml).
"""
from __future__ import annotations

import ctypes
import math
import weakref
from ctypes import byref, c_size_t
from typing import Callable

FMI_OK, FMI_WARNING, FMI_DISCARD, FMI_ERROR = 0, 1, 2, 3

# FMPy's varargs logger proxy keeps one FMI 2.0 logger per process: route messages by componentEnvironment.
_FMI2_SINKS: "weakref.WeakValueDictionary[int, object]" = weakref.WeakValueDictionary()
_FMI2_LOGGER = []


def _sink_by_name(instance_name):
    """The one live instance with this name (bytes), for an FMU that logs with another componentEnvironment."""
    name = instance_name.decode("utf-8", "replace") if instance_name else None
    found = [s for s in list(_FMI2_SINKS.values()) if name is None or getattr(s, "instance_name", None) == name]
    return found[0] if len(found) == 1 else None


def _fmi2_logger(logger_type):
    if not _FMI2_LOGGER:
        def dispatch(env, instance_name, status, category, message):
            sink = _FMI2_SINKS.get(env or 0) or _sink_by_name(instance_name)
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
    # what FmuPlant calls the FMI functions it watches (fmu.watchdog) and names in its messages
    call_names = {"instantiate": "instantiation", "reset": "reset", "initialize": "initialisation",
                  "step": "doStep", "free": "freeing the instance"}

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

    def initialize(self, start_time: float, stop_time: float | None = None) -> None:
        """Set up the experiment from start_time [s] (with stop_time [s] defined when given) and initialise."""
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
    call_names = {"instantiate": "fmi2Instantiate", "reset": "fmi2Reset",
                  "initialize": "fmi2SetupExperiment/EnterInitializationMode/ExitInitializationMode",
                  "step": "fmi2DoStep", "free": "fmi2Terminate/fmi2FreeInstance"}
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

    slave_class = "FMU2Slave"

    @classmethod
    def instantiate(cls, description, unzipdir: str, instance_name: str, sink) -> "Fmi2Adapter":
        """Instantiate with a logger that stores each message as `sink.last_message`."""
        import fmpy.fmi2
        from fmpy.fmi2 import (
            calloc,
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
            free,
        )
        from fmpy.logging import addLoggerProxy

        callbacks = fmi2CallbackFunctions()
        callbacks.logger = _fmi2_logger(fmi2CallbackLoggerTYPE)
        key = max((k for k in _FMI2_SINKS.keys() if k < 2**31), default=0) + 1
        _FMI2_SINKS[key] = sink
        callbacks.componentEnvironment = key
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(callbacks))
        fmu = getattr(fmpy.fmi2, cls.slave_class)(guid=description.guid, unzipDirectory=unzipdir,
                                                  modelIdentifier=description.model_identifier,
                                                  instanceName=instance_name)
        fmu.instantiate(callbacks=callbacks)
        adapter = cls(fmu)
        adapter._callbacks = callbacks  # keep the callback structure alive with the instance
        return adapter

    def initialize(self, start_time, stop_time=None):
        self._fmu.setupExperiment(startTime=start_time, stopTime=stop_time)
        self._fmu.enterInitializationMode()
        self._fmu.exitInitializationMode()


class Fmi3Adapter(FmiAdapter):
    """FMI 3.0 co-simulation: fmi3SetFloat64(c, vr, nvr, v, nv), fmi3DoStep(c, t, h, noSetPrior, flags...)."""

    prefix = "fmi3"
    byte_type = ctypes.c_uint8
    call_names = {"instantiate": "fmi3InstantiateCoSimulation", "reset": "fmi3Reset",
                  "initialize": "fmi3EnterInitializationMode/ExitInitializationMode", "step": "fmi3DoStep",
                  "free": "fmi3Terminate/fmi3FreeInstance"}
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

    def initialize(self, start_time, stop_time=None):
        self._fmu.enterInitializationMode(startTime=start_time, stopTime=stop_time)
        self._fmu.exitInitializationMode()


class Fmi2ModelExchangeAdapter(Fmi2Adapter):
    """FMI 2.0 model exchange (FMPy's FMU2Model): each communication step is integrated by FMPy's CVode
    solver, restarted at the step's start (the inputs jump there and the state may have been set), with
    step, state and time events handled at the points where they occur. A failed integration keeps the
    states from before the step and reports discard, like a co-simulation FMU that rejects a step."""

    slave_class = "FMU2Model"
    call_names = {**Fmi2Adapter.call_names, "step": "the model-exchange step (CVode over fmi2GetDerivatives, events)"}
    relative_tolerance = 1e-8   # CVode's; absolute tolerance = this x the FMU's state nominals

    def __init__(self, fmu):
        super().__init__(fmu)
        self._solver = None
        self._next_event_time = math.inf

    @classmethod
    def instantiate(cls, description, unzipdir, instance_name, sink):
        adapter = super().instantiate(description, unzipdir, instance_name, sink)
        adapter._nx, adapter._nz = description.n_states, description.n_event_indicators
        adapter._x_saved = (ctypes.c_double * max(adapter._nx, 1))()
        return adapter

    def initialize(self, start_time, stop_time=None):
        fmu = self._fmu
        fmu.setupExperiment(startTime=start_time, stopTime=stop_time)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        self._event_iteration()
        if self._solver is None:
            from fmpy.sundials import CVodeSolver

            class _NoInput:
                @staticmethod
                def apply(t):  # the inputs are held over the step; FmuPlant sets them before it
                    return None

            # the raw ctypes functions (no FMPy call logging): the solver calls them for every right-hand side
            c, f = self.component, self.function
            raw = {name: f(name) for name in ("SetTime", "SetContinuousStates", "GetDerivatives",
                                              "GetContinuousStates", "GetEventIndicators",
                                              "GetNominalsOfContinuousStates")}
            self._solver = CVodeSolver(
                nx=self._nx, nz=self._nz, get_x=lambda x, n: raw["GetContinuousStates"](c, x, n),
                set_x=lambda x, n: raw["SetContinuousStates"](c, x, n),
                get_dx=lambda dx, n: raw["GetDerivatives"](c, dx, n),
                get_z=lambda z, n: raw["GetEventIndicators"](c, z, n),
                get_nominals=lambda x, n: raw["GetNominalsOfContinuousStates"](c, x, n),
                set_time=lambda t: raw["SetTime"](c, t), input=_NoInput(),
                startTime=start_time, relativeTolerance=self.relative_tolerance, maxNumSteps=100_000)
        else:
            self._solver.reset(start_time)

    def _event_iteration(self) -> None:
        """Event mode until the FMU needs no new discrete states, then back to continuous-time mode."""
        fmu = self._fmu
        needed, self._next_event_time = True, math.inf
        while needed:
            needed, terminate, _, _, defined, t_next = fmu.newDiscreteStates()
            if terminate:
                raise RuntimeError("the FMU asked to terminate the simulation")
            self._next_event_time = t_next if defined else math.inf
        fmu.enterContinuousTimeMode()

    def stepper(self, step_size_s):
        h = float(step_size_s)
        return lambda t: self._integrate(t, t + h)

    def _integrate(self, t: float, t_end: float) -> int:
        fmu, solver, nx = self._fmu, self._solver, self._nx
        if nx:
            fmu.getContinuousStates(self._x_saved, nx)
        try:
            fmu.setTime(t)
            solver.reset(t)
            time = t
            while time < t_end - 1e-12 * max(1.0, abs(t_end)):
                stop = min(t_end, self._next_event_time)
                state_event, _, time = solver.step(time, stop)
                fmu.setTime(time)
                step_event, terminate = fmu.completedIntegratorStep()
                if terminate:
                    raise RuntimeError("the FMU asked to terminate the simulation")
                if state_event or step_event or time >= self._next_event_time:
                    fmu.enterEventMode()
                    self._event_iteration()
                    solver.reset(time)
        except Exception as exc:  # CVode failure or an FMU error: back to the state before the step
            if nx:
                fmu.setContinuousStates(self._x_saved, nx)
            fmu.setTime(t)
            self._error = str(exc)
            return FMI_DISCARD
        return FMI_OK

    def terminate(self):
        self._fmu.terminate()


class Fmi1Adapter(Fmi2Adapter):
    """FMI 1.0 co-simulation (FMPy's FMU1Slave): fmiSetReal(c, vr, n, v), fmiDoStep(c, t, h, newStep), the
    call shapes of FMI 2.0. FMI 1.0 has no FMU state functions: such an FMU cannot be its own predictive prior."""

    prefix = "fmi1"
    state_names = ()
    call_names = {"instantiate": "fmiInstantiateSlave", "reset": "fmiResetSlave", "initialize": "fmiInitializeSlave",
                  "step": "fmiDoStep", "free": "fmiTerminateSlave/fmiFreeSlaveInstance"}

    def __init__(self, fmu):
        super().__init__(fmu)
        # FMPy 0.3 declares some FMI 1.0 functions (fmiInitializeSlave, fmiDoStep, ...) as returning a
        # string; every function but these returns an fmiStatus
        for name, function in self._f.items():
            if name not in ("fmi1GetVersion", "fmi1GetTypesPlatform", "fmi1InstantiateSlave", "fmi1FreeSlaveInstance"):
                function.restype = ctypes.c_int

    @classmethod
    def instantiate(cls, description, unzipdir: str, instance_name: str, sink) -> "Fmi1Adapter":
        """Instantiate with a logger that stores each message as `sink.last_message`."""
        from fmpy.fmi1 import (
            FMU1Slave,
            calloc,
            fmi1CallbackAllocateMemoryTYPE,
            fmi1CallbackFreeMemoryTYPE,
            fmi1CallbackFunctions,
            fmi1CallbackLoggerTYPE,
            free,
        )
        from fmpy.fmi2 import fmi2CallbackLoggerTYPE
        from fmpy.logging import addLoggerProxy

        callbacks = fmi1CallbackFunctions()
        # FMPy's formatting proxy keeps one Python logger per process: the same dispatcher as FMI 2.0,
        # keyed by the component pointer (FMI 1.0 passes it where FMI 2.0 passes the environment)
        address = ctypes.cast(_fmi2_logger(fmi2CallbackLoggerTYPE), ctypes.c_void_p).value
        callbacks.logger = fmi1CallbackLoggerTYPE(address)
        callbacks.allocateMemory = fmi1CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi1CallbackFreeMemoryTYPE(free)
        callbacks.stepFinished = None
        addLoggerProxy(byref(callbacks))
        fmu = FMU1Slave(guid=description.guid, unzipDirectory=unzipdir,
                        modelIdentifier=description.model_identifier, instanceName=instance_name)
        fmu.instantiate(functions=callbacks)
        if not fmu.component:
            raise RuntimeError("fmiInstantiateSlave returned NULL")
        _FMI2_SINKS[fmu.component] = sink
        adapter = cls(fmu)
        adapter._callbacks = callbacks
        return adapter

    def initialize(self, start_time, stop_time=None):
        status = self.function("InitializeSlave")(self.component, float(start_time), int(stop_time is not None),
                                                  float(stop_time or 0.0))
        if status > FMI_WARNING:
            raise RuntimeError(f"fmiInitializeSlave returned status {status}")

    def _unsupported(self, *args) -> int:
        return FMI_ERROR

    get_state = set_state = free_state = serialized_size = serialize = deserialize = _unsupported


def adapter_class(fmi_version: str, co_simulation: bool = True) -> type[FmiAdapter]:
    """The adapter for a modelDescription's fmiVersion ("1.0", "2.0", "3.0") and interface."""
    if fmi_version.startswith("1"):
        return Fmi1Adapter
    if fmi_version.startswith("3"):
        return Fmi3Adapter
    return Fmi2Adapter if co_simulation else Fmi2ModelExchangeAdapter
