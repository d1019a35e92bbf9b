"""A heated vessel whose heater is switched: it heats with 2 kW when the command exceeds 0.5, else not at
all; the temperature follows as a first-order lag (tau 50 s, 10 K per kW over 20 degC ambient)."""
import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Real


class OnOffValve(Fmi2Slave):
    author = "prlpid-fmi tests"
    description = "a heater that is either on or off"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.command = 0.7
        self.T = 40.0
        self.register_variable(Real("command", causality=Fmi2Causality.input))
        self.register_variable(Real("T", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        power = 2.0 if self.command > 0.5 else 0.0
        a = math.exp(-step_size / 50.0)
        self.T = a * self.T + (1 - a) * (20.0 + 10.0 * power)
        return True
