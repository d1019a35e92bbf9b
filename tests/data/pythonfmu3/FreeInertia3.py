"""The free inertia of tests/data/pythonfmu/FreeInertia.py as an FMI 3.0 co-simulation FMU (pythonfmu3):
J dw/dt = M - d w + M_load, dphi/dt = w, J = 0.002 kg m², d = 0.001 N m s; exact for torques held over a step."""
import math

from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64


class FreeInertia3(Fmi3Slave):
    author = "prlpid-fmi tests"
    description = "free inertia with viscous damping (torque in, angle and speed out)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.J, self.d = 0.002, 0.001
        self.M = 0.0
        self.M_load = 0.0
        self.phi = 0.0
        self.w = 0.0
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous))
        for name in ("J", "d"):
            self.register_variable(Float64(name, causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable))
        self.register_variable(Float64("M", causality=Fmi3Causality.input, description="motor torque"))
        self.register_variable(Float64("M_load", causality=Fmi3Causality.input, description="load torque"))
        self.register_variable(Float64("phi", causality=Fmi3Causality.output, description="angle"))
        self.register_variable(Float64("w", causality=Fmi3Causality.output, description="speed"))

    def do_step(self, current_time, step_size):
        T = self.J / self.d
        w_ss = (self.M + self.M_load) / self.d
        e = math.exp(-step_size / T)
        self.phi += w_ss * step_size + (self.w - w_ss) * T * (1 - e)
        self.w = w_ss + (self.w - w_ss) * e
        return True
