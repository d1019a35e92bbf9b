"""The scenario schema: pydantic models of the YAML (model.py), value types (types.py), checks against the
FMU (checks.py), one-line messages (messages.py), YAML reading with duplicate keys (document.py).

``json_schema()`` is the published JSON Schema (``prlpid-fmi schema``; a copy ships as
scenarios/scenario.schema.json for editors, kept current by tests/test_schema.py).
"""
from __future__ import annotations

import json
from typing import Any

from prlpid_fmi.schema.model import (
    AgentModel,
    AnchorBandsModel,
    BaselineModel,
    ControllerModel,
    DeployModel,
    DisturbanceModel,
    EvaluationModel,
    GainsModel,
    LoopModel,
    PlantModel,
    PriorModel,
    RewardModel,
    ScenarioModel,
    SetpointModel,
    StrategiesModel,
    TrainingModel,
    default,
)
from prlpid_fmi.schema.types import (
    ALGORITHMS,
    DISTURBANCE_TYPES,
    GAIN_MAPPINGS,
    GAIN_SCALES,
    LOOP_TARGETS,
    VEC_ENVS,
    Algorithm,
    AntiWindup,
    DisturbanceKind,
    DisturbanceType,
    GainMapping,
    GainScale,
    Smoothing,
    VecEnv,
)

SCHEMA_FILE_NAME = "scenario.schema.json"


def json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a scenario file."""
    schema = ScenarioModel.model_json_schema(mode="validation")
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}


def json_schema_text() -> str:
    """json_schema() as the text of the shipped file (sorted keys, 2-space indent, final newline)."""
    return json.dumps(json_schema(), indent=2, sort_keys=False, ensure_ascii=False) + "\n"


__all__ = [
    "ScenarioModel", "PlantModel", "LoopModel", "GainsModel", "PriorModel", "ControllerModel", "AnchorBandsModel",
    "StrategiesModel", "RewardModel", "AgentModel", "TrainingModel", "EvaluationModel", "SetpointModel",
    "DisturbanceModel", "BaselineModel", "DeployModel", "default", "json_schema", "json_schema_text",
    "SCHEMA_FILE_NAME", "ALGORITHMS", "DISTURBANCE_TYPES", "GAIN_MAPPINGS", "GAIN_SCALES", "LOOP_TARGETS", "VEC_ENVS",
    "Algorithm", "AntiWindup", "DisturbanceKind", "DisturbanceType", "GainMapping", "GainScale", "Smoothing", "VecEnv",
]
