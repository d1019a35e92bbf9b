"""Gain tables from a trained policy: settled setpoint holds (extract_schedule) or trajectories (error tables),
dispatched by extract."""
from __future__ import annotations

import dataclasses
import math
import warnings
from typing import Sequence

import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.loop.evaluation import GAIN_NAMES, Policy
from prlpid_fmi.loop.gains import Gains
from prlpid_fmi.tuning.schedule.table import LOOP_VARIABLE, GainSchedule, exact_mean, schedule_from_rows, table_meta
from prlpid_fmi.tuning.schedule.trajectories import trajectory_schedule
from prlpid_fmi.loop.scheduling import SchedulingVariable
from prlpid_fmi.tuning.schedule.variable import variable_name

SETTLED_FRACTION = 0.2  # gains and breakpoint: mean over the last 20 % of each hold


def _nominal(config: TuningConfig) -> TuningConfig:
    """`config` without parameter randomisation (schedules are read at nominal parameters)."""
    if config.randomize:
        return dataclasses.replace(config, randomize=type(config.randomize)())
    return config


def extract_schedule(policy: Policy, config: TuningConfig, schedule_by: str = "setpoint",
                     points: int | Sequence[float] = 9, settle_steps: int | None = None, seed: int = 0,
                     hold_setpoints: Sequence[float] | None = None, anchor: Gains | None = None) -> GainSchedule:
    """Record the gains `policy` settles on at operating points of the scheduling variable.

    The setpoint of the scheduled loop (the one named in ``setpoint[<loop>]`` / ``measurement[<loop>]``,
    else loop 0) is held at each of `points` values — an int K: evenly spaced over that loop's
    setpoint_range; a sequence: those setpoints. The other loops hold `hold_setpoints` (default: the
    middle of their setpoint_range; the scheduled loop's entry is ignored). Each hold is a fresh
    episode of `settle_steps` samples (default: config.episode_steps) from the plant's initial state,
    with forecast, noise and disturbances off and the config's smoothing on (so the recorded gains
    are the ones applied). Gains and breakpoint are means over the last 20 % of the hold.

    schedule_by: "setpoint", "measurement" (of loop 0), "setpoint[<loop>]", "measurement[<loop>]", or
    an FMU variable name. Rows are sorted by breakpoint; rows whose breakpoints coincide (a variable
    that does not depend on the setpoint) are averaged into one, with a warning.
    anchor: the fixed-PID gains the policy's anchored gain map was trained around (as in training).
    Raises PrlPidError when the closed loop diverges at an operating point (the table would be unsafe).
    """
    from prlpid_fmi.loop.env import PidTuningEnv

    names = [l.output for l in config.loops]
    variable = variable_name(schedule_by, names)
    m = LOOP_VARIABLE.match(variable)
    if m and m.group(1) == "error":
        raise PrlPidError(f"{variable}: settled holds have no error to schedule on (expected setpoint, measurement "
                          "or an FMU variable; error tables come from policy trajectories, "
                          "prlpid_fmi.tuning.schedule.trajectories.trajectory_schedule)")
    loop = names.index(m.group(2)) if m else 0
    setpoints = operating_setpoints(config.loops[loop].setpoint_range, points)
    steps = int(settle_steps if settle_steps is not None else config.episode_steps)
    if steps < 1:
        raise PrlPidError(f"settle_steps must be >= 1, got {steps}")
    others = (list(hold_setpoints) if hold_setpoints is not None
              else [0.5 * (l.setpoint_range[0] + l.setpoint_range[1]) for l in config.loops])
    if len(others) != config.n_loops:
        raise PrlPidError(f"hold_setpoints needs {config.n_loops} values, got {len(others)}")
    tail = max(1, math.ceil(SETTLED_FRACTION * steps))

    rows, excluded, failures = [], [], {}  # failures: reason -> setpoints (one warning per reason)
    held = _nominal(dataclasses.replace(config, episode_steps=steps, forecast_horizon=0, measurement_noise_std=0.0,
                                        actuator_noise_std=0.0, disturbances=()))
    env = PidTuningEnv(held, info=False, anchor=anchor)
    try:
        probe = SchedulingVariable(variable, env.core)
        unit = probe.unit()
        meta = table_meta(env.core, config)
        for sp in setpoints:
            hold = list(others)
            hold[loop] = float(sp)
            row, why = _settled_row(env, probe, policy, hold, seed, steps, tail)
            if row is None:  # no safe gains exist there: leave the point out of the table
                excluded.append(float(sp))
                failures.setdefault(why, []).append(float(sp))
            else:
                rows.append(row)
    finally:
        env.close()

    for why, where in failures.items():
        points_text = f"setpoint {where[0]:g}" if len(where) == 1 else \
            f"{len(where)} setpoints ({', '.join(f'{v:g}' for v in where)})"
        warnings.warn(f"the closed loop failed at {variable} {points_text} ({why}); "
                      f"{'that operating point is' if len(where) == 1 else 'they are'} left out of the schedule",
                      stacklevel=2)
    if not rows:
        raise PrlPidError(f"the closed loop diverged at every operating point of {variable} "
                          f"({', '.join(f'{v:g}' for v in excluded)}): no gains can be scheduled; "
                          "train longer or narrow the operating range")
    return schedule_from_rows(config, variable, unit, rows, meta, excluded=tuple(excluded))


def operating_setpoints(setpoint_range: tuple[float, float], points: int | Sequence[float]) -> list[float]:
    """The setpoints a table is read at: an int K evenly spaced over setpoint_range (K = 1: its middle), or the
    given values. PrlPidError for K < 1 or no values."""
    lo, hi = setpoint_range
    if isinstance(points, (int, np.integer)):
        if points < 1:
            raise PrlPidError(f"points must be >= 1, got {points}")
        return [0.5 * (lo + hi)] if points == 1 else list(np.linspace(lo, hi, int(points)))
    setpoints = [float(v) for v in points]
    if not setpoints:
        raise PrlPidError("points: no operating points given")
    return setpoints


def _settled_row(env, probe: SchedulingVariable, policy: Policy, hold: list[float], seed: int, steps: int,
                 tail: int) -> tuple[tuple | None, str]:
    """One hold of `steps` samples at setpoints `hold`: (row, "") with the means of the scheduling variable and of
    the applied gains over the last `tail` samples, or (None, why) when the closed loop ended early."""
    obs, _ = env.reset(seed=seed, options={"setpoint_schedule": ((0, tuple(hold)),)})
    values, gains = [], []
    for k in range(steps):
        values.append(probe())
        obs, _, terminated, _, _ = env.step(policy(obs))
        if terminated:
            return None, env.core.termination.message if env.core.termination else f"diverged at step {k + 1}"
        gains.append(env.gains)
    g = {name: np.array([x[i] for x in gains[-tail:]], float) for i, name in enumerate(GAIN_NAMES)
         if gains[0][i] is not None}
    return (float(exact_mean(np.array(values[-tail:]))), {key: exact_mean(v) for key, v in g.items()}), ""


def extract(policy: Policy, config: TuningConfig, schedule_by: str, points: int, seed: int,
            anchor: Gains | None = None) -> GainSchedule:
    """One candidate table: error tables from trajectories, every other variable from settled holds."""
    from prlpid_fmi.tuning.schedule.extraction import extract_schedule

    m = LOOP_VARIABLE.match(schedule_by)
    if schedule_by == "error" or (m and m.group(1) == "error"):
        return trajectory_schedule(policy, config, schedule_by, points=points, seed=seed, anchor=anchor)
    return extract_schedule(policy, config, schedule_by=schedule_by, points=points, seed=seed, anchor=anchor)
