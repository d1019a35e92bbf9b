"""Value types of the scenario schema: numbers, integers, flags, names, and the choice Literals.

Every type here checks one value and raises ``problem(...)`` (a pydantic custom error that carries a
short problem and, optionally, what was expected); ``messages.py`` turns those into the one-line
``<file>: <key.path>: <problem> (got …; expected …)`` form. Bounds are pydantic ``Field`` constraints,
so they show up in the JSON Schema (``exclusiveMinimum``, ``maximum``, …).

Numbers: YAML 1.1 reads ``3e-4`` as a string, so numeric strings are accepted; booleans and NaN
never are. ``number()`` is finite unless ``infinite=True`` (only the actuator limits allow ``.inf``).
"""
from __future__ import annotations

import math
import re
from typing import Annotated, Any, Literal, Optional, Union, get_args

from pydantic import BeforeValidator, Field, PlainValidator, Strict, WithJsonSchema
from pydantic_core import PydanticCustomError

from prlpid_fmi.control.pid import ANTI_WINDUP_MODES, GAIN_CHANGE_MODES
from prlpid_fmi.control.smoothing import SMOOTHING_METHODS

# choices (the tuples of names live where the behaviour lives; these Literals type the schema and config)
AntiWindup = Literal[ANTI_WINDUP_MODES]  # clamping | back_calculation | none
GainChange = Literal[GAIN_CHANGE_MODES]  # bumpless | positional (control.pid)
Smoothing = Literal[SMOOTHING_METHODS]  # none | sma | lwma | era
GainScale = Literal["log", "linear"]
GainMapping = Literal["anchored", "absolute"]
AnchorOn = Literal["auto", "fixed_pid"]  # controller.anchor_on: what action 0 reproduces (loop.actions)
Algorithm = Literal["ppo", "sac", "td3"]
VecEnv = Literal["dummy", "subproc"]
Isolation = Literal["auto", "process", "none"]  # where the plant FMU runs (prlpid_fmi.loop.isolated)
DisturbanceType = Literal["step", "pulse", "parameter_change"]
DisturbanceKind = Literal["fmu", "actuator", "measurement"]  # config.Disturbance.kind
LOOP_TARGETS = ("actuator", "measurement")  # disturbance targets that act on a loop, not on the FMU

GAIN_SCALES: tuple[str, ...] = get_args(GainScale)
GAIN_MAPPINGS: tuple[str, ...] = get_args(GainMapping)
ALGORITHMS: tuple[str, ...] = get_args(Algorithm)
VEC_ENVS: tuple[str, ...] = get_args(VecEnv)
DISTURBANCE_TYPES: tuple[str, ...] = get_args(DisturbanceType)


def problem(text: str, expected: Optional[str] = None, got: Optional[str] = None) -> PydanticCustomError:
    """A validation error for one value: `text` is the problem; `expected` None = derived from the schema;
    `got` None = the value as written in the file."""
    ctx: dict[str, Any] = {"problem": text}
    if expected is not None:
        ctx["expected"] = expected
    if got is not None:
        ctx["got"] = got
    return PydanticCustomError("scenario", "{problem}", ctx)


_NUMBER_TEXT = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def as_number(value: Any) -> Any:
    """A scenario value as a number: numeric text becomes a float; NaN, bools and other types are refused."""
    if isinstance(value, str) and _NUMBER_TEXT.match(value.strip()):
        return float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise problem("not a number")
    if math.isnan(value):
        raise problem("not a number (NaN)")
    return value


def as_integer(value: Any) -> Any:
    """A scenario value as an integer: a whole float (5e4) becomes an int; fractions, bools and other types are refused."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise problem("not an integer")
    return value


def number(infinite: bool = False, **bounds: float) -> Any:
    """A float type with pydantic bounds (gt, ge, lt, le); finite unless `infinite`."""
    return Annotated[float, Field(allow_inf_nan=infinite, **bounds), BeforeValidator(as_number)]


def tuned_or_number(low: float, high: float = math.inf) -> Any:
    """The word "tuned" or a finite number in [low, high]: one value type with one message either way (a Union
    would report one failure per member)."""
    expected = f"tuned, or a number in [{low:g}, {high:g}]" if math.isfinite(high) else f"tuned, or a number >= {low:g}"

    def check(value: Any) -> Any:
        if value == "tuned":
            return value
        try:
            v = float(as_number(value))
        except PydanticCustomError:
            raise problem("neither 'tuned' nor a number", expected) from None
        if not (math.isfinite(v) and low <= v <= high):
            raise problem("out of range", expected)
        return v

    return Annotated[Union[str, float], PlainValidator(check), WithJsonSchema(
        {"anyOf": [{"const": "tuned"}, {"type": "number", "minimum": low,
                                         **({"maximum": high} if math.isfinite(high) else {})}]})]


def _auto_or_flag(value: Any) -> Any:
    if value == "auto" or isinstance(value, bool):
        return value
    raise problem("neither 'auto' nor true/false", "auto, true or false")


AutoOrFlag = Annotated[Union[str, bool], PlainValidator(_auto_or_flag), WithJsonSchema(
    {"anyOf": [{"const": "auto"}, {"type": "boolean"}]})]  # "auto" or a boolean: one value type with one message


def integer(**bounds: int) -> Any:
    """An int type with pydantic bounds; 200.0 is read as 200, true/false and 1.5 are refused."""
    return Annotated[int, Field(**bounds), BeforeValidator(as_integer)]


Finite = number()
Positive = number(gt=0)
NonNegative = number(ge=0)
Fraction = number(ge=0, le=1)
Count = integer(ge=1)  # samples, sizes
Steps = integer(ge=0)  # sample indices, horizons
MAX_SEED = 2**31 - 1  # seeds reach numpy's legacy seeding (< 2**32) with per-env and per-episode offsets added
Seed = integer(ge=0, le=MAX_SEED)
Flag = Annotated[bool, Strict()]
Name = Annotated[str, Strict(), Field(min_length=1)]
