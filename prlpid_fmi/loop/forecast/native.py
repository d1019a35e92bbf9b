"""The reward forecast in one C call: a ctypes binding to `prlpid_forecast` of the bundled plants.

The shared C layer (plant_sources/common/forecast.c) exports, beside the FMI API, a plain function that
copies the plant instance's state into the prior and rolls the prior N samples with the PID and
reward arithmetic of prlpid_fmi.control, in the same operation order and without floating-point
contraction: the result equals FmiForecast's bit for bit. Python fills preallocated ctypes structs by
slice assignment and makes one foreign call per forecast.

The PID's structure (setpoint weights b, c and measurement filter Tf, control.pid) can change between
episodes (PID.set_structure, the fixed-PID search), so each call copies it into the setup together with the
PID's state (filter state included); the measurement filter's order and the rate limits are fixed at the PID's
construction. The rate limit's previous output (PID.last_output, NaN: none yet) is part of the state copied in, and
so are the previous sample's gains and proportional error (PID.raw_gain_state), from which the bumpless gain change
(PID.gain_change "bumpless") rescales the error sum at the roll-out's first step.

The C call moves the prior inside the library; FmuPlant keeps the prior's communication time in
`prior.time`, so the binding writes the prior's time after the roll-out back to it (the FMI path
leaves `prior.time` at the same value), and FmuPlant calls on the prior stay consistent.
"""
from __future__ import annotations

import ctypes
import math
from ctypes import c_double, c_int, c_uint, c_void_p

from prlpid_fmi.control.pid import ANTI_WINDUP_MODES, GAIN_CHANGE_MODES
from prlpid_fmi.errors import PlantError
from prlpid_fmi.loop.forecast.base import Forecast

ABI_VERSION = 4  # forecast.h PRLPID_FORECAST_ABI
MAX_LOOPS = 3
ANTI_WINDUP_CODES = {"clamping": 0, "back_calculation": 1, "none": 2}
assert set(ANTI_WINDUP_CODES) == set(ANTI_WINDUP_MODES)
GAIN_CHANGE_CODES = {"positional": 0, "bumpless": 1}
assert set(GAIN_CHANGE_CODES) == set(GAIN_CHANGE_MODES)
_EFMU, _EZERODIV, _EDOMAIN = -2, -3, -4
_L = MAX_LOOPS


class ForecastSetup(ctypes.Structure):
    """PrlpidForecastSetup of forecast.h (field for field)."""

    _fields_ = [("n_loops", c_int), ("horizon", c_int), ("anti_windup", c_int), ("coupled", c_int),
                ("has_derivative_filter", c_int), ("has_Tt", c_int), ("n_overrides", c_int),
                ("measurement_filter_order", c_int), ("gain_change", c_int),
                ("input_vr", c_uint * _L), ("output_vr", c_uint * _L),
                ("pid_sample_time", c_double), ("step_size", c_double), ("derivative_filter_N", c_double),
                ("Tt", c_double * _L), ("setpoint_weight", c_double * _L), ("derivative_weight", c_double * _L),
                ("measurement_filter", c_double * _L), ("u_rate_limit", c_double * _L),
                ("u_min", c_double * _L), ("u_max", c_double * _L),
                ("scale", c_double * _L), ("bound", c_double * _L), ("u_scale", c_double * _L),
                ("penalty", c_double),
                ("alpha", c_double), ("beta", c_double), ("v_clip", c_double), ("e_clip", c_double),
                ("bonus_threshold", c_double), ("bonus_numerator", c_double), ("bonus_offset", c_double),
                ("control_variation_weight", c_double),
                ("override_vr", ctypes.POINTER(c_uint)), ("override_value", ctypes.POINTER(c_double)),
                ("measurements", ctypes.POINTER(c_double)), ("rewards", ctypes.POINTER(c_double))]


# PrlpidForecastInput: these double arrays in this order, then `int initialized`.
_INPUT_ARRAYS = (("setpoint", _L), ("measurement", _L), ("Kp", _L), ("Ti", _L), ("Td", _L), ("coupling", 6),
                 ("u_prev", _L), ("integral", _L), ("last_error", _L), ("derivative", _L), ("filtered", _L),
                 ("filter_stage", _L), ("last_output", _L), ("last_p_error", _L), ("last_Kp", _L), ("last_Ti", _L),
                 ("last_Td", _L))


class ForecastInput(ctypes.Structure):
    """PrlpidForecastInput of forecast.h."""

    _fields_ = [(name, c_double * size) for name, size in _INPUT_ARRAYS] + [("initialized", c_int)]


class ForecastResult(ctypes.Structure):
    """PrlpidForecastResult of forecast.h."""

    _fields_ = [("mean_reward", c_double), ("prior_time", c_double), ("steps", c_int),
                ("n_measurements", c_int), ("stopped", c_int)]


def _abi_ok(library) -> bool:
    """True when the library exports the forecast with this ABI version and these struct sizes."""
    try:
        abi, size, _ = library["prlpid_forecast_abi"], library["prlpid_forecast_struct_size"], library["prlpid_forecast"]
    except (AttributeError, TypeError):
        return False
    abi.restype, abi.argtypes = c_int, []
    size.restype, size.argtypes = ctypes.c_size_t, [c_int]
    return abi() == ABI_VERSION and [size(k) for k in range(3)] == [
        ctypes.sizeof(ForecastSetup), ctypes.sizeof(ForecastInput), ctypes.sizeof(ForecastResult)]


def native_unavailable(plant, prior) -> str | None:
    """Why the one-call forecast cannot serve this plant and prior, or None when it can."""
    if plant is prior:
        return "plant and prior are the same instance"
    if not plant.description.co_simulation:
        return "a model-exchange FMU is integrated by FMPy's solver, not by its binary's own step"
    if plant.description.guid != prior.description.guid or plant.path.resolve() != prior.path.resolve():
        return f"the prior ({prior.path}) is not the plant's FMU ({plant.path})"
    if getattr(plant.library, "_handle", None) != getattr(prior.library, "_handle", None):
        return "plant and prior are not loaded from the same binary"
    if not _abi_ok(plant.library):
        return f"its binary does not export prlpid_forecast with ABI version {ABI_VERSION}"
    if not 1 <= len(prior.inputs) <= MAX_LOOPS:
        return f"it handles 1 to {MAX_LOOPS} loops, got {len(prior.inputs)}"
    return None


class NativeForecast(Forecast):
    """The forecast as one call into the FMU's binary; arguments as control.forecast.Forecast.

    After a call, `last_rewards` and `last_measurements` (built on access from the C buffers) describe
    the roll-out as in FmiForecast.
    """

    def __init__(self, plant, prior, pid, horizon: int, scale, bound, penalty: float, weights, u_scale,
                 overrides: dict | None = None):
        super().__init__(plant, prior, pid, horizon, scale, bound, penalty, weights, u_scale, overrides)
        reason = native_unavailable(plant, prior)
        if reason is not None:
            raise PlantError(f"{prior.path.name}: the one-call forecast is not available: {reason}")
        n, N = self.n_loops, self.horizon
        core = pid.pid if self.coupled else pid
        if core.sample_time_s != prior.sample_time_s:
            raise ValueError(f"PID sample time {core.sample_time_s} s differs from the prior's {prior.sample_time_s} s")
        vr = prior.value_reference
        s = self._setup = ForecastSetup()
        s.n_loops, s.horizon, s.coupled = n, N, int(self.coupled)
        s.anti_windup = ANTI_WINDUP_CODES[core.anti_windup]
        s.measurement_filter_order = core.measurement_filter_order
        s.gain_change = GAIN_CHANGE_CODES[core.gain_change]
        s.has_derivative_filter = int(core.derivative_filter_N is not None)
        s.derivative_filter_N = core.derivative_filter_N if core.derivative_filter_N is not None else math.nan
        Tt = core.Tt
        s.has_Tt = int(Tt is not None)
        if Tt is not None:
            s.Tt[:n] = Tt.tolist()
        s.input_vr[:n] = [vr(name) for name in prior.inputs]
        s.output_vr[:n] = [vr(name) for name in prior.outputs]
        s.pid_sample_time, s.step_size = core.sample_time_s, prior.sample_time_s
        s.u_min[:n], s.u_max[:n] = core.u_min.tolist(), core.u_max.tolist()
        s.u_rate_limit[:n] = core.u_rate_limit.tolist()  # inf (HUGE_VAL in C): none
        self._core = core  # the PID holding last_output (CoupledPID's inner PID)
        s.scale[:n], s.bound[:n], s.u_scale[:n] = self.scale, self.bound, self.u_scale
        s.penalty = self.penalty
        w = weights
        (s.alpha, s.beta, s.v_clip, s.e_clip, s.bonus_threshold, s.bonus_numerator, s.bonus_offset,
         s.control_variation_weight) = (float(w.alpha), float(w.beta), float(w.v_clip), float(w.e_clip),
                                        float(w.bonus_threshold), float(w.bonus_numerator),
                                        float(w.bonus_offset), float(w.control_variation_weight))
        names = list(self.overrides)
        for name in names:
            prior.description.require(name, ("input", "parameter"), "an override")
        self._override_vr = (c_uint * max(1, len(names)))(*[vr(name) for name in names])
        self._override_value = (c_double * max(1, len(names)))(*[self.overrides[name] for name in names])
        s.n_overrides = len(names)
        s.override_vr = ctypes.cast(self._override_vr, ctypes.POINTER(c_uint))
        s.override_value = ctypes.cast(self._override_value, ctypes.POINTER(c_double))
        self._measurements = (c_double * (N * n))()
        s.measurements = ctypes.cast(self._measurements, ctypes.POINTER(c_double))
        self._rewards = (c_double * N)()
        s.rewards = ctypes.cast(self._rewards, ctypes.POINTER(c_double))

        self._input = ForecastInput()
        self._result = ForecastResult()
        # one double view per input array (in _INPUT_ARRAYS order): a call fills them by slice assignment
        self._views = tuple(getattr(self._input, name) for name, _ in _INPUT_ARRAYS)
        call = plant.library["prlpid_forecast"]
        call.restype = c_int  # no argtypes: the arguments are c_void_p objects, the cheapest ctypes call
        self._call = call
        self._components = (plant.component, prior.component)
        self._args = (c_void_p(plant.component), c_void_p(prior.component), c_void_p(ctypes.addressof(s)),
                      c_void_p(ctypes.addressof(self._input)), c_void_p(ctypes.addressof(self._result)))

    def mean_reward(self, setpoint: list, measurement: list, Kp: list, Ti: list, Td: list, coupling: list | None,
                    u_prev: list) -> float:
        """As FmiForecast.mean_reward, in one C call."""
        n = self.n_loops
        (v_setpoint, v_measurement, v_Kp, v_Ti, v_Td, v_coupling, v_u_prev, v_integral, v_last_error, v_derivative,
         v_filtered, v_filter_stage, v_last_output, v_last_p, v_last_Kp, v_last_Ti, v_last_Td) = self._views
        v_setpoint[:n] = setpoint
        v_measurement[:n] = measurement
        v_Kp[:n] = Kp
        v_Ti[:n] = Ti
        v_Td[:n] = Td
        if self.coupled:
            v_coupling[:] = coupling
        v_u_prev[:n] = u_prev
        integral, last_error, derivative, initialized, filtered, filter_stage = self.pid.raw_state()
        v_integral[:n] = integral
        v_last_error[:n] = last_error
        v_derivative[:n] = derivative
        v_filtered[:n] = filtered
        v_filter_stage[:n] = filter_stage
        v_last_output[:n] = self._core.last_output  # replaced (not mutated) by every step: read it each call
        last_p, last_Kp, last_Ti, last_Td = self.pid.raw_gain_state()
        v_last_p[:n] = last_p
        v_last_Kp[:n] = last_Kp
        v_last_Ti[:n] = last_Ti
        v_last_Td[:n] = last_Td
        self._input.initialized = initialized
        s = self._setup  # the structure in force now (set_structure may have changed it)
        b, c, tf = self.pid.raw_structure()
        s.setpoint_weight[:n] = b
        s.derivative_weight[:n] = c
        s.measurement_filter[:n] = tf
        if (self.plant.component, self.prior.component) != self._components:  # re-instantiated (reset fallback)
            self._components = (self.plant.component, self.prior.component)
            self._args[0].value, self._args[1].value = self._components
        crumb = self.prior.crumb  # a worker's (fmu.worker): a crash in this call is the prior's doStep
        if crumb is not None:
            prior = self.prior
            crumb.call, crumb.plant, crumb.role, crumb.t, crumb.busy = 4, prior.crumb_id, prior.crumb_role, \
                self.plant.time, 1
        rc = self._call(*self._args)
        if crumb is not None:
            crumb.busy = 0
        if rc:
            self._raise(rc)
        result = self._result
        self.prior.time = result.prior_time
        return result.mean_reward

    def _raise(self, rc: int):
        if rc == _EFMU:
            raise PlantError(f"{self.prior.path.name}: the forecast failed on the prior: {self.prior.last_message}")
        if rc == _EZERODIV:
            raise ZeroDivisionError("float division by zero (Ti = 0, or a negative Td or Tt cancelling the sample time)")
        if rc == _EDOMAIN:
            raise ValueError("math domain error (sqrt of a negative Ti*Td for the back-calculation time constant)")
        raise RuntimeError(f"prlpid_forecast rejected its arguments (code {rc})")

    @property
    def last_measurements(self) -> list[list[float]]:
        """The prior's outputs after each step of the last roll-out (one list of n_loops floats per step)."""
        n, m = self.n_loops, self._measurements
        return [m[k * n:(k + 1) * n] for k in range(self._result.n_measurements)]

    @property
    def last_rewards(self) -> list[float]:
        """Each step's reward in the last roll-out (the penalty included)."""
        return self._rewards[:self._result.steps]
