"""``biso-cosim fmu``: build the FMUs, validate them, list their variables."""

from __future__ import annotations

import argparse
from pathlib import Path

from biso_cosim.cli import UserError

_NAMES = ("BisoEstimator", "BisoImuPlugin", "BisoVehicle")  # biso_cosim.fmu.build.FMU_NAMES (light import)
_NATIVE = ("BisoEstimator", "BisoImuPlugin")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fmu",
        help="build and validate the co-simulation FMUs (estimator, IMU plug-in: native C, FMI 2.0 and 3.0; "
             "vehicle: Python)",
        description=(
            "FMUs of biso_cosim for other co-simulation tools. Native (C99, no Python needed, compiled here by "
            "the system C compiler, with their C sources inside): BisoEstimator-fmi2/-fmi3.fmu (an attitude "
            "estimator) and BisoImuPlugin-fmi2/-fmi3.fmu (virtual MPU-9250 + estimator for your vehicle). "
            "Python-based (our C shell embedding CPython, FMI 2.0 and 3.0): BisoVehicle-fmi2/-fmi3.fmu, the whole "
            "MuJoCo co-simulation, which runs on the Python of the host process (or starts the Python that built "
            "it) and needs biso_cosim there (docs/fmu.md)."
        ),
    )
    commands = p.add_subparsers(dest="fmu_command", metavar="ACTION", required=True)
    b = commands.add_parser("build", help="build FMUs into a directory and validate them")
    b.add_argument("--out", required=True, metavar="DIR", help="output directory")
    b.add_argument("--only", action="append", choices=_NAMES, metavar="NAME",
                   help=f"build only this FMU (repeatable): {', '.join(_NAMES)}")
    b.add_argument("--profile", action="append", default=[], metavar="FILE",
                   help="a sensor profile file (.toml) to build into the native BisoImuPlugin beside the built-in "
                        "profiles (repeatable); select it with sensor.profile = its name")
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
    from biso_cosim.fmu.build import build_fmu
    from biso_cosim.fmu.native.compiler import CompilerNotFound

    names = list(dict.fromkeys(args.only or _NAMES))
    profiles = []
    for item in args.profile:
        if not Path(item).is_file():
            raise UserError(f"--profile: no such profile file: {item}")
        profiles.append(item)
    paths: list[Path] = []
    for name in names:
        try:
            paths += build_fmu(name, args.out, extra_profiles=profiles if name in _NATIVE else ())
        except CompilerNotFound as exc:
            raise UserError(str(exc)) from None
        except ValueError as exc:  # a profile file the model refuses
            raise UserError(str(exc)) from None
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
