"""prlpid-fmi command line. Each command parses its arguments and calls one library function.

Errors the user can fix (PrlPidError) are printed as one line on stderr with exit code 2.
"""
from __future__ import annotations

import argparse
import sys
import warnings

from .errors import PrlPidError


def _build_fmus(args: argparse.Namespace) -> int:
    from .fmu import build_fmu, bundled_plant_names

    names = args.plants or bundled_plant_names()
    for name in names:
        path = build_fmu(name, args.fmi_version, args.out)
        print(f"built {path}")
    return 0


def _inspect(args: argparse.Namespace) -> int:
    from .fmu import describe_fmu, format_description

    print(format_description(describe_fmu(args.fmu)))
    return 0


def _check_plants(args: argparse.Namespace) -> int:
    from .fmu.check import step_response_report

    print(step_response_report(args.fmi_version))
    return 0


def _validate(args: argparse.Namespace) -> int:
    from .scenario import load_scenario

    s = load_scenario(args.scenario)
    t = s.tuning
    print(f"{args.scenario}: ok: {s.name}: plant {t.fmu}, {t.n_loops} loop(s) "
          f"({', '.join(f'{l.input} -> {l.output}' for l in t.loops)}), Ts = {t.sample_time_s:g} s, "
          f"{s.agent.algorithm.upper()} for {s.agent.total_timesteps} steps, forecast N = {t.forecast_horizon}, "
          f"smoothing {t.smoothing}")
    return 0


def _init(args: argparse.Namespace) -> int:
    from .scenario import init_scenario

    sys.stdout.write(init_scenario(args.fmu))
    return 0


def _tune(args: argparse.Namespace) -> int:
    from .run import tune

    run_dir = tune(args.scenario, timesteps=args.timesteps, seed=args.seed, out=args.out, resume=args.resume,
                   progress_bar=not args.no_progress, baseline=not args.no_baseline)
    print((run_dir / "report.md").read_text())
    print(f"run directory: {run_dir}")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from .run import evaluate_run

    out_dir = evaluate_run(args.run_dir, args.scenario)
    print((out_dir / "report.md").read_text())
    print(f"evaluation written to {out_dir}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from .run import export_schedule

    path, comparison = export_schedule(args.run_dir, args.output, args.schedule_by, args.points, args.replay)
    print(f"gain schedule written to {path}")
    if comparison:
        p, s = comparison["policy"]["overall"], comparison["schedule"]["overall"]
        print(f"{'metric':<24}{'live policy':>14}{'schedule (plain PID)':>22}")
        for k in p:
            if isinstance(p[k], float) and k in s:
                print(f"{k:<24}{p[k]:>14.5g}{s[k]:>22.5g}")
    return 0


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="prlpid-fmi", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("build-fmus", help="build the bundled plants into fmus/<Name>.fmu")
    p.add_argument("plants", nargs="*", help="plant names (default: all bundled plants)")
    p.add_argument("--fmi-version", type=int, choices=(2, 3), default=2,
                   help="FMI version (2 writes fmus/<Name>.fmu, 3 writes fmus/fmi3/<Name>.fmu)")
    p.add_argument("--out", default=None, help="output directory (default: the repository's fmus/)")
    p.set_defaults(func=_build_fmus)

    p = sub.add_parser("inspect", help="show what an FMU offers and whether it can be a plant and a prior")
    p.add_argument("fmu", help="path to a .fmu file")
    p.set_defaults(func=_inspect)

    p = sub.add_parser("validate", help="check a scenario file; one clear line per mistake")
    p.add_argument("scenario", help="scenario YAML file")
    p.set_defaults(func=_validate)

    p = sub.add_parser("init", help="print a ready scenario for an FMU (redirect it to a .yaml file)")
    p.add_argument("fmu", help="path to a .fmu file")
    p.set_defaults(func=_init)

    p = sub.add_parser("tune", help="train the adaptive PID, compare it with a tuned fixed PID, export the schedule")
    p.add_argument("scenario", help="scenario YAML file")
    p.add_argument("--timesteps", type=int, default=None, help="training steps (default: agent.total_timesteps)")
    p.add_argument("--seed", type=int, default=None, help="seed (default: agent.seed)")
    p.add_argument("--out", default=None, help="run directory (default: runs/<name>-<UTC time>; never overwritten)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its latest checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-baseline", action="store_true", help="skip tuning the fixed-PID baseline")
    p.set_defaults(func=_tune)

    p = sub.add_parser("evaluate", help="re-evaluate a trained policy (into RUN_DIR/evaluations/<n>/)")
    p.add_argument("run_dir")
    p.add_argument("--scenario", default=None, help="use this scenario's evaluation (setpoints, disturbances)")
    p.set_defaults(func=_evaluate)

    p = sub.add_parser("export", help="write the tuned gain schedule as CSV for a plain PID")
    p.add_argument("run_dir")
    p.add_argument("-o", "--output", required=True, help="CSV file to write")
    p.add_argument("--schedule-by", default="setpoint",
                   help="setpoint, measurement, or an FMU variable name (default: setpoint)")
    p.add_argument("--points", type=int, default=9, help="number of operating points (default: 9)")
    p.add_argument("--replay", action="store_true",
                   help="run the table as a plain gain-scheduled PID on the FMU and compare with the policy")
    p.set_defaults(func=_export)

    p = sub.add_parser("check-plants", help="build every bundled plant and check its open-loop step response")
    p.add_argument("--fmi-version", type=int, choices=(2, 3), default=2)
    p.set_defaults(func=_check_plants)
    return parser


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    return f"prlpid-fmi: warning: {message}\n"


def main(argv: list[str] | None = None) -> int:
    warnings.formatwarning = _one_line_warning
    args = make_parser().parse_args(argv)
    try:
        return args.func(args)
    except PrlPidError as exc:
        print(f"prlpid-fmi: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("prlpid-fmi: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
