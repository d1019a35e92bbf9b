"""Scenario files: one YAML per tuning problem, validated at the edge and built into typed configs.

``load_scenario(path)`` reads a YAML scenario (layout: docs/scenarios.md, template:
scenarios/template.yaml, schema: prlpid_fmi/schema/model.py), validates it through the pydantic
scenario model (types, ranges, choices, unknown and repeated keys, and the FMU: archive, variables,
causalities) and returns a frozen ``Scenario`` holding a ``TuningConfig`` (training), an
``AgentConfig``, an ``EvaluationConfig``, a ``BaselineConfig`` and a ``DeployConfig``.
Every mistake in the file is reported at once: ScenarioError's message has one line per mistake,
``<file>: <key.path>: <problem> (got <value>; expected <what>)``, in file order.

``scenario_to_dict`` dumps the resolved scenario (every key, defaults filled in, FMU paths absolute)
from the model; it loads back into an equal Scenario. ``init_scenario(fmu)`` writes a starter scenario.
"""
from __future__ import annotations

import dataclasses
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import yaml
from pydantic import ValidationError

from prlpid_fmi.config import (
    AgentConfig,
    AnchorBands,
    BaselineConfig,
    DeployConfig,
    Disturbance,
    GainRange,
    LoopConfig,
    PriorConfig,
    TuningConfig,
)
from prlpid_fmi.control.reward import RewardWeights
from prlpid_fmi.errors import ScenarioError
from prlpid_fmi.schema import (
    ALGORITHMS,
    DISTURBANCE_TYPES,
    GAIN_SCALES,
    LOOP_TARGETS,
    SCHEMA_FILE_NAME,
    ScenarioModel,
    default,
)
from prlpid_fmi.schema import model as m
from prlpid_fmi.schema.checks import State
from prlpid_fmi.schema.document import parse_yaml, syntax_error_line
from prlpid_fmi.schema.messages import error_line

GAIN_NAMES = ("Kp", "Ti", "Td")


@dataclass(frozen=True)
class EvaluationConfig:
    """How a trained controller is evaluated (the paper's figures and tables).

    setpoint_schedule: ((step, (setpoint per loop, ...)), ...), first step 0; None = random setpoints
    from each loop's setpoint_range held setpoint_hold_steps (as in training), seeded by `seed`.
    intervals: ((start_step, end_step), ...) half-open windows for per-interval metrics (Table 2).
    episode_steps / noise stds: None = the training value (load_scenario fills them in).
    randomize: {FMU parameter: (low, high)} of the Monte-Carlo set (load_scenario fills in training's when the
    file gives none); randomize_samples: its number of episodes, 0 = no Monte-Carlo set.
    """

    setpoint_schedule: Optional[tuple[tuple[int, tuple[float, ...]], ...]] = None
    episode_steps: Optional[int] = None
    intervals: tuple[tuple[int, int], ...] = ()
    disturbances: tuple[Disturbance, ...] = ()
    measurement_noise_std: Optional[float] = None
    actuator_noise_std: Optional[float] = None
    seed: int = default(m.EvaluationModel, "seed")
    randomize: dict = field(default_factory=dict)
    randomize_samples: int = default(m.EvaluationModel, "randomize_samples")


@dataclass(frozen=True)
class Scenario:
    """A validated scenario file: training problem, agent, evaluation protocol, baseline budget, deployment."""

    name: str
    path: Optional[str] = field(compare=False)  # the source file; not part of equality
    tuning: TuningConfig
    agent: AgentConfig
    evaluation: EvaluationConfig = EvaluationConfig()
    baseline: BaselineConfig = BaselineConfig()
    deploy: DeployConfig = DeployConfig()

    def evaluation_config(self) -> TuningConfig:
        """The tuning config with the evaluation's schedule, disturbances, noise, length and randomisation."""
        e, t = self.evaluation, self.tuning
        return dataclasses.replace(
            t, setpoint_schedule=e.setpoint_schedule,
            episode_steps=t.episode_steps if e.episode_steps is None else e.episode_steps,
            disturbances=e.disturbances,
            measurement_noise_std=t.measurement_noise_std if e.measurement_noise_std is None else e.measurement_noise_std,
            actuator_noise_std=t.actuator_noise_std if e.actuator_noise_std is None else e.actuator_noise_std,
            randomize=e.randomize, load_disturbance=0.0)


# ---------------------------------------------------------------------------------------------
# model -> config dataclasses

def _schedule(entries) -> Optional[tuple]:
    if entries is None:
        return None
    return tuple((s.at_step, tuple(s.value)) for s in entries)


def _disturbances(entries) -> tuple[Disturbance, ...]:
    out = []
    for d in entries:
        end = None if d.duration_steps is None else d.at_step + d.duration_steps
        if d.target in LOOP_TARGETS:
            out.append(Disturbance(d.target, d.loop, d.at_step, d.value, end))
        else:
            out.append(Disturbance("fmu", d.target, d.at_step, d.value, end))
    return tuple(out)


def _randomize(spec: dict) -> dict:
    return {name: (float(lo), float(hi)) for name, (lo, hi) in spec.items()}


def _loop(l: m.LoopModel) -> LoopConfig:
    return LoopConfig(input=l.input, output=l.output, setpoint_range=tuple(l.setpoint_range),
                      u_min=l.u_limits[0], u_max=l.u_limits[1],
                      u_rate_limit=float("inf") if l.u_rate_limit is None else float(l.u_rate_limit),
                      **{g: GainRange(*getattr(l.gains, g)) for g in GAIN_NAMES},
                      measurement_scale=l.measurement_scale, divergence_bound=l.divergence_bound,
                      control_scale=l.control_scale)


def _fields(model, names) -> dict:
    return {k: getattr(model, k) for k in names}


def build_scenario(model: ScenarioModel, name: str, path: Optional[str] = None) -> Scenario:
    """The config dataclasses of a validated ScenarioModel (evaluation keys left out take training's)."""
    p, c, st, r, t, e = model.plant, model.controller, model.strategies, model.reward, model.training, model.evaluation
    reward_keys = [f.name for f in dataclasses.fields(RewardWeights)]
    tuning = TuningConfig(
        fmu=p.fmu, loops=tuple(_loop(l) for l in p.loops), plant_parameters=dict(p.parameters),
        sample_time_s=p.sample_time, fmi_version=p.fmi_version, isolation=p.isolation,
        leak_check_every=p.leak_check_every, leak_limit_mb=p.leak_limit_mb, step_timeout_s=p.step_timeout_s,
        prior=PriorConfig(fmu=model.prior.fmu, parameters=dict(model.prior.parameters),
                          state_map=dict(model.prior.state_map)),
        **_fields(c, ("anti_windup", "derivative_filter_N", "setpoint_weight", "derivative_weight", "measurement_filter",
                     "measurement_filter_order", "coupled", "coupling_range", "gain_mapping", "gain_change", "anchor_on")),
        anchor_bands=AnchorBands(**c.anchor_bands.model_dump()),
        **_fields(st, ("forecast_horizon", "smoothing", "smoothing_window", "smoothing_alpha")),
        reward=RewardWeights(**_fields(r, reward_keys)), divergence_penalty=r.divergence_penalty,
        episode_steps=t.episode_steps, setpoint_hold_steps=t.setpoint_hold_steps,
        setpoint_schedule=_schedule(t.setpoints), disturbances=_disturbances(t.disturbances),
        measurement_noise_std=t.measurement_noise_std, actuator_noise_std=t.actuator_noise_std,
        randomize=_randomize(t.randomize), load_disturbance=t.load_disturbance)
    agent = AgentConfig(**{**model.agent.model_dump(), "net_arch": tuple(model.agent.net_arch),
                           "extra": dict(model.agent.extra)})

    def inherit(value, training_value):
        return training_value if value is None else value

    evaluation = EvaluationConfig(
        setpoint_schedule=_schedule(e.setpoints), episode_steps=inherit(e.episode_steps, t.episode_steps),
        intervals=tuple(tuple(i) for i in e.intervals),
        disturbances=tuning.disturbances if e.disturbances is None else _disturbances(e.disturbances),
        measurement_noise_std=inherit(e.measurement_noise_std, t.measurement_noise_std),
        actuator_noise_std=inherit(e.actuator_noise_std, t.actuator_noise_std), seed=e.seed,
        randomize=tuning.randomize if e.randomize is None else _randomize(e.randomize),
        randomize_samples=e.randomize_samples)
    return Scenario(name=model.name or name, path=path, tuning=tuning, agent=agent, evaluation=evaluation,
                    baseline=BaselineConfig(**model.baseline.model_dump()),
                    deploy=DeployConfig(**model.deploy.model_dump()))


# ---------------------------------------------------------------------------------------------
# config dataclasses -> model (the resolved scenario)

def _schedule_doc(schedule) -> Optional[list]:
    if schedule is None:
        return None
    return [{"at_step": step, "value": list(values)} for step, values in schedule]


def _disturbance_doc(d: Disturbance) -> dict:
    out: dict[str, Any] = {"type": "step" if d.end_step is None else "pulse"}
    out.update({"target": d.target} if d.kind == "fmu" else {"target": d.kind, "loop": d.target})
    out["at_step"] = d.start_step
    if d.end_step is not None:
        out["duration_steps"] = d.end_step - d.start_step
    out["value"] = d.value
    return out


def scenario_model(s: Scenario) -> ScenarioModel:
    """The ScenarioModel of a Scenario: every key, training values written out where evaluation inherits them."""
    t, e = s.tuning, s.evaluation
    asdict = dataclasses.asdict
    loops = [{"input": l.input, "output": l.output, "u_limits": [l.u_min, l.u_max],
              "u_rate_limit": None if l.u_rate_limit == float("inf") else l.u_rate_limit,
              "setpoint_range": list(l.setpoint_range), "measurement_scale": l.measurement_scale,
              "divergence_bound": l.divergence_bound, "control_scale": l.control_scale,
              "gains": {g: [getattr(l, g).low, getattr(l, g).high, getattr(l, g).scale] for g in GAIN_NAMES}}
             for l in t.loops]
    doc = {
        "name": s.name,
        "plant": {"fmu": t.fmu, "fmi_version": t.fmi_version, "sample_time": t.sample_time_s,
                  "parameters": dict(t.plant_parameters), "loops": loops, "isolation": t.isolation,
                  "leak_check_every": t.leak_check_every, "leak_limit_mb": t.leak_limit_mb,
                  "step_timeout_s": t.step_timeout_s},
        "prior": asdict(t.prior),
        "controller": {**_fields(t, m.ControllerModel.model_fields.keys() - {"anchor_bands"}),
                       "anchor_bands": asdict(t.anchor_bands)},
        "strategies": _fields(t, m.StrategiesModel.model_fields),
        "reward": {**asdict(t.reward), "divergence_penalty": t.divergence_penalty},
        "agent": asdict(s.agent),
        "training": {"episode_steps": t.episode_steps, "setpoint_hold_steps": t.setpoint_hold_steps,
                     "setpoints": _schedule_doc(t.setpoint_schedule),
                     "measurement_noise_std": t.measurement_noise_std, "actuator_noise_std": t.actuator_noise_std,
                     "disturbances": [_disturbance_doc(d) for d in t.disturbances],
                     "load_disturbance": t.load_disturbance,
                     "randomize": {k: list(v) for k, v in dict(t.randomize).items()}},
        "evaluation": {"episode_steps": e.episode_steps, "setpoints": _schedule_doc(e.setpoint_schedule),
                       "intervals": [list(i) for i in e.intervals],
                       "disturbances": [_disturbance_doc(d) for d in e.disturbances],
                       "measurement_noise_std": e.measurement_noise_std, "actuator_noise_std": e.actuator_noise_std,
                       "seed": e.seed,
                       "randomize": {k: list(v) for k, v in e.randomize.items()},
                       "randomize_samples": e.randomize_samples},
        "baseline": asdict(s.baseline),
        "deploy": asdict(s.deploy),
    }
    return ScenarioModel.model_validate(doc)


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def scenario_to_dict(s: Scenario) -> dict:
    """The resolved scenario (every key, defaults filled in) as plain YAML-able data; loads back equal."""
    return _plain(scenario_model(s).model_dump(mode="python"))


def scenario_to_yaml(s: Scenario) -> str:
    """scenario_to_dict as YAML text (key order kept)."""
    return yaml.safe_dump(scenario_to_dict(s), sort_keys=False, default_flow_style=None, width=120)


# ---------------------------------------------------------------------------------------------
# loading

def _read(path: Path, file: str) -> str:
    if not path.is_file():
        raise ScenarioError(f"{file}: scenario file not found (got {file!r}; expected a path to a .yaml file)")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        if zipfile.is_zipfile(path):  # most likely the plant itself, given where a scenario belongs
            raise ScenarioError(f"{file}: (top level): a ZIP archive (an FMU?), not a scenario (got binary data; "
                                f"expected UTF-8 YAML: write a scenario for an FMU with `prlpid-fmi init "
                                f"{file} > scenario.yaml`)") from None
        raise ScenarioError(f"{file}: (top level): not a text file (got binary data; expected UTF-8 YAML)") from None
    except OSError as exc:
        raise ScenarioError(f"{file}: (top level): cannot be read: {exc.strerror} "
                            f"(got {file!r}; expected a readable file)") from None


def load_scenario(path: str | Path, base: str | Path | None = None) -> Scenario:
    """Read, validate and build a scenario file.

    base: a complete scenario file that a file without a `plant:` section is laid over (each section the file has
    replaces the base's whole; the file may then hold only, say, `evaluation:`); paths then resolve against base's
    folder, and the scenario keeps base's name unless the file gives one. A file with a `plant:` section is complete
    by itself: base is not read. Raises ScenarioError listing every mistake, one line each, in file order.
    """
    p = Path(path)
    file = str(path)
    text = _read(p, file)
    try:
        document = parse_yaml(text)
    except yaml.YAMLError as exc:
        raise ScenarioError(syntax_error_line(file, exc)) from None
    lines = list(zip((d[0] for d in document.duplicates), document.duplicate_lines(file)))
    data, folder, name = document.data, p.resolve().parent, p.stem
    if base is not None and isinstance(data, dict) and "plant" not in data:
        under = parse_yaml(_read(Path(base), str(base))).data
        if isinstance(data, dict) and isinstance(under, dict):
            data, folder, name = {**under, **data}, Path(base).resolve().parent, str(under.get("name") or Path(base).stem)
    model = None
    try:
        model = ScenarioModel.model_validate(data, context={"state": State(folder)})
    except ValidationError as exc:
        lines += [(tuple(err["loc"]), error_line(file, data, err)) for err in exc.errors()]
    if lines:
        ordered = sorted(range(len(lines)), key=lambda i: (document.line_of(lines[i][0]) or 10**9, i))
        unique = list(dict.fromkeys(lines[i][1] for i in ordered))
        raise ScenarioError("\n".join(unique))
    return build_scenario(model, name, file)


def validate_scenario(path: str | Path) -> Scenario:
    """Same as load_scenario (validation is loading); for `prlpid-fmi validate`."""
    return load_scenario(path)


validate = validate_scenario


def schema_uri() -> str:
    """file:// URI of the shipped JSON Schema (for the yaml-language-server line of generated scenarios)."""
    from prlpid_fmi.bundled import SCENARIO_DIR

    return (SCENARIO_DIR / SCHEMA_FILE_NAME).resolve().as_uri()


__all__ = ["Scenario", "EvaluationConfig", "load_scenario", "validate_scenario", "validate", "build_scenario",
           "scenario_model", "scenario_to_dict", "scenario_to_yaml", "schema_uri",
           "DISTURBANCE_TYPES", "GAIN_SCALES", "ALGORITHMS"]
