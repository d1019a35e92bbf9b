"""The fixed PID's design as typed records: what tuning.design_rule returns (`DesignResult`, its `DesignReport` and
`DesignDetails`) and the records of its searches inside them (`ModelSearch`, `Trade`, `Followed`, `ModelPath`,
`CandidateRecord`). JSON only at the run directory: `as_json` / `from_json` are fixed_pid.json's form; every field
of a record has a default, so a file written before a field existed still reads."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from prlpid_fmi.loop.gains import Gains, GainValues, gains_from_dict


def _known(cls, data: dict | None) -> dict:
    """The entries of `data` that are fields of the dataclass cls (keys from other versions left out)."""
    names = {f.name for f in dataclasses.fields(cls)}
    return {k: v for k, v in (data or {}).items() if k in names}


@dataclass
class ModelSearch:
    """A setpoint search on the identified local models and the FMU's check of its result (fixed_pid.json's
    "setpoint_refined", and "on_models" in "traded_for_overshoot" and "followed_setpoints"): its evaluations, its
    best's load cost and worst overshoot [%] on the models, whether that meets every limit there (or, trading, all but
    the load tolerance: nearest_on_models), its setpoint ISE / its start's on the models, the ISE to beat (requirement
    5), whether the classical rules bounded its load cost; after the check, b chosen again and the load cost, ISE and
    overshoot on the FMU, whether it settles the range episode (None: not checked), and whether it was kept."""

    evaluations: int = 0
    model_load_cost: float = math.nan
    model_overshoot: float = math.nan
    feasible_on_models: bool = False
    kept: bool = False
    model_ise_ratio: float | None = None
    nearest_on_models: bool | None = None
    ISE_before: float | None = None
    classical_bound: bool | None = None
    load_cost: float | None = None
    ISE: float | None = None
    Overshoot: float | None = None
    b: float | None = None
    settles_range: bool | None = None

    @classmethod
    def from_json(cls, data: dict | None) -> "ModelSearch | None":
        return None if data is None else cls(**_known(cls, data))


def _with_on_models(cls, data: dict | None):
    """cls (a record with an "on_models" ModelSearch) of its JSON form; None for None."""
    if data is None:
        return None
    known = _known(cls, data)
    return cls(**{**known, "on_models": ModelSearch.from_json(known.get("on_models"))})


@dataclass
class Trade:
    """The setpoint search within the load tolerance where no b met the overshoot limit (fixed_pid.json's
    "traded_for_overshoot"): its best's load cost [output units s per input unit] (on the FMU), setpoint ISE and
    worst overshoot [%] on the training episodes, whether it meets every limit, or every limit but the load tolerance
    (nearest_load_tolerance), its evaluations, its first try on the models (on_models), and, where its load cost was
    predicted on the models, that prediction and its relative error against the FMU."""

    load_cost: float = math.nan
    ISE: float = math.nan
    Overshoot: float = math.nan
    feasible: bool = False
    nearest_load_tolerance: bool = False
    evaluations: int = 0
    on_models: ModelSearch | None = None
    load_cost_model: float | None = None
    validation_error: float | None = None

    @classmethod
    def from_json(cls, data: dict | None) -> "Trade | None":
        return _with_on_models(cls, data)


@dataclass
class Followed:
    """What replaced the load-optimal gains to follow the setpoint episodes (fixed_pid.json's "followed_setpoints",
    tuning.design_rule.follow_setpoints): source "search", "stabilising PID" or None (nothing did), the objective
    minimised ("load" or "setpoint"), whether the load-optimal gains diverged on the episodes, the result's load cost,
    setpoint ISE, worst overshoot [%], whether it meets every limit, its evaluations, its first try on the models."""

    source: str | None = None
    objective: str = "load"
    load_optimal_diverged: bool = True
    load_cost: float = math.nan
    ISE: float = math.nan
    Overshoot: float = math.nan
    feasible: bool = False
    evaluations: int = 0
    on_models: ModelSearch | None = None

    @classmethod
    def from_json(cls, data: dict | None) -> "Followed | None":
        return _with_on_models(cls, data)


@dataclass(frozen=True)
class ChatterCheck:
    """The fixed PID's command on the design's quiet episodes (tuning.design_rule.quiet_command): its worst
    metrics.fast_reversals before [fraction of samples], the target it was held to (CHATTER_MARGIN x
    deploy.max_chatter), lambda of the detuning (Kp / lambda, Ti and Td x lambda; 1: none), the fraction after, and
    the episodes it was measured on."""

    before: float
    target: float
    detuned_by: float = 1.0
    after: float = math.nan
    episodes: int = 0

    @property
    def met(self) -> bool:
        return bool(min(self.before, self.after if math.isfinite(self.after) else math.inf) <= self.target
                    or not math.isfinite(self.before))

    @classmethod
    def from_json(cls, data: dict | None) -> "ChatterCheck | None":
        return cls(**{k: math.nan if v is None else v for k, v in _known(cls, data).items()}) if data else None


@dataclass
class ModelPath:
    """Which path the load search took (fixed_pid.json's "design_model", tuning.load_design.LoadDesign.
    search_verified): requested ("identified" | "fmu"), the path taken, why the models were not used or not kept
    (note), the local models (robustness.local_model.LocalModel.as_dict each; "loop" with several loops), the models'
    load cost of the choice against the FMU's, the FMU's chatter, their relative error and its tolerance, whether they
    agree, and the setpoint search's path and note."""

    requested: str = "fmu"
    path: str = "fmu"
    note: str = ""
    models: list = dataclasses.field(default_factory=list)
    predicted_load_cost: float | None = None
    fmu_load_cost: float | None = None
    fmu_chatter: float | None = None
    validation_error: float | None = None
    tolerance: float | None = None
    agrees: bool | None = None
    setpoint_search: str | None = None
    setpoint_search_note: str | None = None

    @classmethod
    def from_json(cls, data: dict | None) -> "ModelPath":
        return cls(**_known(cls, data))


@dataclass(frozen=True)
class Relaxation:
    """A noise preference given up for requirement 1: `limit` ("measurement_filter", "max_noise_gain",
    "max_noise_increment") from `requested` to `used` (the filter: 0 / 1 for not searched / searched)."""

    limit: str
    requested: float
    used: float


@dataclass(frozen=True)
class Following:
    """Requirement 1 on the range episode: setpoint steps, those unsettled at the end of their hold, those settled
    only after setpoint_hold_steps (slow), divergence, worst overshoot [% of the step], ISE [output units^2 s]."""

    steps: int
    unsettled: int
    slow: int
    diverged: bool
    overshoot: float
    ise: float

    @property
    def settles(self) -> bool:
        return not self.diverged and self.unsettled == 0


@dataclass(frozen=True)
class Requirement:
    """One requirement's measured value against its limit (limit None: a quantity minimised, no limit)."""

    rank: int
    name: str
    value: float
    limit: float | None
    met: bool


@dataclass(frozen=True)
class CandidateRecord:
    """One design the rule ranked (fixed_pid.json's "candidates"): the noise preferences it relaxed, requirement 1 on
    the range episode, its load cost, setpoint ISE and worst overshoot [%] on the training episodes, whether the FMU
    met the Ms limit, its gains, and whether it was kept."""

    relaxed: tuple[Relaxation, ...] = ()
    following: Following | None = None
    load_cost: float = math.nan
    ISE: float = math.nan
    Overshoot: float = math.nan
    ms_met: bool = True
    gains: Gains | None = None
    kept: bool = False

    def as_json(self) -> dict:
        return {"relaxed": [dataclasses.asdict(r) for r in self.relaxed],
                "following": dataclasses.asdict(self.following) if self.following is not None else None,
                "load_cost": self.load_cost, "ISE": self.ISE, "Overshoot": self.Overshoot, "ms_met": self.ms_met,
                "gains": ({k: np.asarray(v).tolist() for k, v in self.gains.as_dict().items()}
                          if self.gains is not None else None), "kept": self.kept}

    @classmethod
    def from_json(cls, data: dict) -> "CandidateRecord":
        known = _known(cls, data)
        following = known.get("following")
        return cls(**{**known, "relaxed": tuple(Relaxation(**r) for r in known.get("relaxed") or ()),
                      "following": Following(**following) if following else None,
                      "gains": gains_from_dict(known["gains"]) if known.get("gains") else None})


@dataclass(frozen=True)
class DesignDetails:
    """The load design's own record (fixed_pid.json "design" keys besides the rule's): the load cost and optimum
    [output units s per input unit], the load step [fraction of the control span], the trades and refinements
    (tuning.load_design's records: traded_for_overshoot, followed_setpoints, setpoint_refined; None where not
    made), the Ms and noise estimates per point, the limits that held the design, the setpoint weights tried,
    the stabilising PID's gains, the noise shares, the design model's record, and every candidate the rule ranked."""

    objective: str = "load"
    load_cost: float = math.nan
    load_optimum: float | None = None
    load_step: float = math.nan
    traded_for_overshoot: Trade | None = None
    followed_setpoints: Followed | None = None
    setpoint_refined: ModelSearch | None = None
    estimates: list = dataclasses.field(default_factory=list)
    active_limits: list = dataclasses.field(default_factory=list)
    setpoint_weights: list = dataclasses.field(default_factory=list)
    stabilising_gains: dict | None = None
    feasible: bool = True
    fell_back_to_setpoint_search: bool = False
    noise_increment_limit_relaxed: bool = False
    noise: dict | None = None
    design_model: ModelPath = dataclasses.field(default_factory=ModelPath)
    chatter: ChatterCheck | None = None
    candidates: tuple[CandidateRecord, ...] = ()

    @property
    def held_by(self) -> set:
        """The names of the limits that held the design (LoadDesign.active_limits)."""
        return {a["limit"] for a in self.active_limits}

    def as_json(self) -> dict:
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            out[f.name] = dataclasses.asdict(value) if dataclasses.is_dataclass(value) else value
        out["candidates"] = [c.as_json() for c in self.candidates]
        return out

    @classmethod
    def from_json(cls, design: dict) -> "DesignDetails":
        """The record of a fixed_pid.json "design" (keys it does not know, from older files, are left out)."""
        known = {k: v for k, v in _known(cls, design).items() if v is not None}
        return cls(**{**known, "traded_for_overshoot": Trade.from_json(known.get("traded_for_overshoot")),
                      "followed_setpoints": Followed.from_json(known.get("followed_setpoints")),
                      "setpoint_refined": ModelSearch.from_json(known.get("setpoint_refined")),
                      "design_model": ModelPath.from_json(known.get("design_model")),
                      "chatter": ChatterCheck.from_json(known.get("chatter")),
                      "candidates": tuple(CandidateRecord.from_json(c) for c in known.get("candidates") or ())})


@dataclass(frozen=True)
class DesignReport:
    """Which requirement bound the design (`bound`, one of the `Requirement` names), what was relaxed, each
    requirement's measured value, requirement 1 on the range episode, and the search's own record (`details`)."""

    bound: str
    relaxed: tuple[Relaxation, ...]
    requirements: tuple[Requirement, ...]
    following: Following | None  # None only in a fixed_pid.json written before the rule by priority
    details: DesignDetails

    def as_json(self) -> dict:
        """fixed_pid.json's "design": the search's record plus "bound", "relaxed", "requirements", "following"."""
        return {**self.details.as_json(), "bound": self.bound,
                "relaxed": [dataclasses.asdict(r) for r in self.relaxed],
                "requirements": [dataclasses.asdict(r) for r in self.requirements],
                "following": dataclasses.asdict(self.following) if self.following is not None else None}

    @classmethod
    def from_json(cls, design: dict) -> "DesignReport":
        """The report of fixed_pid.json's "design" (as_json's form; a file written before the rule has only the
        search's record: no bound, relaxations, requirements or following)."""
        following = design.get("following")
        return cls(bound=design.get("bound") or "",
                   relaxed=tuple(Relaxation(**r) for r in design.get("relaxed") or ()),
                   requirements=tuple(Requirement(**r) for r in design.get("requirements") or ()),
                   following=Following(**following) if following else None,
                   details=DesignDetails.from_json(design))


@dataclass(frozen=True)
class DesignResult:
    """The fixed PID: gains, structure (b, c, Tf lists per loop), its search vector, load cost (objective "load") or
    setpoint cost, the cost evaluations spent, and the design report (None for baseline.objective "setpoint")."""

    action: np.ndarray
    gains: Gains
    cost: float
    evaluations: int
    structure: tuple
    report: DesignReport | None = None

    def structure_dict(self) -> dict:
        """{"setpoint_weight", "derivative_weight", "measurement_filter_s"}: lists per loop (fixed_pid.json)."""
        b, c, tf = self.structure
        return {"setpoint_weight": list(b), "derivative_weight": list(c), "measurement_filter_s": list(tf)}

    def as_json(self) -> dict:
        """fixed_pid.json: {"action", "gains", "cost", "evaluations", "structure", "design": the design report}."""
        return {"action": np.asarray(self.action).tolist(), "gains": self.gains.as_dict(), "cost": self.cost,
                "evaluations": self.evaluations, "structure": self.structure_dict() if self.structure else None,
                "design": self.report.as_json() if self.report is not None else {}}

    @classmethod
    def from_json(cls, data: dict) -> "DesignResult":
        """The design of a fixed_pid.json (as_json's form). A file without "structure" (written before the 2-DOF law)
        gives structure None: the controller's settings apply."""
        s = data.get("structure")
        structure = (tuple(map(float, s["setpoint_weight"])), tuple(map(float, s["derivative_weight"])),
                     tuple(map(float, s["measurement_filter_s"]))) if s else None
        design = data.get("design") or {}
        return cls(action=np.asarray(data.get("action", ()), float), gains=gains_from_dict(data["gains"]),
                   cost=float(data.get("cost", math.nan)), evaluations=int(data.get("evaluations", 0)),
                   structure=structure, report=DesignReport.from_json(design) if design else None)

    def gains_values(self) -> GainValues:
        """The gains as GainValues, what LoopCore.step takes."""
        return self.gains.values()

