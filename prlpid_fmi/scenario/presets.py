"""The bundled scenarios: the paper's six experiments (§4.1-4.6) and the commented template.

scenarios/<name>.yaml is the single source of truth; `preset(name)` is its TuningConfig. A bundled
scenario can be named wherever a scenario file is expected (`prlpid-fmi tune first_order`).
Gain ranges there were chosen so that the paper's plants are stabilisable inside them at
Ts = 0.1 s (grid search of fixed PIDs on the ZOH-discretised plants: e.g. 1/(s-1) needs
1 < Kp < 20 with P action alone; eq. 17 has a negative DC gain and needs Kp < 0).
"""
from __future__ import annotations

import dataclasses
import os
from functools import lru_cache
from pathlib import Path

from prlpid_fmi.bundled import SCENARIO_DIR
from prlpid_fmi.config import TuningConfig
from prlpid_fmi.errors import PrlPidError, ScenarioError

PRESET_NAMES = ("first_order", "second_order", "first_order_1p5", "time_varying", "two_tank", "quadrotor")


def bundled_scenario_names() -> list[str]:
    """Names of the bundled scenario files (scenarios/<name>.yaml), sorted."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def scenario_path(name: str) -> Path:
    """Path of a bundled scenario (a paper experiment or "template")."""
    names = bundled_scenario_names()
    if name not in names:
        raise PrlPidError(f"unknown preset {name!r}; expected one of: {', '.join(names) or 'none found'}")
    return SCENARIO_DIR / f"{name}.yaml"


def resolve_scenario(arg: str | Path) -> Path:
    """A scenario argument as a file: an existing path wins, else a bundled scenario's name.

    Raises ScenarioError naming the argument and the bundled names when it is neither.
    """
    path = Path(arg)
    if path.exists():
        return path
    if str(arg) in bundled_scenario_names():
        return SCENARIO_DIR / f"{arg}.yaml"
    names = ", ".join(bundled_scenario_names()) or "none found"
    raise ScenarioError(f"{arg}: no such scenario file or bundled scenario "
                        f"(expected a path to a .yaml file or one of: {names})")


@lru_cache(maxsize=None)
def preset(name: str) -> TuningConfig:
    """The training TuningConfig of one bundled scenario (see PRESET_NAMES)."""
    from prlpid_fmi.scenario.load import load_scenario

    return load_scenario(scenario_path(name)).tuning


def make_env(config="first_order", scenario=None, **overrides):
    """A PidTuningEnv for a TuningConfig, a preset name or a scenario file path (`config`, or `scenario`:
    a path or a bundled scenario's name), with TuningConfig fields overridden by keyword."""
    from prlpid_fmi.config import TuningConfig
    from prlpid_fmi.loop.env import PidTuningEnv
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
