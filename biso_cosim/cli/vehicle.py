"""``biso-cosim vehicle``: the reference car's figures.

``biso-cosim vehicle performance`` drives the MuJoCo car at full throttle from rest on a
straight, flat road and prints 0-100 km/h, top speed and rear-wheel slip against the
published figures of its class (docs/vehicle.md); ``--params`` prints the drivetrain's
parameters with their sources.
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
    params.set_defaults(func=show_params)


def performance(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.duration) and args.duration > 20.0):
        raise ValueError(f"--duration must be a number of seconds > 20, got {args.duration:g}")
    from dataclasses import asdict

    from biso_cosim.vehicle.performance import measure_performance

    perf = measure_performance(duration_s=args.duration)
    print(json.dumps(asdict(perf), indent=2) if args.json else perf.table())
    return 0


def show_params(args: argparse.Namespace) -> int:
    from biso_cosim.vehicle.drivetrain import DrivetrainParams

    print(DrivetrainParams.table())
    return 0
