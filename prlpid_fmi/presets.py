"""The paper's six experiments (§4.1-4.6): the training configs of the bundled scenarios/ files.

scenarios/<name>.yaml is the single source of truth; `preset(name)` is its TuningConfig.
Gain ranges there were chosen so that the paper's plants are stabilisable inside them at
Ts = 0.1 s (grid search of fixed PIDs on the ZOH-discretised plants: e.g. 1/(s-1) needs
1 < Kp < 20 with P action alone; eq. 17 has a negative DC gain and needs Kp < 0).
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from .config import TuningConfig
from .errors import PrlPidError

SCENARIO_DIR = Path(__file__).resolve().parents[1] / "scenarios"
PRESET_NAMES = ("first_order", "second_order", "first_order_1p5", "time_varying", "two_tank", "quadrotor")


def scenario_path(name: str) -> Path:
    """Path of a bundled paper scenario."""
    if name not in PRESET_NAMES:
        raise PrlPidError(f"unknown preset {name!r}; expected one of: {', '.join(PRESET_NAMES)}")
    return SCENARIO_DIR / f"{name}.yaml"


@lru_cache(maxsize=None)
def preset(name: str) -> TuningConfig:
    """The training TuningConfig of one paper experiment (see PRESET_NAMES)."""
    from .scenario import load_scenario

    return load_scenario(scenario_path(name)).tuning
