"""prlpid-fmi: tune PID controllers for FMU plants with predictive reinforcement learning (PRL-PID)."""
from __future__ import annotations

import dataclasses

import gymnasium

__version__ = "0.1.0"
ENV_ID = "prlpid_fmi/PidTuning-v0"


def make_env(config="first_order", **overrides):
    """A PidTuningEnv for a TuningConfig or a preset name, with TuningConfig fields overridden by keyword."""
    from .config import TuningConfig
    from .env import PidTuningEnv
    from .presets import preset

    if not isinstance(config, TuningConfig):
        config = preset(config)
    if overrides:
        config = dataclasses.replace(config, **overrides)
    return PidTuningEnv(config)


if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point="prlpid_fmi:make_env")
