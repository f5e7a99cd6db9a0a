"""``biso-cosim routes``: list, draw, import and check routes.

Every input is checked before any work, and every output before the work that makes it: a
bad file or option is one line naming it (exit code 2). Outputs are written atomically.
Warnings of the route layer (a value capped to the car's limit, a track smoothed further than
asked) are printed as one line each.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import warnings
from pathlib import Path

_PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("routes", help="list, draw, import and check routes",
                       description="Without a sub-command: list the route library.")
    p.set_defaults(func=list_routes)
    actions = p.add_subparsers(dest="action", metavar="ACTION")

    show = actions.add_parser("show", help="draw a route's map with its elevation and speed profiles")
    show.add_argument("route", help="library name or route file")
    show.add_argument("--out", required=True, help="image file (.png, .pdf or .svg)")
    show.set_defaults(func=show_route)

    imp = actions.add_parser(
        "import", help="make a route file from a GPX track or a CSV of lat/lon(/alt)(/speed)(/t_s)",
        description="Make a route from a recorded track: every point checked, stops found from the time "
                    "stamps, positions and heights smoothed (further, with a warning, where the car could "
                    "not drive them), leg speeds from the recording. See docs/routes.md.")
    imp.add_argument("track", help=".gpx or .csv (columns lat_deg, lon_deg, optionally alt_m, speed_mps, t_s)")
    imp.add_argument("--out", required=True, help="route file to write (.toml; never the input)")
    imp.add_argument("--name", default=None, help="route name (default: the file name)")
    imp.add_argument("--speed", type=float, default=10.0, metavar="MPS",
                     help="speed where the track has none (no speed column, no time stamps); default 10")
    imp.add_argument("--max-lateral-accel", type=float, default=2.5, metavar="MPS2",
                     help="the driver slows for curves to keep below this; default 2.5")
    imp.add_argument("--smoothing", type=float, default=15.0, metavar="M",
                     help="positions' smoothing: the wavelength halved in amplitude; default 15")
    imp.add_argument("--height-smoothing", type=float, default=200.0, metavar="M",
                     help="heights' smoothing (GNSS heights scatter by metres); default 200")
    imp.add_argument("--min-stop", type=float, default=2.0, metavar="S",
                     help="standing this long or longer is a stop of the route; default 2")
    imp.add_argument("--flat", action="store_true", help="ignore the track's heights: a flat route")
    imp.add_argument("--max-length-km", type=float, default=200.0, metavar="KM",
                     help="refuse longer tracks; default 200")
    imp.add_argument("--max-file-mb", type=float, default=200.0, metavar="MB",
                     help="refuse larger files; default 200")
    imp.add_argument("--no-progress", action="store_true", help="no progress bar")
    imp.set_defaults(func=import_route)

    check = actions.add_parser("check", help="drive whole routes and report tracking and attitude ranges")
    check.add_argument("routes", nargs="*", help="route names or files (default: the whole library)")
    check.add_argument("--out", default=None, help="write the results as JSON here (.json)")
    check.set_defaults(func=check_routes)


@contextlib.contextmanager
def _route_warnings(command: str):
    """Route warnings as one line each on stderr (not Python's two-line warning format)."""
    from biso_cosim.routes import RouteWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RouteWarning)
        try:
            yield
        finally:
            for w in caught:
                if issubclass(w.category, RouteWarning):
                    print(f"biso-cosim {command}: warning: {w.message}", file=sys.stderr)
                else:
                    warnings.showwarning(w.message, w.category, w.filename, w.lineno)


def _route(name: str):
    from biso_cosim.routes import load_route

    return load_route(name)


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
    from biso_cosim.output import check_output_file

    inputs = [args.route] if Path(args.route).exists() else []
    out = check_output_file(args.out, suffixes=_PLOT_SUFFIXES, inputs=inputs)
    with _route_warnings("routes show"):
        route = _route(args.route)
    from biso_cosim.routes.plot import plot_route

    args.running = True
    print(f"wrote {plot_route(route, out)}")
    return 0


class _Bar:
    """The import's progress on a tqdm bar (in percent, with the stage as its label); shown
    when stderr is a terminal."""

    def __init__(self, enabled: bool):
        from tqdm import tqdm

        self.bar = tqdm(total=100, unit="%", bar_format="{desc:<22}{percentage:3.0f}%|{bar}| {elapsed}",
                        disable=None if enabled else True, file=sys.stderr, leave=False)

    def __call__(self, fraction: float, stage: str) -> None:
        self.bar.set_description_str(stage, refresh=False)
        self.bar.update(max(int(round(100 * fraction)) - self.bar.n, 0))

    def close(self) -> None:
        self.bar.close()


def import_route(args: argparse.Namespace) -> int:
    from biso_cosim.routes import parse_route
    from biso_cosim.output import check_output_file
    from biso_cosim.routes.importing import convert_track, read_track, write_route_file
    from biso_cosim.routes.tracks import check_track_file

    track_path = Path(args.track)
    if track_path.is_dir():
        raise ValueError(f"{args.track} is a directory; expected a .gpx or .csv track file")
    out = check_output_file(args.out, suffixes=(".toml",), inputs=[args.track])
    check_track_file(track_path, args.max_file_mb)
    bar = _Bar(not args.no_progress)
    try:
        with _route_warnings("routes import"):
            track = read_track(track_path, max_file_mb=args.max_file_mb,
                               progress=lambda fraction: bar(0.5 * fraction, "reading the track"))
            if args.flat:
                from dataclasses import replace

                track = replace(track, alt_m=None)
            result = convert_track(track, name=args.name, speed_mps=args.speed,
                                   max_lateral_accel_mps2=args.max_lateral_accel, smoothing_m=args.smoothing,
                                   height_smoothing_m=args.height_smoothing, min_stop_s=args.min_stop,
                                   max_length_km=args.max_length_km,
                                   progress=lambda fraction, stage: bar(0.5 + 0.5 * fraction, stage))
            route = parse_route(result.data, source=args.track)  # validates before writing anything
            bar(1.0, "done")
    finally:
        bar.close()
    args.running = True
    write_route_file(result.data, out)
    s = route.summary()
    dropped = result.points_read - result.points_used
    print(f"{route.name}: {s['length_m'] / 1000:.2f} km, {'closed' if route.closed else 'open'}, "
          f"{s['stops']} stop(s), about {s['nominal_duration_s']:.0f} s; {result.points_used} of "
          f"{result.points_read} points used ({dropped} repeated or standing); smoothed over "
          f"{result.smoothing_m:g} m" + (f" (heights {result.height_smoothing_m:g} m)"
                                         if result.height_smoothing_m else " (no heights)")
          + f"; site {route.site.lat_deg:.5f}° {route.site.lon_deg:.5f}°; wrote {out}")
    return 0


def check_routes(args: argparse.Namespace) -> int:
    from biso_cosim.routes import route_names
    from biso_cosim.routes.check import drive_route_check
    from biso_cosim.output import atomic_output, check_output_file

    names = args.routes or route_names()
    out = check_output_file(args.out, suffixes=(".json",), inputs=[n for n in names if Path(n).exists()]) \
        if args.out else None
    with _route_warnings("routes check"):
        routes = [_route(name) for name in names]  # every route checked before the first drive
    args.running = True
    results = []
    print(f"{'route':<14}{'done':>5}{'time s':>8}{'xte max':>8}{'xte rms':>8}{'roll °':>14}{'pitch °':>14}"
          f"{'f_z m/s²':>14}{'sim/wall':>9}")
    for route in routes:
        r = drive_route_check(route)
        results.append(r)
        print(f"{r['route']:<14}{'yes' if r['completed'] else 'NO':>5}{r['time_s']:>8.1f}"
              f"{r['cross_track_max_m']:>8.2f}{r['cross_track_rms_m']:>8.3f}"
              f"{r['roll_range_deg'][0]:>7.1f}{r['roll_range_deg'][1]:>7.1f}"
              f"{r['pitch_range_deg'][0]:>7.1f}{r['pitch_range_deg'][1]:>7.1f}"
              f"{r['vertical_specific_force_range_mps2'][0]:>7.1f}{r['vertical_specific_force_range_mps2'][1]:>7.1f}"
              f"{r['sim_seconds_per_wall_second']:>9.1f}", flush=True)
    if out is not None:
        with atomic_output(out) as temporary:
            temporary.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {out}")
    return 0 if all(r["completed"] for r in results) else 1
