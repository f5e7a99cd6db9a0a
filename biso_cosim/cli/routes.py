"""``biso-cosim routes``: list, draw, import and check routes."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("routes", help="list, draw, import and check routes",
                       description="Without a sub-command: list the route library.")
    p.set_defaults(func=list_routes)
    actions = p.add_subparsers(dest="action", metavar="ACTION")

    show = actions.add_parser("show", help="draw a route's map with its elevation and speed profiles")
    show.add_argument("route", help="library name or route file")
    show.add_argument("--out", required=True, help="PNG file")
    show.set_defaults(func=show_route)

    imp = actions.add_parser("import", help="make a route file from a GPX track or a CSV of lat/lon(/alt)(/speed)")
    imp.add_argument("track", help=".gpx or .csv (columns lat_deg, lon_deg, optionally alt_m, speed_mps, t_s)")
    imp.add_argument("--out", required=True, help="route file to write (.toml)")
    imp.add_argument("--name", default=None, help="route name (default: the file name)")
    imp.add_argument("--speed", type=float, default=10.0, metavar="MPS",
                     help="speed where the track has none (no speed column, no time stamps); default 10")
    imp.add_argument("--max-lateral-accel", type=float, default=2.5, metavar="MPS2",
                     help="the driver slows for curves to keep below this; default 2.5")
    imp.set_defaults(func=import_route)

    check = actions.add_parser("check", help="drive whole routes and report tracking and attitude ranges")
    check.add_argument("routes", nargs="*", help="route names or files (default: the whole library)")
    check.add_argument("--out", default=None, help="write the results as JSON here")
    check.set_defaults(func=check_routes)


def list_routes(args: argparse.Namespace) -> int:
    from biso_cosim.routes import load_route, route_names

    print(f"{'route':<14}{'length':>9}{'duration':>10}  description / what it excites")
    for name in route_names():
        r = load_route(name)
        s = r.summary()
        print(f"{name:<14}{s['length_m']:>8.0f}m{s['nominal_duration_s']:>9.0f}s  {r.description}")
        print(f"{'':<35}excites: {r.excites}")
    return 0


def show_route(args: argparse.Namespace) -> int:
    from biso_cosim.routes import load_route
    from biso_cosim.routes.plot import plot_route

    out = plot_route(load_route(args.route), args.out)
    print(f"wrote {out}")
    return 0


def import_route(args: argparse.Namespace) -> int:
    from biso_cosim.routes import parse_route
    from biso_cosim.routes.importing import read_track, track_to_route_data, write_route_file

    data = track_to_route_data(read_track(args.track), name=args.name, speed_mps=args.speed,
                               max_lateral_accel_mps2=args.max_lateral_accel)
    route = parse_route(data, source=args.track)  # validates before writing anything
    out = write_route_file(data, args.out)
    s = route.summary()
    print(f"{route.name}: {s['length_m']:.0f} m, {'closed' if route.closed else 'open'}, about "
          f"{s['nominal_duration_s']:.0f} s, site {route.site.lat_deg:.5f}° {route.site.lon_deg:.5f}°; wrote {out}")
    return 0


def check_routes(args: argparse.Namespace) -> int:
    from biso_cosim.routes import route_names
    from biso_cosim.routes.check import drive_route_check

    names = args.routes or route_names()
    results = []
    print(f"{'route':<14}{'done':>5}{'time s':>8}{'xte max':>8}{'xte rms':>8}{'roll °':>14}{'pitch °':>14}"
          f"{'f_z m/s²':>14}{'sim/wall':>9}")
    for name in names:
        r = drive_route_check(name)
        results.append(r)
        print(f"{r['route']:<14}{'yes' if r['completed'] else 'NO':>5}{r['time_s']:>8.1f}"
              f"{r['cross_track_max_m']:>8.2f}{r['cross_track_rms_m']:>8.3f}"
              f"{r['roll_range_deg'][0]:>7.1f}{r['roll_range_deg'][1]:>7.1f}"
              f"{r['pitch_range_deg'][0]:>7.1f}{r['pitch_range_deg'][1]:>7.1f}"
              f"{r['vertical_specific_force_range_mps2'][0]:>7.1f}{r['vertical_specific_force_range_mps2'][1]:>7.1f}"
              f"{r['sim_seconds_per_wall_second']:>9.1f}", flush=True)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.out}")
    return 0 if all(r["completed"] for r in results) else 1
