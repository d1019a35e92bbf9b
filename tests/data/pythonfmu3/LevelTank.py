"""A tank with free inflow q_in and an outflow demand q_load: A h' = q_in - q_load, an integrating level.

Outputs: the level h, and the net inflow q_net = q_in - q_load (A times the level's rate: a rate output beside
the level it integrates to). A = 2 m², so the level rises by 0.5 m per s per m³/s of net inflow.
"""
from pythonfmu3 import Fmi3Causality, Fmi3Slave, Fmi3Variability, Float64


class LevelTank(Fmi3Slave):
    author = "prlpid-fmi tests"
    description = "tank level, integrating"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.area = 2.0
        self.q_in = 0.5
        self.q_load = 0.5
        self.h = 1.0
        self.q_net = 0.0
        self.time = 0.0
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=Fmi3Variability.continuous))
        self.register_variable(Float64("area", causality=Fmi3Causality.parameter, variability=Fmi3Variability.tunable))
        self.register_variable(Float64("q_in", causality=Fmi3Causality.input))
        self.register_variable(Float64("q_load", causality=Fmi3Causality.input))
        self.register_variable(Float64("q_net", causality=Fmi3Causality.output))
        self.register_variable(Float64("h", causality=Fmi3Causality.output))

    def do_step(self, current_time, step_size):
        self.q_net = self.q_in - self.q_load
        self.h = max(self.h + step_size * self.q_net / self.area, 0.0)
        return True
