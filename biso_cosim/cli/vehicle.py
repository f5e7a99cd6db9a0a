"""``biso-cosim vehicle``: the reference car's figures.

``biso-cosim vehicle performance`` drives the MuJoCo car at full throttle from rest on a
straight, flat road and prints 0-100 km/h, top speed and rear-wheel slip against the
published figures of its class (docs/vehicle.md); ``params`` prints the drivetrain's
parameters with their sources (``--tyres``: the Magic Formula tyres'); ``biso-cosim vehicle
handling --out DIR`` runs the handling tests with the slip-based tyres (ISO 4138 steady
circle, ISO 7401 step steer, braking from 100 km/h, the tyre model's cost per physics step)
and writes handling.md, handling.json and a plot into DIR (``vehicle.handling``).
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
    params.add_argument("--tyres", action="store_true", help="the Magic Formula tyres' parameters instead")
    params.set_defaults(func=show_params)
    handling = actions.add_parser("handling", help="ISO 4138 steady circle, ISO 7401 step steer and braking "
                                                   "with the slip-based tyres, against the class's figures",
                                  description="The handling report of the car with tyres='magic_formula' "
                                              "(docs/vehicle.md, section Tyres).")
    handling.add_argument("--out", required=True, metavar="DIR", help="directory for handling.md, .json, .png")
    handling.add_argument("--radius", type=float, default=40.0, metavar="M",
                          help="radius of the steady circle, m (default 40; 20-200)")
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
    if args.tyres:
        from biso_cosim.vehicle.tyres import TyreParams

        print(TyreParams.table())
        return 0
    from biso_cosim.vehicle.drivetrain import DrivetrainParams

    print(DrivetrainParams.table())
    return 0


def run_handling(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.radius) and 20.0 <= args.radius <= 200.0):
        raise ValueError(f"--radius must be a number of metres in [20, 200], got {args.radius:g}")
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
        handling_report(args.out, radius_m=args.radius)
    print((Path(args.out) / "handling.md").read_text(), end="")
    return 0
