"""A mass on a spring with a damper, driven by a force: m x'' = F - k x - c x'.

Outputs in the order an OpenModelica export lists them: the velocity v first, then the position x. The step
is exact for a force held over it (zero-order hold): the state transition of the underdamped oscillator in
closed form, so the FMU's period is the analytic 2 pi / (wn sqrt(1 - zeta^2)), wn = sqrt(k/m), zeta = c/(2 sqrt(k m)).
"""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class MassSpringDamper(Fmi2Slave):
    author = "prlpid-fmi tests"
    description = "mass-spring-damper (force in, velocity and position out)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.m, self.k, self.c = 1.0, 30.0, 1.1
        self.F = 0.0
        self.v = 0.0
        self.x = 0.0
        for name in ("m", "k", "c"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("F", causality=Fmi2Causality.input))
        self.register_variable(Real("v", causality=Fmi2Causality.output))
        self.register_variable(Real("x", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        wn = math.sqrt(self.k / self.m)
        zeta = self.c / (2 * math.sqrt(self.k * self.m))
        wd = wn * math.sqrt(1 - zeta * zeta)
        s = zeta * wn
        e = math.exp(-s * step_size)
        cos, sin = math.cos(wd * step_size), math.sin(wd * step_size)
        x_ss = self.F / self.k                       # the position the held force holds
        dx, v = self.x - x_ss, self.v
        self.x = x_ss + e * (dx * (cos + s / wd * sin) + v / wd * sin)
        self.v = e * (v * (cos - s / wd * sin) - dx * wn * wn / wd * sin)
        return True
