"""prlpid-fmi: tune PID controllers for FMU plants with predictive reinforcement learning (PRL-PID).

The public API is loaded on first use (PEP 562), so ``import prlpid_fmi`` imports neither torch nor
stable-baselines3; no module inside the package imports this one. Importing it registers the Gymnasium
environment ``prlpid_fmi/PidTuning-v0`` (``gymnasium.make(ENV_ID, config="first_order")``).
"""
from __future__ import annotations

import importlib

import gymnasium

from prlpid_fmi.version import __version__

ENV_ID = "prlpid_fmi/PidTuning-v0"

# public name -> the module that defines it
_API = {
    # scenarios and environments
    "load_scenario": "prlpid_fmi.scenario.load",
    "validate_scenario": "prlpid_fmi.scenario.load",
    "Scenario": "prlpid_fmi.scenario.load",
    "init_scenario": "prlpid_fmi.scenario.draft",
    "preset": "prlpid_fmi.scenario.presets",
    "scenario_path": "prlpid_fmi.scenario.presets",
    "make_env": "prlpid_fmi.scenario.presets",
    "TuningConfig": "prlpid_fmi.config",
    "PidTuningEnv": "prlpid_fmi.loop.env",
    # plants
    "FmuPlant": "prlpid_fmi.fmu.plant",
    "describe_fmu": "prlpid_fmi.fmu.description",
    "probe": "prlpid_fmi.probe.open_loop",
    # the workflows on a run directory
    "tune": "prlpid_fmi.run.tune",
    "evaluate_run": "prlpid_fmi.run.evaluate",
    "export_schedule": "prlpid_fmi.run.export",
    "export_controller": "prlpid_fmi.run.export",
    # the pieces a control engineer may call directly
    "tune_fixed_pid": "prlpid_fmi.tuning.design_rule",
    "GainSchedule": "prlpid_fmi.tuning.schedule.table",
    "read_schedule_csv": "prlpid_fmi.tuning.schedule.csv_file",
    "write_schedule_csv": "prlpid_fmi.tuning.schedule.csv_file",
    "replay_schedule": "prlpid_fmi.tuning.schedule.replay",
    "loop_margins": "prlpid_fmi.robustness.margins",
    "Deployed": "prlpid_fmi.deliver.rule",
    # errors
    "PrlPidError": "prlpid_fmi.errors",
    "ScenarioError": "prlpid_fmi.errors",
    "PlantError": "prlpid_fmi.errors",
    "RunError": "prlpid_fmi.errors",
    "Interrupted": "prlpid_fmi.errors",
}

__all__ = ["__version__", "ENV_ID", *_API]


def __getattr__(name: str):
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'prlpid_fmi' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


if ENV_ID not in gymnasium.registry:
    gymnasium.register(ENV_ID, entry_point="prlpid_fmi.scenario.presets:make_env")
