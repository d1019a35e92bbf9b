"""What a run has settled, for its next stage and for later commands: the scenario as the run runs it (plant
isolation, prior fallback, the fixed PID's structure), the fixed PID, the anchor trained around, the policy and the
deployed controller, set by `tune` as it goes and read back from a run directory by `--resume`, `evaluate` and
`export`."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from prlpid_fmi import rundir as rd
from prlpid_fmi.deliver.rule import Deployed
from prlpid_fmi.errors import RunError
from prlpid_fmi.run.record import RunRecord
from prlpid_fmi.scenario.load import Scenario, load_scenario
from prlpid_fmi.tuning.design_result import DesignResult


def one_line(exc: BaseException) -> str:
    """An exception's message with its whitespace (newlines included) collapsed."""
    return " ".join(str(exc).split())


def load_policy(run_dir: Path, algorithm: str):
    """The run's trained policy (model.zip, with vecnormalize.pkl's observation statistics when present) as a
    Policy: observation (n_obs,) -> action (n_params,). RunError for a damaged or foreign file."""
    from prlpid_fmi.loop.evaluation import model_policy
    from prlpid_fmi.tuning.agent import load_model

    path = run_dir / rd.MODEL
    try:
        model = load_model(path, algorithm)
    except Exception as exc:  # a damaged file can fail in zipfile, pickle or torch: all mean the same here
        raise RunError(f"{path}: cannot load the trained policy ({type(exc).__name__}: {one_line(exc)}; "
                       f"expected a {algorithm.upper()} model.zip written by `tune`)") from None
    vecnorm = None
    if (run_dir / rd.VECNORMALIZE).is_file():
        import pickle

        try:
            with open(run_dir / rd.VECNORMALIZE, "rb") as f:
                vecnorm = pickle.load(f)
        except (pickle.UnpicklingError, EOFError, AttributeError, ValueError) as exc:
            raise RunError(f"{run_dir / rd.VECNORMALIZE}: cannot load the observation statistics "
                           f"({type(exc).__name__}: {one_line(exc)}; expected the file written by `tune`)") from None
        vecnorm.training = False
    return model_policy(model, vecnorm)


def with_isolation(scenario: Scenario, isolation: str) -> Scenario:
    """The scenario with plant.isolation `isolation` where it is "auto"."""
    if scenario.tuning.isolation != "auto" or isolation == "auto":
        return scenario
    return dataclasses.replace(scenario, tuning=dataclasses.replace(scenario.tuning, isolation=isolation))


def prior_fallback_for(scenario: Scenario) -> str:
    """What replaces a forecast prior that keeps crashing: "rollback" (the plant's own instance, its state saved
    and set back, where the FMU can get and set its state and the prior is the plant's FMU) or "off" (no forecast)."""
    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.fmu.resolve import resolve_fmu

    t = scenario.tuning
    if t.prior.fmu or t.prior.state_map or t.prior_mode == "rollback":
        return "off"
    return "rollback" if describe_fmu(resolve_fmu(t.fmu, t.fmi_version)).prior_mode else "off"


def with_prior_fallback(scenario: Scenario, fallback: str | None) -> Scenario:
    """The scenario with a crashing prior replaced (run.json's "prior_fallback"): "rollback" or "off" (None: as is)."""
    if fallback == "rollback":
        tuning = dataclasses.replace(scenario.tuning, prior_mode="rollback")
    elif fallback == "off":
        tuning = dataclasses.replace(scenario.tuning, forecast_horizon=0)
    else:
        return scenario
    return dataclasses.replace(scenario, tuning=tuning)


def read_fixed_pid(run_dir: Path) -> DesignResult | None:
    """The run's fixed PID design (fixed_pid.json), or None where the run has none."""
    path = Path(run_dir) / rd.FIXED_PID
    return DesignResult.from_json(json.loads(path.read_text())) if path.is_file() else None


def training_anchor(scenario: Scenario, fixed: DesignResult | None, classical=None):
    """What action 0 of the anchored gain map gives (loop.env): the classical gain table when one was built and
    controller.anchor_on is auto, else the fixed PID's Gains; None for the absolute map or without a fixed PID."""
    if fixed is None or scenario.tuning.gain_mapping != "anchored":
        return None
    if classical is not None and scenario.tuning.anchor_on == "auto":
        return classical
    return fixed.gains


def anchor_name(anchor) -> str | None:
    """run.json's "anchor": "classical gain schedule", "fixed PID", or None (absolute map)."""
    from prlpid_fmi.loop.env import is_table

    if anchor is None:
        return None
    return str(Deployed.CLASSICAL if is_table(anchor) else Deployed.FIXED_PID)


def run_anchor(run_dir: Path, scenario: Scenario, fixed: DesignResult | None):
    """The anchor a finished run trained around, read back (run.json's "anchor"; classical_schedule.csv)."""
    from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv

    record = RunRecord.read(run_dir)
    named = record.anchor if record is not None else None
    path = run_dir / rd.CLASSICAL_SCHEDULE
    classical = read_schedule_csv(path) if named == str(Deployed.CLASSICAL) and path.is_file() else None
    return training_anchor(scenario, fixed, classical)


def with_structure(scenario: Scenario, fixed: DesignResult | None) -> Scenario:
    """The scenario with the fixed PID's structure (b, c, Tf per loop) in force (unchanged for a run without one,
    or one written before the 2-DOF law: those ran with the controller's settings)."""
    if fixed is None or not fixed.structure:
        return scenario
    structure = tuple(zip(*(map(float, part) for part in fixed.structure)))
    return dataclasses.replace(scenario, tuning=dataclasses.replace(scenario.tuning, tuned_structure=structure))


def load_trained(run_dir: Path) -> Scenario:
    """The scenario of a finished run (its scenario.yaml), with the plant isolation its run.json recorded."""
    if not (run_dir / rd.SCENARIO).is_file() or not (run_dir / rd.MODEL).is_file():
        raise RunError(f"{run_dir}: not a finished run directory (expected {rd.SCENARIO} and {rd.MODEL} from `tune`)")
    scenario = load_scenario(run_dir / rd.SCENARIO)
    record = RunRecord.read(run_dir) or RunRecord()  # a run whose plant crashed the tool once keeps it in a worker
    isolation, fallback = record.isolation, record.prior_fallback
    return with_structure(with_prior_fallback(with_isolation(scenario, isolation), fallback),
                          read_fixed_pid(run_dir))


def on_other_evaluation(trained: Scenario, scenario_path: str | Path) -> Scenario:
    """Another scenario's evaluation (setpoints, disturbances, ...) around the trained run's loops. A file without a
    `plant:` section (e.g. only `evaluation:`) is laid over the run's own scenario.yaml (load_scenario's base)."""
    other = load_scenario(scenario_path, base=trained.path)
    if [(l.input, l.output) for l in other.tuning.loops] != [(l.input, l.output) for l in trained.tuning.loops] \
            or other.tuning.coupled != trained.tuning.coupled:
        raise RunError(f"{scenario_path}: plant.loops differ from the trained run's "
                       f"(got {[l.output for l in other.tuning.loops]}; expected the same loops and coupling)")
    return with_isolation(dataclasses.replace(other, tuning=dataclasses.replace(
        other.tuning, loops=trained.tuning.loops, coupled=trained.tuning.coupled,
        prior_mode=trained.tuning.prior_mode,
        forecast_horizon=other.tuning.forecast_horizon if trained.tuning.forecast_horizon else 0,
        coupling_range=trained.tuning.coupling_range, tuned_structure=trained.tuning.tuned_structure,
        measurement_filter_order=trained.tuning.measurement_filter_order,
        derivative_filter_N=trained.tuning.derivative_filter_N)), trained.tuning.isolation)


def deployed_controller(run_dir: Path):
    """(what the run deployed: a Deployed, its schedule.csv as a GainSchedule when that is the adaptive
    schedule); (None, None) for a run whose choice was not made (no metrics.json entry, e.g. an absolute map
    without baseline)."""
    from prlpid_fmi.tuning.schedule.csv_file import read_schedule_csv

    try:
        deployed = Deployed.read(json.loads((run_dir / rd.METRICS).read_text()).get("deployed"))
    except (OSError, ValueError, AttributeError):
        return None, None
    if deployed in (Deployed.SCHEDULE, Deployed.CLASSICAL):
        return (deployed, read_schedule_csv(run_dir / rd.SCHEDULE)) if (run_dir / rd.SCHEDULE).is_file() \
            else (None, None)
    return deployed, None
