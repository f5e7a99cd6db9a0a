"""``biso-cosim estimate``: run an estimator on a recorded sensor log (CSV), SI or raw registers."""

from __future__ import annotations

import argparse
import json
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
            "the options below. On a run's log.csv with its summary.json beside it, every estimator "
            "of the run is repeated bit for bit with what the run fed it: the wheel odometry (odometry_mps), "
            "the GNSS fixes of GNSS-aided estimators (gnss_t_s, gnss_t_arrival_s, gnss_vel_e_mps ... on the "
            "rows where a fix arrives), the gyro increments of a coning-algorithm gyro_step (dtheta1_x_rad ... "
            "or dtheta_sub1_x_rad ...), the declination, the sensor flags (docs/logs.md); a log cut short or "
            "disagreeing with its summary is refused. Writes t_s (if given), q_wb (w, x, y, z, body -> ENU), "
            "roll, pitch, heading in degrees and the per-sample flags."
        ),
    )
    p.add_argument("input", help="sensor log, CSV")
    p.add_argument("--out", required=True, help="output CSV (never the input)")
    p.add_argument("--method", default=None,
                   help="estimator name (default: every estimator of the run when the log has a run's "
                        "summary.json beside it, else biso)")
    p.add_argument("--summary", default=None, metavar="FILE",
                   help="the run's summary.json (default: the one beside the log, if any): the estimators, their "
                        "parameters, the inputs the run fed them and the sample rate are taken from it, and the "
                        "log's row count is checked against it")
    p.add_argument("--no-summary", action="store_true", help="ignore a summary.json beside the log")
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
                    help="column with the forward speed in m/s for estimators that take speed_mps (default: "
                         "the column the run's summary names, else odometry_mps if the log has it)")
    p.set_defaults(func=main)


def sample_rate_from_times(t_s: np.ndarray, path: Path | str = "the log") -> float:
    """The sample rate of uniformly spaced, increasing time stamps; errors name the file and
    the data row (1 = the first after the header) where they are not."""
    dt = np.diff(t_s)
    if t_s.shape[0] < 2:
        raise UserError(f"{path}: t_s: need at least two samples to know the sample rate (or give --fs)")
    bad = np.flatnonzero(~(dt > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise UserError(f"{path}, line {i + 2} (data row {i + 1}): t_s must increase, but t = {float(t_s[i]):g} s follows "
                        f"t = {float(t_s[i - 1]):g} s")
    step = float(np.median(dt))
    off = np.flatnonzero(np.abs(dt - step) > 0.01 * step)
    if off.size:
        i = int(off[0])
        raise UserError(f"{path}, line {i + 3} (data row {i + 2}): t_s must be evenly spaced ({step:.6g} s): the step before it "
                        f"is {float(dt[i]):.6g} s (resample the log, or give --fs to ignore t_s)")
    return 1.0 / step


def _header_columns(path: Path) -> list[str]:
    """Column names of a CSV whose first non-comment line names them."""
    if not path.is_file():
        raise FileNotFoundError(f"input file {str(path)!r} does not exist")
    try:
        with path.open() as handle:
            for line in handle:
                text = line.strip()
                if "\x00" in text:
                    raise UserError(f"{path}: a binary file, not a CSV text file")
                if text and not text.startswith("#"):
                    return [c.strip() for c in text.split(",")]
    except UnicodeDecodeError as exc:
        raise UserError(f"{path}: a binary file, not a CSV text file (a byte of it is not UTF-8)") from None
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


def _read_si(log: "_Log", columns: list[str], speed_column: str | None, method: str, takes: tuple[str, ...]):
    path = log.path
    data = log.sensor()
    inputs = {}
    if "imu_flags" in columns and "imu_flags" in takes:
        inputs["imu_flags"] = _column(path, columns, "imu_flags", "imu_flags")
    if speed_column is not None:
        if "speed_mps" not in takes:
            raise UserError(f"--speed-column: {method} takes no speed input")
        inputs["speed_mps"] = _column(path, columns, speed_column, "--speed-column")
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


def _run_summary(path: Path, args: argparse.Namespace) -> tuple[Path | None, dict | None]:
    """The run's summary.json: --summary, else the one beside the log (a run's output
    directory), else none; a file that is not a run's summary is refused when named."""
    if args.no_summary:
        return None, None
    named = args.summary is not None
    where = Path(args.summary) if named else path.with_name("summary.json")
    if not where.is_file():
        if named:
            raise UserError(f"--summary {str(where)!r} " + ("is a directory" if where.is_dir() else "does not exist")
                            + "; expected a run's summary.json")
        return None, None
    try:
        summary = json.loads(where.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        if named:
            raise UserError(f"--summary {str(where)!r}: not JSON ({exc}); expected a run's summary.json") from None
        return None, None
    if not (isinstance(summary, dict) and isinstance(summary.get("estimators"), dict) and "samples" in summary):
        if named:
            raise UserError(f"--summary {str(where)!r}: not a run's summary.json (no samples, estimators)")
        return None, None
    return where, summary


def _jobs(args: argparse.Namespace, summary: dict | None) -> list[tuple[str, str, dict, dict]]:
    """(label, method, parameters, log columns of the per-sample inputs) of each estimator to
    run: --method, or else every estimator of the run (its summary), or else biso."""
    if args.method is not None or summary is None:
        method = args.method or "biso"
        entry = _summary_entry(summary, method) if summary is not None else None
        return [(method, method, dict(entry["params"]) if entry else {}, _inputs_of(summary, entry))]
    return [(label, entry["method"], dict(entry.get("params") or {}), _inputs_of(summary, label))
            for label, entry in summary["estimators"].items()]


def _summary_entry(summary: dict, method: str):
    """The run's estimator of that name without a label of its own, if any (its inputs are reused)."""
    entry = summary["estimators"].get(method)
    return entry if entry is not None and entry.get("method") == method else None


def _inputs_of(summary: dict | None, label) -> dict:
    if summary is None or label is None:
        return {}
    key = label if isinstance(label, str) else None
    if key is None:  # an entry: find its label
        key = next((k for k, e in summary["estimators"].items() if e is label), None)
    return (summary.get("estimator_inputs") or {}).get(key, {})


def _count_rows(path: Path) -> int:
    """Data rows of a CSV (lines after the header that are neither empty nor comments)."""
    with path.open() as handle:
        lines = (line.strip() for line in handle)
        return sum(1 for line in lines if line and not line.startswith("#")) - 1


class _Log:
    """The columns of one SI log, each read once (the estimators of a run share them)."""

    def __init__(self, path: Path, columns: list[str]):
        self.path, self.columns = path, columns
        self._sensor = None
        self._fixes: Any = False

    def sensor(self) -> dict:
        from biso_cosim.logs import read_sensor_csv

        if self._sensor is None:
            self._sensor = read_sensor_csv(self.path)
        return self._sensor

    def fixes(self):
        """The GNSS fixes of the log's fix columns, or None."""
        from biso_cosim.logs import read_gnss_fixes

        if self._fixes is False:
            self._fixes = read_gnss_fixes(self.path)
        return self._fixes

    def has(self, names) -> bool:
        return all(name in self.columns for name in names)


def _gnss_input(log: _Log, label: str, fed: dict, summary_path: Path | None, several: bool):
    """The fixes a GNSS-aided estimator is fed from the log's fix columns; None (after a
    note) when the log has none: a sensor log, not a run's; "skip" for an estimator of an
    older run whose log holds no fixes. A log whose fixes disagree with its summary is refused."""
    from biso_cosim.logs import GNSS_COLUMNS

    fixes = log.fixes()
    wanted = "gnss" in (fed.get("columns") or {})
    if fixes is None:
        if wanted:
            raise UserError(f"{log.path}: {summary_path} says {label} was fed GNSS fixes from the columns "
                            f"{', '.join(fed['columns']['gnss'])}, which the log does not have")
        if several:
            return "skip"
        print(f"note: {log.path} carries no GNSS fixes (columns {', '.join(GNSS_COLUMNS)}); {label} runs on its "
              "unaided fall-back (docs/gnss.md)")
        return None
    expected = fed.get("gnss_fixes")
    if expected is not None and len(fixes) != expected:
        raise UserError(f"{log.path} holds {len(fixes)} GNSS fixes, but {summary_path} says the run fed {label} "
                        f"{expected}: the log is cut or from another run (give --no-summary to use it anyway)")
    return fixes


def _increments_input(log: _Log, label: str, method: str, form: tuple[str, int], fed: dict,
                      summary_path: Path | None, several: bool):
    """The gyro increments (k, m, 3) a coning-algorithm ``gyro_step`` integrates, from the log
    columns the run's summary names (else those of its form, logs.increment_columns); "skip"
    for an estimator of an older run whose log holds none."""
    from biso_cosim.logs import increment_columns, read_log_columns

    named = (fed.get("columns") or {}).get("dtheta_b")
    names = list(named) if named else list(increment_columns(*form))
    m = form[1]
    if len(names) != 3 * m:
        raise UserError(f"{summary_path}: {label} was fed {len(names)} increment columns, but its gyro_step takes "
                        f"{m} rows of three ({', '.join(increment_columns(*form))})")
    if not log.has(names):
        if several and not named:
            return "skip"
        missing = [n for n in names if n not in log.columns]
        raise UserError(f"{log.path}: {label} ({method}) integrates the gyro increments of its gyro_step, columns "
                        f"{', '.join(missing)}, which the log does not have (a run logs them when one of its "
                        "estimators has such a gyro_step)")
    try:
        values = read_log_columns(log.path, names, f"{label}'s gyro_step")
    except ValueError as exc:
        raise UserError(str(exc)) from None
    return values.reshape(values.shape[0], m, 3)


def main(args: argparse.Namespace) -> int:
    from biso_cosim.estimators import estimate_attitude, estimator_inputs, estimator_names, flags, make_estimator
    from biso_cosim.estimators.rawlog import is_raw_header
    from biso_cosim.logs import ODOMETRY_COLUMN, write_estimates_table
    from biso_cosim.output import check_output_file

    path = Path(args.input)
    if path.is_dir():
        raise UserError(f"input {str(path)!r} is a directory; expected a CSV sensor log")
    if args.method is not None and args.method not in estimator_names():
        raise UserError(f"--method: unknown estimator {args.method!r}; known: {', '.join(estimator_names())}")
    out_path = check_output_file(args.out, inputs=[path])
    if args.fs is not None and not (math.isfinite(args.fs) and 0.1 <= args.fs <= 100_000.0):
        raise UserError(f"--fs must be a sample rate in Hz between 0.1 and 100000, got {args.fs:g}")
    columns = _header_columns(path)
    kind = args.format if args.format != "auto" else ("raw" if is_raw_header(columns) else "si")
    summary_path, summary = _run_summary(path, args) if kind == "si" else (None, None)
    if summary is not None:
        rows = _count_rows(path)
        if rows != summary["samples"]:
            raise UserError(f"{path} has {rows} rows, but {summary_path} says the run logged {summary['samples']} "
                            "samples: the log is cut short or from another run (give --no-summary to use it anyway)")
    jobs = _jobs(args, summary)
    several = len(jobs) > 1
    log = _Log(path, columns)
    estimates, lines = {}, []
    for label, method, params, inputs_of_run in jobs:
        takes = estimator_inputs(method)
        speed_column = args.speed_column
        if speed_column is None and "speed_mps" in takes:
            speed_column = (inputs_of_run.get("columns") or {}).get("speed_mps")
            if speed_column is None and ODOMETRY_COLUMN in columns:
                speed_column = ODOMETRY_COLUMN
        if kind == "raw":
            arrays, t_s, fs_header, inputs, config = _read_raw(path, args)
        else:
            arrays, t_s, fs_header, inputs, config = _read_si(log, columns, speed_column, method, takes)
        if args.fs is not None:
            fs = args.fs
        elif summary is not None:
            fs = float(summary["sensor"]["output_rate_hz"])
        elif fs_header is not None:
            fs = fs_header
        elif t_s is not None:
            fs = sample_rate_from_times(t_s, path)
        else:
            raise UserError(f"{args.input}: no t_s column (nor fs_hz in the header); give the sample rate with --fs")
        params |= {k: tuple(v) if isinstance(v, list) else v
                   for k, v in (inputs_of_run.get("params") or {}).items()}
        params |= parse_params(args.param, "--param")
        if args.declination_deg is not None or "declination_rad" not in params:
            params["declination_rad"] = math.radians(_declination_deg(path, columns, args.declination_deg))
        fed = []
        if "gnss" in takes and kind == "si":
            fixes = _gnss_input(log, label, inputs_of_run, summary_path, several)
            if isinstance(fixes, str):
                print(f"skipped {label}: it was fed GNSS fixes, which this log does not hold")
                continue
            if fixes is not None:
                inputs["gnss"] = fixes
                fed.append(f"{len(fixes)} GNSS fixes from the log")
        form = make_estimator(method, fs, **params).gyro_increments if "dtheta_b" in takes else None
        if form is not None:
            if kind == "raw":
                raise UserError(f"{label} ({method}): gyro_step {params.get('gyro_step')!r} integrates gyro increments, "
                                "which a raw register log does not hold (use gyro_step=hold)")
            dtheta = _increments_input(log, label, method, form, inputs_of_run, summary_path, several)
            if isinstance(dtheta, str):
                print(f"skipped {label}: it was fed the gyro increments of its coning step, which this log does not hold")
                continue
            inputs["dtheta_b"] = dtheta
            fed.append(f"gyro increments ({form[0]}, {form[1]} rows) from the log")
        est = estimate_attitude(*arrays, fs=fs, method=method, full_output=True, **config, **params, **inputs)
        estimates[label] = (est.q_wb, est.flags)
        counts = [f"{name} {int(np.count_nonzero(est.flags & bit))}" for bit, name in flags.NAMES.items()
                  if np.any(est.flags & bit)]
        if "speed_mps" in inputs:
            fed.insert(0, f"speed from {speed_column}")
        lines.append(f"{label} ({method}) on a {kind} log at {fs:g} Hz, {est.q_wb.shape[0]} samples, declination "
                     f"{math.degrees(params['declination_rad']):.2f}°{''.join(', ' + f for f in fed)}; flagged: "
                     f"{', '.join(counts) if counts else 'none'}")
    if not estimates:
        raise UserError(f"{path}: none of the run's estimators can run on this log")
    out = write_estimates_table(out_path, estimates, t_s)
    if summary is not None:
        print(f"inputs from {summary_path}")
    print("\n".join(lines))
    print(f"wrote {out}")
    return 0
