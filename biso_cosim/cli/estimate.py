"""``biso-cosim estimate``: run an estimator on a recorded sensor log (CSV)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from biso_cosim.cli import UserError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "estimate",
        help="estimate attitude from a sensor log (CSV)",
        description=(
            "Estimate attitude from a CSV of gyro (rad/s), accelerometer (m/s²) and magnetometer (µT) "
            "samples in body axes (x forward, y left, z up), columns gyro_x_rad_s, gyro_y_rad_s, "
            "gyro_z_rad_s, accel_x_m_s2, accel_y_m_s2, accel_z_m_s2, mag_x_ut, mag_y_ut, mag_z_ut and "
            "optionally t_s (the sensor columns of a run's log.csv). Writes t_s (if given), q_wb "
            "(w, x, y, z, body -> ENU), roll, pitch, heading in degrees and the flags."
        ),
    )
    p.add_argument("input", help="sensor log, CSV")
    p.add_argument("--out", required=True, help="output CSV")
    p.add_argument("--method", default="biso", help="estimator name (default biso)")
    p.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="sample rate; default from the t_s column (required without it)")
    p.add_argument("--declination-deg", type=float, default=0.0,
                   help="magnetic declination at the site, east positive (default 0)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="estimator parameter, e.g. --param cutoff_hz=5 (repeatable)")
    p.set_defaults(func=main)


def _parse_params(items: list[str]) -> dict[str, float]:
    params = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise UserError(f"--param expects NAME=VALUE, got {item!r}")
        try:
            params[name.strip()] = float(value)
        except ValueError:
            raise UserError(f"--param {name}: expected a number, got {value!r}") from None
    return params


def sample_rate_from_times(t_s: np.ndarray) -> float:
    """The sample rate of uniformly spaced, increasing time stamps; errors say where they are not."""
    dt = np.diff(t_s)
    if t_s.shape[0] < 2:
        raise UserError("t_s: need at least two samples to know the sample rate (or give --fs)")
    bad = np.flatnonzero(~(dt > 0))
    if bad.size:
        raise UserError(f"t_s must increase: sample {bad[0] + 1} (t = {t_s[bad[0] + 1]!r}) does not")
    step = float(np.median(dt))
    off = np.flatnonzero(np.abs(dt - step) > 0.01 * step)
    if off.size:
        raise UserError(f"t_s must be evenly spaced ({step:.6g} s): the step after sample {off[0]} is "
                        f"{dt[off[0]]:.6g} s (resample the log, or give --fs to ignore t_s)")
    return 1.0 / step


def main(args: argparse.Namespace) -> int:
    from biso_cosim.estimators import estimate_attitude
    from biso_cosim.logs import read_sensor_csv, write_estimates_csv

    data = read_sensor_csv(args.input)
    if args.fs is not None:
        if not (math.isfinite(args.fs) and args.fs > 0):
            raise UserError(f"--fs must be a positive sample rate in Hz, got {args.fs}")
        fs = args.fs
    elif data["t_s"] is not None:
        fs = sample_rate_from_times(data["t_s"])
    else:
        raise UserError(f"{args.input}: no t_s column; give the sample rate with --fs")
    params = _parse_params(args.param)
    params.setdefault("declination_rad", math.radians(args.declination_deg))
    est = estimate_attitude(data["gyro"], data["accel"], data["mag"], fs, method=args.method,
                            full_output=True, **params)
    q, flags = est.q_wb, est.flags
    out = write_estimates_csv(Path(args.out), q, flags, data["t_s"], prefix=args.method)
    print(f"{args.method} at {fs:g} Hz on {q.shape[0]} samples; flagged {int(np.count_nonzero(flags))}; wrote {out}")
    return 0
