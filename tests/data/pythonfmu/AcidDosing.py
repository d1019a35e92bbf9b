"""A pH-like plant: acid dosed at rate u mixes in with time constant tau, and the pH is a titration-like
static nonlinearity of the mixed concentration: x' = (u - x) / tau, pH = 7 + 3 tanh(3 (1 - x)).

More acid, lower pH: a reverse-acting plant. Held at u = 0 the pH settles at 7 + 3 tanh(3) = 9.985, at
u = 2 at 7 - 3 tanh(3) = 4.015; the slope at u = 1 (pH 7) is -9 pH per unit, 30 times the slope near u = 0.
"""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class AcidDosing(Fmi2Slave):
    author = "prlpid-fmi tests"
    description = "acid dosing with a titration-like pH curve"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.tau = 20.0
        self.acid = 1.0
        self.x = 1.0
        self.pH = 7.0
        self.register_variable(Real("tau", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        self.register_variable(Real("acid", causality=Fmi2Causality.input))
        self.register_variable(Real("pH", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        a = math.exp(-step_size / self.tau)
        self.x = a * self.x + (1 - a) * self.acid
        self.pH = 7 + 3 * math.tanh(3 * (1 - self.x))
        return True
