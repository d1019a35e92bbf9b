"""Checks that need more than one value: the FMU behind a scenario, and what earlier sections said.

A scenario is validated in one pass, in the order of its sections (plant first). ``State`` is passed
in the pydantic validation context and collects what later checks need: the FMU's description,
the number of loops and their outputs, the episode length in force, the chosen algorithm. A check
whose inputs were themselves invalid is skipped, so one mistake gives one line. Without a context
(a model built from Python values, e.g. to dump a resolved scenario) these checks are skipped.
"""
from __future__ import annotations

import difflib
import inspect
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any, Optional

from pydantic import ValidationInfo

from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu.description import REAL_TYPES
from prlpid_fmi.schema.types import problem


@dataclass
class State:
    """What the validation of one scenario file has learnt so far (see the module docstring)."""

    base_dir: Path
    fmi_version: int = 2
    desc: Any = None  # FmuDescription of the plant, once plant.fmu is valid
    prior_desc: Any = None  # of prior.fmu when given and valid
    prior_fmu_given: Optional[bool] = None  # None: unknown (prior.fmu invalid)
    n_loops: Optional[int] = None
    loop_inputs: list = field(default_factory=list)
    outputs: list = field(default_factory=list)
    episode_steps: Optional[int] = None  # of the section being validated (training, then evaluation)
    training_steps: Optional[int] = None
    raw_training_steps: Optional[int] = None  # training.episode_steps as written (or default), if a valid count
    last_step: int = -1  # last at_step of the setpoint schedule being validated
    last_setpoint: Optional[tuple] = None  # last value of that schedule (one number per loop)
    largest_step: list = field(default_factory=list)  # per valid loop: divergence_bound x measurement_scale
    algorithm: Optional[str] = None


def state_of(info: ValidationInfo) -> Optional[State]:
    """The State in the validation context, or None (structure-only validation)."""
    return (info.context or {}).get("state") if isinstance(info.context, dict) else None


def did_you_mean(word: str, choices) -> str:
    """'; did you mean 'x'?' for the closest choice (case-insensitive), or ''."""
    choices = [str(c) for c in choices]
    lower = {c.lower(): c for c in choices}
    close = difflib.get_close_matches(str(word).lower(), list(lower), n=1)
    return f"; did you mean {lower[close[0]]!r}?" if close else ""


# ---------------------------------------------------------------------------------------------
# FMU files

def scenario_fmu(value: str, state: State) -> tuple[str, Path]:
    """plant.fmu / prior.fmu resolved (prlpid_fmi.fmu.resolve.resolve_fmu, relative to the scenario's folder):
    (value for the config: a bundled name, or an absolute path; the .fmu file). Raises problem()."""
    from prlpid_fmi.fmu.build import bundled_plant_names
    from prlpid_fmi.fmu.resolve import fmu_file, resolve_fmu

    names = bundled_plant_names()
    try:
        path = resolve_fmu(value, state.fmi_version, base_dir=state.base_dir)
    except PlantError as exc:
        if value in names:
            raise problem(f"cannot build the bundled plant: {exc}".splitlines()[0], "a buildable bundled plant")
        from prlpid_fmi.fmu.description import missing_fmu_text

        missing = fmu_file(value, state.base_dir)
        raise problem(f"{missing_fmu_text(missing)}: {missing}",
                      "a path to a .fmu file (relative to the scenario's folder) or a bundled plant: "
                      + (", ".join(names) or "none found"))
    return (value if value in names else str(path)), path


def describe(path: Path):
    """The FmuDescription of an FMU whose archive passed check_archive; problem() otherwise."""
    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.fmu.archive import archive_problems

    problems = archive_problems(path)
    if problems:
        raise problem("; ".join(problems), "an FMU: a ZIP archive with a modelDescription.xml and a binary for "
                      "this platform")
    try:
        return describe_fmu(path)
    except PlantError as exc:
        text = str(exc).removeprefix(f"{path}: ").removeprefix(f"{path.resolve()}: ")
        raise problem(text.split(" (expected")[0], "an FMU: a ZIP archive with a modelDescription.xml")


def check_variable(desc, name: str, causalities: tuple[str, ...], role: str,
                   variabilities: Optional[tuple[str, ...]] = None) -> None:
    """`name` is a real variable of the FMU with one of `causalities` (and, for parameters, `variabilities`)."""
    v = desc.variable(name)
    wanted = " or ".join(causalities)
    pool = [x.name for x in desc.variables if x.causality in causalities and x.scalar_real
            and (variabilities is None or x.causality != "parameter" or x.variability in variabilities)]
    if v is None:
        raise problem(f"the FMU {desc.path.name} has no variable {name!r}",
                      f"{role} ({wanted}) of the FMU: {', '.join(pool) or 'none'}{did_you_mean(name, pool)}")
    if v.causality not in causalities:
        raise problem(f"causality mismatch: {name!r} is {v.causality!r} in the FMU, not {wanted}",
                      f"{role}: {', '.join(pool) or 'none'}")
    if v.type not in REAL_TYPES:
        raise problem(f"{name!r} is a {v.type} variable", f"a real (Real/Float64) variable as {role}")
    if v.dimensions:
        raise problem(f"{name!r} is an array variable (FMI 3 dimensions)",
                      f"a scalar real variable as {role}: {', '.join(pool) or 'none'}")
    if variabilities is not None and v.causality == "parameter" and v.variability not in variabilities:
        raise problem(f"{name!r} is a {v.variability} parameter and cannot change during a run",
                      "an input or a tunable parameter")


# ---------------------------------------------------------------------------------------------
# agent.extra against the Stable-Baselines3 constructor

# constructor arguments the tool sets itself (prlpid_fmi.tuning.agent.build_model); agent.<key> covers the rest
_SET_BY_THE_TOOL = ("policy", "env", "seed", "device", "tensorboard_log", "verbose", "policy_kwargs", "_init_setup_model")


@lru_cache(maxsize=None)
def algorithm_arguments(algorithm: str) -> tuple[str, ...]:
    """Keyword arguments of the Stable-Baselines3 class for `algorithm` (ppo | sac | td3)."""
    import stable_baselines3

    cls = getattr(stable_baselines3, algorithm.upper())
    return tuple(p for p in inspect.signature(cls.__init__).parameters if p != "self")


def check_extra_key(key: str, algorithm: str, agent_keys: tuple[str, ...]) -> None:
    """One agent.extra key: a constructor argument of the algorithm that no agent.<key> already sets."""
    if key in agent_keys:
        raise problem(f"{key!r} is set by agent.{key}", f"agent.{key} instead of agent.extra.{key}")
    if key in _SET_BY_THE_TOOL:
        raise problem(f"{key!r} is set by prlpid-fmi itself", "another constructor argument")
    known = [a for a in algorithm_arguments(algorithm) if a not in _SET_BY_THE_TOOL and a not in agent_keys]
    if key not in known:
        raise problem(f"not an argument of stable_baselines3.{algorithm.upper()}",
                      f"one of {', '.join(known)}{did_you_mean(key, known)}")
