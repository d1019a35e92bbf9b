"""What an FMU offers, read once from its modelDescription.xml: variables, interfaces, capabilities."""
from __future__ import annotations

import zipfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from prlpid_fmi.errors import PlantError

REAL_TYPES = ("Real", "Float64")


@dataclass(frozen=True)
class FmuVariable:
    name: str
    value_reference: int
    causality: str
    variability: str
    type: str
    start: float | str | None
    unit: str | None
    description: str
    min: float | None = None      # declared range and nominal value (modelDescription), FMU units
    max: float | None = None
    nominal: float | None = None
    dimensions: int = 0           # FMI 3 array variables: number of <Dimension> elements (0: a scalar)

    @property
    def scalar_real(self) -> bool:
        """A scalar Real / Float64: the only kind a loop, a parameter or a scheduling variable can be."""
        return self.type in REAL_TYPES and not self.dimensions


@dataclass(frozen=True)
class FmuDescription:
    """The parts of a modelDescription that decide whether an FMU can be a plant or a prior."""

    path: Path
    fmi_version: str
    model_name: str
    model_identifier: str
    guid: str
    co_simulation: bool
    model_exchange: bool
    can_get_and_set_state: bool
    can_serialize_state: bool
    default_step_size_s: float | None
    variables: tuple[FmuVariable, ...]
    once_per_process: bool = False  # canBeInstantiatedOnlyOncePerProcess
    n_states: int = 0             # continuous states (model exchange integrates them)
    n_event_indicators: int = 0
    default_start_time_s: float | None = None   # DefaultExperiment startTime [s]
    default_stop_time_s: float | None = None    # DefaultExperiment stopTime [s] (some FMUs refuse steps past it)
    own_step_s: float | None = None   # the only step a co-simulation FMU takes: its fixedInternalStepSize (FMI 3.0),
                                      # or its DefaultExperiment stepSize when it cannot vary the step (FMI 2.0)

    def variable(self, name: str) -> FmuVariable | None:
        for v in self.variables:
            if v.name == name:
                return v
        return None

    def unit_of(self, name: str) -> str:
        """The declared unit of variable `name` ("" when the variable is unknown or has no unit)."""
        v = self.variable(name)
        return (v.unit or "") if v is not None else ""

    def _names(self, causality: str) -> tuple[str, ...]:
        return tuple(v.name for v in self.variables if v.causality == causality and v.scalar_real)

    def _arrays(self, causality: str) -> tuple[str, ...]:
        return tuple(v.name for v in self.variables if v.causality == causality and v.type in REAL_TYPES
                     and v.dimensions)

    @property
    def input_names(self) -> tuple[str, ...]:
        return self._names("input")

    @property
    def output_names(self) -> tuple[str, ...]:
        return self._names("output")

    @property
    def parameters(self) -> tuple[FmuVariable, ...]:
        return tuple(v for v in self.variables if v.causality == "parameter")

    def require(self, name: str, causalities: tuple[str, ...] | None, role: str) -> FmuVariable:
        """The real variable `name`, with one of `causalities`; PlantError naming the FMU otherwise."""
        v = self.variable(name)
        if v is None:
            raise PlantError(f"{self.path}: has no variable {name!r} (to use as {role}); "
                             f"inputs: {', '.join(self.input_names) or 'none'}; "
                             f"outputs: {', '.join(self.output_names) or 'none'}")
        if v.type not in REAL_TYPES:
            raise PlantError(f"{self.path}: variable {name!r} is {v.type}, expected a real (Real/Float64) to use as {role}")
        if v.dimensions:
            raise PlantError(f"{self.path}: variable {name!r} is an array (FMI 3 dimensions), expected a scalar real "
                             f"to use as {role}")
        if causalities is not None and v.causality not in causalities:
            raise PlantError(f"{self.path}: variable {name!r} has causality {v.causality!r}, "
                             f"expected {' or '.join(causalities)} to use as {role}")
        return v

    def plant_problems(self) -> list[str]:
        """Why this FMU cannot be stepped as a plant (empty when it can)."""
        problems = []
        if not (self.co_simulation or self.model_exchange):
            problems.append("neither a co-simulation nor a model-exchange interface")
        for causality in ("input", "output"):
            if not self._names(causality):
                arrays = self._arrays(causality)
                problems.append(f"no scalar real {causality}s (only arrays: {', '.join(arrays)})" if arrays
                                else f"no real {causality}s")
        return problems

    def prior_problems(self) -> list[str]:
        """Why this FMU cannot serve as its own predictive prior (empty when it can)."""
        problems = self.plant_problems()
        if not self.can_get_and_set_state:
            problems.append("cannot get and set its state (canGetAndSetFMUstate)")
        return problems

    @property
    def prior_mode(self) -> str | None:
        """How the FMU serves as its own prior: "copy" (a second instance receives the plant's serialized
        state), "rollback" (the plant's own state is saved, N steps rolled, set back: the FMU cannot
        serialize its state or may be instantiated only once per process), or None (no state access)."""
        if self.prior_problems():
            return None
        return "copy" if self.can_serialize_state and not self.once_per_process else "rollback"

    def prior_summary(self) -> str:
        """One line: which prior applies, and why."""
        mode = self.prior_mode
        if mode == "copy":
            return "yes: a second instance receives the plant's state each step"
        if mode == "rollback":
            why = ("it may be instantiated only once per process" if self.once_per_process
                   else "it cannot serialize its state (canSerializeFMUstate)")
            return ("yes: single-instance rollback (the plant's own state is saved, N steps rolled, set back; "
                    f"{why})")
        return "no: " + "; ".join(self.prior_problems())


@lru_cache(maxsize=64)
def _describe(path: str, mtime: float) -> FmuDescription:
    from fmpy import read_model_description

    try:
        md = read_model_description(path, validate=False)
    except (zipfile.BadZipFile, KeyError):
        raise PlantError(f"{path}: not an FMU (expected a ZIP archive with a modelDescription.xml)") from None
    except Exception as exc:
        raise PlantError(f"{path}: cannot read its modelDescription.xml: {exc}") from None
    cs = md.coSimulation or md.modelExchange  # the capabilities of the interface FmuPlant uses

    def number(v, key):
        value = getattr(v, key, None)
        if value is None and v.declaredType is not None:
            value = getattr(v.declaredType, key, None)
        try:
            return float(value) if value is not None else None
        except (TypeError, ValueError):
            return None

    variables = tuple(
        FmuVariable(v.name, int(v.valueReference), v.causality, v.variability, v.type,
                    v.start, getattr(v, "unit", None) or (v.declaredType.unit if v.declaredType is not None else None),
                    v.description or "", number(v, "min"), number(v, "max"), number(v, "nominal"),
                    len(getattr(v, "dimensions", None) or ()))
        for v in md.modelVariables)
    def experiment(key):
        try:
            return float(getattr(md.defaultExperiment, key))
        except (AttributeError, TypeError, ValueError):
            return None

    step, start, stop = experiment("stepSize"), experiment("startTime"), experiment("stopTime")
    return FmuDescription(
        path=Path(path), fmi_version=md.fmiVersion, model_name=md.modelName,
        model_identifier=cs.modelIdentifier if cs else "",
        guid=md.guid, co_simulation=md.coSimulation is not None, model_exchange=md.modelExchange is not None,
        can_get_and_set_state=bool(cs and cs.canGetAndSetFMUstate),
        can_serialize_state=bool(cs and cs.canSerializeFMUstate),
        default_step_size_s=float(step) if step else None, variables=variables,
        once_per_process=bool(cs and cs.canBeInstantiatedOnlyOncePerProcess),
        n_states=int(md.numberOfContinuousStates or len(md.derivatives)),
        n_event_indicators=int(md.numberOfEventIndicators or 0), default_start_time_s=start,
        default_stop_time_s=stop, own_step_s=_own_step(md, step))


def _own_step(md, step: float | None) -> float | None:
    """The step a co-simulation FMU is bound to (None: it takes any step)."""
    co = md.coSimulation
    if co is None:
        return None
    fixed = getattr(co, "fixedInternalStepSize", None)
    try:
        if fixed is not None and float(fixed) > 0:
            return float(fixed)
    except (TypeError, ValueError):
        pass
    if getattr(co, "canHandleVariableCommunicationStepSize", True) is False and step:
        return float(step)
    return None


def missing_fmu_text(path: Path) -> str:
    """Why `path`, which is not a file, is no FMU: a folder (e.g. an extracted FMU) or nothing there."""
    if path.is_dir():
        return "a folder, not an FMU file (an extracted FMU? zip its contents back into a .fmu archive)"
    return "FMU file not found"


def describe_fmu(path: str | Path) -> FmuDescription:
    """Read an FMU's model description (cached per file and modification time)."""
    p = Path(path)
    if not p.is_file():
        raise PlantError(f"{p}: {missing_fmu_text(p)}")
    if not zipfile.is_zipfile(p):
        raise PlantError(f"{p}: not an FMU (expected a ZIP archive with a modelDescription.xml)")
    return _describe(str(p.resolve()), p.stat().st_mtime)


def format_description(d: FmuDescription) -> str:
    """Human-readable summary for `prlpid-fmi inspect`."""
    kinds = [k for k, on in (("co-simulation", d.co_simulation), ("model exchange", d.model_exchange)) if on]
    lines = [
        f"FMU          {d.path}",
        f"Model        {d.model_name}",
        f"FMI version  {d.fmi_version}",
        f"Interfaces   {', '.join(kinds) or 'none'}",
        f"State        get/set: {'yes' if d.can_get_and_set_state else 'no'}, "
        f"serialize: {'yes' if d.can_serialize_state else 'no'}",
        f"Instances    {'one per process (canBeInstantiatedOnlyOncePerProcess)' if d.once_per_process else 'several'}",
    ]
    if d.default_step_size_s:
        lines.append(f"Default step {d.default_step_size_s:g} s")
    if d.default_stop_time_s is not None:
        lines.append(f"Experiment   from {d.default_start_time_s or 0:g} s to {d.default_stop_time_s:g} s "
                     "(DefaultExperiment; the stop time is set up where an FMU enforces it)")
    for title, causality in (("Inputs", "input"), ("Outputs", "output"), ("Parameters", "parameter")):
        group = [v for v in d.variables if v.causality == causality]
        lines.append(f"{title}:" + ("" if group else " none"))
        for v in group:
            start = "" if v.start is None else f"start={v.start}"
            unit = f"[{v.unit}]" if v.unit else ""
            extra = f" ({v.variability})" if causality == "parameter" else ""
            lines.append(f"  {v.name:<16} {v.type:<8} {start:<18} {unit:<10} {v.description}{extra}".rstrip())
    plant = d.plant_problems()
    lines.append("As plant     " + ("yes" if not plant else "no: " + "; ".join(plant)))
    lines.append("As prior     " + d.prior_summary())
    return "\n".join(lines)
