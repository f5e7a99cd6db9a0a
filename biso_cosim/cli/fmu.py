"""``biso-cosim fmu``: build the FMUs, validate them, list their variables."""

from __future__ import annotations

import argparse
from pathlib import Path

from biso_cosim.cli import UserError

_NAMES = ("BisoEstimator", "BisoImuPlugin", "BisoVehicle")  # biso_cosim.fmu.build.FMU_NAMES (light import)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fmu",
        help="build and validate the FMI 2.0 co-simulation FMUs (estimator, IMU plug-in, vehicle)",
        description=(
            "FMUs of biso_cosim for other co-simulation tools, built with pythonfmu: BisoEstimator "
            "(an attitude estimator), BisoImuPlugin (virtual MPU-9250 + estimator for your vehicle), "
            "BisoVehicle (the whole MuJoCo co-simulation). They run on the Python that loads them, "
            "which must import biso_cosim (docs/fmu.md)."
        ),
    )
    commands = p.add_subparsers(dest="fmu_command", metavar="ACTION", required=True)
    b = commands.add_parser("build", help="build FMUs into a directory and validate them")
    b.add_argument("--out", required=True, metavar="DIR", help="output directory")
    b.add_argument("--only", action="append", choices=_NAMES, metavar="NAME",
                   help=f"build only this FMU (repeatable): {', '.join(_NAMES)}")
    b.add_argument("--no-validate", action="store_true", help="skip FMPy's validation of the built FMUs")
    b.set_defaults(func=build)
    v = commands.add_parser("validate", help="validate FMU files with FMPy (exit code 1 on problems)")
    v.add_argument("fmus", nargs="+", metavar="FILE", help=".fmu files")
    v.set_defaults(func=validate)
    t = commands.add_parser("variables", help="print the variables of an FMU as a Markdown table")
    t.add_argument("name", choices=_NAMES, help="FMU name")
    t.add_argument("--causality", action="append", choices=("parameter", "input", "output"),
                   help="only variables of this causality (repeatable)")
    t.set_defaults(func=variables)
    d = commands.add_parser("docs", help="refresh the generated variable tables of a Markdown file (docs/fmu.md)")
    d.add_argument("path", metavar="FILE", help="Markdown file with <!-- BEGIN fmu NAME --> blocks")
    d.set_defaults(func=docs)


def _report(paths: list[Path]) -> int:
    from biso_cosim.fmu.build import validate_fmu

    failed = 0
    for path in paths:
        problems = validate_fmu(path)
        print(f"{path}: {'valid' if not problems else f'{len(problems)} problem(s)'}")
        for problem in problems:
            print(f"  {problem}")
        failed += bool(problems)
    return 1 if failed else 0


def build(args: argparse.Namespace) -> int:
    try:
        from biso_cosim.fmu.build import build_fmus
    except ImportError as exc:  # pythonfmu is an optional dependency
        raise UserError(f"building FMUs needs pythonfmu: pip install 'biso_cosim[fmu]' ({exc})") from None
    paths = build_fmus(args.out, only=args.only)
    if args.no_validate:
        for path in paths:
            print(f"built {path}")
        return 0
    return _report(paths)


def validate(args: argparse.Namespace) -> int:
    paths = [Path(p) for p in args.fmus]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise UserError(f"no such FMU file(s): {', '.join(missing)}")
    return _report(paths)


def variables(args: argparse.Namespace) -> int:
    from biso_cosim.fmu.variables import variable_table

    print(variable_table(args.name, args.causality))
    return 0


def docs(args: argparse.Namespace) -> int:
    from biso_cosim.fmu.variables import fill_docs

    path = Path(args.path)
    if not path.is_file():
        raise UserError(f"no such file: {path}")
    text = path.read_text("utf-8")
    new = fill_docs(text)
    path.write_text(new, "utf-8")
    print(f"{path}: {'tables refreshed' if new != text else 'tables up to date'}")
    return 0
