"""Sweep files: a base scenario, the scenario keys to vary, the seeds; validated like scenario files.

A sweep file (YAML; examples in scenarios/sweeps/)::

    name: forecast_horizon            # optional; default: the file name without .yaml
    scenario: second_order            # base scenario: a path (relative to this file) or a bundled name
    seeds: 5                          # seeds 0..4, or a list such as [0, 7, 11]
    timesteps: 500000                 # optional: overrides agent.total_timesteps of every trial
    set:                              # optional: the same keys for every variant
      controller.gain_mapping: absolute
    vary:                             # optional: every combination of these values (a product)
      strategies.forecast_horizon: [0, 1, 3, 5, 10]
    variants:                         # optional: named variants, each a set of keys
      PPO: {strategies.forecast_horizon: 0, strategies.smoothing: none}
      PPO+RF+AS: {strategies.forecast_horizon: 3, strategies.smoothing: era}

Keys are scenario key paths (``strategies.forecast_horizon``, ``plant.loops[0].setpoint_range``). A
mapping value is merged into the base's mapping (``plant.parameters: {a: 1.5}`` keeps the other
parameters); any other value replaces the base's. Order: base, then ``set``, then the named variant,
then the ``vary`` combination. With both ``variants`` and ``vary``, the variants are their product;
with neither, one variant named ``base``.

``load_sweep(path)`` validates the file (one line per mistake, ``<file>: <key>: <problem> (got …;
expected …)``) and then every variant's scenario (all failing variants at once), raising
ScenarioError; it returns a ``Sweep`` whose variants hold their validated ``Scenario``.
"""
from __future__ import annotations

import copy
import itertools
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Optional

import yaml
from pydantic import AfterValidator, BaseModel, BeforeValidator, ConfigDict, Field, ValidationError

from prlpid_fmi.errors import ScenarioError
from prlpid_fmi.schema.checks import did_you_mean
from prlpid_fmi.schema.document import parse_yaml, syntax_error_line
from prlpid_fmi.schema.messages import MISSING, PROBLEMS, key_path, raw_value, schema_at, show
from prlpid_fmi.schema.types import MAX_SEED, Count, Name, Seed, as_integer, problem

SWEEP_DIR_NAME = "sweeps"  # bundled sweep files: scenarios/sweeps/<name>.yaml
BASE_VARIANT = "base"
_VARIANT_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+=,\-]*$")
_KEY_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)((?:\[\d+\])*)$")
_EXAMPLE_KEY = "strategies.forecast_horizon"


# ---------------------------------------------------------------------------------------------
# scenario key paths

def parse_key(key: str) -> tuple:
    """'plant.loops[0].gains.Kp' -> ('plant', 'loops', 0, 'gains', 'Kp'); ValueError when malformed."""
    loc: list = []
    for part in key.split("."):
        m = _KEY_PART.match(part)
        if not m:
            raise ValueError(part)
        loc.append(m.group(1))
        loc += [int(i) for i in re.findall(r"\[(\d+)\]", m.group(2))]
    return tuple(loc)


def _scenario_keys(prefix: tuple = ()) -> list[str]:
    """Dotted names of the sections and keys the scenario schema knows (for did-you-mean hints)."""
    node = schema_at(prefix) or {}
    out = []
    for name in node.get("properties", {}):
        out.append(".".join(map(str, prefix + (name,))))
        if prefix == ():
            out += _scenario_keys((name,))
    return out


def _check_key(key: str) -> str:
    try:
        loc = parse_key(key)
    except ValueError:
        indexed = re.sub(r"\.(\d+)(?=\.|$)", r"[\1]", key)  # plant.loops.0.input -> plant.loops[0].input
        hint = f"; did you mean {indexed!r}?" if indexed != key else ""
        raise problem("not a scenario key path",
                      f"dotted names with optional [index], e.g. {_EXAMPLE_KEY}{hint}") from None
    if schema_at(loc) is None:
        raise problem("unknown scenario key", f"a key of the scenario file, e.g. {_EXAMPLE_KEY}"
                      + did_you_mean(key, _scenario_keys()))
    return key


ScenarioKey = Annotated[str, AfterValidator(_check_key)]


def _check_variant_name(name: str) -> str:
    if not _VARIANT_NAME.match(name):
        raise problem("not usable as a folder name", "letters, digits and _ . + = , - (first a letter or digit)")
    return name


MAX_SEED_COUNT = 1000  # a count of seeds beyond this is a typo, not a study (each seed is a full training)


def _seeds(value: Any) -> Any:
    """A count n means seeds 0 .. n-1."""
    if isinstance(value, list):
        return value
    n = as_integer(value)
    if not 1 <= n <= MAX_SEED_COUNT:
        raise problem("out of range", _EXPECTED["seeds"])
    return list(range(n))


def _unique(values: list) -> list:
    repeated = sorted({v for v in values if values.count(v) > 1})
    if repeated:
        raise problem(f"repeated seed(s) {', '.join(map(str, repeated))}", "each seed once")
    return values


# what each key of a sweep file expects (the field descriptions and the error messages)
_EXPECTED = {
    "name": "a non-empty string (default: the file name; output folder runs/sweeps/<name>)",
    "scenario": "a path to a scenario file (relative to the sweep file) or a bundled scenario's name",
    "seeds": f"a number of seeds from 1 to {MAX_SEED_COUNT}, or a list of seeds from 0 to {MAX_SEED}",
    "timesteps": "an integer >= 1 (training steps of every trial), or null for the scenario's budget",
    "set": "a mapping {scenario key: value}",
    "vary": "a mapping {scenario key: [value, ...]} with at least one value each (every combination)",
    "variants": "a mapping {variant name: {scenario key: value}}",
}


class SweepModel(BaseModel):
    """The sweep file."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: Optional[Name] = Field(None, description=_EXPECTED["name"])
    scenario: Name = Field(description=_EXPECTED["scenario"])
    seeds: Annotated[list[Seed], BeforeValidator(_seeds), AfterValidator(_unique), Field(min_length=1)] = Field(
        description=_EXPECTED["seeds"])
    timesteps: Optional[Count] = Field(None, description=_EXPECTED["timesteps"])
    set: dict[ScenarioKey, Any] = Field(default_factory=dict, description=_EXPECTED["set"])
    vary: dict[ScenarioKey, Annotated[list[Any], Field(min_length=1)]] = Field(default_factory=dict,
                                                                                description=_EXPECTED["vary"])
    variants: dict[Annotated[str, AfterValidator(_check_variant_name)], dict[ScenarioKey, Any]] = Field(
        default_factory=dict, description=_EXPECTED["variants"])


def _error_line(file: str, doc: Any, err: dict) -> str:
    """One pydantic error of the sweep file as `<file>: <key>: <problem> (got …; expected …)`."""
    loc = tuple(err["loc"])
    kind, ctx = err["type"], err.get("ctx") or {}
    raw = raw_value(doc, loc)
    got = ctx.get("got") or ("nothing" if raw is MISSING else show(raw))
    expected = _EXPECTED.get(loc[0] if loc else "", "a valid value")
    if kind == "scenario":
        text, expected = ctx["problem"], ctx.get("expected") or expected
    elif kind == "extra_forbidden":
        text, got = "unknown key", show(loc[-1])
        expected = "a known key" + (did_you_mean(loc[-1], _EXPECTED) or f": one of {', '.join(_EXPECTED)}")
    elif kind == "missing":
        text = "missing key"
    elif kind == "too_short":
        text = "empty"
    else:
        text = PROBLEMS.get(kind, err.get("msg", "invalid").lower())
        if loc and loc[0] == "seeds" and len(loc) > 1:
            expected = f"an integer in [0, {MAX_SEED}]"
    return f"{file}: {key_path(loc, doc)}: {text} (got {got}; expected {expected})"


# ---------------------------------------------------------------------------------------------
# the validated sweep

@dataclass(frozen=True)
class Variant:
    """One point of the sweep: its folder name, the keys it sets ((scenario key, value, "set" | "variants.<name>" |
    "vary"), in the order applied), and its validated scenario (the base's seed and budget; each trial sets its
    own)."""

    name: str
    overrides: tuple
    scenario: Any  # prlpid_fmi.scenario.load.Scenario


@dataclass(frozen=True)
class Sweep:
    """A validated sweep file."""

    name: str
    path: Path
    base: Path  # the base scenario file
    seeds: tuple[int, ...]
    timesteps: Optional[int]
    variants: tuple[Variant, ...]


def _format_value(value: Any) -> str:
    text = yaml.safe_dump(value, default_flow_style=True, width=10_000).strip()
    text = text.removesuffix("\n...").strip()
    return re.sub(r"[^A-Za-z0-9_.+=,\[\]\-]", "", text.replace(", ", ","))


def _grid_names(keys: list[str], combos: list[tuple]) -> list[str]:
    """'forecast_horizon=3' per combination (the key's last name, or the whole key where last names repeat)."""
    last = [str(parse_key(k)[-1]) if isinstance(parse_key(k)[-1], str) else k for k in keys]
    labels = [k if last.count(lbl) > 1 else lbl for k, lbl in zip(keys, last)]
    return [",".join(f"{lbl}={_format_value(v)}" for lbl, v in zip(labels, combo)) for combo in combos]


def _deep_merge(old: Any, new: Any) -> Any:
    """`new` merged into `old`: mappings key by key (recursively), anything else replaced."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = dict(old)
        for k, v in new.items():
            out[k] = _deep_merge(old.get(k), v)
        return out
    return copy.deepcopy(new)


def _merge(into: dict, key: str, value: Any) -> None:
    """Set scenario key path `key` in document `into` to `value` (merged into a mapping the base has there).

    Raises IndexError naming the list index the base scenario does not have.
    """
    loc = parse_key(key)
    node = into
    for i, part in enumerate(loc):
        last = i == len(loc) - 1
        if isinstance(part, int):
            if not isinstance(node, list) or part >= len(node):
                size = len(node) if isinstance(node, list) else 0
                raise IndexError(f"index {part}; expected an index below {size}, the number of items of "
                                 f"{key_path(loc[:i])}")
        elif not last and not isinstance(node.get(part), (dict, list)):
            node[part] = [] if isinstance(loc[i + 1], int) else {}
        if last:
            node[part] = _deep_merge(node[part] if isinstance(part, int) else node.get(part), value)
        else:
            node = node[part]


def _resolve_base(arg: str, sweep_dir: Path) -> Path:
    """The base scenario: a file (relative to the sweep file's folder) wins over a bundled scenario's name."""
    from prlpid_fmi.bundled import SCENARIO_DIR
    from prlpid_fmi.scenario.presets import bundled_scenario_names

    local = sweep_dir / Path(arg).expanduser()
    if local.is_file():
        return local
    if arg in bundled_scenario_names():
        return SCENARIO_DIR / f"{arg}.yaml"
    raise ScenarioError(f"no such scenario file or bundled scenario (got {arg!r}; expected a path relative to the "
                        f"sweep file or one of: {', '.join(bundled_scenario_names())})")


def resolve_sweep(arg: str | Path) -> Path:
    """A sweep argument as a file: an existing path, else a bundled sweep's name (scenarios/sweeps/<name>.yaml)."""
    from prlpid_fmi.bundled import SCENARIO_DIR

    path = Path(arg)
    if path.exists():
        return path
    bundled = SCENARIO_DIR / SWEEP_DIR_NAME / f"{arg}.yaml"
    if bundled.is_file():
        return bundled
    names = ", ".join(bundled_sweep_names()) or "none found"
    raise ScenarioError(f"{arg}: no such sweep file or bundled sweep (got {str(arg)!r}; expected a path to a .yaml "
                        f"file or one of: {names})")


def is_sweep_file(path: Path) -> bool:
    """Does the YAML file at `path` look like a sweep file (a top-level `scenario` key, no `plant`)?
    False for anything unreadable: the scenario reader then says what is wrong with it."""
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError, RecursionError):
        return False
    return isinstance(data, dict) and "scenario" in data and "plant" not in data


def bundled_sweep_names() -> list[str]:
    """Names of the bundled sweep files (scenarios/sweeps/<name>.yaml), sorted."""
    from prlpid_fmi.bundled import SCENARIO_DIR

    return sorted(p.stem for p in (SCENARIO_DIR / SWEEP_DIR_NAME).glob("*.yaml"))


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file and every variant's scenario. Raises ScenarioError (one line per mistake)."""
    from prlpid_fmi.scenario.load import build_scenario, load_scenario
    from prlpid_fmi.schema import ScenarioModel
    from prlpid_fmi.schema.checks import State
    from prlpid_fmi.schema.messages import error_line

    p = Path(path)
    file = str(path)
    if not p.is_file():
        raise ScenarioError(f"{file}: sweep file not found (got {file!r}; expected a path to a .yaml file)")
    try:
        document = parse_yaml(p.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise ScenarioError(f"{file}: (top level): not a text file (got binary data; expected UTF-8 YAML)") from None
    except yaml.YAMLError as exc:
        raise ScenarioError(syntax_error_line(file, exc)) from None
    lines = document.duplicate_lines(file)
    model = None
    if not isinstance(document.data, dict):
        lines.append(f"{file}: (top level): not a mapping (got {show(document.data)}; expected a mapping "
                     f"{{{', '.join(_EXPECTED)}}})")
    else:
        try:
            model = SweepModel.model_validate(document.data)
        except ValidationError as exc:
            errors = sorted(exc.errors(), key=lambda e: document.line_of(tuple(e["loc"])) or 10**9)
            lines += [_error_line(file, document.data, e) for e in errors]
    if model is not None:
        lines += _overlap_lines(file, model)
    if lines:
        raise ScenarioError("\n".join(dict.fromkeys(lines)))

    try:
        base_path = _resolve_base(model.scenario, p.resolve().parent)
    except ScenarioError as exc:
        raise ScenarioError(f"{file}: scenario: {exc}") from None
    base = load_scenario(base_path)  # the base itself must be valid: its own file's lines
    base_doc = parse_yaml(base_path.read_text(encoding="utf-8")).data
    state_dir = base_path.resolve().parent

    named = list(model.variants.items()) or [(None, {})]
    grid_keys = list(model.vary)
    combos = list(itertools.product(*model.vary.values())) if grid_keys else [()]
    grid_names = _grid_names(grid_keys, combos) if grid_keys else [""]
    repeated = sorted({n for n in grid_names if grid_names.count(n) > 1})
    if repeated:
        raise ScenarioError(f"{file}: vary: values that give the same variant twice (got {', '.join(repeated)}; "
                            "expected distinct values per key)")
    variants, problems = [], {}  # problems: (label, rest of the line) -> variant names
    for (vname, vkeys), (gname, combo) in itertools.product(named, zip(grid_names, combos)):
        name = ",".join(n for n in (vname, gname) if n) or BASE_VARIANT
        overrides = [(k, v, "set") for k, v in model.set.items()]
        overrides += [(k, v, f"variants.{vname}") for k, v in vkeys.items()]
        overrides += [(k, v, "vary") for k, v in zip(grid_keys, combo)]
        doc = copy.deepcopy(base_doc)
        found = []
        for key, value, origin in overrides:
            try:
                _merge(doc, key, value)
            except IndexError as exc:
                found.append((origin, f"{key}: no such item in the base scenario {base_path} (got {exc})"))
        try:
            sm = ScenarioModel.model_validate(doc, context={"state": State(state_dir)})
        except ValidationError as exc:
            for err in exc.errors():
                loc = tuple(x for x in err["loc"] if x != "[key]")
                origin = next((o for k, _, o in reversed(overrides) if _overlaps(parse_key(k), loc)), None)
                found.append((origin or f"variant {name}", error_line(_MARK, doc, err).removeprefix(_MARK + ": ")))
        else:
            if found:
                continue
            variants.append(Variant(name, tuple(overrides),
                                    build_scenario(sm, base.name, str(base_path))))
        for label_line in found:
            problems.setdefault(label_line, []).append(name)
    if problems:
        n_variants = len(named) * len(combos)
        raise ScenarioError("\n".join(
            f"{file}: {label}{_which(names, n_variants, label)}: {line}" for (label, line), names in problems.items()))
    return Sweep(name=model.name or p.stem, path=p, base=base_path, seeds=tuple(model.seeds),
                 timesteps=model.timesteps, variants=tuple(variants))


_MARK = "\0"


def _which(names: list[str], n_variants: int, label: str) -> str:
    """' (variants a, b)' when a shared setting fails in only some variants."""
    if label != "set" or len(names) == n_variants:
        return ""
    if len(names) == 1:
        return f" (variant {names[0]})"
    return f" (in {len(names)} of {n_variants} variants, e.g. {names[0]})"


def _overlaps(a: tuple, b: tuple) -> bool:
    """One key path is the other or lies inside it."""
    n = min(len(a), len(b))
    return a[:n] == b[:n]


def _leaves(loc: tuple, value: Any) -> list[tuple]:
    """The key paths a value sets at `loc`: a mapping (merged into the base's) sets its leaves, anything else `loc`."""
    if isinstance(value, dict) and value:
        return [leaf for k, v in value.items() for leaf in _leaves(loc + (k,), v)]
    return [loc]


def _overlap_lines(file: str, model: SweepModel) -> list[str]:
    """A key in `vary` that a named variant also sets would make equal trials: refused."""
    lines = []
    for key, values in model.vary.items():
        varied = {leaf for v in values for leaf in _leaves(parse_key(key), v)}
        for vname, vkeys in model.variants.items():
            for other, value in vkeys.items():
                if any(_overlaps(a, b) for a in varied for b in _leaves(parse_key(other), value)):
                    lines.append(f"{file}: vary.{key}: also set by variants.{vname}.{other} (got both; expected each "
                                 "key in vary or in variants, not both)")
    return lines
