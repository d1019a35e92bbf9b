"""Magnetic levitation: a steel ball of mass m under an electromagnet, gap x from the magnet,
m x'' = m g - k (V/R)^2 / x^2 + F_d, between two stops (the magnet at x_min, the rest at x_max: the ball stops
there). With k = m g x0^2 R^2 / V0^2 the ball floats at x0 = 10 mm for V0 = 5 V; around it
x'' = (2 g / x0) dx - (2 g / V0) dV: poles +-sqrt(2 g / x0) = +-44.3 1/s, any constant voltage parks the ball on a
stop. RK4 sub-steps of 0.1 ms."""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

G = 9.81


class MagLev(Fmi2Slave):
    author = "prlpid-fmi tests"
    description = "magnetic levitation with stops (coil voltage and disturbance force in, gap out)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.m, self.R, self.x0, self.V0 = 0.05, 1.0, 0.01, 5.0
        self.x_min, self.x_max = 0.002, 0.02
        self.V = 5.0
        self.F_d = 0.0
        self.x = 0.01
        self._v = 0.0
        self._state = None
        for name in ("m", "R", "x0", "V0", "x_min", "x_max"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("V", causality=Fmi2Causality.input, description="coil voltage"))
        self.register_variable(Real("F_d", causality=Fmi2Causality.input, description="disturbance force"))
        self.register_variable(Real("x", causality=Fmi2Causality.output, description="air gap"))

    def _acc(self, x, V):
        k = self.m * G * self.x0 ** 2 * self.R ** 2 / self.V0 ** 2
        return G - k * (V / self.R) ** 2 / (x * x) / self.m + self.F_d / self.m

    def do_step(self, current_time, step_size):
        if self._state is None:
            self._state = (self.x0, 0.0)
        x, v = self._state
        k = max(1, math.ceil(step_size / 1e-4))
        h = step_size / k
        for _ in range(k):
            def f(x, v):
                return v, self._acc(x, self.V)
            k1 = f(x, v)
            k2 = f(x + h / 2 * k1[0], v + h / 2 * k1[1])
            k3 = f(x + h / 2 * k2[0], v + h / 2 * k2[1])
            k4 = f(x + h * k3[0], v + h * k3[1])
            x += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            v += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            if x <= self.x_min:
                x, v = self.x_min, max(v, 0.0) if self._acc(self.x_min, self.V) > 0 else 0.0
            elif x >= self.x_max:
                x, v = self.x_max, min(v, 0.0) if self._acc(self.x_max, self.V) < 0 else 0.0
        self._state = (x, v)
        self.x = x
        return True
