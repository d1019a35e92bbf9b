"""Replay a gain table as a plain PID on the FMU, and score it over seeded training-distribution episodes."""
from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.tuning.schedule.table import GainSchedule
from prlpid_fmi.loop.scheduling import SchedulingVariable

SELECTION_EPISODES = 8  # further episodes the candidate tables are scored on (auto)
SELECTION_SEED_OFFSET = 20_000


def training_ise(schedule: GainSchedule, config: TuningConfig, seed: int = 0,
                 episodes: int = SELECTION_EPISODES, offset: int = SELECTION_SEED_OFFSET) -> float:
    """ISE (summed over loops) of the replayed table, summed over seeded training-distribution episodes
    (seeds seed + offset + i); infinity when an episode diverges."""
    return training_metrics(schedule, config, seed, episodes, offset)["ISE"]


def training_metrics(schedule: GainSchedule, config: TuningConfig, seed: int = 0,
                     episodes: int = SELECTION_EPISODES, offset: int = SELECTION_SEED_OFFSET) -> dict:
    """Over seeded training-distribution episodes (seeds seed + offset + i) of the replayed table:
    {"ISE": summed over loops and episodes, "TotalVariation": of u, likewise, "unsettled": episodes with a setpoint
    step that never settles (metrics: SettlingTime inf)}; ISE and TotalVariation infinity when an episode diverges
    (the rest is not run)."""
    from prlpid_fmi.metrics import overall_metric

    total = {"ISE": 0.0, "TotalVariation": 0.0, "unsettled": 0}
    for i in range(episodes):
        metrics, _ = replay_schedule(schedule, config, seed=seed + offset + i)
        if metrics.get("terminated"):
            return {"ISE": math.inf, "TotalVariation": math.inf, "unsettled": total["unsettled"]}
        total["ISE"] += overall_metric(metrics["overall"], "ISE")
        total["TotalVariation"] += overall_metric(metrics["overall"], "TotalVariation")
        total["unsettled"] += int(overall_metric(metrics["overall"], "SettlingTime") == math.inf)
    return total


def replay_schedule(schedule: GainSchedule, config: TuningConfig, seed: int = 0,
                    intervals=None) -> tuple[dict, dict]:
    """Run the plain gain-scheduled PID (table lookup, no neural network) on the FMU; (metrics, Trajectory).

    The table drives the loop core (prlpid_fmi.loop.core.LoopCore, or its isolated twin) as one of its
    three drivers, through prlpid_fmi.loop.evaluation.evaluate_gains: the config's (evaluation) setpoint
    schedule, noise and disturbances, the forecast off; the PID's structure (b, c, Tf per loop and the measurement
    filter's order), the loops' output rate limits and the gain-change law (bumpless or positional: the gains change
    every sample between breakpoints) are the table's, not the config's, so that a table read from
    its CSV replays the controller it was tuned as (and exported). Before each step the scheduling variable is read
    (setpoint, measurement, error or an FMU variable: prlpid_fmi.tuning.schedule.variable), the table gives
    Kp, Ti, Td (and coupling) there, and the core's PID, saturation, anti-windup and plant use them. No
    action smoothing and no action <-> gain map is involved, so a table with constant gains reproduces a
    rollout with those gains bit for bit.

    metrics: compute_metrics, as evaluate() computes them. The Trajectory (loop.evaluation.Trajectory)
    also holds scheduling_value (n,). Raises PrlPidError when the table's loops or coupling do not match.
    """

    names = [l.output for l in config.loops]
    if list(schedule.loop_names) != names:
        raise PrlPidError(f"the schedule's loops {list(schedule.loop_names)} differ from the config's {names}")
    if (schedule.coupling is not None) != bool(config.coupled):
        raise PrlPidError("the schedule and the config disagree on whether the PID is cross-axis coupled")
    if not math.isclose(schedule.sample_time_s, config.sample_time_s, rel_tol=1e-12):
        warnings.warn(f"the schedule was tuned at Ts = {schedule.sample_time_s} s, the config runs at "
                      f"Ts = {config.sample_time_s} s", stacklevel=2)
    from prlpid_fmi.loop.evaluation import evaluate_gains
    from prlpid_fmi.loop.isolated import make_core

    loops = tuple(dataclasses.replace(l, u_rate_limit=float(r)) for l, r in zip(config.loops, schedule.u_rate_limit))
    config = dataclasses.replace(config, forecast_horizon=0, tuned_structure=schedule.structure,
                                 measurement_filter_order=schedule.measurement_filter_order, loops=loops,
                                 gain_change=schedule.gain_change)
    core = make_core(config)
    try:
        probe = SchedulingVariable(schedule.variable, core)
        values, last = [], [None, None]  # the last value looked up and its gains (a setpoint holds for many samples)

        def table_gains(core):  # called before every step: read the scheduling variable, look the gains up
            z = probe()
            values.append(z)
            if z != last[0]:
                last[0], last[1] = z, schedule.gains_object(z).values()
            return last[1]

        metrics, traj = evaluate_gains(table_gains, config, seed=seed, intervals=intervals, core=core)
    finally:
        core.close()
    traj.scheduling_value = np.array(values)
    return metrics, traj
