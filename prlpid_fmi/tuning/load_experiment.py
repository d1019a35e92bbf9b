"""The load experiment: the IAE per unit load of a step at the plant input of a loop held at an operating point.

At each operating point p (the low end, middle and high end of the setpoint range: robustness.margins.
setpoint_range_points) the loop holds setpoint p for training.setpoint_hold_steps samples (the setpoint ramped to p
from the FMU's start state over the first half of them, `approach`: a step through an unstable region can run a
reactor away that the PID holds at p), then loop i is loaded with d_i (baseline.load_step x its control span, signed
away from the actuator limit nearer to u, `signed_loads`), one loop after another, setpoint_hold_steps apart::

    J_load = mean over points p and loops i of  sum_k Ts |y0_k - y_k| / |d_i|   [output units * s / input unit]

y0 is the same controller's run without the load (the load response by superposition: a loop still settling onto
p when the load comes does not have that transient counted). No noise, no randomisation: the cost is
deterministic; a diverging episode costs DIVERGED_COST. Also the plant's measured frequency responses at those
points (`plant_responses`) and the Monte-Carlo parameter draws (`parameter_samples`) the design meets its limits on.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from prlpid_fmi.config import Disturbance, TuningConfig
from prlpid_fmi.loop.core import control_scales, randomized_parameters
from prlpid_fmi.loop.gains import GainValues
from prlpid_fmi.loop.isolated import make_core
from prlpid_fmi.robustness.margins import margins_of, setpoint_range_points
from prlpid_fmi.robustness.plant_response import MeasuredPlant
from prlpid_fmi.robustness.status import Robustness, status

DIVERGED_COST = 1e6


def plant_responses(config: TuningConfig, gains: GainValues, points: list[list[float]]) -> list[list[MeasuredPlant] | None]:
    """Per point, each loop's measured plant response (with `gains` in the loop; the others closed), or None where
    the estimate is not verified (robustness.status: the loop diverged or sat at a limit, or the plant varies
    faster than the experiment): no constraint comes from that point, the final check on the FMU still applies."""
    out = []
    for p in points:
        m = margins_of(config, gains, p)
        loops = m.per_loop or (m,)
        if any(len(x.frequencies_rad_s) < 2 or not np.all(np.isfinite(x.plant_response)) or
               status(x) != Robustness.VERIFIED for x in loops):  # no linear response to design on
            out.append(None)
            continue
        out.append([MeasuredPlant(x.frequencies_rad_s, x.plant_response, config.sample_time_s, tuple(p), (),
                                  x.own_response, np.abs(1.0 / (1.0 + x.controller_response * x.plant_response)))
                    for x in loops])
    return out


MC_SAMPLES = 4  # parameter draws of training.randomize whose responses the design also meets the limits on
MC_SEED = 20_000  # their seed (used for nothing else)


def parameter_samples(config: TuningConfig) -> list[TuningConfig]:
    """With training.randomize set, MC_SAMPLES configs of the plant with parameters drawn uniformly from its ranges
    (seeded: the same draws every run), their other randomisation off; else none."""
    ranges = randomized_parameters(config)
    if not ranges:
        return []
    rng = np.random.default_rng(MC_SEED)
    return [dataclasses.replace(config, randomize={}, plant_parameters={
        **config.plant_parameters, **{name: float(rng.uniform(lo, hi)) for name, lo, hi in ranges}})
        for _ in range(MC_SAMPLES)]


APPROACH_STEPS = 25  # setpoint values of the ramp from the FMU's start state to the operating point


def start_measurement(config: TuningConfig) -> list[float]:
    """The measurement per loop of the FMU's start state (a reset loop core, no noise, nothing stepped)."""
    core = open_core(dataclasses.replace(config, forecast_horizon=0, measurement_noise_std=0.0,
                                          actuator_noise_std=0.0, randomize={}))
    try:
        core.reset(np.random.default_rng(0))
        return [float(y) for y in core.measurement]
    finally:
        core.close()


def approach(start: list[float] | None, point: list[float], hold: int) -> tuple:
    """The setpoint schedule ((step, setpoints), ...) that ramps from `start` to `point` over the first half of the
    hold in APPROACH_STEPS steps, as the margin experiment approaches its operating point (a step through an
    unstable region can run a reactor away that the PID holds at the point); ((0, point),) from no start."""
    if start is None or hold < 2 * APPROACH_STEPS:
        return ((0, tuple(point)),)
    length = hold // 2
    schedule = []
    for j in range(APPROACH_STEPS):
        f = (j + 1) / APPROACH_STEPS
        schedule.append((j * length // APPROACH_STEPS, tuple(float(a + f * (b - a)) for a, b in zip(start, point))))
    return tuple(schedule)


def load_config(config: TuningConfig, point: list[float], loads: list[float],
                 start: list[float] | None = None) -> TuningConfig:
    """The load experiment at `point`: the setpoint ramped there from `start` (approach) and held, loop i loaded with
    loads[i] [input units] from setpoint_hold_steps * (i + 1) samples on; no noise, no randomisation."""
    hold = config.setpoint_hold_steps
    disturbances = tuple(Disturbance("actuator", l.output, hold * (i + 1), float(loads[i]))
                         for i, l in enumerate(config.loops))
    return dataclasses.replace(config, setpoint_schedule=approach(start, point, hold), disturbances=disturbances,
                               episode_steps=hold * (config.n_loops + 1), measurement_noise_std=0.0,
                               actuator_noise_std=0.0, randomize={}, forecast_horizon=0, load_disturbance=0.0)


def open_core(config: TuningConfig):
    """A loop core for `config`, in a worker process when the FMU may be instantiated only once per process (the
    design holds several cores open at once: one per operating point)."""
    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.fmu.resolve import resolve_fmu

    if config.isolation != "process" and describe_fmu(resolve_fmu(config.fmu, config.fmi_version)).once_per_process:
        config = dataclasses.replace(config, isolation="process")
    return make_core(config)


def signed_loads(config: TuningConfig, probe, load_step: float) -> list[float]:
    """Per loop, the load [input units]: load_step x the control span, signed away from the actuator limit nearer
    to u at the end of the probe's hold (a Trajectory of the unloaded experiment; u = 0 if it ended early)."""
    hold = config.setpoint_hold_steps
    u_held = probe.control_signal[min(hold, probe.steps) - 1] if not probe.terminated else None
    loads = []
    for i, (l, span) in enumerate(zip(config.loops, control_scales(config))):
        u = float(u_held[i]) if u_held is not None else 0.0
        mid = 0.5 * (l.u_min + l.u_max) if math.isfinite(l.u_min + l.u_max) else 0.0
        # u in the lower half: a negative load, which the PID meets by raising u (away from u_min)
        loads.append((-1.0 if u <= mid else 1.0) * load_step * span)
    return loads


def load_iae(traj, config: TuningConfig, unloaded=None) -> float:
    """sum over loops of Ts * sum_k |y0_k - y_k| / |d_i| from the first load on (one experiment, module docstring),
    y0 the measurement of `unloaded` (the same controller's run without the load; None: the setpoint);
    DIVERGED_COST (more for an earlier end) when either episode ended early."""
    for t in (traj, unloaded):
        if t is not None and t.terminated:
            return DIVERGED_COST * (1.0 + (config.episode_steps - t.steps) / config.episode_steps)
    reference = traj.setpoint if unloaded is None else unloaded.measurement
    e = np.abs(reference - traj.measurement)[config.setpoint_hold_steps:]
    loads = np.array([abs(d.value) for d in config.disturbances])
    return float(np.sum(e / loads) * config.sample_time_s) / len(loads)


def load_experiment(config: TuningConfig, load_step: float, run) -> float:
    """J_load of any controller: run(config) -> Trajectory runs it on a config (a fixed PID, a schedule replay).
    Each point: an unloaded probe (for the load's sign), then the loaded experiment."""
    config = dataclasses.replace(config, forecast_horizon=0)
    total, points, start = 0.0, setpoint_range_points(config), start_measurement(config)
    for p in points:
        probe = run(load_config(config, p, [0.0] * config.n_loops, start))
        loaded = load_config(config, p, signed_loads(config, probe, load_step), start)
        total += load_iae(run(loaded), loaded, probe)
    return total / len(points)
