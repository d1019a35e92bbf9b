"""Gain tables that carry transient adaptation, binned from the policy's trajectories.

A table of *settled* gains (prlpid_fmi.tuning.schedule.extraction.extract_schedule) records what the policy
does once the loop has come to rest. A policy that adapts during disturbances — larger gains while the
error is large — is invisible there: on a regulation task at one setpoint such a table has one effective row.

``trajectory_schedule`` rolls the policy out on seeded episodes of the TRAINING distribution (the
config `tune` trained on: its random setpoints, noise, disturbances and parameter randomisation,
forecast and smoothing on, exactly as in training), reads the scheduling variable before every step
(the same reading replay_schedule and the PLC exports make) and the gains the step applied, and bins
the pairs: K bins of equal sample count (edges at the i/K quantiles of the visited values), breakpoint
= the median value in the bin (the (i + 1/2)/K quantile), gains = the median of each gain column in
the bin. States the policy visits during transients get rows of their own, in proportion to the time
spent there. Neighbouring bins whose medians lie within RESOLUTION of the visited span of each other
are averaged into one row (a noise-free loop at rest puts most samples at e = 0 exactly: without this,
rows 1e-9 apart). Any scheduling variable works; ``error[<loop>]`` is the one for transients.

Seeds: extraction episodes use seed + EXTRACTION_SEED_OFFSET + i; the candidate selection
(prlpid_fmi.deliver.candidates) and the deliverable rule's held-out episodes (prlpid_fmi.deliver.evidence)
use seed + SELECTION_SEED_OFFSET + i and seed + HOLDOUT_SEED_OFFSET + i: disjoint from each other and from
the evaluation's seeds.
"""
from __future__ import annotations

import warnings

import numpy as np

from prlpid_fmi.config import TuningConfig
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.loop.evaluation import GAIN_NAMES, Policy
from prlpid_fmi.loop.gains import Gains
from prlpid_fmi.tuning.schedule.table import GainSchedule, schedule_from_rows, table_meta
from prlpid_fmi.loop.scheduling import SchedulingVariable
from prlpid_fmi.tuning.schedule.variable import variable_name

TRAJECTORY_EPISODES = 8  # training-distribution episodes the trajectory table is binned from
EXTRACTION_SEED_OFFSET = 10_000
RESOLUTION = 1e-3  # bins whose medians lie closer than this fraction of the visited span become one row

__all__ = ["trajectory_schedule", "trajectory_samples", "bin_rows"]


def bin_rows(values: np.ndarray, gains: dict[str, np.ndarray], points: int) -> list[tuple[float, dict]]:
    """Equal-count bins of the samples by `values` (n,): [(median value, {key: median gains per column})].

    gains: {"Kp": (n, n_loops), ...}. Bin i holds the samples whose rank lies in [i*n/K, (i+1)*n/K)
    (ties broken by sample order, so equal values may share bins; equal medians are merged later).
    """
    n = len(values)
    if n == 0:
        raise PrlPidError("no samples to bin: every episode ended at its first step")
    k = max(1, min(int(points), n))
    order = np.argsort(values, kind="stable")
    rows = []
    for idx in np.array_split(order, k):
        rows.append((float(np.median(values[idx])), {key: np.median(g[idx], axis=0) for key, g in gains.items()}))
    return rows


def trajectory_schedule(policy: Policy, config: TuningConfig, schedule_by: str = "error", points: int = 9,
                        episodes: int = TRAJECTORY_EPISODES, seed: int = 0, anchor: Gains | None = None
                        ) -> GainSchedule:
    """The policy's applied gains binned by a scheduling variable over seeded training episodes.

    config: the training config (its setpoints, noise, disturbances and randomisation are used as they
    are). schedule_by: "error", "setpoint", "measurement" (of loop 0), "<kind>[<loop>]" or an FMU
    variable. points: K >= 1 bins (fewer when there are fewer samples). Episodes run with seeds
    seed + EXTRACTION_SEED_OFFSET + i; an episode that diverges contributes its samples up to the
    failure and is named in a warning. anchor: the fixed-PID gains of an anchored gain map.
    """
    if points < 1 or episodes < 1:
        raise PrlPidError(f"points and episodes must be >= 1 (got {points}, {episodes})")
    variable = variable_name(schedule_by, [l.output for l in config.loops])
    values, gains, unit, meta = trajectory_samples(policy, config, variable, episodes, seed, anchor)
    rows = bin_rows(values, gains, points)
    resolution = RESOLUTION * float(values.max() - values.min())
    with warnings.catch_warnings():  # bins of (nearly) equal medians merge silently
        warnings.simplefilter("ignore")
        return schedule_from_rows(config, variable, unit, rows, meta, resolution=resolution)


def trajectory_samples(policy: Policy, config: TuningConfig, variable: str, episodes: int, seed: int,
                       anchor: Gains | None = None) -> tuple[np.ndarray, dict, str, dict]:
    """The rollouts of trajectory_schedule: (values (n,), {"Kp": (n, n_loops), ...}, unit, table_meta)."""
    from prlpid_fmi.loop.env import PidTuningEnv

    values, applied, failed = [], [], []
    env = PidTuningEnv(config, info=False, anchor=anchor)
    try:
        probe = SchedulingVariable(variable, env.core)
        unit, meta = probe.unit(), table_meta(env.core, config)
        for i in range(episodes):
            episode_seed = seed + EXTRACTION_SEED_OFFSET + i
            obs, _ = env.reset(seed=episode_seed)
            for _ in range(config.episode_steps):
                z = probe()
                obs, _, terminated, _, _ = env.step(policy(obs))
                if terminated:
                    failed.append(episode_seed)
                    break
                values.append(z)
                applied.append(env.gains)
    finally:
        env.close()
    if failed:
        warnings.warn(f"{variable}: the closed loop with the policy diverged in training episode(s) with seed "
                      f"{', '.join(map(str, failed))}; their samples up to the failure are binned", stacklevel=3)
    gains = {name: np.array([g[i] for g in applied], float) for i, name in enumerate(GAIN_NAMES)
             if applied and applied[0][i] is not None}
    return np.array(values, float), gains, unit, meta
