"""Export a run's controller: the gain table as CSV (from the policy, optionally replayed) or as code (ST, PLCopen
XML, C)."""
from __future__ import annotations

from pathlib import Path

from prlpid_fmi import rundir as rd
from prlpid_fmi.errors import ArgumentError, RunError
from prlpid_fmi.export.controller import controller_name, from_schedule
from prlpid_fmi.export.formats import CODE_FORMATS, output_paths, render
from prlpid_fmi.run.state import load_policy, load_trained, on_other_evaluation, read_fixed_pid, run_anchor
from prlpid_fmi.rundir import write_atomic
from prlpid_fmi.scenario.load import Scenario


def check_output(run_dir: Path, output: Path, force: bool = False) -> None:
    """Refuse an output file that is a directory, a file the run owns (even with force), or an existing
    file without force. Raises RunError."""
    owned = rd.owned_name(run_dir, output)
    if output.is_dir():
        raise RunError(f"{output}: is a directory (expected a file name for the gain schedule CSV)")
    if owned is not None:
        raise RunError(f"{output}: belongs to the run directory {run_dir} (its {owned}; expected a file outside "
                       f"the run's own files, e.g. {run_dir.name}_schedule.csv)")
    if output.exists() and not force:
        raise ArgumentError(f"{output}: exists (expected a new file name, or {{force}} to replace it)")


def _check_schedule_options(trained: Scenario, schedule_by: str, points: int) -> None:
    """points >= 1, and schedule_by a loop signal or a real variable of the run's plant FMU (RunError)."""
    from prlpid_fmi.fmu import describe_fmu
    from prlpid_fmi.fmu.resolve import resolve_fmu
    from prlpid_fmi.tuning.schedule.table import LOOP_SIGNALS, LOOP_VARIABLE

    if points < 1:
        raise ArgumentError(f"{{points}}: must be at least 1 (got {points}; expected a number of operating points "
                            ">= 1)")
    if schedule_by in LOOP_SIGNALS:
        return
    m, loops = LOOP_VARIABLE.match(schedule_by), [loop.output for loop in trained.tuning.loops]
    if m:
        if m.group(2) not in loops:
            raise ArgumentError(f"{{schedule_by}}: no loop measures {m.group(2)!r} (got {schedule_by!r}; expected "
                                f"{m.group(1)}[<loop>] with one of the loops: {', '.join(loops)})")
        return
    fmu = resolve_fmu(trained.tuning.fmu, trained.tuning.fmi_version)
    desc = describe_fmu(fmu)
    v = desc.variable(schedule_by)
    if v is None or not v.scalar_real:
        names = [x.name for x in desc.variables if x.scalar_real]
        shown = ", ".join(names[:12]) + (", ..." if len(names) > 12 else "")
        raise ArgumentError(f"{{schedule_by}}: the plant {fmu.name} has no scalar real variable {schedule_by!r} "
                            f"(got {schedule_by!r}; expected {', '.join(LOOP_SIGNALS)}, <signal>[<loop>], or one of: "
                            f"{shown})")


def export_schedule(run_dir: str | Path, output: str | Path, schedule_by: str = "setpoint", points: int = 9,
                    replay: bool = False, scenario_path: str | Path | None = None,
                    force: bool = False) -> tuple[Path, dict | None]:
    """Write the tuned gain schedule CSV; with replay, run it as a plain PID and compare with the policy.

    output: a new file (an existing one only with force), never one of the run's own files.
    scenario_path: with replay, replay on this scenario's evaluation instead of the run's own.
    Returns (csv path, comparison or None): comparison = {"policy": metrics, "schedule": metrics}.
    """
    from prlpid_fmi.loop.evaluation import evaluate
    from prlpid_fmi.tuning.schedule.csv_file import write_schedule_csv
    from prlpid_fmi.tuning.schedule.extraction import extract
    from prlpid_fmi.tuning.schedule.replay import replay_schedule

    run_dir, output = Path(run_dir), Path(output)
    trained = load_trained(run_dir)
    check_output(run_dir, output, force)
    _check_schedule_options(trained, schedule_by, points)
    if scenario_path is not None and not replay:
        raise ArgumentError(f"{{scenario_path}} {scenario_path}: only used with {{replay}} (expected {{replay}}, or no "
                            "{{scenario_path}})")
    scenario = trained if scenario_path is None else on_other_evaluation(trained, scenario_path)
    policy = load_policy(run_dir, trained.agent.algorithm)
    anchor = run_anchor(run_dir, trained, read_fixed_pid(run_dir))
    schedule = extract(policy, trained.tuning, schedule_by, points, trained.agent.seed, anchor)
    path = write_schedule_csv(schedule, output)
    if not replay:
        return path, None
    config = scenario.evaluation_config()
    intervals = list(scenario.evaluation.intervals) or None
    seed = scenario.evaluation.seed
    policy_m, _ = evaluate(policy, config, seed=seed, intervals=intervals, anchor=anchor)
    schedule_m, _ = replay_schedule(schedule, config, seed=seed, intervals=intervals)
    return path, {"policy": policy_m, "schedule": schedule_m}


def export_controller(run_dir: str | Path, output: str | Path, fmt: str, fixed: bool = False,
                      name: str | None = None, force: bool = False, not_deployable: bool = False) -> list[Path]:
    """Write the run's deployed controller (schedule.csv; fixed_pid.csv with `fixed`) as code; the paths written.

    output: the file to write (for C: <stem>.c, with <stem>.h beside it). name: the identifier in the
    code (default: made from the output file's stem). Files the run owns are never written; existing
    files only with `force`. A table marked NOT DEPLOYABLE (the deliverable rule refused it) only with
    `not_deployable`; otherwise ArgumentError.
    """
    from prlpid_fmi import rundir as rd
    from prlpid_fmi.run.export import check_output
    from prlpid_fmi.tuning.schedule.csv_file import not_deployable as refused, read_schedule_csv

    run_dir, output = Path(run_dir), Path(output)
    table = run_dir / (rd.FIXED_PID_CSV if fixed else rd.SCHEDULE)
    if not table.is_file():
        what = "the tuned fixed PID (written by `tune` when it searched one)" if fixed else \
            "the deployed controller (written by `tune` when a controller is deployable)"
        raise RunError(f"{table}: missing (expected {what})")
    why = refused(table)
    if why and not not_deployable:
        raise ArgumentError(f"{table}: marked NOT DEPLOYABLE ({why}); expected a deployable table, or "
                            "{not_deployable} to export it anyway")
    paths = output_paths(output, fmt)
    for path in paths:
        check_output(run_dir, path, force)
    base = paths[0].with_suffix("").name if fmt == "c" else None
    controller = from_schedule(read_schedule_csv(table), name or controller_name(paths[0].stem),
                               source=f"{run_dir.name}/{table.name}")
    files = render(controller, fmt, basename=base)
    return [write_atomic(path, text) for path, text in zip(paths, files.values())]


def deployable_files(run_dir: str | Path) -> str:
    """A report paragraph naming the run's deployable files and how to turn them into PLC or C code."""
    from prlpid_fmi import rundir as rd

    from prlpid_fmi.tuning.schedule.csv_file import not_deployable

    run_dir = Path(run_dir)
    have = [(f, what) for f, what in ((rd.SCHEDULE, "the deployed controller: a plain (gain-scheduled) PID table"),
                                      (rd.FIXED_PID_CSV, "the tuned fixed PID as a one-row table"))
            if (run_dir / f).is_file() and not not_deployable(run_dir / f)]
    refused = [f for f in (rd.FIXED_PID_CSV, rd.CLASSICAL_SCHEDULE, rd.ADAPTIVE_SCHEDULE)
               if (run_dir / f).is_file() and not_deployable(run_dir / f)]
    if refused:
        said = (f"Marked NOT DEPLOYABLE in their header (they failed a check; `export --force-not-deployable` "
                f"writes code from them anyway): {', '.join(f'`{f}`' for f in refused)}.\n")
    else:
        said = ""
    if not have:
        return "Deployable files: none (no controller was deployable).\n" + said
    lines = ["Deployable files:", ""] + [f"- `{f}`: {what}" for f, what in have]
    formats = CODE_FORMATS.values()
    lines += ["", f"As code for a PLC or a microcontroller ({', '.join(f.description for f in formats)}; see "
                  f"docs/deploy.md): `prlpid-fmi export RUN --format {'|'.join(f.name for f in formats)} -o FILE`"
              + (" (`--fixed` for fixed_pid.csv)." if any(f == rd.FIXED_PID_CSV for f, _ in have) else ".")]
    return "\n".join(lines) + "\n" + (("\n" + said) if said else "")
