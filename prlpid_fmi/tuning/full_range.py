"""The full-range episodes: the largest setpoint steps of the training distribution.

Training draws each hold's setpoint uniformly from the loop's setpoint_range, so a step from one end of the range
to the other is in the distribution, but a few random episodes may not contain one, and that step is where a
saturating or nonlinear loop chatters, overshoots or diverges most. Two episodes of training's length and holds (at
least two holds), every loop's setpoint alternating between the ends of its range, one from the low end and one
from the high end, without random load steps and without noise (the controller's own command: `quiet`). The fixed
PID's design checks its chatter on them (tuning.design_rule) and the acceptance check replays every candidate on
them (deliver.evidence). None where training's setpoints are a schedule, not random.
"""
from __future__ import annotations

import dataclasses

from prlpid_fmi.config import TuningConfig

SEED_OFFSET = 40_000  # the episodes' seeds are seed + this (+ 1): their parameter draws with training.randomize


def quiet(config: TuningConfig) -> TuningConfig:
    """config without random load steps and without measurement or actuator noise."""
    return dataclasses.replace(config, load_disturbance=0.0, measurement_noise_std=0.0, actuator_noise_std=0.0)


def full_range_episodes(config: TuningConfig, seed: int) -> list[tuple[str, TuningConfig, int]]:
    """(label, config, seed) of the two full-range episodes of training config `config` (module docstring)."""
    if config.setpoint_schedule is not None:
        return []
    hold = config.setpoint_hold_steps
    n = max(config.episode_steps, 2 * hold)
    out = []
    for first, end in ((0, "low"), (1, "high")):
        steps = tuple((k, tuple(float(loop.setpoint_range[(first + j) % 2]) for loop in config.loops))
                      for j, k in enumerate(range(0, n, hold)))
        out.append((f"the full-range steps from the {end} end",
                    dataclasses.replace(quiet(config), setpoint_schedule=steps, episode_steps=n),
                    seed + SEED_OFFSET + first))
    return out
