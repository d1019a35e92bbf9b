"""prlpid-fmi command line. Each command parses its arguments and calls one library function.

Errors the user can fix (PrlPidError, a bad argument, an OS error such as a full disk) are printed as
one line on stderr with exit code 2. Results go to stdout, progress to stderr; -q keeps only results.
"""
from __future__ import annotations

import argparse
import math
import sys
import warnings

from prlpid_fmi.errors import ArgumentError, Interrupted, PrlPidError
from prlpid_fmi.export.formats import CODE_FORMATS, FORMATS
from prlpid_fmi.version import __version__

PROG = "prlpid-fmi"


# a library parameter -> the option that sets it (ArgumentError messages are shown with these)
OPTIONS = {"timesteps": "--timesteps", "seed": "--seed", "points": "--points", "schedule_by": "--schedule-by",
           "scenario_path": "--scenario", "replay": "--replay", "name": "--name", "fmt": "--format",
           "fmi_version": "--fmi-version", "ray": "--ray", "workers": "--workers", "resume": "--resume", "out": "--out",
           "force": "--force", "not_deployable": "--force-not-deployable"}


def _say(args: argparse.Namespace, text: str) -> None:
    """Print informational output unless --quiet."""
    if not args.quiet:
        print(text)


def _scenario(arg: str):
    """A scenario argument: an existing path, else a bundled scenario's name."""
    from prlpid_fmi.scenario.presets import resolve_scenario

    return resolve_scenario(arg)


def _plant_names(requested: list[str]) -> list[str]:
    from prlpid_fmi.errors import PlantError
    from prlpid_fmi.fmu.build import PLANT_SOURCES, bundled_plant_names

    names = bundled_plant_names()
    if not names:
        raise PlantError(f"{PLANT_SOURCES}: no bundled plant sources found (expected folders with a model.yaml; "
                         "is the package installed completely?)")
    return requested or names


def _build_fmus(args: argparse.Namespace) -> int:
    from pathlib import Path

    from prlpid_fmi.errors import PlantError
    from prlpid_fmi.fmu import build_fmu

    if args.out is not None and Path(args.out).exists() and not Path(args.out).is_dir():
        raise PlantError(f"{args.out}: is a file, not a folder (got --out {args.out}; expected a folder for the FMUs)")
    for name in _plant_names(args.plants):
        path = build_fmu(name, args.fmi_version, args.out)
        _say(args, f"built {path}")
    return 0


def _inspect(args: argparse.Namespace) -> int:
    from prlpid_fmi.fmu import describe_fmu, format_description

    print(format_description(describe_fmu(args.fmu)))
    if args.probe:
        from prlpid_fmi.fmu.dynamic_check import dynamic_check, failed, format_findings

        findings = dynamic_check(args.fmu, step_timeout_s=args.step_timeout)
        print("Dynamic checks (--probe):")
        print(format_findings(findings))
        return 1 if failed(findings) else 0
    return 0


def _check_plants(args: argparse.Namespace) -> int:
    from prlpid_fmi.fmu.check import step_response_report

    _plant_names([])
    print(step_response_report(args.fmi_version))
    return 0


def _validate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from prlpid_fmi.scenario.load import load_scenario
    from prlpid_fmi.scenario.presets import bundled_scenario_names
    from prlpid_fmi.sweep.spec import bundled_sweep_names, is_sweep_file, load_sweep, resolve_sweep

    arg = Path(args.scenario)
    if (is_sweep_file(arg) if arg.is_file() else
            args.scenario in bundled_sweep_names() and args.scenario not in bundled_scenario_names()):
        sweep = load_sweep(resolve_sweep(args.scenario))
        n, m = len(sweep.variants), len(sweep.seeds)
        _say(args, f"{args.scenario}: ok: sweep {sweep.name}: {n} variant(s) x {m} seed(s) = {n * m} trials of "
                   f"{sweep.base}" + (f", {sweep.timesteps} training steps each" if sweep.timesteps else ""))
        return 0
    path = _scenario(args.scenario)
    s = load_scenario(path)
    t = s.tuning
    _say(args, f"{path}: ok: {s.name}: plant {t.fmu}, {t.n_loops} loop(s) "
               f"({', '.join(f'{l.input} -> {l.output}' for l in t.loops)}), Ts = {t.sample_time_s:g} s, "
               f"{s.agent.algorithm.upper()} for {s.agent.total_timesteps} steps, forecast N = {t.forecast_horizon}, "
               f"smoothing {t.smoothing}")
    return 0


def _schema(args: argparse.Namespace) -> int:
    from prlpid_fmi.schema import json_schema_text

    sys.stdout.write(json_schema_text())
    return 0


def _start_values(pairs: list[str]) -> dict:
    """--set NAME=VALUE arguments as {name: float}; one line for a malformed one."""
    out = {}
    for pair in pairs or []:
        name, sep, value = pair.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise PrlPidError(f"--set {pair}: expected NAME=NUMBER (got {pair!r})") from None
        if not sep or not name.strip():
            raise PrlPidError(f"--set {pair}: expected NAME=NUMBER (got {pair!r})")
    return out


def _init(args: argparse.Namespace) -> int:
    from prlpid_fmi.scenario.draft import init_isolated

    text = init_isolated(args.fmu, args.step_timeout, output=args.output, start_values=_start_values(args.set))
    sys.stdout.write(text)  # only a complete scenario reaches stdout
    return 0


def _probe(args: argparse.Namespace) -> int:
    from pathlib import Path

    from prlpid_fmi.fmu.worker import crash_seen
    from prlpid_fmi.probe.isolated import probe_isolated
    from prlpid_fmi.probe.open_loop import format_probe, plot_probe

    result = probe_isolated(args.fmu, args.step_timeout, output=args.output, inputs=args.input or None,
                            start_values=_start_values(args.set))
    print(format_probe(result))
    crash = crash_seen([args.fmu])
    if crash:
        print(f"{crash}: probed again with each run in a worker process of its own; a scenario for this FMU "
              "needs plant.isolation: process (init writes it)")
    plot = Path(args.plot) if args.plot else Path(f"{Path(args.fmu).stem}-probe.png")
    plot_probe(result, plot)
    _say(args, f"plot: {plot}")
    return 0


def _interrupt_on_signals():
    """SIGTERM and SIGINT raise Interrupted (once; a second signal is ignored while the checkpoint is saved).
    Returns the previous handlers."""
    import signal

    from prlpid_fmi.errors import Interrupted

    def handler(signum, frame):
        for s in (signal.SIGTERM, signal.SIGINT):
            signal.signal(s, signal.SIG_IGN)
        raise Interrupted(signum)

    return {s: signal.signal(s, handler) for s in (signal.SIGTERM, signal.SIGINT)}


def _tune(args: argparse.Namespace) -> int:
    """`tune`; as the program (not a library call of main), under a supervising parent (run.supervise): a crash of
    the process that runs it resumes the run with the plant in a worker process, or ends with one line."""
    if not args.supervised:
        return _tune_here(args)
    from prlpid_fmi.run.supervise import supervised

    def work(announce, restart) -> int:
        args.supervised = False  # the child: errors are its own (main's handlers), exit codes its own
        return _tune_here(args, announce, restart)

    return supervised(work)


def _tune_here(args: argparse.Namespace, announce=None, restart=None) -> int:
    """`tune` in this process; announce(run_dir) as soon as the run directory exists; restart: (run_dir, the crash's
    line) to resume a run whose process crashed (run.supervise)."""
    import signal

    from prlpid_fmi.run.tune import tune

    scenario, out, resume, crash = _scenario(args.scenario), args.out, args.resume, None
    if restart is not None:
        out, crash = restart
        scenario, resume = out / "scenario.yaml", True
    previous = _interrupt_on_signals()
    try:
        run_dir = tune(scenario, timesteps=args.timesteps, seed=args.seed, out=out, resume=resume,
                       progress_bar=not (args.no_progress or args.quiet), baseline=not args.no_baseline,
                       on_run_dir=announce, crash=crash)
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    _say(args, (run_dir / "report.md").read_text())
    print(f"run directory: {run_dir}")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from prlpid_fmi.run.evaluate import evaluate_run

    out_dir = evaluate_run(args.run_dir, None if args.scenario is None else _scenario(args.scenario))
    _say(args, (out_dir / "report.md").read_text())
    print(f"evaluation written to {out_dir}")
    return 0


def csv_only_options(args) -> list[str]:
    """The `export` options given that do not apply to args.format (CSV extraction vs code generation)."""
    if args.format == "csv":
        given = (("--fixed", args.fixed), ("--name", args.name is not None),
                 ("--force-not-deployable", args.force_not_deployable))
    else:
        given = (("--schedule-by", args.schedule_by is not None), ("--points", args.points is not None),
                 ("--replay", args.replay), ("--scenario", args.scenario is not None))
    return [option for option, present in given if present]


def _export(args: argparse.Namespace) -> int:
    from prlpid_fmi.run.export import export_controller, export_schedule

    wrong = csv_only_options(args)
    if wrong:
        raise PrlPidError(f"{wrong[0]}: not used with --format {args.format} (expected " + (
            "--format csv; the code carries the run's deployed schedule.csv)" if args.format != "csv" else
            f"--format {', '.join(list(CODE_FORMATS)[:-1])} or {list(CODE_FORMATS)[-1]})"))
    if args.format != "csv":
        for path in export_controller(args.run_dir, args.output, args.format, fixed=args.fixed, name=args.name,
                                      force=args.force, not_deployable=args.force_not_deployable):
            print(f"controller code written to {path}")
        return 0
    scenario = None if args.scenario is None else _scenario(args.scenario)
    given = {k: v for k, v in (("schedule_by", args.schedule_by), ("points", args.points)) if v is not None}
    path, comparison = export_schedule(args.run_dir, args.output, replay=args.replay, scenario_path=scenario,
                                       force=args.force, **given)
    print(f"gain schedule written to {path}")
    if comparison and not args.quiet:
        p, s = comparison["policy"]["overall"], comparison["schedule"]["overall"]
        print(f"{'metric':<24}{'live policy':>14}{'schedule (plain PID)':>22}")
        for k in p:
            if isinstance(p[k], float) and k in s:
                print(f"{k:<24}{p[k]:>14.5g}{s[k]:>22.5g}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    import signal

    from prlpid_fmi.sweep import resolve_sweep, run_sweep

    previous = _interrupt_on_signals()  # SIGTERM too (a job manager, `timeout`): stop the workers, summarise
    try:
        result = run_sweep(resolve_sweep(args.sweep), out=args.out, workers=args.workers, ray=args.ray is not None,
                           ray_address=args.ray or None, log=(lambda line: None) if args.quiet else
                           (lambda line: print(line, file=sys.stderr, flush=True)))
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    for label, error in result.failed:
        print(f"{PROG}: error: {label}: {error}", file=sys.stderr)
    print(f"sweep summary: {result.out / 'summary.md'}")
    return 1 if result.failed else 0


def _whole_number(text: str) -> int:
    """An integer option: 50000, 50_000 or 5e4 (written as a float, it must be a whole number)."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or not value.is_integer():
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r} "
                                         "(expected a whole number, e.g. 3, 50000 or 5e4)")
    return int(value)


class _Parser(argparse.ArgumentParser):
    """argparse with the tool's error convention: one line on stderr, exit code 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


SCENARIO_HELP = "scenario YAML file, or the name of a bundled scenario (first_order, two_tank, ...)"
STEP_TIMEOUT_HELP = ("seconds an FMU call may take before it counts as hung (the FMU runs in a worker process; "
                     "default: 100 x the measured step cost, at least 10 s)")


def _seconds(text: str) -> float:
    """A positive number of seconds (--step-timeout)."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"not a positive number of seconds: {text!r} (expected e.g. 5 or 0.5)")
    return value


def make_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    parser.add_argument("-q", "--quiet", action="store_true", help="print only results and errors (no progress)")
    # -q is also accepted after the command; SUPPRESS keeps it from resetting a -q given before it
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                        help="print only results and errors (no progress)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name: str, func, help: str) -> argparse.ArgumentParser:
        # the command list %-formats each help (a "95 %" would break `--help`); the description is not
        p = sub.add_parser(name, help=help.replace("%", "%%"), description=help, parents=[common])
        p.set_defaults(func=func)
        return p

    p = command("build-fmus", _build_fmus, "build the bundled plants into FMUs (default: the per-user FMU cache)")
    p.add_argument("plants", nargs="*", help="plant names (default: all bundled plants)")
    p.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                   help="FMI version (2 writes <out>/<Name>.fmu, 3 writes <out>/fmi3/<Name>.fmu)")
    p.add_argument("--out", default=None,
                   help="output directory (default: the per-user cache, e.g. ~/.cache/prlpid-fmi/<version>/fmus)")

    p = command("inspect", _inspect, "show what an FMU offers and whether it can be a plant and a prior")
    p.add_argument("fmu", help="path to a .fmu file")
    p.add_argument("--probe", action="store_true",
                   help="also run it: state save/restore, independent instances, reset, memory after 100 resets "
                        "(one line per finding; exit code 1 when one fails)")
    p.add_argument("--step-timeout", type=_seconds, default=None, metavar="S", help=STEP_TIMEOUT_HELP)

    p = command("validate", _validate, "check a scenario file or a sweep file; one clear line per mistake")
    p.add_argument("scenario", help=SCENARIO_HELP + "; or a sweep file, or a bundled sweep's name")

    command("schema", _schema, "print the JSON Schema of scenario files (for editors and other tools)")

    operating_point = dict(action="append", metavar="NAME=VALUE",
                           help="a parameter or input start value for the operating point (repeatable)")
    p = command("init", _init, "print a ready scenario for an FMU from a step and trim test (redirect it to a .yaml file)")
    p.add_argument("fmu", help="path to a .fmu file")
    p.add_argument("--output", default=None, help="the output to control (default: the FMU's first output)")
    p.add_argument("--set", **operating_point)
    p.add_argument("--step-timeout", type=_seconds, default=None, metavar="S", help=STEP_TIMEOUT_HELP)

    p = command("probe", _probe, "open-loop step and trim test: each input's gain, time constant or growth rate, "
                                 "dead time, with a plot")
    p.add_argument("fmu", help="path to a .fmu file")
    p.add_argument("--output", default=None, help="the output to watch (default: the FMU's first output)")
    p.add_argument("--input", action="append", help="probe only this input (repeatable; default: every input)")
    p.add_argument("--set", **operating_point)
    p.add_argument("--plot", default=None, help="PNG to write (default: <fmu name>-probe.png here)")
    p.add_argument("--step-timeout", type=_seconds, default=None, metavar="S", help=STEP_TIMEOUT_HELP)

    p = command("tune", _tune, "train the adaptive PID, compare it with a tuned fixed PID, export the schedule")
    p.add_argument("scenario", help=SCENARIO_HELP)
    p.add_argument("--timesteps", type=_whole_number, default=None,
                   help="training steps >= 1, e.g. 50000 or 5e4 (default: agent.total_timesteps)")
    p.add_argument("--seed", type=_whole_number, default=None,
                   help="seed, the same range as agent.seed (default: agent.seed)")
    p.add_argument("--out", default=None, help="run directory (default: runs/<name>-<UTC time>; never overwritten)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its latest checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress on stderr")
    p.add_argument("--no-baseline", action="store_true",
                   help="with controller.gain_mapping: absolute only, skip the fixed-PID search (nothing is then "
                        "compared or chosen); the anchored map (the default) trains around the fixed PID and "
                        "searches it anyway")

    p = command("sweep", _sweep, "run a scenario's variants over several seeds (local processes or Ray) and "
                                 "summarise them: mean and 95 % interval per variant")
    p.add_argument("sweep", help="sweep YAML file, or the name of a bundled sweep (scenarios/sweeps/)")
    p.add_argument("--out", default=None, help="sweep folder (default: runs/sweeps/<name>); run again to continue")
    p.add_argument("--workers", type=_whole_number, default=None, help="local processes (default: one per CPU core)")
    p.add_argument("--ray", nargs="?", const="", default=None, metavar="ADDRESS",
                   help="run the trials as Ray tasks: on the cluster at ADDRESS (e.g. auto, ray://host:10001), or "
                        "without ADDRESS on RAY_ADDRESS or a new local Ray instance")

    p = command("evaluate", _evaluate, "re-evaluate a trained policy (into RUN_DIR/evaluations/<n>/)")
    p.add_argument("run_dir")
    p.add_argument("--scenario", default=None,
                   help="use this scenario's evaluation (setpoints, disturbances); a file or a bundled name")

    p = command("export", _export, "write the tuned gain schedule as CSV for a plain PID, or the deployed "
                                   "controller as PLC or C code")
    p.add_argument("run_dir")
    p.add_argument("-o", "--output", required=True,
                   help="file to write, outside the run's own files (csv; st: .st; plcopen: .xml; "
                        "c: NAME.c and NAME.h beside it)")
    p.add_argument("--format", choices=FORMATS, default=FORMATS[0],
                   help="csv: extract a gain schedule from the policy (default); st: IEC 61131-3 function block; "
                        "plcopen: PLCopen TC6 XML; c: C99 header and source (the code carries the run's "
                        "schedule.csv, see docs/deploy.md)")
    p.add_argument("--fixed", action="store_true", help="st/plcopen/c: export the tuned fixed PID (fixed_pid.csv)")
    p.add_argument("--name", default=None,
                   help="st/plcopen/c: identifier in the code (default: from the output file name)")
    p.add_argument("--force", action="store_true", help="replace an existing output file (never a run's own file)")
    p.add_argument("--force-not-deployable", action="store_true",
                   help="st/plcopen/c: export a table marked NOT DEPLOYABLE (it failed the acceptance check) anyway")
    p.add_argument("--schedule-by", default=None,
                   help="csv: setpoint, measurement (settled holds), error (setpoint - measurement, binned from "
                        "training-distribution trajectories), or an FMU variable name (default: setpoint)")
    p.add_argument("--points", type=_whole_number, default=None, help="csv: number of operating points (default: 9)")
    p.add_argument("--replay", action="store_true",
                   help="run the table as a plain gain-scheduled PID on the FMU and compare with the policy")
    p.add_argument("--scenario", default=None,
                   help="with --replay: replay on this scenario's evaluation instead of the run's own")

    p = command("check-plants", _check_plants, "build every bundled plant and check its open-loop step response")
    p.add_argument("--fmi-version", type=int, choices=(2, 3), default=2)
    return parser


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    return f"{PROG}: warning: {message}\n"


def _os_error_line(exc: OSError) -> str:
    """'<file>: <reason>' for an OSError (disk full, permission, ...)."""
    reason = exc.strerror or str(exc)
    return f"{exc.filename}: {reason}" if exc.filename else reason


def main(argv: list[str] | None = None) -> int:
    warnings.formatwarning = _one_line_warning
    args = make_parser().parse_args(argv)
    args.supervised = argv is None  # the program (its own command line), not a library call: `tune` is supervised
    try:
        return args.func(args)
    except PrlPidError as exc:
        text = exc.worded(OPTIONS) if isinstance(exc, ArgumentError) else str(exc)
        for line in text.splitlines():  # a scenario with several mistakes: one line each
            print(f"{PROG}: error: {line}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"{PROG}: error: {_os_error_line(exc)}", file=sys.stderr)
        return 2
    except Interrupted as exc:
        import signal

        resumable = exc.run_dir is not None and (exc.run_dir / "scenario.yaml").is_file()
        where = (f"; continue the run with `{PROG} tune {exc.run_dir}/scenario.yaml --out {exc.run_dir} --resume`"
                 if resumable else "")
        print(f"\n{PROG}: interrupted by {signal.Signals(exc.signum).name}{where}", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print(f"\n{PROG}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
