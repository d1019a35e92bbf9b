"""prlpid-fmi command line. Each command parses its arguments and calls one library function.

Errors the user can fix (PrlPidError) are printed as one line on stderr with exit code 2.
"""
from __future__ import annotations

import argparse
import sys

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

    p = sub.add_parser("check-plants", help="build every bundled plant and check its open-loop step response")
    p.add_argument("--fmi-version", type=int, choices=(2, 3), default=2)
    p.set_defaults(func=_check_plants)
    return parser


def main(argv: list[str] | None = None) -> int:
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
