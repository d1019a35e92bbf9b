"""The paper's six experiments (§4.1-4.6) as ready TuningConfigs for the bundled plants.

Gain ranges were chosen so that the paper's plants are stabilisable inside them at Ts = 0.1 s
(checked with a grid search of fixed PIDs on the ZOH-discretised plants: e.g. 1/(s-1) needs
1 < Kp < 20 for stability with P action alone; eq. 17 has a negative DC gain and needs Kp < 0).
"""
from __future__ import annotations

from .config import Disturbance, GainRange, LoopConfig, TuningConfig

_FIRST_ORDER_LOOP = LoopConfig(
    input="u", output="y", setpoint_range=(-1.0, 1.0), u_min=-10.0, u_max=10.0,
    Kp=GainRange(0.5, 30.0, "log"), Ti=GainRange(0.2, 20.0, "log"), Td=GainRange(0.0, 0.2, "linear"),
    measurement_scale=1.0, divergence_bound=5.0)


def _presets() -> dict[str, TuningConfig]:
    return {
        # §4.1: G(s) = 1/(s - 1)
        "first_order": TuningConfig(fmu="FirstOrderUnstable", loops=(_FIRST_ORDER_LOOP,), plant_parameters={"a": 1.0}),
        # §4.2: eq. 17, second-order unstable with a right-half-plane zero and negative DC gain
        "second_order": TuningConfig(
            fmu="SecondOrderUnstable",
            loops=(LoopConfig(input="u", output="y", setpoint_range=(-1.0, 1.0), u_min=-20.0, u_max=20.0,
                              Kp=GainRange(-1.0, -0.01, "linear"), Ti=GainRange(1.0, 200.0, "log"),
                              Td=GainRange(0.0, 60.0, "linear"), divergence_bound=10.0),),
            episode_steps=1000, setpoint_hold_steps=500),
        # §4.3: G(s) = 1/(s - 1.5), for the action-smoothing comparison
        "first_order_1p5": TuningConfig(fmu="FirstOrderUnstable", loops=(_FIRST_ORDER_LOOP,),
                                        plant_parameters={"a": 1.5}),
        # §4.4: time-varying first order, trained on setpoints in [0, 2]
        "time_varying": TuningConfig(
            fmu="TimeVaryingFirstOrder",
            loops=(LoopConfig(input="u", output="y", setpoint_range=(0.0, 2.0), u_min=-10.0, u_max=10.0,
                              Kp=GainRange(0.5, 30.0, "log"), Ti=GainRange(0.2, 20.0, "log"),
                              Td=GainRange(0.0, 0.2, "linear"), divergence_bound=5.0),)),
        # §4.5: two-tank level h2 by pump inflow, with sensor and actuator noise, starting in steady state
        "two_tank": TuningConfig(
            fmu="TwoTank",
            loops=(LoopConfig(input="q_in", output="h2", setpoint_range=(5.0, 15.0), u_min=0.0, u_max=50.0,
                              Kp=GainRange(0.5, 50.0, "log"), Ti=GainRange(1.0, 200.0, "log"),
                              Td=GainRange(0.0, 5.0, "linear"), measurement_scale=10.0,
                              divergence_bound=10.0),),
            plant_parameters={"h1_0": 15.4, "h2_0": 10.0}, episode_steps=600, setpoint_hold_steps=200,
            measurement_noise_std=0.05, actuator_noise_std=0.5),
        # §4.6: quadrotor attitude, cross-axis coupled PID on roll, pitch, yaw
        "quadrotor": TuningConfig(
            fmu="QuadrotorAttitude",
            loops=tuple(LoopConfig(input=u, output=y, setpoint_range=(-0.5, 0.5), u_min=-2.0, u_max=2.0,
                                   Kp=GainRange(0.1, 20.0, "log"), Ti=GainRange(0.5, 100.0, "log"),
                                   Td=GainRange(0.05, 2.0, "linear"), measurement_scale=0.5,
                                   divergence_bound=6.0)
                        for u, y in (("U_phi", "phi"), ("U_theta", "theta"), ("U_psi", "psi"))),
            coupled=True, episode_steps=300, setpoint_hold_steps=150),
    }


PRESET_NAMES = tuple(_presets())


def preset(name: str) -> TuningConfig:
    """The TuningConfig of one paper experiment (see PRESET_NAMES)."""
    presets = _presets()
    if name not in presets:
        from .errors import PrlPidError
        raise PrlPidError(f"unknown preset {name!r}; expected one of: {', '.join(presets)}")
    return presets[name]


__all__ = ["PRESET_NAMES", "preset", "Disturbance"]
