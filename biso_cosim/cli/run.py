"""``biso-cosim run``: drive a route with the estimators in the loop; print and write the results."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from biso_cosim.cli import UserError, estimator_spec

BASELINE = "poisson"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="drive a route with the virtual MPU-9250 and estimators in the loop",
        description=(
            "Drive a route with the scripted driver; the virtual MPU-9250 feeds the estimators in "
            "the loop. Prints RMS and largest errors of roll, pitch and heading per estimator and, "
            "on closed routes driven to the end, the start-to-end difference of each angle. Writes "
            "OUT/summary.json, OUT/log.csv and OUT/attitude.png. Exit codes: 0 the run drove its "
            "route (or the part --duration asked for), 2 bad input, 3 the run failed (status and reason "
            "first on screen and in summary.json; see --allow-incomplete), 130 interrupted by Ctrl-C "
            "(what was simulated is written)."
        ),
    )
    p.add_argument("--route", default="loop600", help="library route name or route file (.toml); default loop600")
    p.add_argument("--duration", type=float, default=None, metavar="S",
                   help="simulated seconds (default: the route's nominal duration + 10 s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor errors (default 0)")
    p.add_argument("--estimator", action="append", metavar="[LABEL=]NAME[:P=V,...]",
                   help="estimator to run (repeatable), optionally with parameters and a label, e.g. "
                        "biso:cutoff_hz=5 or inv=poisson:gyro_step=invariant; default: biso (the paper's) "
                        "and biso_plus (its vehicle variant, with wheel odometry). The uncorrected "
                        f"integration '{BASELINE}' runs too, as the baseline, unless --no-baseline")
    p.add_argument("--no-baseline", action="store_true", help=f"do not add the '{BASELINE}' baseline")
    p.add_argument("--sensor-profile", default=None, metavar="NAME|FILE",
                   help="MPU-9250 profile: mpu9250_calibrated (default: the chip after the usual start-up "
                        "calibration), mpu9250 (raw, datasheet tolerances), ideal, or a profile file")
    p.add_argument("--gyro-calibration", type=float, default=0.0, metavar="S",
                   help="average the gyro at rest for S seconds before the start and subtract it, as a "
                        "driver does at start-up (for the raw mpu9250 profile); default 0")
    p.add_argument("--navigator", action="append", default=[], metavar="NAME",
                   help="also run a dead-reckoning navigator from the true initial state (repeatable): "
                        "one_sample, two_sample, smoothing, invariant (Litmanovich 2002 families); writes "
                        "OUT/navigation.png")
    p.add_argument("--out", default=None, metavar="DIR", help="output directory (default out/<route>)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-log", action="store_true", help="skip log.csv (large for long routes)")
    p.add_argument("--allow-incomplete", action="store_true",
                   help="exit 0 even when the run failed (the car left the route, rolled over, got stuck or did "
                        "not finish; summary.json's status says which): without it such a run exits 3")
    p.set_defaults(func=main)


def _format_table(summary: dict) -> str:
    w = max([14] + [len(key) + 1 for key in summary["estimators"]])  # the name column fits every label
    rows = []
    head = f"{'estimator':<{w}}" + "".join(f"{h:>26}" for h in ("RMS error (°)", "max |error| (°)"))
    has_closure = summary["truth_start_end_deg"] is not None
    if has_closure:
        head += f"{'start-to-end (°)':>26}"
    rows.append(head)
    sub = f"{'':<{w}}" + ("    roll   pitch heading  " * (3 if has_closure else 2))
    rows.append(sub.rstrip())
    if has_closure:
        t = summary["truth_start_end_deg"]
        rows.append(f"{'truth':<{w}}" + " " * 52 + f"{t['roll']:8.3f}{t['pitch']:8.3f}{t['heading']:8.3f}")
    for key, entry in summary["estimators"].items():
        e = entry["errors"]
        line = f"{key:<{w}}"
        line += "".join(f"{e[a]['rms_deg']:8.3f}" for a in ("roll", "pitch", "heading")) + "  "
        line += "".join(f"{e[a]['max_abs_deg']:8.3f}" for a in ("roll", "pitch", "heading")) + "  "
        if has_closure:
            d = entry["start_end_deg"]
            line += "".join(f"{d[a]:8.3f}" for a in ("roll", "pitch", "heading"))
        rows.append(line.rstrip())
    return "\n".join(rows)


def print_summary(summary: dict) -> None:
    r = summary["route"]
    s = summary["sensor"]
    site = summary["site"]
    speed = summary["sim_seconds_per_wall_second"]
    print(f"route {r['name']}: {r['length_m']:.0f} m, {'closed' if r['closed'] else 'open'}, "
          f"nominal {r['nominal_duration_s']:.0f} s; simulated {summary['duration_s']:.0f} s "
          f"({'route completed' if summary['completed_route'] else 'route NOT completed'}), seed {summary['seed']}")
    print(f"MPU-9250 '{s['profile']}' at {s['output_rate_hz']:g} Hz, AK8963 at {s['mag_rate_hz']:g} Hz; "
          f"site {site['lat_deg']:.2f}° N {site['lon_deg']:.2f}° E, declination {site['declination_deg']:.2f}°")
    print(f"wall time {summary['wall_time_s']:.1f} s: {speed:.1f} simulated seconds per wall second; "
          f"driver cross-track RMS {summary['cross_track_rms_m']:.3f} m")
    print(_format_table(summary))
    if summary.get("navigators"):
        print(f"{'navigator':<14}{'attitude RMS °':>16}{'end °':>8}{'horizontal end m':>18}{'vertical end m':>16}"
              f"{'velocity RMS m/s':>18}")
        for key, e in summary["navigators"].items():
            print(f"{key:<14}{e['attitude_rms_deg']:>16.4f}{e['attitude_end_deg']:>8.4f}"
                  f"{e['horizontal_position_end_m']:>18.3f}{e['vertical_position_end_m']:>16.3f}"
                  f"{e['velocity_rms_mps']:>18.4f}")
    if summary["truth_start_end_deg"] is None:
        print("(no start-to-end differences: the route is open or was not driven to its end)")
    else:
        print("start-to-end: angle at the end (car at rest at the finish) minus angle at the start (at rest, "
              "before driving off), each averaged over 1 s")


def _output_files(args: argparse.Namespace, out: Path, inputs: list[str]) -> None:
    """--out checked before any work: a directory that can be written in, and none of the
    files the run writes there an input."""
    from biso_cosim.output import check_output_dir, check_output_file

    check_output_dir(out, inputs=inputs)
    for name in ("summary.json", "log.csv", "attitude.png", "navigation.png"):
        check_output_file(out / name, inputs=inputs)


def main(args: argparse.Namespace) -> int:
    from biso_cosim.compiling import compile_notice
    from biso_cosim.cosim import DEFAULT_ESTIMATORS, DEFAULT_SENSOR_PROFILE, CoSimulation
    from biso_cosim.logs import run_log_inputs
    from biso_cosim.routes import load_route
    from biso_cosim.runstatus import EXIT_INTERRUPTED, EXIT_RUN_FAILED, interrupted, judge_run

    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise UserError(f"--duration must be a positive number of seconds, got {args.duration}")
    if args.seed < 0:
        raise UserError(f"--seed must be >= 0, got {args.seed}")
    route = load_route(args.route)
    specs = [estimator_spec(s) for s in dict.fromkeys(args.estimator or
                                                       [n for n in DEFAULT_ESTIMATORS if n != BASELINE])]
    if not args.no_baseline and BASELINE not in {s.key for s in specs}:
        specs.append(estimator_spec(BASELINE))
    out = Path(args.out or Path("out") / route.name)
    inputs = [p for p in (args.route, args.sensor_profile) if p and Path(p).exists()]
    _output_files(args, out, inputs)
    sim = CoSimulation(route, duration_s=args.duration, seed=args.seed, estimators=specs,
                       sensor_profile=args.sensor_profile or DEFAULT_SENSOR_PROFILE,
                       gyro_calibration_s=args.gyro_calibration, navigators=args.navigator)
    args.running = True  # from here on an exception is not an input problem (see cli.main)
    notice = compile_notice()
    if notice:
        print(notice, file=sys.stderr, flush=True)
    result = sim.run(progress=not args.no_progress, stop_on_interrupt=True)
    if len(result.truth) == 0:
        print("biso-cosim run: interrupted before the first sample; nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    status = interrupted(result) if result.interrupted else judge_run(result)
    summary = result.summary()
    summary.update(status.as_dict())
    fed = run_log_inputs(sim, result)  # what the run fed its estimators: the log's columns, the summary's record
    summary["estimator_inputs"] = fed.estimators
    _print_status(status, args)
    print_summary(summary)
    written = _write_outputs(fed, result, summary, out, args)
    if written is None:
        return EXIT_INTERRUPTED
    print("wrote " + ", ".join(str(p) for p in written))
    if status.status == "interrupted":
        return EXIT_INTERRUPTED
    if status.failed and not args.allow_incomplete:
        return EXIT_RUN_FAILED
    return 0


def _print_status(status, args: argparse.Namespace) -> None:
    """The run's status, first: a failed run in capitals, so that no one reads its table as a result."""
    if status.failed:
        accepted = " (accepted: --allow-incomplete)" if args.allow_incomplete else ""
        print(f"RUN FAILED: {status.status}: {status.reason}{accepted}; the errors below describe a car that did "
              "not drive its route")
    elif status.status == "interrupted":
        print(f"RUN INTERRUPTED: {status.reason}; writing what was simulated")
    else:
        print(f"run {status.status}: {status.reason}")


def _write_outputs(fed, result, summary: dict, out: Path, args: argparse.Namespace) -> list[Path] | None:
    """summary.json, log.csv and the plots, each whole or not at all; None when Ctrl-C cut
    the writing short (the files written so far are whole)."""
    from biso_cosim.logs import write_run_log
    from biso_cosim.output import write_text_atomic
    from biso_cosim.plotting import plot_navigation, plot_run

    written: list[Path] = []
    try:
        if not args.no_log:  # the log before the summary that counts its rows
            written.append(write_run_log(result, out / "log.csv", fed))
        written.append(write_text_atomic(out / "summary.json", json.dumps(summary, indent=2, default=str) + "\n"))
        written.append(plot_run(result, out / "attitude.png"))
        if result.navigation:
            written.append(plot_navigation(result, out / "navigation.png"))
    except KeyboardInterrupt:
        print("biso-cosim run: interrupted while writing; whole files written: "
              + (", ".join(str(p) for p in written) or "none"), file=sys.stderr)
        return None
    return written
