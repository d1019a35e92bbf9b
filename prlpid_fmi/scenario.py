"""Scenario files: one YAML per tuning problem, validated at the edge and built into typed configs.

``load_scenario(path)`` reads a YAML scenario (layout: docs/scenarios.md, template:
scenarios/template.yaml), checks every key, type, range and FMU variable, and returns a frozen
``Scenario`` holding a ``TuningConfig`` (training), an ``AgentConfig`` and an ``EvaluationConfig``.
Every default comes from the dataclasses in prlpid_fmi.config (keys left out are simply not passed).
Any mistake raises one ScenarioError, one line:
``<file>: <key.path>: <problem> (got <value>; expected <what>)``.

``scenario_to_dict`` gives the resolved scenario (every key, defaults filled in, FMU paths absolute)
that loads back into an equal Scenario; ``init_scenario(fmu)`` writes a starter scenario for any FMU.
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import yaml

from .config import AgentConfig, BaselineConfig, Disturbance, GainRange, LoopConfig, PriorConfig, TuningConfig
from .control.pid import ANTI_WINDUP_MODES
from .control.reward import RewardWeights
from .control.smoothing import DEFAULT_ALPHA, SMOOTHING_METHODS
from .errors import PlantError, ScenarioError

ALGORITHMS = ("ppo", "sac", "td3")  # = prlpid_fmi.train.ALGORITHMS (not imported: that pulls in torch)
VEC_ENVS = ("dummy", "subproc")
GAIN_SCALES = ("log", "linear")
GAIN_NAMES = ("Kp", "Ti", "Td")
DISTURBANCE_TYPES = ("step", "pulse", "parameter_change")
LOOP_TARGETS = ("actuator", "measurement")  # disturbance targets that act on a loop, not on the FMU
INF = math.inf


@dataclass(frozen=True)
class EvaluationConfig:
    """How a trained controller is evaluated (the paper's figures and tables).

    setpoint_schedule: ((step, (setpoint per loop, ...)), ...), first step 0; None = random setpoints
    from each loop's setpoint_range held setpoint_hold_steps (as in training), seeded by `seed`.
    intervals: ((start_step, end_step), ...) half-open windows for per-interval metrics (Table 2).
    episode_steps / noise stds: None = the training value (load_scenario fills them in).
    """

    setpoint_schedule: Optional[tuple[tuple[int, tuple[float, ...]], ...]] = None
    episode_steps: Optional[int] = None
    intervals: tuple[tuple[int, int], ...] = ()
    disturbances: tuple[Disturbance, ...] = ()
    measurement_noise_std: Optional[float] = None
    actuator_noise_std: Optional[float] = None
    seed: int = 0


@dataclass(frozen=True)
class Scenario:
    """A validated scenario file: training problem, agent, and evaluation protocol."""

    name: str
    path: Optional[str] = field(compare=False)  # the source file; not part of equality
    tuning: TuningConfig
    agent: AgentConfig
    evaluation: EvaluationConfig = EvaluationConfig()
    baseline: BaselineConfig = BaselineConfig()

    def evaluation_config(self) -> TuningConfig:
        """The tuning config with the evaluation's schedule, disturbances, noise and length substituted."""
        e, t = self.evaluation, self.tuning
        return dataclasses.replace(
            t, setpoint_schedule=e.setpoint_schedule,
            episode_steps=t.episode_steps if e.episode_steps is None else e.episode_steps,
            disturbances=e.disturbances,
            measurement_noise_std=t.measurement_noise_std if e.measurement_noise_std is None else e.measurement_noise_std,
            actuator_noise_std=t.actuator_noise_std if e.actuator_noise_std is None else e.actuator_noise_std)


# ---------------------------------------------------------------------------------------------
# defaults (taken from the dataclasses, never repeated here)

def _defaults(cls) -> dict[str, Any]:
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
            out[f.name] = f.default_factory()  # type: ignore[misc]
    return out


# YAML key -> TuningConfig field, per section
_PLANT_KEYS = {"fmu": "fmu", "fmi_version": "fmi_version", "sample_time": "sample_time_s",
               "parameters": "plant_parameters", "loops": "loops"}
_CONTROLLER_KEYS = ("anti_windup", "derivative_filter_N", "coupled", "coupling_range")
_STRATEGY_KEYS = ("forecast_horizon", "smoothing", "smoothing_window", "smoothing_alpha")
_REWARD_KEYS = tuple(f.name for f in dataclasses.fields(RewardWeights)) + ("divergence_penalty",)
_TRAINING_KEYS = ("episode_steps", "setpoint_hold_steps", "setpoints", "measurement_noise_std",
                  "actuator_noise_std", "disturbances")
_EVALUATION_KEYS = ("episode_steps", "setpoints", "intervals", "disturbances", "measurement_noise_std",
                    "actuator_noise_std", "seed")
_LOOP_KEYS = ("input", "output", "u_limits", "setpoint_range", "measurement_scale", "divergence_bound", "gains")
_PRIOR_KEYS = tuple(f.name for f in dataclasses.fields(PriorConfig))
_AGENT_KEYS = tuple(f.name for f in dataclasses.fields(AgentConfig))
_DISTURBANCE_KEYS = ("type", "target", "loop", "at_step", "duration_steps", "value")
_TOP_KEYS = ("name", "plant", "prior", "controller", "strategies", "reward", "agent", "training", "evaluation",
             "baseline")
_BASELINE_KEYS = tuple(f.name for f in dataclasses.fields(BaselineConfig))
_OPTIONAL_FLOAT = {"derivative_filter_N", "smoothing_alpha"}


# ---------------------------------------------------------------------------------------------
# the reader: typed access to the YAML with key paths for messages

def _show(value: Any) -> str:
    text = repr(value) if isinstance(value, str) else yaml.safe_dump(value, default_flow_style=True,
                                                                      width=10_000).strip()
    if text.endswith("\n..."):
        text = text[:-4].strip()
    return text if len(text) <= 80 else text[:77] + "..."


_NUMBER_RE = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^[-+]?\.?inf$", re.IGNORECASE)


class _Reader:
    def __init__(self, file: str, base_dir: Path):
        self.file = file
        self.base_dir = base_dir

    def error(self, key: str, problem: str, got: Any, expected: str) -> ScenarioError:
        return ScenarioError(f"{self.file}: {key}: {problem} (got {_show(got)}; expected {expected})")

    def mapping(self, value: Any, key: str, known: tuple[str, ...]) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise self.error(key, "not a mapping", value, f"a mapping with keys {', '.join(known)}")
        for k in value:
            if k not in known:
                close = difflib.get_close_matches(str(k), known, n=1)
                hint = f"a known key; did you mean {close[0]!r}?" if close else f"one of {', '.join(known)}"
                raise self.error(f"{key}.{k}" if key else str(k), "unknown key", k, hint)
        return value

    def number(self, value: Any, key: str, optional: bool = False) -> Optional[float]:
        if value is None and optional:
            return None
        if isinstance(value, str) and _NUMBER_RE.match(value.strip()):  # YAML 1.1 reads 1e-3 as a string
            return float(value)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, "not a number", value, "a number" + (" or null" if optional else ""))
        if math.isnan(value):
            raise self.error(key, "not a number", value, "a number")
        return float(value)

    def integer(self, value: Any, key: str) -> int:
        if isinstance(value, float) and value.is_integer():
            return int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, "not an integer", value, "an integer")
        return value

    def boolean(self, value: Any, key: str) -> bool:
        if not isinstance(value, bool):
            raise self.error(key, "not a boolean", value, "true or false")
        return value

    def string(self, value: Any, key: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.error(key, "not a string", value, "a non-empty string")
        return value

    def choice(self, value: Any, key: str, choices: tuple[str, ...], what: str) -> str:
        if value not in choices:
            raise self.error(key, f"unknown {what}", value, f"one of {', '.join(choices)}")
        return value

    def sequence(self, value: Any, key: str, length: Optional[int] = None, what: str = "a list") -> list:
        if not isinstance(value, (list, tuple)) or (length is not None and len(value) != length):
            raise self.error(key, "not " + what if not isinstance(value, (list, tuple))
                             else f"list of length {len(value)}", value, what)
        return list(value)

    def range_(self, value: Any, key: str) -> tuple[float, float]:
        lo, hi = self.sequence(value, key, 2, "a list [low, high] of two numbers")
        lo, hi = self.number(lo, f"{key}[0]"), self.number(hi, f"{key}[1]")
        if not lo < hi:
            raise self.error(key, "low >= high", value, "low < high")
        return lo, hi

    def positive(self, value: Any, key: str, integer: bool = False, minimum: float = 0.0,
                 inclusive: bool = False) -> float:
        v = self.integer(value, key) if integer else self.number(value, key)
        if not (v >= minimum if inclusive else v > minimum):
            op = ">=" if inclusive else ">"
            raise self.error(key, "out of range", value, f"{'an integer' if integer else 'a number'} {op} {minimum:g}")
        return v

    def params(self, value: Any, key: str) -> dict:
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise self.error(key, "not a mapping", value, "a mapping {variable name: number}")
        return {self.string(k, f"{key}"): self.number(v, f"{key}.{k}") for k, v in value.items()}


# ---------------------------------------------------------------------------------------------
# FMU resolution and variable checks

def _resolve_fmu(r: _Reader, value: str, key: str, fmi_version: int) -> tuple[str, Path]:
    """(value for TuningConfig.fmu, path of the FMU file). Bundled names stay names; paths become absolute."""
    from .fmu import bundled_fmu, bundled_plant_names

    names = bundled_plant_names()
    if value in names:
        try:
            return value, bundled_fmu(value, fmi_version)
        except PlantError as exc:
            raise r.error(key, f"cannot build the bundled plant: {exc}", value, "a buildable bundled plant") from None
    path = Path(value).expanduser()
    if not path.is_absolute():
        path = (r.base_dir / path).resolve()
    if not path.is_file():
        raise r.error(key, f"FMU file not found: {path}", value,
                      f"a path to a .fmu file (relative to the scenario's folder) or a bundled plant: {', '.join(names)}")
    return str(path), path


def _describe(r: _Reader, path: Path, key: str, value: str):
    from .fmu import describe_fmu

    try:
        return describe_fmu(path)
    except PlantError as exc:
        problem = str(exc)
        prefix = f"{path}: "
        problem = problem[len(prefix):] if problem.startswith(prefix) else problem
        raise r.error(key, problem.split(" (expected")[0], value,
                      "an FMU: a ZIP archive with a modelDescription.xml") from None


def _check_variable(r: _Reader, desc, name: str, key: str, causalities: tuple[str, ...], role: str,
                    variabilities: Optional[tuple[str, ...]] = None) -> None:
    v = desc.variable(name)
    wanted = " or ".join(causalities)
    if v is None:
        pool = [x.name for x in desc.variables if x.causality in causalities]
        close = difflib.get_close_matches(name, pool, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise r.error(key, f"the FMU {desc.path.name} has no variable {name!r}", name,
                      f"{role} ({wanted}) of the FMU: {', '.join(pool) or 'none'}{hint}")
    if v.causality not in causalities:
        pool = [x.name for x in desc.variables if x.causality in causalities]
        raise r.error(key, f"causality mismatch: {name!r} is {v.causality!r} in the FMU, not {wanted}", name,
                      f"{role}: {', '.join(pool) or 'none'}")
    if v.type not in ("Real", "Float64"):
        raise r.error(key, f"{name!r} is a {v.type} variable", name, f"a real (Real/Float64) variable as {role}")
    if variabilities is not None and v.causality == "parameter" and v.variability not in variabilities:
        raise r.error(key, f"{name!r} is a {v.variability} parameter and cannot change during a run", name,
                      "an input or a tunable parameter")


# ---------------------------------------------------------------------------------------------
# sections

def _gain(r: _Reader, value: Any, key: str, default: GainRange, gain: str) -> GainRange:
    items = r.sequence(value, key, None, "a list [low, high] or [low, high, scale]")
    if len(items) not in (2, 3):
        raise r.error(key, f"list of length {len(items)}", value, "[low, high] or [low, high, log|linear]")
    lo, hi = r.range_(items[:2], key)
    scale = r.choice(items[2], f"{key}[2]", GAIN_SCALES, "gain scale") if len(items) == 3 else default.scale
    if scale == "log" and lo <= 0:
        raise r.error(key, "a log range needs low > 0", value, "low > 0, or scale linear")
    if gain == "Ti" and lo <= 0:
        raise r.error(key, "Ti divides the integral term and must stay > 0", value, "low > 0")
    if gain == "Td" and lo < 0:
        raise r.error(key, "Td must be >= 0", value, "low >= 0")
    return GainRange(lo, hi, scale)


def _loop(r: _Reader, raw: Any, key: str) -> LoopConfig:
    m = r.mapping(raw, key, _LOOP_KEYS)
    defaults = _defaults(LoopConfig)
    for req in ("input", "output"):
        if req not in m:
            raise r.error(f"{key}.{req}", "missing key", None, "the FMU variable name")
    kw: dict[str, Any] = {"input": r.string(m["input"], f"{key}.input"),
                          "output": r.string(m["output"], f"{key}.output")}
    if "u_limits" in m:
        lo, hi = r.range_(m["u_limits"], f"{key}.u_limits")
        kw["u_min"], kw["u_max"] = lo, hi
    if "setpoint_range" in m:
        kw["setpoint_range"] = r.range_(m["setpoint_range"], f"{key}.setpoint_range")
    for k in ("measurement_scale", "divergence_bound"):
        if k in m:
            kw[k] = r.positive(m[k], f"{key}.{k}")
    gains = r.mapping(m.get("gains"), f"{key}.gains", GAIN_NAMES)
    for g, v in gains.items():
        kw[g] = _gain(r, v, f"{key}.gains.{g}", defaults[g], g)
    return LoopConfig(**kw)


def _setpoints(r: _Reader, raw: Any, key: str, n_loops: int, episode_steps: int):
    if raw is None:
        return None
    items = r.sequence(raw, key, None, "a list of {at_step, value}")
    if not items:
        raise r.error(key, "empty schedule", raw, "at least one {at_step: 0, value: ...}, or null")
    schedule, last = [], -1
    for i, item in enumerate(items):
        k = f"{key}[{i}]"
        m = r.mapping(item, k, ("at_step", "value"))
        for req in ("at_step", "value"):
            if req not in m:
                raise r.error(f"{k}.{req}", "missing key", None, "at_step (integer) and value")
        step = r.integer(m["at_step"], f"{k}.at_step")
        if i == 0 and step != 0:
            raise r.error(f"{k}.at_step", "the schedule must start at step 0", step, "0")
        if step <= last or step >= episode_steps:
            raise r.error(f"{k}.at_step", "out of order or past the episode", step,
                          f"an integer in ({last}, {episode_steps}) (episode_steps = {episode_steps})")
        last = step
        value = m["value"]
        if isinstance(value, (list, tuple)):
            if len(value) != n_loops:
                raise r.error(f"{k}.value", f"{len(value)} setpoints for {n_loops} loop(s)", value,
                              f"a list of {n_loops} numbers, one per loop")
            values = tuple(r.number(v, f"{k}.value[{j}]") for j, v in enumerate(value))
        else:
            if n_loops != 1 and not isinstance(value, bool) and isinstance(value, (int, float)):
                raise r.error(f"{k}.value", f"a single setpoint for {n_loops} loops", value,
                              f"a list of {n_loops} numbers, one per loop")
            values = (r.number(value, f"{k}.value"),)
        schedule.append((step, values))
    return tuple(schedule)


def _disturbances(r: _Reader, raw: Any, key: str, desc, outputs: list[str], episode_steps: int):
    if raw is None:
        return ()
    out = []
    for i, item in enumerate(r.sequence(raw, key, None, "a list of disturbances")):
        k = f"{key}[{i}]"
        m = r.mapping(item, k, _DISTURBANCE_KEYS)
        for req in ("type", "target", "at_step", "value"):
            if req not in m:
                raise r.error(f"{k}.{req}", "missing key", None, "type, target, at_step and value")
        dtype = r.choice(m["type"], f"{k}.type", DISTURBANCE_TYPES, "disturbance type")
        target = r.string(m["target"], f"{k}.target")
        start = r.integer(m["at_step"], f"{k}.at_step")
        if not 0 <= start < episode_steps:
            raise r.error(f"{k}.at_step", "outside the episode", start, f"an integer in [0, {episode_steps})")
        value = r.number(m["value"], f"{k}.value")
        end = None
        if dtype == "pulse" and "duration_steps" not in m:
            raise r.error(f"{k}.duration_steps", "missing key (a pulse needs a duration)", None, "an integer >= 1")
        if m.get("duration_steps") is not None:
            end = start + int(r.positive(m["duration_steps"], f"{k}.duration_steps", integer=True))
        if target in LOOP_TARGETS:
            if dtype == "parameter_change":
                raise r.error(f"{k}.target", "a parameter_change needs an FMU parameter", target,
                              "the name of a tunable parameter of the FMU")
            if "loop" not in m and len(outputs) == 1:
                loop = outputs[0]
            else:
                loop = m.get("loop")
                if loop not in outputs:
                    raise r.error(f"{k}.loop", "not a loop output", loop,
                                  f"the output of a loop: {', '.join(outputs)}")
            out.append(Disturbance(target, loop, start, value, end))
        else:
            if "loop" in m:
                raise r.error(f"{k}.loop", f"only for targets {' / '.join(LOOP_TARGETS)}", m["loop"],
                              "no loop key for an FMU variable target")
            if dtype == "parameter_change":
                _check_variable(r, desc, target, f"{k}.target", ("parameter",), "a parameter", ("tunable",))
            else:
                _check_variable(r, desc, target, f"{k}.target", ("input", "parameter"),
                                "an input or tunable parameter", ("tunable",))
            out.append(Disturbance("fmu", target, start, value, end))
    return tuple(out)


def _section_values(r: _Reader, m: dict, key: str, defaults: dict) -> dict:
    """Type-check the plain scalar keys of a section against the type of the dataclass default."""
    kw = {}
    for k, v in m.items():
        path = f"{key}.{k}"
        d = defaults[k]
        if k in _OPTIONAL_FLOAT:
            kw[k] = r.number(v, path, optional=True)
        elif isinstance(d, bool):
            kw[k] = r.boolean(v, path)
        elif isinstance(d, int):
            kw[k] = r.integer(v, path)
        elif isinstance(d, float):
            kw[k] = r.number(v, path)
        elif isinstance(d, str):
            kw[k] = r.string(v, path)
        elif isinstance(d, tuple):
            kw[k] = tuple(r.positive(x, f"{path}[{j}]", integer=True)
                          for j, x in enumerate(r.sequence(v, path, None, "a list of integers")))
        elif isinstance(d, dict):
            if v is not None and not isinstance(v, dict):
                raise r.error(path, "not a mapping", v, "a mapping")
            kw[k] = dict(v or {})
        else:  # pragma: no cover - a new field type in config.py
            raise r.error(path, "unsupported key", v, "a known key")
    return kw


def _agent(r: _Reader, raw: Any) -> AgentConfig:
    m = r.mapping(raw, "agent", _AGENT_KEYS)
    kw = _section_values(r, m, "agent", _defaults(AgentConfig))
    if "algorithm" in kw:
        r.choice(kw["algorithm"], "agent.algorithm", ALGORITHMS, "algorithm")
    if "vec_env" in kw:
        r.choice(kw["vec_env"], "agent.vec_env", VEC_ENVS, "vectorised environment")
    for k, minimum, inclusive in (("total_timesteps", 0, False), ("n_envs", 1, True), ("learning_rate", 0, False),
                                  ("n_steps", 1, True), ("batch_size", 1, True), ("n_epochs", 1, True),
                                  ("buffer_size", 1, True), ("learning_starts", 0, True),
                                  ("checkpoint_every", 1, True), ("torch_threads", 1, True),
                                  ("clip_range", 0, False), ("ent_coef", 0, True)):
        if k in kw:
            r.positive(m[k], f"agent.{k}", integer=isinstance(kw[k], int), minimum=minimum, inclusive=inclusive)
    for k in ("gamma", "gae_lambda"):
        if k in kw and not 0 <= kw[k] <= 1:
            raise r.error(f"agent.{k}", "out of range", m[k], "a number in [0, 1]")
    if "net_arch" in kw and not kw["net_arch"]:
        raise r.error("agent.net_arch", "empty", m["net_arch"], "a list of layer sizes, e.g. [64, 64]")
    return AgentConfig(**kw)


def _build(r: _Reader, doc: Any, stem: str) -> Scenario:
    doc = r.mapping(doc, "", _TOP_KEYS) if isinstance(doc, dict) else doc
    if not isinstance(doc, dict):
        raise ScenarioError(f"{r.file}: (top level): not a mapping (got {_show(doc)}; "
                            f"expected a mapping with keys {', '.join(_TOP_KEYS)})")
    name = r.string(doc["name"], "name") if doc.get("name") is not None else stem
    tdef = _defaults(TuningConfig)
    kw: dict[str, Any] = {}

    # plant
    if "plant" not in doc:
        raise r.error("plant", "missing section", None, "a mapping with fmu and loops")
    plant = r.mapping(doc["plant"], "plant", tuple(_PLANT_KEYS))
    if "fmi_version" in plant:
        kw["fmi_version"] = r.integer(plant["fmi_version"], "plant.fmi_version")
        if kw["fmi_version"] not in (2, 3):
            raise r.error("plant.fmi_version", "unsupported FMI version", plant["fmi_version"], "2 or 3")
    fmi_version = kw.get("fmi_version", tdef["fmi_version"])
    if plant.get("fmu") is None:
        raise r.error("plant.fmu", "missing key", None, "a bundled plant name or a path to a .fmu file")
    fmu_value = r.string(plant["fmu"], "plant.fmu")
    kw["fmu"], fmu_path = _resolve_fmu(r, fmu_value, "plant.fmu", fmi_version)
    desc = _describe(r, fmu_path, "plant.fmu", fmu_value)
    if not desc.co_simulation:
        raise r.error("plant.fmu", "the FMU has no co-simulation interface", fmu_value,
                      "an FMU exported for co-simulation")
    if "sample_time" in plant:
        kw["sample_time_s"] = r.positive(plant["sample_time"], "plant.sample_time")
    if "parameters" in plant:
        kw["plant_parameters"] = r.params(plant["parameters"], "plant.parameters")
        for p in kw["plant_parameters"]:
            _check_variable(r, desc, p, f"plant.parameters.{p}", ("parameter", "input"), "a parameter")
    raw_loops = plant.get("loops")
    loops_list = r.sequence(raw_loops, "plant.loops", None, "a list of loops {input, output, ...}")
    if not loops_list:
        raise r.error("plant.loops", "no loops", raw_loops, "at least one loop {input, output}")
    loops = tuple(_loop(r, l, f"plant.loops[{i}]") for i, l in enumerate(loops_list))
    for i, loop in enumerate(loops):
        _check_variable(r, desc, loop.input, f"plant.loops[{i}].input", ("input",), "a loop input")
        _check_variable(r, desc, loop.output, f"plant.loops[{i}].output", ("output", "local"), "a loop output")
        for attr in ("input", "output"):
            if getattr(loop, attr) in [getattr(other, attr) for other in loops[:i]]:
                raise r.error(f"plant.loops[{i}].{attr}", f"two loops share the {attr}", getattr(loop, attr),
                              f"a different {attr} per loop")
    kw["loops"] = loops
    outputs = [l.output for l in loops]

    # prior
    if "prior" in doc:
        pm = r.mapping(doc["prior"], "prior", _PRIOR_KEYS)
        pkw: dict[str, Any] = {}
        prior_desc = desc
        if pm.get("fmu") is not None:
            pval = r.string(pm["fmu"], "prior.fmu")
            pkw["fmu"], ppath = _resolve_fmu(r, pval, "prior.fmu", fmi_version)
            prior_desc = _describe(r, ppath, "prior.fmu", pval)
            for i, loop in enumerate(loops):
                _check_variable(r, prior_desc, loop.input, "prior.fmu", ("input",), f"loop {i}'s input")
                _check_variable(r, prior_desc, loop.output, "prior.fmu", ("output", "local"), f"loop {i}'s output")
        if "parameters" in pm:
            pkw["parameters"] = r.params(pm["parameters"], "prior.parameters")
            for p in pkw["parameters"]:
                _check_variable(r, prior_desc, p, f"prior.parameters.{p}", ("parameter", "input"), "a parameter")
        if "state_map" in pm and pm["state_map"] is not None:
            smap = pm["state_map"]
            if not isinstance(smap, dict):
                raise r.error("prior.state_map", "not a mapping", smap, "a mapping {prior parameter: plant variable}")
            for pp, pv in smap.items():
                _check_variable(r, prior_desc, str(pp), f"prior.state_map.{pp}", ("parameter",), "a prior parameter")
                _check_variable(r, desc, r.string(pv, f"prior.state_map.{pp}"), f"prior.state_map.{pp}",
                                ("output", "local", "parameter", "input"), "a plant variable")
            pkw["state_map"] = {str(k): v for k, v in smap.items()}
        if pkw.get("fmu") is not None and prior_desc.path != desc.path and not pkw.get("state_map"):
            raise r.error("prior.state_map", "a different prior FMU needs a state map", pm.get("state_map"),
                          "a mapping {prior parameter: plant variable} (its state cannot be copied from the plant)")
        kw["prior"] = PriorConfig(**pkw)

    # controller, strategies, reward
    for section, keys in (("controller", _CONTROLLER_KEYS), ("strategies", _STRATEGY_KEYS)):
        if section in doc:
            kw.update(_section_values(r, r.mapping(doc[section], section, keys), section, tdef))
    anti_windup, smoothing = kw.get("anti_windup", tdef["anti_windup"]), kw.get("smoothing", tdef["smoothing"])
    r.choice(anti_windup, "controller.anti_windup", ANTI_WINDUP_MODES, "anti-windup mode")
    if kw.get("derivative_filter_N") is not None and not kw["derivative_filter_N"] > 0:
        raise r.error("controller.derivative_filter_N", "out of range", kw["derivative_filter_N"], "a number > 0 or null")
    if "coupling_range" in kw:
        r.positive(kw["coupling_range"], "controller.coupling_range")
    if kw.get("coupled", tdef["coupled"]) and len(loops) != 3:
        raise r.error("controller.coupled", f"the cross-axis coupled PID needs exactly 3 loops, the plant has {len(loops)}",
                      True, "false, or 3 loops (roll, pitch, yaw)")
    r.choice(smoothing, "strategies.smoothing", SMOOTHING_METHODS, "smoothing method")
    if "forecast_horizon" in kw:
        r.positive(kw["forecast_horizon"], "strategies.forecast_horizon", integer=True, inclusive=True)
    if "smoothing_window" in kw:
        r.positive(kw["smoothing_window"], "strategies.smoothing_window", integer=True, minimum=1, inclusive=True)
    alpha = kw.get("smoothing_alpha", tdef["smoothing_alpha"])
    if alpha is not None:
        if smoothing not in DEFAULT_ALPHA:
            raise r.error("strategies.smoothing_alpha", f"smoothing {smoothing!r} takes no alpha", alpha,
                          f"null, or smoothing {' / '.join(DEFAULT_ALPHA)}")
        lo_ok = alpha >= 0 if smoothing == "lwma" else alpha > 0
        if not (lo_ok and alpha <= 1):
            raise r.error("strategies.smoothing_alpha", "out of range", alpha,
                          "a number in [0, 1]" if smoothing == "lwma" else "a number in (0, 1]")
    horizon = kw.get("forecast_horizon", tdef["forecast_horizon"])
    if horizon > 0 and kw.get("prior", tdef["prior"]).fmu is None:
        problems = desc.prior_problems()
        if problems:
            raise r.error("strategies.forecast_horizon", "the plant FMU cannot serve as its own prior: "
                          + "; ".join(problems), horizon,
                          "0 (no reward forecast), or a prior.fmu with a state_map")
    if "reward" in doc:
        rm = r.mapping(doc["reward"], "reward", _REWARD_KEYS)
        rkw = _section_values(r, {k: v for k, v in rm.items() if k != "divergence_penalty"}, "reward",
                              _defaults(RewardWeights))
        for k, v in rkw.items():
            strict = k in ("v_clip", "e_clip", "bonus_offset")
            r.positive(v, f"reward.{k}", inclusive=not strict)
        kw["reward"] = RewardWeights(**rkw)
        if "divergence_penalty" in rm:
            kw["divergence_penalty"] = r.number(rm["divergence_penalty"], "reward.divergence_penalty")

    # training
    tm = r.mapping(doc.get("training"), "training", _TRAINING_KEYS)
    for k in ("episode_steps", "setpoint_hold_steps"):
        if k in tm:
            kw[k] = r.positive(tm[k], f"training.{k}", integer=True)
    for k in ("measurement_noise_std", "actuator_noise_std"):
        if k in tm:
            kw[k] = r.positive(tm[k], f"training.{k}", inclusive=True)
    episode_steps = kw.get("episode_steps", tdef["episode_steps"])
    if tm.get("setpoints") is not None:
        kw["setpoint_schedule"] = _setpoints(r, tm["setpoints"], "training.setpoints", len(loops), episode_steps)
    if "disturbances" in tm:
        kw["disturbances"] = _disturbances(r, tm["disturbances"], "training.disturbances", desc, outputs,
                                           episode_steps)
    tuning = TuningConfig(**kw)

    agent = _agent(r, doc.get("agent"))

    # evaluation
    em = r.mapping(doc.get("evaluation"), "evaluation", _EVALUATION_KEYS)
    ekw: dict[str, Any] = {
        "episode_steps": tuning.episode_steps, "measurement_noise_std": tuning.measurement_noise_std,
        "actuator_noise_std": tuning.actuator_noise_std, "disturbances": tuning.disturbances}
    if "episode_steps" in em:
        ekw["episode_steps"] = r.positive(em["episode_steps"], "evaluation.episode_steps", integer=True)
    n_eval = ekw["episode_steps"]
    for k in ("measurement_noise_std", "actuator_noise_std"):
        if k in em:
            ekw[k] = r.positive(em[k], f"evaluation.{k}", inclusive=True)
    if "seed" in em:
        ekw["seed"] = r.integer(em["seed"], "evaluation.seed")
    if em.get("setpoints") is not None:
        ekw["setpoint_schedule"] = _setpoints(r, em["setpoints"], "evaluation.setpoints", len(loops), n_eval)
    if "disturbances" in em:
        ekw["disturbances"] = _disturbances(r, em["disturbances"], "evaluation.disturbances", desc, outputs, n_eval)
    intervals = []
    for i, iv in enumerate(r.sequence(em.get("intervals") or [], "evaluation.intervals", None,
                                      "a list of [start_step, end_step]")):
        key = f"evaluation.intervals[{i}]"
        a, b = r.sequence(iv, key, 2, "a list [start_step, end_step]")
        a, b = r.integer(a, f"{key}[0]"), r.integer(b, f"{key}[1]")
        if not 0 <= a < b <= n_eval:
            raise r.error(key, "outside the evaluation episode or empty", iv,
                          f"0 <= start < end <= {n_eval} (evaluation.episode_steps)")
        intervals.append((a, b))
    ekw["intervals"] = tuple(intervals)

    bm = r.mapping(doc.get("baseline"), "baseline", _BASELINE_KEYS)
    bkw = _section_values(r, bm, "baseline", _defaults(BaselineConfig))
    for k in bkw:
        r.positive(bm[k], f"baseline.{k}", integer=True, minimum=1, inclusive=True)
    return Scenario(name=name, path=r.file, tuning=tuning, agent=agent, evaluation=EvaluationConfig(**ekw),
                    baseline=BaselineConfig(**bkw))


# ---------------------------------------------------------------------------------------------
# public API

def load_scenario(path: str | Path) -> Scenario:
    """Read, validate and build a scenario file. Raises ScenarioError (one line) for any mistake."""
    p = Path(path)
    file = str(path)
    if not p.is_file():
        raise ScenarioError(f"{file}: scenario file not found (got {file!r}; expected a path to a .yaml file)")
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "unknown position"
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ScenarioError(f"{file}: (top level): not valid YAML at {where}: {problem} "
                            f"(got unparsable text; expected a YAML mapping)") from None
    except UnicodeDecodeError:
        raise ScenarioError(f"{file}: (top level): not a text file (got binary data; expected UTF-8 YAML)") from None
    r = _Reader(file, p.resolve().parent)
    return _build(r, doc, p.stem)


def validate_scenario(path: str | Path) -> Scenario:
    """Same as load_scenario (validation is loading); for `prlpid-fmi validate`."""
    return load_scenario(path)


validate = validate_scenario


def _range(lo: float, hi: float) -> list[float]:
    return [float(lo), float(hi)]


def _disturbance_to_dict(d: Disturbance) -> dict:
    out: dict[str, Any] = {"type": "step" if d.end_step is None else "pulse"}
    if d.kind == "fmu":
        out["target"] = d.target
    else:
        out["target"] = d.kind
        out["loop"] = d.target
    out["at_step"] = d.start_step
    if d.end_step is not None:
        out["duration_steps"] = d.end_step - d.start_step
    out["value"] = float(d.value)
    return out


def _schedule_to_list(schedule) -> Optional[list]:
    if schedule is None:
        return None
    return [{"at_step": int(s), "value": [float(v) for v in values]} for s, values in schedule]


def scenario_to_dict(s: Scenario) -> dict:
    """The resolved scenario (every key, defaults filled in) as plain YAML-able data; loads back equal."""
    t, a, e = s.tuning, s.agent, s.evaluation
    loops = [{"input": l.input, "output": l.output, "u_limits": _range(l.u_min, l.u_max),
              "setpoint_range": _range(*l.setpoint_range), "measurement_scale": float(l.measurement_scale),
              "divergence_bound": float(l.divergence_bound),
              "gains": {g: [float(getattr(l, g).low), float(getattr(l, g).high), getattr(l, g).scale]
                        for g in GAIN_NAMES}} for l in t.loops]
    agent = {}
    for f in dataclasses.fields(AgentConfig):
        v = getattr(a, f.name)
        agent[f.name] = list(v) if isinstance(v, tuple) else (dict(v) if isinstance(v, dict) else v)
    return {
        "name": s.name,
        "plant": {"fmu": t.fmu, "fmi_version": t.fmi_version, "sample_time": float(t.sample_time_s),
                  "parameters": {k: float(v) for k, v in t.plant_parameters.items()}, "loops": loops},
        "prior": {"fmu": t.prior.fmu, "parameters": {k: float(v) for k, v in t.prior.parameters.items()},
                  "state_map": dict(t.prior.state_map)},
        "controller": {k: getattr(t, k) for k in _CONTROLLER_KEYS},
        "strategies": {k: getattr(t, k) for k in _STRATEGY_KEYS},
        "reward": {**dataclasses.asdict(t.reward), "divergence_penalty": float(t.divergence_penalty)},
        "agent": agent,
        "training": {"episode_steps": t.episode_steps, "setpoint_hold_steps": t.setpoint_hold_steps,
                     "setpoints": _schedule_to_list(t.setpoint_schedule),
                     "measurement_noise_std": float(t.measurement_noise_std),
                     "actuator_noise_std": float(t.actuator_noise_std),
                     "disturbances": [_disturbance_to_dict(d) for d in t.disturbances]},
        "evaluation": {"episode_steps": e.episode_steps, "setpoints": _schedule_to_list(e.setpoint_schedule),
                       "intervals": [[int(x), int(y)] for x, y in e.intervals],
                       "disturbances": [_disturbance_to_dict(d) for d in e.disturbances],
                       "measurement_noise_std": e.measurement_noise_std,
                       "actuator_noise_std": e.actuator_noise_std, "seed": e.seed},
        "baseline": dataclasses.asdict(s.baseline),
    }


def scenario_to_yaml(s: Scenario) -> str:
    """scenario_to_dict as YAML text (key order kept)."""
    return yaml.safe_dump(scenario_to_dict(s), sort_keys=False, default_flow_style=None, width=120)


def init_scenario(fmu_path: str | Path) -> str:
    """YAML text of a ready-to-edit scenario for an FMU: its first real input/output as the loop.

    Raises ScenarioError when the FMU cannot be read or has no real input or output.
    """
    from .fmu import describe_fmu

    p = Path(fmu_path)
    try:
        d = describe_fmu(p)
    except PlantError as exc:
        raise ScenarioError(f"{fmu_path}: {exc}") from None
    problems = d.plant_problems()
    if problems:
        raise ScenarioError(f"{fmu_path}: cannot be a plant: {'; '.join(problems)} "
                            f"(got {d.model_name!r}; expected a co-simulation FMU with real inputs and outputs)")
    ins, outs = d.input_names, d.output_names
    ts = d.default_step_size_s or _defaults(TuningConfig)["sample_time_s"]
    tunable = [v for v in d.parameters if v.variability == "tunable" and v.type in ("Real", "Float64")]

    def unit(name):
        v = d.variable(name)
        return f" [{v.unit}]" if v is not None and v.unit else ""

    pairs = "\n".join(f"    #   {i}{unit(i)} -> {o}{unit(o)}" for i in ins for o in outs[:8])
    params = "\n".join(f"  #   {v.name}: {v.start}{'   # ' + v.unit if v.unit else ''}" for v in tunable[:20])
    tdef, adef = _defaults(TuningConfig), _defaults(AgentConfig)
    n_train = tdef["episode_steps"]
    n_eval = 2 * n_train
    prior_problems = d.prior_problems()
    if prior_problems:
        forecast = (f"forecast_horizon: 0   # this FMU cannot be its own prior ({'; '.join(prior_problems)}); "
                    "give prior.fmu + prior.state_map to use the reward forecast")
    else:
        forecast = f"forecast_horizon: {tdef['forecast_horizon']}   # reward forecast over N steps on a copy of the FMU; 0 = off"
    fmu_text = yaml.safe_dump(str(p.resolve()), default_style='"').strip()
    step_note = "the FMU's DefaultExperiment stepSize" if d.default_step_size_s else "the FMU gives no stepSize: ADJUST"
    name = re.sub(r"[^A-Za-z0-9_.-]+", "-", d.model_name).strip("-") or "my-plant"
    return f"""\
# Scenario for {d.model_name} ({p.name}), written by init_scenario.
# Check it with `prlpid-fmi validate <this file>`. Every key, unit and default: docs/scenarios.md.
# Lines marked ADJUST need your plant's numbers.
name: {name}
plant:
  fmu: {fmu_text}   # a relative path resolves against this file's folder
  sample_time: {ts!r}   # s, control period ({step_note})
  parameters: {{}}   # {{FMU parameter: value}} set before each episode
  # tunable parameters of this FMU (start values):
{params or '  #   none'}
  loops:
    # one loop per controlled output; input -> output pairs this FMU offers:
{pairs}
    - input: {ins[0]}                 # FMU input the PID drives{unit(ins[0])}
      output: {outs[0]}                # FMU output it measures{unit(outs[0])}
      u_limits: [-10.0, 10.0]         # ADJUST: actuator saturation [input units]
      setpoint_range: [0.0, 1.0]      # ADJUST: training setpoints are drawn from here [output units]
      measurement_scale: 1.0          # ADJUST: typical setpoint step [output units]; normalises errors
      divergence_bound: 10.0          # |error| / measurement_scale that ends an episode as diverged
      gains:                          # ranges the agent's actions map into; widen them if needed
        Kp: [0.01, 100.0, log]        # use a negative linear range for a plant with negative gain
        Ti: [0.1, 1000.0, log]        # s
        Td: [0.0, 10.0, linear]       # s
controller:
  anti_windup: {tdef['anti_windup']}   # {' | '.join(ANTI_WINDUP_MODES)}
strategies:
  {forecast}
  smoothing: {tdef['smoothing']}   # {' | '.join(SMOOTHING_METHODS)}
agent:
  algorithm: {adef['algorithm']}   # {' | '.join(ALGORITHMS)}
  total_timesteps: {adef['total_timesteps']}
  seed: {adef['seed']}
training:
  episode_steps: {n_train}   # ADJUST: a few settling times of the closed loop [samples]
  setpoint_hold_steps: {tdef['setpoint_hold_steps']}   # samples between random setpoint changes
evaluation:
  episode_steps: {n_eval}
  setpoints:   # value: a number (one loop) or a list with one number per loop
    - {{at_step: 0, value: 0.5}}
    - {{at_step: {n_eval // 2}, value: 1.0}}
  intervals: [[0, {n_eval // 2}], [{n_eval // 2}, {n_eval}]]
"""


__all__ = ["Scenario", "EvaluationConfig", "load_scenario", "validate_scenario", "validate", "scenario_to_dict",
           "scenario_to_yaml", "init_scenario", "DISTURBANCE_TYPES", "GAIN_SCALES", "ALGORITHMS"]
