"""prlpid-fmi: tune PID controllers for FMU plants with predictive reinforcement learning (PRL-PID)."""
from __future__ import annotations

import dataclasses
import os

import gymnasium

__version__ = "0.1.0"
ENV_ID = "prlpid_fmi/PidTuning-v0"


def make_env(config="first_order", scenario=None, **overrides):
    """A PidTuningEnv for a TuningConfig, a preset name or a scenario file path (`config`, or `scenario`:
    a path or a bundled scenario's name), with TuningConfig fields overridden by keyword."""
    from prlpid_fmi.config import TuningConfig
    from prlpid_fmi.loop.env import PidTuningEnv
    from prlpid_fmi.scenario.presets import preset, resolve_scenario
    from prlpid_fmi.scenario.load import load_scenario

    if scenario is not None:
        config = load_scenario(resolve_scenario(str(scenario))).tuning
    elif isinstance(config, (str, os.PathLike)) and (os.path.isfile(config) or str(config).endswith((".yaml", ".yml"))):
        config = load_scenario(config).tuning
    elif not isinstance(config, TuningConfig):
        config = preset(config)
    if overrides:
        config = dataclasses.replace(config, **overrides)
    return PidTuningEnv(config)


if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point="prlpid_fmi:make_env")
