"""``biso-cosim estimate``: run an estimator on a recorded sensor log (CSV), SI or raw registers."""

from __future__ import annotations

import argparse
import ast
import math
from pathlib import Path
from typing import Any

import numpy as np

from biso_cosim.cli import UserError, parse_params


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "estimate",
        help="estimate attitude from a sensor log (CSV: SI readings or raw MPU-9250 registers)",
        description=(
            "Estimate attitude from a CSV log. SI logs: gyro (rad/s), accelerometer (m/s²) and "
            "magnetometer (µT) in body axes (x forward, y left, z up), columns gyro_x_rad_s, "
            "gyro_y_rad_s, gyro_z_rad_s, accel_x_m_s2, accel_y_m_s2, accel_z_m_s2, mag_x_ut, mag_y_ut, "
            "mag_z_ut, optionally t_s and imu_flags (the sensor's flag bits: saturation, AK8963 "
            "overflow), as in a run's log.csv. Raw logs: the MPU-9250 and AK8963 16-bit words "
            "accel_x_raw ... mag_z_raw and the status bytes ak_st1, ak_st2 (docs/estimators.md), with "
            "the register configuration, ASA bytes and mounting in '# key = value' header lines or "
            "the options below. Writes t_s (if given), q_wb (w, x, y, z, body -> ENU), roll, pitch, "
            "heading in degrees and the per-sample flags."
        ),
    )
    p.add_argument("input", help="sensor log, CSV")
    p.add_argument("--out", required=True, help="output CSV")
    p.add_argument("--method", default="biso", help="estimator name (default biso)")
    p.add_argument("--fs", type=float, default=None, metavar="HZ",
                   help="sample rate; default from the header (raw logs) or the t_s column")
    p.add_argument("--declination-deg", type=float, default=None,
                   help="magnetic declination at the site, east positive (default: the log's "
                        "declination_deg column, as in a run's log.csv, else 0)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="estimator parameter, e.g. --param cutoff_hz=5 or --param reference=euler (repeatable)")
    p.add_argument("--format", choices=("auto", "si", "raw"), default="auto",
                   help="log format (default auto: raw if the raw columns are present)")
    raw = p.add_argument_group("raw logs (override the header)")
    raw.add_argument("--gyro-fs-sel", type=int, choices=range(4), default=None,
                     help="GYRO_FS_SEL: 0..3 for ±250/500/1000/2000 °/s (default 0)")
    raw.add_argument("--accel-fs-sel", type=int, choices=range(4), default=None,
                     help="ACCEL_FS_SEL: 0..3 for ±2/4/8/16 g (default 1)")
    raw.add_argument("--mag-bits", type=int, choices=(14, 16), default=None,
                     help="AK8963 output resolution (default: from ST2.BITM)")
    raw.add_argument("--asa", default=None, metavar="X,Y,Z", help="AK8963 fuse-ROM ASA bytes (default 128,128,128)")
    raw.add_argument("--mounting", default=None, metavar="W,X,Y,Z",
                     help="rotation chip -> body: q_body_chip, or 9 numbers row by row (default identity)")
    si = p.add_argument_group("SI logs")
    si.add_argument("--speed-column", default=None, metavar="NAME",
                    help="column with the forward speed in m/s for estimators that take speed_mps "
                         "(e.g. speed_mps of a run's log)")
    p.set_defaults(func=main)


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


def _header_columns(path: Path) -> list[str]:
    """Column names of a CSV whose first non-comment line names them."""
    if not path.is_file():
        raise FileNotFoundError(f"input file {str(path)!r} does not exist")
    with path.open() as handle:
        for line in handle:
            text = line.strip()
            if text and not text.startswith("#"):
                return [c.strip() for c in text.split(",")]
    raise UserError(f"{path}: the file is empty")


def _column(path: Path, columns: list[str], name: str, option: str) -> np.ndarray:
    if name not in columns:
        raise UserError(f"{option}: {path} has no column {name!r}")
    return np.atleast_1d(np.loadtxt(path, delimiter=",", skiprows=1, usecols=columns.index(name), comments="#"))


def _declination_deg(path: Path, columns: list[str], option: float | None) -> float:
    """--declination-deg, else the log's ``declination_deg`` column (one value), else 0."""
    if option is not None:
        if not math.isfinite(option):
            raise UserError(f"--declination-deg must be finite, got {option}")
        return option
    if "declination_deg" not in columns:
        return 0.0
    values = _column(path, columns, "declination_deg", "declination_deg")
    if not (np.all(np.isfinite(values)) and np.all(values == values[0])):
        raise UserError(f"{path}: the declination_deg column must hold one finite value in every row "
                        "(or give --declination-deg)")
    return float(values[0])


def _read_si(path: Path, columns: list[str], args: argparse.Namespace, takes: tuple[str, ...]):
    from biso_cosim.logs import read_sensor_csv

    data = read_sensor_csv(path)
    inputs = {}
    if "imu_flags" in columns and "imu_flags" in takes:
        inputs["imu_flags"] = _column(path, columns, "imu_flags", "imu_flags")
    if args.speed_column is not None:
        if "speed_mps" not in takes:
            raise UserError(f"--speed-column: {args.method} takes no speed input")
        inputs["speed_mps"] = _column(path, columns, args.speed_column, "--speed-column")
    return (data["gyro"], data["accel"], data["mag"]), data["t_s"], None, inputs, {}


def _read_raw(path: Path, args: argparse.Namespace):
    from biso_cosim.estimators.rawlog import parse_header_value, read_raw_csv

    log = read_raw_csv(path)
    registers = dict(log.registers)
    if args.gyro_fs_sel is not None:
        registers["gyro_fs_sel"] = args.gyro_fs_sel
    if args.accel_fs_sel is not None:
        registers["accel_fs_sel"] = args.accel_fs_sel
    if args.mag_bits is not None:
        registers["mag_bit16"] = args.mag_bits == 16
    asa = log.asa if args.asa is None else parse_header_value("asa", args.asa, "--asa")
    mounting = log.mounting if args.mounting is None else parse_header_value("mounting", args.mounting, "--mounting")
    config = {"registers": registers, "asa": asa, "mounting": mounting}
    return (log.raw,), log.t_s, log.fs_hz, {}, config


def main(args: argparse.Namespace) -> int:
    from biso_cosim.estimators import estimate_attitude, estimator_inputs, flags
    from biso_cosim.estimators.rawlog import is_raw_header
    from biso_cosim.logs import write_estimates_csv

    path = Path(args.input)
    columns = _header_columns(path)
    kind = args.format if args.format != "auto" else ("raw" if is_raw_header(columns) else "si")
    takes = estimator_inputs(args.method)
    if kind == "raw":
        arrays, t_s, fs_header, inputs, config = _read_raw(path, args)
    else:
        arrays, t_s, fs_header, inputs, config = _read_si(path, columns, args, takes)
    if args.fs is not None:
        if not (math.isfinite(args.fs) and args.fs > 0):
            raise UserError(f"--fs must be a positive sample rate in Hz, got {args.fs}")
        fs = args.fs
    elif fs_header is not None:
        fs = fs_header
    elif t_s is not None:
        fs = sample_rate_from_times(t_s)
    else:
        raise UserError(f"{args.input}: no t_s column (nor fs_hz in the header); give the sample rate with --fs")
    params = parse_params(args.param, "--param")
    declination_deg = _declination_deg(path, columns, args.declination_deg)
    params.setdefault("declination_rad", math.radians(declination_deg))
    if "gnss" in takes:
        print(f"note: a sensor log carries no GNSS fixes; {args.method} runs on its unaided fall-back "
              "(docs/gnss.md); use the Python API with GnssFixes for GNSS aiding")
    est = estimate_attitude(*arrays, fs=fs, method=args.method, full_output=True, **config, **params, **inputs)
    q, out_flags = est.q_wb, est.flags
    out = write_estimates_csv(Path(args.out), q, out_flags, t_s, prefix=args.method)
    counts = [f"{name} {int(np.count_nonzero(out_flags & bit))}" for bit, name in flags.NAMES.items()
              if np.any(out_flags & bit)]
    print(f"{args.method} on a {kind} log at {fs:g} Hz, {q.shape[0]} samples, declination "
          f"{math.degrees(params['declination_rad']):.2f}°; flagged: "
          f"{', '.join(counts) if counts else 'none'}; wrote {out}")
    return 0
