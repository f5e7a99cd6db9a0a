"""Speed of ``biso-cosim routes import`` on a long 10 Hz track (issue 19's goal: a 50 km track
at 10 Hz within 10 s on 2 cores).

    python benchmarks/route_import.py [--km 50] [--rate 10] [--kind mountain] [--repeat 3]

Makes a recorded-like track (biso_cosim.routes.synthetic, seed 0: receiver noise, lost fixes,
dropouts) and writes it as GPX, then times, best of ``--repeat``:

* reading the GPX alone (the baseline: what any import must pay to see the points);
* the whole import as ``routes import`` does it (read, check, stops, smoothing, waypoints,
  speeds, the route's own checks, its nominal duration, the TOML written), in this process
  after one warm-up run (numba's kernels are cached on disk, as for the command).

Prints both with the ratio import / reading, each stage's share, the process's CPU time (on a
shared machine the wall time includes waiting for a core) and the absolute time against the
10 s goal.
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

from biso_cosim.routes import RouteWarning, parse_route
from biso_cosim.routes.importing import convert_track, write_route_file
from biso_cosim.routes.synthetic import ROAD_KINDS, synthetic_track, write_gpx
from biso_cosim.routes.tracks import read_track

GOAL_S = 10.0


def import_once(gpx: Path, out: Path) -> dict[str, float]:
    """One import as the command runs it, with the time of each stage."""
    times = {}
    cpu = time.process_time()
    start = time.perf_counter()
    track = read_track(gpx)
    times["read"] = time.perf_counter() - start
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RouteWarning)
        mark = time.perf_counter()
        result = convert_track(track)
        times["convert"] = time.perf_counter() - mark
        mark = time.perf_counter()
        route = parse_route(result.data, source=str(gpx))
        route.nominal_duration_s  # noqa: B018 -- the command prints it
        times["route checks"] = time.perf_counter() - mark
    mark = time.perf_counter()
    write_route_file(result.data, out)
    times["write"] = time.perf_counter() - mark
    times["total"] = time.perf_counter() - start
    times["cpu"] = time.process_time() - cpu
    times["points"] = len(track)
    times["waypoints"] = len(result.data["waypoint"])
    times["length_m"] = route.path.length_m
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--km", type=float, default=50.0)
    parser.add_argument("--rate", type=float, default=10.0, help="fixes per second")
    parser.add_argument("--kind", choices=ROAD_KINDS, default="mountain")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as folder:
        gpx = write_gpx(synthetic_track(args.kind, length_m=args.km * 1000.0, rate_hz=args.rate, seed=0,
                                        dropouts=5).track, Path(folder) / "long.gpx")
        size_mb = gpx.stat().st_size / 1e6
        out = Path(folder) / "long.toml"
        import_once(gpx, out)  # warm-up
        reads, runs = [], []
        for _ in range(args.repeat):
            start = time.perf_counter()
            read_track(gpx)
            reads.append(time.perf_counter() - start)
            runs.append(import_once(gpx, out))
    best = min(runs, key=lambda r: r["total"])
    read_s = min(reads)
    print(f"track: {args.kind}, {best['length_m'] / 1000:.1f} km, {best['points']} fixes at {args.rate:g} Hz, "
          f"GPX {size_mb:.1f} MB -> {best['waypoints']} waypoints")
    print(f"reading the GPX alone: {read_s:.2f} s (best of {args.repeat})")
    print(f"whole import:          {best['total']:.2f} s = {best['total'] / read_s:.1f} x reading "
          f"(CPU time of this process {best['cpu']:.2f} s: the wall time is longer when others share the cores)")
    for stage in ("read", "convert", "route checks", "write"):
        print(f"  {stage:<14} {best[stage]:6.2f} s  ({best[stage] / best['total']:.0%})")
    verdict = "within" if best["total"] <= GOAL_S else "OVER"
    print(f"goal: a 50 km 10 Hz track in {GOAL_S:g} s -> {best['total']:.2f} s, {verdict} the goal "
          f"({best['total'] / GOAL_S:.0%} of it)")


if __name__ == "__main__":
    main()
