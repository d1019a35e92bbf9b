"""Scenario files: the bundled ones load and equal the presets, round trips, one clear error per mistake."""
from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import pytest
import yaml

from prlpid_fmi.config import Disturbance, TuningConfig
from prlpid_fmi.errors import ScenarioError
from prlpid_fmi.fmu import bundled_fmu
from prlpid_fmi.scenario.presets import PRESET_NAMES, preset
from prlpid_fmi.scenario.load import (
    ALGORITHMS, EvaluationConfig, Scenario, load_scenario, scenario_to_dict, validate_scenario)
from prlpid_fmi.scenario.draft import init_scenario

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
EXPERIMENTS = sorted(p.stem for p in SCENARIOS.glob("*.yaml") if p.stem != "template")


def _raw(name: str) -> dict:
    return yaml.safe_load((SCENARIOS / f"{name}.yaml").read_text())


def _write(tmp_path: Path, doc, name: str = "bad.yaml") -> Path:
    path = tmp_path / name
    path.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc, sort_keys=False))
    return path


def test_every_experiment_has_a_scenario():
    assert sorted(PRESET_NAMES) == EXPERIMENTS


@pytest.mark.parametrize("name", EXPERIMENTS + ["template"])
def test_bundled_scenarios_load(name):
    s = load_scenario(SCENARIOS / f"{name}.yaml")
    assert isinstance(s, Scenario) and isinstance(s.tuning, TuningConfig)
    assert s.evaluation.episode_steps >= 1


def test_paper_scenarios_match_the_paper():
    """The experiments as §4 describes them (the presets are these files' training configs)."""
    def s(name):
        return load_scenario(SCENARIOS / f"{name}.yaml")
    assert s("first_order").tuning.plant_parameters.get("a", 1.0) == 1.0
    assert s("first_order_1p5").tuning.plant_parameters["a"] == 1.5
    assert s("second_order").tuning.fmu == "SecondOrderUnstable"
    tv = s("time_varying")
    assert tv.tuning.loops[0].setpoint_range == (0.0, 2.0)
    values = [v[0] for _, v in tv.evaluation.setpoint_schedule]
    assert min(values) == -0.3 and max(values) == 2.5
    tank = s("two_tank").evaluation
    assert sorted(d.start_step for d in tank.disturbances) == [100, 300, 500]
    assert tank.intervals == ((0, 200), (200, 400), (400, 600), (600, 800))
    assert s("two_tank").tuning.measurement_noise_std > 0 and s("two_tank").tuning.actuator_noise_std > 0
    quad = s("quadrotor").tuning
    assert quad.coupled and [l.output for l in quad.loops] == ["phi", "theta", "psi"]
    assert all(preset(n) == s(n).tuning for n in EXPERIMENTS)


@pytest.mark.parametrize("name", EXPERIMENTS + ["template"])
def test_round_trip(name, tmp_path):
    s = load_scenario(SCENARIOS / f"{name}.yaml")
    path = _write(tmp_path, yaml.safe_dump(scenario_to_dict(s), sort_keys=False), "resolved.yaml")
    again = load_scenario(path)
    assert again == s
    assert again.path == str(path)


def test_algorithms_match_training():
    from prlpid_fmi.tuning.agent import ALGORITHMS as TRAIN_ALGORITHMS
    assert ALGORITHMS == TRAIN_ALGORITHMS


def test_defaults_come_from_the_dataclasses(tmp_path):
    doc = {"plant": {"fmu": "FirstOrderUnstable", "loops": [{"input": "u", "output": "y"}]}}
    s = load_scenario(_write(tmp_path, doc, "minimal.yaml"))
    assert s.name == "minimal"
    assert s.tuning == TuningConfig(fmu="FirstOrderUnstable", loops=s.tuning.loops)
    assert s.tuning.loops[0] == type(s.tuning.loops[0])(input="u", output="y")
    assert s.agent == type(s.agent)()
    assert s.evaluation == EvaluationConfig(episode_steps=s.tuning.episode_steps, measurement_noise_std=0.0,
                                            actuator_noise_std=0.0)
    # plain numbers written as 3e-4 (YAML 1.1 reads them as strings) are accepted
    doc["agent"] = {"learning_rate": "3e-4"}
    assert load_scenario(_write(tmp_path, doc, "minimal.yaml")).agent.learning_rate == 3e-4


def test_two_tank_evaluation(tmp_path):
    s = load_scenario(SCENARIOS / "two_tank.yaml")
    e = s.evaluation
    assert e.episode_steps == 800
    assert e.intervals == ((0, 200), (200, 400), (400, 600), (600, 800))
    assert e.disturbances == (Disturbance("fmu", "q_d", 100, -20.0, 110), Disturbance("fmu", "q_d", 300, 20.0, 310),
                              Disturbance("fmu", "valve_factor", 500, 0.7, None))
    c = s.evaluation_config()
    assert c.episode_steps == 800 and c.setpoint_schedule == ((0, (10.0,)),)
    assert c.disturbances == e.disturbances
    assert (c.measurement_noise_std, c.actuator_noise_std) == (0.05, 0.5)
    assert c.loops == s.tuning.loops and c.fmu == s.tuning.fmu
    assert s.tuning.disturbances == () and s.tuning.setpoint_schedule is None  # training untouched


def test_evaluation_config_substitutes_everything(tmp_path):
    doc = _raw("first_order")
    doc["training"].update({"measurement_noise_std": 0.1, "actuator_noise_std": 0.2})
    doc["evaluation"] = {
        "episode_steps": 300, "setpoints": [{"at_step": 0, "value": 0.5}, {"at_step": 100, "value": [-0.5]}],
        "measurement_noise_std": 0.0, "seed": 7,
        "disturbances": [{"type": "step", "target": "actuator", "at_step": 50, "value": 1.5},
                         {"type": "pulse", "target": "measurement", "loop": "y", "at_step": 60,
                          "duration_steps": 5, "value": 0.1},
                         {"type": "parameter_change", "target": "a", "at_step": 200, "value": 1.2}]}
    s = load_scenario(_write(tmp_path, doc, "eval.yaml"))
    c = s.evaluation_config()
    assert c.episode_steps == 300 and s.tuning.episode_steps == 200
    assert c.setpoint_schedule == ((0, (0.5,)), (100, (-0.5,)))
    assert c.measurement_noise_std == 0.0 and c.actuator_noise_std == 0.2  # unset: inherits training
    assert c.disturbances == (Disturbance("actuator", "y", 50, 1.5), Disturbance("measurement", "y", 60, 0.1, 65),
                              Disturbance("fmu", "a", 200, 1.2))
    assert s.evaluation.seed == 7
    assert c.load_disturbance == 0.0 and s.tuning.load_disturbance == 0.05  # the evaluation's disturbances only
    assert dataclasses.replace(c, setpoint_schedule=None, episode_steps=200, disturbances=(),
                               measurement_noise_std=0.1, load_disturbance=0.05) == s.tuning


def test_init_scenario_loads_back(tmp_path):
    text = init_scenario(bundled_fmu("TwoTank", 3))
    s = load_scenario(_write(tmp_path, text, "two_tank_init.yaml"))
    assert s.tuning.loops[0].input == "q_in" and s.tuning.loops[0].output == "h1"
    assert s.tuning.sample_time_s > 0 and "sample_time: " in text and "(probe)" in text  # from the step test
    assert Path(s.tuning.fmu) == bundled_fmu("TwoTank", 3).resolve()
    assert "ADJUST" in text and "q_d" in text  # other pairs listed as comments


def test_init_scenario_rejects_non_fmu(tmp_path):
    bad = tmp_path / "x.fmu"
    bad.write_text("hello")
    with pytest.raises(ScenarioError, match="x.fmu"):
        init_scenario(bad)


def test_relative_fmu_path_resolves_against_the_yaml(tmp_path):
    import shutil
    shutil.copy(bundled_fmu("FirstOrderUnstable", 2), tmp_path / "plant.fmu")
    doc = _raw("first_order")
    doc["plant"]["fmu"] = "plant.fmu"
    sub = tmp_path / "sub"
    sub.mkdir()
    doc["plant"]["fmu"] = "../plant.fmu"
    s = load_scenario(_write(sub, doc, "rel.yaml"))
    assert Path(s.tuning.fmu) == (tmp_path / "plant.fmu").resolve()


# --------------------------------------------------------------------------------------------
# mistakes: (id, base scenario, edit(doc, tmp_path), key path in the message, offending value in the message)

def _set(path: str, value):
    def edit(doc, tmp_path):
        node = doc
        keys = path.split(".")
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node.setdefault(k, {})
        node[int(keys[-1]) if isinstance(node, list) else keys[-1]] = value
    return edit


def _do(fn):
    return lambda doc, tmp_path: fn(doc)


def _not_an_fmu(doc, tmp_path):
    (tmp_path / "notes.fmu").write_text("not a zip")
    doc["plant"]["fmu"] = "notes.fmu"


MISTAKES = [
    ("unknown-top-key", "first_order", _set("strategy", {}), "strategy", "'strategy'"),
    ("unknown-nested-key", "first_order", _set("strategies.smoothing_windw", 3),
     "strategies.smoothing_windw", "smoothing_window"),
    ("unknown-loop-key", "first_order", _set("plant.loops.0.u_limit", [0, 1]), "plant.loops[0].u_limit", "u_limits"),
    ("string-for-number", "first_order", _set("plant.sample_time", "fast"), "plant.sample_time", "'fast'"),
    ("non-positive-sample-time", "first_order", _set("plant.sample_time", 0), "plant.sample_time", "0"),
    ("range-length", "first_order", _set("plant.loops.0.u_limits", [1, 2, 3]), "plant.loops[0].u_limits", "[1, 2, 3]"),
    ("range-low-ge-high", "first_order", _set("plant.loops.0.setpoint_range", [1, -1]),
     "plant.loops[0].setpoint_range", "[1, -1]"),
    ("log-gain-low-le-0", "first_order", _set("plant.loops.0.gains.Kp", [0, 10, "log"]),
     "plant.loops[0].gains.Kp", "[0, 10, log]"),
    ("unknown-gain-scale", "first_order", _set("plant.loops.0.gains.Ti", [1, 10, "exp"]),
     "plant.loops[0].gains.Ti[2]", "'exp'"),
    ("unknown-smoothing", "first_order", _set("strategies.smoothing", "ema"), "strategies.smoothing", "'ema'"),
    ("unknown-anti-windup", "first_order", _set("controller.anti_windup", "clamp"), "controller.anti_windup", "'clamp'"),
    ("unknown-algorithm", "first_order", _set("agent.algorithm", "dqn"), "agent.algorithm", "'dqn'"),
    ("negative-horizon", "first_order", _set("strategies.forecast_horizon", -1), "strategies.forecast_horizon", "-1"),
    ("horizon-as-long-as-the-episode", "first_order", _set("strategies.forecast_horizon", 200),
     "strategies.forecast_horizon", "200"),
    ("window-lt-1", "first_order", _set("strategies.smoothing_window", 0), "strategies.smoothing_window", "0"),
    ("alpha-out-of-range", "first_order", _set("strategies.smoothing_alpha", 1.5), "strategies.smoothing_alpha", "1.5"),
    ("missing-fmu", "first_order", _set("plant.fmu", "nowhere.fmu"), "plant.fmu", "'nowhere.fmu'"),
    ("not-an-fmu", "first_order", _not_an_fmu, "plant.fmu", "'notes.fmu'"),
    ("unknown-loop-output", "first_order", _set("plant.loops.0.output", "yy"), "plant.loops[0].output", "'yy'"),
    ("unknown-parameter", "first_order", _set("plant.parameters", {"pole": 1.0}), "plant.parameters.pole", "'pole'"),
    ("output-as-input", "two_tank", _set("plant.loops.0.input", "h1"), "plant.loops[0].input", "'h1'"),
    ("unknown-disturbance-target", "two_tank", _set("evaluation.disturbances.0.target", "q_x"),
     "evaluation.disturbances[0].target", "'q_x'"),
    ("unknown-disturbance-type", "two_tank", _set("evaluation.disturbances.0.type", "ramp"),
     "evaluation.disturbances[0].type", "'ramp'"),
    ("disturbance-loop", "two_tank", _set("evaluation.disturbances.0", {"type": "step", "target": "actuator",
                                                                        "loop": "h1", "at_step": 3, "value": 1}),
     "evaluation.disturbances[0].loop", "'h1'"),
    ("coupled-needs-3-loops", "first_order", _set("controller.coupled", True), "controller.coupled", "true"),
    ("setpoint-list-length", "quadrotor", _set("evaluation.setpoints.1.value", [0.1, 0.2]),
     "evaluation.setpoints[1].value", "[0.1, 0.2]"),
    ("interval-outside", "two_tank", _set("evaluation.intervals.3", [600, 900]), "evaluation.intervals[3]", "[600, 900]"),
    ("total-timesteps", "first_order", _set("agent.total_timesteps", 0), "agent.total_timesteps", "0"),
    ("n-envs", "first_order", _set("agent.n_envs", 0), "agent.n_envs", "0"),
    ("bool-for-int", "first_order", _set("training.episode_steps", True), "training.episode_steps", "true"),
    ("prior-missing-parameter", "first_order", _set("prior", {"parameters": {"c": 2.0}}), "prior.parameters.c", "'c'"),
    ("fixed-parameter-disturbed", "two_tank", _set("evaluation.disturbances.0",
                                                   {"type": "parameter_change", "target": "h1_0", "at_step": 3,
                                                    "value": 1.0}),
     "evaluation.disturbances[0].target", "'h1_0'"),
]


@pytest.mark.parametrize("case", MISTAKES, ids=[m[0] for m in MISTAKES])
def test_mistake_gives_one_clear_error(case, tmp_path):
    _, base, edit, key, shown = case
    doc = copy.deepcopy(_raw(base))
    edit(doc, tmp_path)
    path = _write(tmp_path, doc)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: {key}: "), msg
    assert shown in msg, msg
    assert "(got " in msg and "; expected " in msg, msg


def test_file_level_mistakes(tmp_path):
    missing = tmp_path / "missing.yaml"
    with pytest.raises(ScenarioError, match="missing.yaml: scenario file not found"):
        load_scenario(missing)
    with pytest.raises(ScenarioError, match=r"broken.yaml: \(top level\): not valid YAML at line 3"):
        load_scenario(_write(tmp_path, "name: x\nplant: [unclosed\n", "broken.yaml"))
    with pytest.raises(ScenarioError, match=r"list.yaml: \(top level\): not a mapping \(got \[1, 2\]"):
        load_scenario(_write(tmp_path, "[1, 2]\n", "list.yaml"))
    with pytest.raises(ScenarioError,
                       match="noplant.yaml: plant: missing section .*expected a mapping with fmu, loops"):
        load_scenario(_write(tmp_path, "name: x\n", "noplant.yaml"))
    # an alias inside its own anchor would make the data contain itself (before: RecursionError)
    with pytest.raises(ScenarioError, match=r"self.yaml: \(top level\): not valid YAML at line 2, column 8: this "
                                            r"anchor is used inside itself"):
        load_scenario(_write(tmp_path, "name: x\nplant: &p\n  fmu: *p\n", "self.yaml"))
    assert validate_scenario(SCENARIOS / "first_order.yaml") == load_scenario(SCENARIOS / "first_order.yaml")


def test_nested_aliases_cost_no_more_than_the_text(tmp_path):
    """Ten levels of ten aliases each stand for 10^10 leaves; the key-line walk visits each node once, so the file
    is refused for its unknown keys at once instead of being walked 10^10 times."""
    lines = ["l0: &l0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    lines += [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 10)}]" for i in range(1, 11)]
    path = _write(tmp_path, "\n".join(lines) + "\n", "aliases.yaml")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert "l10: unknown key" in str(info.value)
