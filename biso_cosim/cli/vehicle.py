"""``biso-cosim vehicle``: the reference car's figures.

``biso-cosim vehicle performance`` drives the MuJoCo car at full throttle from rest on a
straight, flat road and prints 0-100 km/h, top speed and rear-wheel slip against the
published figures of its class (docs/vehicle.md); ``params`` prints the drivetrain's
parameters with their sources (``--tyres``: the Magic Formula tyres', ``--chassis``: the
brakes, ABS and compliance steer of the slip-tyre car, ``tyres.ChassisParams``); ``biso-cosim
vehicle handling --out DIR`` runs the handling tests with the slip-based tyres (ISO 4138
steady circle, ISO 7401 step steer, braking from 100 km/h, the tyre model's cost per physics
step) and writes handling.md, handling.json and a plot into DIR (``vehicle.handling``), with
``--tyre NAME=VALUE`` and ``--chassis NAME=VALUE`` setting parameters of those two tables
(a name not in the table, or a value outside its range, is refused naming it and the range).
"""

from __future__ import annotations

import argparse
import json
import math


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("vehicle", help="the reference car's drivetrain and performance")
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    perf = actions.add_parser("performance", help="measure 0-100 km/h, top speed and wheel slip with the MuJoCo car",
                              description="Full throttle from rest on a straight, flat road (docs/vehicle.md).")
    perf.add_argument("--duration", type=float, default=120.0, metavar="S",
                      help="simulated seconds of the run (default 120: the top speed settles)")
    perf.add_argument("--json", action="store_true", help="print the figures as JSON")
    perf.set_defaults(func=performance)
    params = actions.add_parser("params", help="the drivetrain's parameters with their sources (Markdown)")
    table = params.add_mutually_exclusive_group()
    table.add_argument("--tyres", action="store_true", help="the Magic Formula tyres' parameters instead")
    table.add_argument("--chassis", action="store_true",
                       help="the slip-tyre car's brakes, ABS and compliance steer (ChassisParams) instead")
    params.set_defaults(func=show_params)
    handling = actions.add_parser("handling", help="ISO 4138 steady circle, ISO 7401 step steer and braking "
                                                   "with the slip-based tyres, against the class's figures",
                                  description="The handling report of the car with tyres='magic_formula' "
                                              "(docs/vehicle.md, section Tyres).")
    handling.add_argument("--out", required=True, metavar="DIR", help="directory for handling.md, .json, .png")
    handling.add_argument("--radius", type=float, default=40.0, metavar="M",
                          help="radius of the steady circle, m (default 40; 20-200)")
    handling.add_argument("--tyre", action="append", default=[], metavar="NAME=VALUE",
                          help="set a tyre parameter (`biso-cosim vehicle params --tyres`; repeatable)")
    handling.add_argument("--chassis", action="append", default=[], metavar="NAME=VALUE",
                          help="set a brake, ABS or compliance-steer parameter (`biso-cosim vehicle params "
                               "--chassis`; repeatable)")
    handling.set_defaults(func=run_handling)


def performance(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.duration) and args.duration > 20.0):
        raise ValueError(f"--duration must be a number of seconds > 20, got {args.duration:g}")
    from dataclasses import asdict

    from biso_cosim.vehicle.performance import measure_performance

    perf = measure_performance(duration_s=args.duration)
    print(json.dumps(asdict(perf), indent=2) if args.json else perf.table())
    return 0


def show_params(args: argparse.Namespace) -> int:
    if args.tyres or args.chassis:
        from biso_cosim.vehicle.tyres import ChassisParams, TyreParams

        print((TyreParams if args.tyres else ChassisParams).table())
        return 0
    from biso_cosim.vehicle.drivetrain import DrivetrainParams

    print(DrivetrainParams.table())
    return 0


def parameter_record(record_type: type, settings: list[str], option: str):
    """``record_type`` (``TyreParams``, ``ChassisParams``) with the ``NAME=VALUE`` settings of
    ``option``, checked (``record.check()``: the parameter's name and range), or None without
    settings."""
    from dataclasses import fields, replace

    if not settings:
        return None
    known = [f.name for f in fields(record_type)]
    values = {}
    for item in settings:
        name, sep, text = item.partition("=")
        if not sep or name not in known:
            raise ValueError(f"{option} must be NAME=VALUE with NAME one of {', '.join(known)}, got {item!r}")
        try:
            values[name] = float(text)
        except ValueError:
            raise ValueError(f"{option} {name} must be a number, got {text!r}") from None
    record = replace(record_type(), **values)
    record.check()
    return record


def run_handling(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.radius) and 20.0 <= args.radius <= 200.0):
        raise ValueError(f"--radius must be a number of metres in [20, 200], got {args.radius:g}")
    from biso_cosim.vehicle.tyres import ChassisParams, TyreParams

    tyre_params = parameter_record(TyreParams, args.tyre, "--tyre")
    chassis_params = parameter_record(ChassisParams, args.chassis, "--chassis")
    import warnings
    from pathlib import Path

    from biso_cosim.cli import UserError
    from biso_cosim.fmu.native.compiler import CompilerNotFound
    from biso_cosim.routes.route import RouteWarning
    from biso_cosim.vehicle.handling import handling_report
    from biso_cosim.vehicle.tyres import load_plugin

    try:
        load_plugin()  # built on first use: without a C compiler, one line saying what to install
    except CompilerNotFound as exc:
        raise UserError(str(exc)) from None
    args.running = True
    with warnings.catch_warnings():
        # the circle's lateral-acceleration cap of the route: the runs hold their own speed
        warnings.simplefilter("ignore", RouteWarning)
        handling_report(args.out, radius_m=args.radius, tyre_params=tyre_params, chassis_params=chassis_params)
    print((Path(args.out) / "handling.md").read_text(), end="")
    return 0
