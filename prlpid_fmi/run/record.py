"""The run's record (run.json) as a typed object: what `tune` ran, how far it got and what happened on the way.

`RunRecord.write` is the only writer of run.json and `RunRecord.read` its only reader; the stages of run.tune set
its fields, and run.state, evaluate and the sweep read them. A key this version does not know (a newer run.json)
is kept in `extra` and written back unchanged.
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path

from prlpid_fmi import rundir as rd


@dataclass
class TrainingStopped:
    """Training ended early on a repeated FMU fault: the steps trained, the episodes in a row that ended at the
    same fault, and that fault's termination record (loop.core's {"message", "time_s", ...})."""

    steps: int
    episodes: int
    termination: dict


@dataclass
class RunRecord:
    """run.json. Times are ISO 8601 strings (rundir.now); None fields are left out of the file.

    command: the argv; versions: {package: version}; seed, total_timesteps, algorithm: the budget as run;
    isolation ("process" once an FMU crash put the plant in a worker; otherwise "auto", not written) and
    isolation_reason (the crash's line); classical_schedule: why the classical schedule was or was not built and its
    design details (tuning.schedule.classical); anchor: what the gain map trained around ("fixed PID", "classical
    gain schedule"); trained_timesteps; prior_fallback ("rollback" or "off") and its reason; training_stopped;
    schedule_by, schedule_candidates_training_ise ({kind: ISE}), schedule_detuned_rows, schedule_error: the adaptive
    table's choice (deliver.candidates.ScheduleChoice); stage_seconds: {stage: s}; resumed, finished: times.
    """

    command: list[str] = field(default_factory=list)
    started: str | None = None
    versions: dict[str, str] = field(default_factory=dict)
    resumed: str | None = None
    seed: int | None = None
    total_timesteps: int | None = None
    algorithm: str | None = None
    isolation: str = "auto"
    isolation_reason: str | None = None
    classical_schedule: dict | None = None
    anchor: str | None = None
    trained_timesteps: int | None = None
    prior_fallback: str | None = None
    prior_fallback_reason: str | None = None
    training_stopped: TrainingStopped | None = None
    schedule_by: str | None = None
    schedule_candidates_training_ise: dict[str, float] | None = None
    schedule_detuned_rows: list[str] | None = None
    schedule_error: str | None = None
    stage_seconds: dict[str, float] | None = None
    finished: str | None = None
    extra: dict = field(default_factory=dict)

    def as_json(self) -> dict:
        """run.json's content: the fields that are set (isolation only when not "auto"), then `extra`."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "extra" or value is None or (f.name == "isolation" and value == "auto"):
                continue
            out[f.name] = dataclasses.asdict(value) if isinstance(value, TrainingStopped) else value
        return {**out, **self.extra}

    @classmethod
    def from_json(cls, data: dict) -> "RunRecord":
        """The record of a run.json's content (unknown keys kept in `extra`)."""
        names = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        known = {k: v for k, v in data.items() if k in names}
        if isinstance(known.get("training_stopped"), dict):
            known["training_stopped"] = TrainingStopped(**known["training_stopped"])
        return cls(**known, extra={k: v for k, v in data.items() if k not in names})

    @classmethod
    def read(cls, run_dir: Path) -> "RunRecord | None":
        """The run directory's record; None without a readable run.json."""
        try:
            data = json.loads((Path(run_dir) / rd.RUN_INFO).read_text())
        except (OSError, ValueError):
            return None
        return cls.from_json(data) if isinstance(data, dict) else None

    def write(self, run_dir: Path) -> Path:
        """Write run.json (atomically)."""
        return rd.write_json(Path(run_dir) / rd.RUN_INFO, self.as_json())
