"""Gain schedules that carry transient adaptation: tables binned from policy trajectories, and the choice
between candidate tables that `tune` makes (scenario option deploy.schedule_by).

A table of *settled* gains (prlpid_fmi.schedule.extract_schedule) records what the policy does once
the loop has come to rest. A policy that adapts during disturbances — larger gains while the error is
large — is invisible there: on a regulation task at one setpoint such a table has one effective row.

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

``deliverable_schedule`` is what `tune` calls: it builds the candidate tables of deploy.schedule_by
(auto: settled setpoint holds and error trajectories), projects each onto the Ms limit
(assess.robust_schedule), and with more than one candidate keeps the one with the lowest ISE summed
over SELECTION_EPISODES further seeded training-distribution episodes (replayed as plain PIDs; a
diverged episode scores infinity). The evaluation schedule is never used for the choice.

Seeds: extraction episodes use seed + EXTRACTION_SEED_OFFSET + i, selection episodes
seed + SELECTION_SEED_OFFSET + i, and the held-out episodes of the deliverable rule (assess, deliver)
seed + HOLDOUT_SEED_OFFSET + i (disjoint from each other and from the evaluation's seeds).
"""
from __future__ import annotations

import math
import warnings
from typing import Callable

import numpy as np

from prlpid_fmi.loop.actions import Gains
from prlpid_fmi.config import TuningConfig
from prlpid_fmi.errors import PrlPidError
from prlpid_fmi.loop.evaluation import GAIN_NAMES
from prlpid_fmi.tuning.schedule.table import (
    LOOP_VARIABLE, GainSchedule, _Probe, _variable_name, schedule_from_rows, table_meta)

Policy = Callable[[np.ndarray], np.ndarray]

TRAJECTORY_EPISODES = 8  # training-distribution episodes the trajectory table is binned from
SELECTION_EPISODES = 8  # further episodes the candidate tables are scored on (auto)
EXTRACTION_SEED_OFFSET = 10_000
SELECTION_SEED_OFFSET = 20_000
HOLDOUT_EPISODES = 8  # further episodes the deliverable rule compares the schedule and the fixed PID on
HOLDOUT_SEED_OFFSET = 30_000
RESOLUTION = 1e-3  # bins whose medians lie closer than this fraction of the visited span become one row
AUTO_CANDIDATES = ("setpoint", "error")  # what auto compares

__all__ = ["trajectory_schedule", "bin_rows", "training_ise", "deliverable_schedule", "extract"]


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
    variable = _variable_name(schedule_by, [l.output for l in config.loops])
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
        probe = _Probe(variable, env.core)
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


def extract(policy: Policy, config: TuningConfig, schedule_by: str, points: int, seed: int,
            anchor: Gains | None = None) -> GainSchedule:
    """One candidate table: error tables from trajectories, every other variable from settled holds."""
    from prlpid_fmi.tuning.schedule.table import extract_schedule

    m = LOOP_VARIABLE.match(schedule_by)
    if schedule_by == "error" or (m and m.group(1) == "error"):
        return trajectory_schedule(policy, config, schedule_by, points=points, seed=seed, anchor=anchor)
    return extract_schedule(policy, config, schedule_by=schedule_by, points=points, seed=seed, anchor=anchor)


def training_ise(schedule: GainSchedule, config: TuningConfig, seed: int = 0,
                 episodes: int = SELECTION_EPISODES, offset: int = SELECTION_SEED_OFFSET) -> float:
    """ISE (summed over loops) of the replayed table, summed over seeded training-distribution episodes
    (seeds seed + offset + i); infinity when an episode diverges."""
    from prlpid_fmi.deliver.rule import overall_metric
    from prlpid_fmi.tuning.schedule.table import replay_schedule

    total = 0.0
    for i in range(episodes):
        metrics, _ = replay_schedule(schedule, config, seed=seed + offset + i)
        if metrics.get("terminated"):
            return math.inf
        total += overall_metric(metrics["overall"], "ISE")
    return total


def deliverable_schedule(policy: Policy, scenario, seed: int, anchor: Gains | None = None
                         ) -> tuple[GainSchedule, str, dict]:
    """The table `tune` assesses against the fixed PID: (schedule, report note, info for run.json).

    Candidates per scenario.deploy.schedule_by (auto: AUTO_CANDIDATES), each projected onto the Ms
    limit (assess.robust_schedule); with several, the lowest training_ise wins. Raises PrlPidError
    when no candidate could be built (the message of each).
    """
    from prlpid_fmi.deliver.evidence import max_sensitivity, robust_schedule

    config, limit = scenario.tuning, max_sensitivity(scenario)
    by = scenario.deploy.schedule_by
    kinds = AUTO_CANDIDATES if by == "auto" else (by,)
    built, errors = [], []
    for kind in kinds:
        try:
            schedule = extract(policy, config, kind, scenario.deploy.schedule_points, seed, anchor)
        except PrlPidError as exc:
            errors.append(f"{kind}: {exc}")
            continue
        note = ""
        if schedule.excluded:
            note = ("The closed loop diverged at setpoint(s) " + ", ".join(f"{v:g}" for v in schedule.excluded)
                    + ": left out of the schedule.\n")
        schedule, detuned = robust_schedule(schedule, config, limit)
        if detuned:
            note += (f"Rows of the gain schedule ({schedule.variable}) detuned (Kp / lambda, Ti * lambda) to meet "
                     f"Ms <= {limit:g}: " + "; ".join(detuned) + ".\n")
        built.append((kind, schedule, note, {"schedule_detuned_rows": detuned} if detuned else {}))
    if not built:
        raise PrlPidError("; ".join(errors))
    if len(built) == 1:
        kind, schedule, note, info = built[0]
        return schedule, note, {**info, "schedule_by": schedule.variable}
    scores = {kind: training_ise(s, config, seed) for kind, s, _, _ in built}
    kind, schedule, note, info = min(built, key=lambda b: scores[b[0]])
    info = {**info, "schedule_candidates_training_ise": scores, "schedule_by": schedule.variable}
    words = ", ".join(f"{k} {v:.4g}" for k, v in scores.items())
    note += (f"Gain schedule over {schedule.variable} chosen (deploy.schedule_by: auto): lowest ISE over "
             f"{SELECTION_EPISODES} seeded training episodes replayed as plain PIDs ({words}).\n")
    if errors:
        note += "Candidate(s) not built: " + "; ".join(errors) + ".\n"
    return schedule, note, info
