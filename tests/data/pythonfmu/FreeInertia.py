"""A free inertia driven by a motor torque, as a Dymola motor model exports it: J dw/dt = M - d w + M_load,
dphi/dt = w; outputs the angle phi and the speed w (J = 0.002 kg m^2, d = 0.001 N m s: the speed's lag J/d = 2 s).
Exact for torques held over a step (the closed-form state transition)."""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class FreeInertia(Fmi2Slave):
    author = "prlpid-fmi tests"
    description = "free inertia with viscous damping (torque in, angle and speed out)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.J, self.d = 0.002, 0.001
        self.M = 0.0
        self.M_load = 0.0
        self.phi = 0.0
        self.w = 0.0
        for name in ("J", "d"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("M", causality=Fmi2Causality.input, description="motor torque"))
        self.register_variable(Real("M_load", causality=Fmi2Causality.input, description="load torque"))
        self.register_variable(Real("phi", causality=Fmi2Causality.output, description="angle"))
        self.register_variable(Real("w", causality=Fmi2Causality.output, description="speed"))

    def do_step(self, current_time, step_size):
        T = self.J / self.d
        w_ss = (self.M + self.M_load) / self.d            # the speed the held torque holds
        e = math.exp(-step_size / T)
        self.phi += w_ss * step_size + (self.w - w_ss) * T * (1 - e)
        self.w = w_ss + (self.w - w_ss) * e
        return True
