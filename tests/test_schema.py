"""The scenario schema: one home for defaults, a published JSON Schema that accepts every bundled scenario
and rejects broken ones (checked with the independent `jsonschema` validator), docs and template complete."""
from __future__ import annotations

import copy
import dataclasses
import re
from pathlib import Path
from typing import Annotated, get_args

import jsonschema
import pytest
from pydantic import BaseModel, TypeAdapter

from prlpid_fmi import config
from prlpid_fmi.cli import main
from prlpid_fmi.control.pid import ANTI_WINDUP_MODES
from prlpid_fmi.control.reward import RewardWeights
from prlpid_fmi.control.smoothing import DEFAULT_WINDOW, SMOOTHING_METHODS
from prlpid_fmi.errors import ScenarioError
from prlpid_fmi.fmu import bundled_fmu
from prlpid_fmi.schema import (AgentModel, BaselineModel, DeployModel, ScenarioModel, json_schema, json_schema_text,
                               model as m)
from prlpid_fmi.schema.document import load_yaml
from prlpid_fmi.scenario.draft import init_scenario
from prlpid_fmi.scenario.load import load_scenario, scenario_to_dict

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
SCHEMA_FILE = SCENARIOS / "scenario.schema.json"
BUNDLED = sorted(SCENARIOS.glob("*.yaml"))


def _models(model: type[BaseModel] = ScenarioModel, path: str = ""):
    """(key path, model class) of every section model reachable from ScenarioModel."""
    yield path, model
    for name, f in model.model_fields.items():
        inner = [a for a in _flat_args(f.annotation) if isinstance(a, type) and issubclass(a, BaseModel)]
        for sub in inner:
            yield from _models(sub, f"{path}.{name}" if path else name)


def _flat_args(tp):
    yield tp
    for a in get_args(tp):
        yield from _flat_args(a)


def _validator():
    return jsonschema.Draft202012Validator(json_schema())


# --------------------------------------------------------------------------------------------
# JSON Schema

def test_shipped_schema_is_current():
    assert SCHEMA_FILE.read_text() == json_schema_text(), \
        "scenarios/scenario.schema.json is stale: regenerate it with `prlpid-fmi schema > scenarios/scenario.schema.json`"


def test_schema_is_a_valid_json_schema():
    jsonschema.Draft202012Validator.check_schema(json_schema())


def test_cli_prints_the_schema(capsys):
    assert main(["schema"]) == 0
    assert capsys.readouterr().out == json_schema_text()


@pytest.mark.parametrize("path", BUNDLED, ids=[p.stem for p in BUNDLED])
def test_every_bundled_scenario_validates_against_the_json_schema(path):
    errors = list(_validator().iter_errors(load_yaml(path.read_text())))
    assert errors == [], [e.message for e in errors]


def _edit(doc: dict, path: str, value):
    node = doc
    keys = path.split(".")
    for k in keys[:-1]:
        node = node[int(k)] if isinstance(node, list) else node.setdefault(k, {})
    node[int(keys[-1]) if isinstance(node, list) else keys[-1]] = value


# (edit path, value): each breaks the structure the JSON Schema describes (and the loader refuses)
BROKEN = [
    ("strategy", {}),  # unknown top-level key
    ("plant.sample_time", -0.1),
    ("plant.sample_time", "fast"),
    ("plant.fmi_version", 4),
    ("plant.loops", []),
    ("plant.loops.0.u_limits", [1, 2, 3]),
    ("plant.loops.0.gains.Kp", [0.1, 10, "exp"]),
    ("plant.loops.0.gains.Ti", [1]),
    ("plant.loops.0.extra", 1),
    ("plant.loops.0.control_scale", 0),
    ("controller.gain_mapping", "relative"),
    ("controller.anchor_bands.Kp", 0.5),
    ("controller.anchor_bands.Td", 1.5),
    ("strategies.smoothing", "ema"),
    ("strategies.forecast_horizon", -1),
    ("reward.control_variation_weight", -1),
    ("agent.algorithm", "dqn"),
    ("agent.gamma", 1.5),
    ("agent.net_arch", []),
    ("agent.normalize", "yes"),
    ("training.episode_steps", 0),
    ("training.randomize", {"a": [1.0]}),
    ("evaluation.randomize_samples", -1),
    ("evaluation.setpoints", [{"at_step": 0}]),
    ("evaluation.disturbances", [{"type": "ramp", "target": "u", "at_step": 0, "value": 1}]),
    ("baseline.popsize", 0),
    ("deploy.max_sensitivity", 1.0),
    ("deploy.margin", 2),
    ("deploy.schedule_by", "errors"),
]


@pytest.mark.parametrize("path,value", BROKEN, ids=[f"{p}={v!r}" for p, v in BROKEN])
def test_json_schema_and_loader_reject_broken_scenarios(path, value, tmp_path):
    import yaml

    doc = load_yaml((SCENARIOS / "first_order.yaml").read_text())
    _edit(doc, path, value)
    assert list(_validator().iter_errors(doc)), f"the JSON Schema accepts {path} = {value!r}"
    file = tmp_path / "broken.yaml"
    file.write_text(yaml.safe_dump(doc))
    with pytest.raises(ScenarioError) as info:
        load_scenario(file)
    written = path.split(".")[-1] if not path.split(".")[-1].isdigit() else path.split(".")[-2]
    assert written in str(info.value)


def test_resolved_scenario_validates_against_the_json_schema():
    doc = scenario_to_dict(load_scenario(SCENARIOS / "two_tank.yaml"))
    assert list(_validator().iter_errors(doc)) == []


# --------------------------------------------------------------------------------------------
# one home for every default

def test_config_defaults_are_the_schema_defaults():
    loop = config.LoopConfig(input="u", output="y")
    lm, gm = m.LoopModel(input="u", output="y"), m.GainsModel()
    assert (loop.u_min, loop.u_max) == lm.u_limits == (-float("inf"), float("inf"))
    assert loop.setpoint_range == lm.setpoint_range
    assert (loop.measurement_scale, loop.divergence_bound, loop.control_scale) == \
        (lm.measurement_scale, lm.divergence_bound, lm.control_scale)
    for g in ("Kp", "Ti", "Td"):
        assert dataclasses.astuple(getattr(loop, g)) == getattr(gm, g)
    t = config.TuningConfig(fmu="x", loops=(loop,))
    c, s, r, tr = m.ControllerModel(), m.StrategiesModel(), m.RewardModel(), m.TrainingModel()
    assert (t.anti_windup, t.derivative_filter_N, t.coupled, t.coupling_range, t.gain_mapping) == \
        (c.anti_windup, c.derivative_filter_N, c.coupled, c.coupling_range, c.gain_mapping)
    assert dataclasses.asdict(t.anchor_bands) == c.anchor_bands.model_dump()
    assert (t.forecast_horizon, t.smoothing, t.smoothing_window, t.smoothing_alpha) == \
        (s.forecast_horizon, s.smoothing, s.smoothing_window, s.smoothing_alpha)
    assert s.smoothing_window == DEFAULT_WINDOW
    assert dataclasses.asdict(t.reward) == r.model_dump(exclude={"divergence_penalty"})
    assert t.divergence_penalty == r.divergence_penalty
    assert (t.episode_steps, t.setpoint_hold_steps, t.measurement_noise_std, t.actuator_noise_std) == \
        (tr.episode_steps, tr.setpoint_hold_steps, tr.measurement_noise_std, tr.actuator_noise_std)
    assert t.sample_time_s == m.PlantModel.model_fields["sample_time"].default
    assert dataclasses.asdict(config.AgentConfig()) == {**AgentModel().model_dump(), "net_arch": (64, 64)}
    assert dataclasses.asdict(config.BaselineConfig()) == BaselineModel().model_dump()
    assert dataclasses.asdict(config.DeployConfig()) == DeployModel().model_dump()


def test_reward_model_covers_every_reward_weight():
    assert {f.name for f in dataclasses.fields(RewardWeights)} <= set(m.RewardModel.model_fields)


def test_no_default_number_is_written_in_config_py():
    """config.py reads its defaults from the schema: no numeric or string literal after a field's '='."""
    source = (ROOT / "prlpid_fmi" / "config.py").read_text()
    literal_defaults = re.findall(r"^    \w+: [^=\n]+= *(-?[\d.]+|\"\w+\"|True|False)\s*(#.*)?$", source, re.M)
    assert literal_defaults == []


def test_choices_match_the_behaviour():
    from prlpid_fmi.tuning.agent import ALGORITHMS

    assert get_args(m.ControllerModel.model_fields["anti_windup"].annotation) == ANTI_WINDUP_MODES
    assert get_args(m.StrategiesModel.model_fields["smoothing"].annotation) == SMOOTHING_METHODS
    assert get_args(m.AgentModel.model_fields["algorithm"].annotation) == tuple(ALGORITHMS)


# --------------------------------------------------------------------------------------------
# docs, template, init

def _node(doc, path: str):
    """The mapping at a model's path in a document (first item of a list); None when not written there."""
    node = doc
    for part in path.split(".") if path else []:
        node = node.get(part) if isinstance(node, dict) else None
        node = node[0] if isinstance(node, list) and node else node
    return node if isinstance(node, dict) else None


def test_every_key_is_documented_and_in_the_template():
    docs = (ROOT / "docs" / "scenarios.md").read_text()
    template = load_yaml((SCENARIOS / "template.yaml").read_text())
    shown = set()
    for path, model in _models():
        for key in model.model_fields:
            assert f"`{key}`" in docs, f"docs/scenarios.md does not document {path}.{key}"
        node = _node(template, path)
        if node is not None:
            shown.add(model)
            assert set(model.model_fields) == set(node), f"scenarios/template.yaml: {path}"
    assert shown == {model for _, model in _models()}, "a section of the schema is not shown in the template"


@pytest.mark.parametrize("section", ["controller", "strategies", "reward", "agent", "baseline", "deploy"])
def test_template_shows_the_defaults(section):
    """The template's commented values are the defaults (sections without example values)."""
    template = load_yaml((SCENARIOS / "template.yaml").read_text())
    model = ScenarioModel.model_fields[section].annotation
    assert model.model_validate(template[section]) == model()


def test_resolved_scenario_has_every_key():
    doc = scenario_to_dict(load_scenario(SCENARIOS / "template.yaml"))
    for path, model in _models():
        node = _node(doc, path)
        assert node is None or set(model.model_fields) == set(node), path
    assert doc["training"]["setpoints"] is None and doc["evaluation"]["setpoints"][0]["at_step"] == 0


def test_template_and_init_point_editors_at_the_schema(tmp_path):
    first = (SCENARIOS / "template.yaml").read_text().splitlines()[0]
    assert first == "# yaml-language-server: $schema=scenario.schema.json"
    text = init_scenario(bundled_fmu("TwoTank", 2))
    first = text.splitlines()[0]
    assert first.startswith("# yaml-language-server: $schema=file://")
    assert Path(first.split("$schema=file://", 1)[1]) == SCHEMA_FILE.resolve()
    assert list(_validator().iter_errors(load_yaml(text))) == []


def test_model_defaults_pass_their_own_constraints():
    """Every default validates (a default outside its own range would never be caught by a user's file)."""
    for _, model in _models():
        for name, f in model.model_fields.items():
            if not f.is_required():
                value = f.get_default(call_default_factory=True)
                kind = Annotated[(f.annotation, *f.metadata)] if f.metadata else f.annotation
                TypeAdapter(kind).validate_python(value)


def test_structure_only_validation_without_a_file():
    """The models validate plain data without a file or an FMU (no context: the FMU checks are skipped)."""
    doc = copy.deepcopy(load_yaml((SCENARIOS / "two_tank.yaml").read_text()))
    assert ScenarioModel.model_validate(doc).plant.fmu == "TwoTank"
