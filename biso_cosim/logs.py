"""The run log (``log.csv``), what a run fed its estimators, and the columns that
``biso-cosim estimate`` reads back to repeat them.

One row per sensor output sample: the time, the truth (attitude, IMU position, speed), the
sensor readings (body axes: x forward, y left, z up), what the estimators were fed besides
the readings, and each estimator's ``q_wb``, angles and flags. The columns, their units and
when each appears are in docs/logs.md (tested against what this module writes). What an
estimator reads is written with 17 significant digits: read back, it is the same double,
so that ``biso-cosim estimate`` on the log repeats the run's estimates exactly. The columns
only some runs need appear only in those runs' logs:

* ``odometry_mps``: the wheel odometry, with an estimator that takes ``speed_mps``;
* the gyro increments of a coning-algorithm ``gyro_step`` (Litmanovich 2002; docs/design.md
  §7): ``dtheta<j>_<axis>_rad[_s<j-1>]``, the j-fold integrals ΔΘ^j, or
  ``dtheta_sub<j>_<axis>_rad``, the sub-interval increments (:func:`increment_columns`);
* the receiver's fixes (:data:`GNSS_COLUMNS`), with a GNSS receiver: each fix on the row of
  the first sample at or after its arrival, where an estimator uses it, empty cells on the
  other rows (the rare second fix of one sample interval, from a receiver faster than the
  sensor, takes the next row: the fix's own ``gnss_t_arrival_s`` is what counts); fixes
  that arrive after the last sample were never used and are not logged.

The sensor columns are also the input format of ``biso-cosim estimate`` for any recording
(``t_s``, ``imu_flags`` and ``declination_deg`` optional there).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from biso_cosim.metrics import attitude_angles_deg
from biso_cosim.output import atomic_output

__all__ = ["SENSOR_COLUMNS", "GNSS_COLUMNS", "ODOMETRY_COLUMN", "RunLogInputs", "increment_columns",
           "run_log_inputs", "write_run_log", "read_sensor_csv", "read_log_columns", "read_gnss_fixes", "write_estimates_csv",
           "write_estimates_table"]

# what the estimators were fed is written with 17 significant digits: read back, it is the
# same double, so that ``biso-cosim estimate`` on the log repeats the run's estimates exactly
_EXACT = "%.17g"

SENSOR_COLUMNS = {
    "gyro": ("gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s"),
    "accel": ("accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2"),
    "mag": ("mag_x_ut", "mag_y_ut", "mag_z_ut"),
}

ODOMETRY_COLUMN = "odometry_mps"
"""The wheel odometry fed to the estimators that take ``speed_mps``."""

GNSS_COLUMNS = ("gnss_t_s", "gnss_t_arrival_s", "gnss_pos_e_m", "gnss_pos_n_m", "gnss_pos_u_m", "gnss_vel_e_mps",
                "gnss_vel_n_mps", "gnss_vel_u_mps", "gnss_valid")
"""The receiver's fix columns (filled on the rows where a fix arrives, empty elsewhere)."""
# the times and velocities are what the GNSS-aided estimators read: exact; the position is for the reader
_GNSS_FORMATS = (_EXACT, _EXACT, "%.4f", "%.4f", "%.4f", _EXACT, _EXACT, _EXACT, "%d")


def increment_columns(form: str, m: int) -> tuple[str, ...]:
    """Log columns of the gyro increments a coning-algorithm ``gyro_step`` takes, in the
    order of its (m, 3) input ``dtheta_b``: ``form`` "multiple", the j-fold integrals ΔΘ^j
    (j = 1…m; rad·s^(j−1)): ``dtheta1_x_rad``, ``dtheta2_x_rad_s``, ``dtheta3_x_rad_s2``, ...;
    ``form`` "sub", the increments over the m parts of the interval: ``dtheta_sub1_x_rad``, ..."""
    if form not in ("multiple", "sub") or isinstance(m, bool) or not isinstance(m, int) or m < 1:
        raise ValueError(f"increments: form must be 'multiple' or 'sub' and m a positive integer, got {form!r}, {m!r}")
    if form == "sub":
        return tuple(f"dtheta_sub{j}_{a}_rad" for j in range(1, m + 1) for a in "xyz")
    units = {1: "rad", 2: "rad_s"}
    return tuple(f"dtheta{j}_{a}_{units.get(j, f'rad_s{j - 1}')}" for j in range(1, m + 1) for a in "xyz")


@dataclass
class RunLogInputs:
    """What a run fed its estimators besides the sensor readings, as its log holds it
    (:func:`run_log_inputs`), and ``estimators``: the summary's ``estimator_inputs``."""

    odometry_mps: np.ndarray | None = None  # (N,), with an estimator that takes speed_mps
    dtheta: np.ndarray | None = None  # (N, r, 3) multiple integrals ΔΘ^1..ΔΘ^r
    dtheta_sub: np.ndarray | None = None  # (N, m, 3) sub-interval increments
    gnss: Any = None  # GnssFixes logged (those that arrive by the last sample)
    gnss_rows: np.ndarray | None = None  # the row of each
    estimators: dict = field(default_factory=dict)


def run_log_inputs(sim, result) -> RunLogInputs:
    """What ``sim`` (a :class:`biso_cosim.cosim.CoSimulation`) fed each estimator over the
    run ``result``, for its log and for summary.json's ``estimator_inputs``: the parameters
    the run set (declination, and the vehicle's parameters the estimator takes from the car,
    ``Estimator.vehicle_params``: where the wheel odometry's speed is measured, the rear
    axle's slip angle per g), the
    log columns of each per-sample input (``speed_mps``, ``imu_flags``, ``dtheta_b``,
    ``gnss``) and the number of fixes logged. ``biso-cosim run`` and the campaigns write
    their logs with it."""
    out = RunLogInputs()
    n = int(result.t_s.shape[0])
    forms = {key: getattr(est, "gyro_increments", None) for key, est in sim.estimators.items()}
    orders = max((m for form, m in filter(None, forms.values()) if form == "multiple"), default=0)
    subs = {m for form, m in filter(None, forms.values()) if form == "sub"}
    if orders:
        out.dtheta = np.ascontiguousarray(result.imu.dtheta[:, :orders])
    if subs:
        out.dtheta_sub = np.ascontiguousarray(result.imu.dtheta_sub)
    if any("speed_mps" in getattr(e, "inputs", ()) for e in sim.estimators.values()):
        out.odometry_mps = sim.odometry_mps(result.truth)
    if result.gnss is not None:
        out.gnss, out.gnss_rows = _fixes_by_row(result.gnss, result.t_s)
    for key, est in sim.estimators.items():
        params = getattr(est, "params", None)
        takes = tuple(getattr(est, "inputs", ()))
        entry: dict = {"params": {}, "columns": {}}
        for name in ("declination_rad", *getattr(est, "vehicle_params", ())):
            if params is not None and hasattr(params, name):
                value = getattr(params, name)
                entry["params"][name] = list(value) if isinstance(value, tuple) else value
        if "speed_mps" in takes:
            entry["columns"]["speed_mps"] = ODOMETRY_COLUMN
        if "imu_flags" in takes:
            entry["columns"]["imu_flags"] = "imu_flags"
        if forms[key] is not None:
            entry["columns"]["dtheta_b"] = list(increment_columns(*forms[key]))
        if "gnss" in takes and out.gnss is not None:
            entry["columns"]["gnss"] = list(GNSS_COLUMNS)
            entry["gnss_fixes"] = len(out.gnss)
        out.estimators[key] = entry
    if n and out.dtheta_sub is not None and out.dtheta_sub.shape[0] != n:
        raise ValueError(f"run_log_inputs: {out.dtheta_sub.shape[0]} increments for {n} samples")
    return out


def _fixes_by_row(fixes, t_s: np.ndarray):
    """The fixes that arrive by the last sample, and the row of each: the first sample at or
    after its arrival (a second fix in one sample interval takes the next row)."""
    rows = np.searchsorted(t_s, np.asarray(fixes.t_arrival_s, dtype=np.float64), side="left")
    keep = rows < t_s.shape[0]
    rows = rows[keep]
    for i in range(1, rows.shape[0]):
        if rows[i] <= rows[i - 1]:
            rows[i] = rows[i - 1] + 1
    if rows.shape[0] and rows[-1] >= t_s.shape[0]:
        raise ValueError(f"the log holds one GNSS fix per sample row, but {int(np.count_nonzero(rows >= t_s.shape[0]))} "
                         "fix(es) arrive after the last rows are taken: the receiver is faster than the sensor")
    return fixes[keep], rows


def _attitude_columns(prefix: str, q: np.ndarray) -> tuple[list[str], list[np.ndarray], list[str]]:
    angles = attitude_angles_deg(q)
    names = [f"{prefix}_q{c}" for c in "wxyz"] + [f"{prefix}_{a}_deg" for a in ("roll", "pitch", "heading")]
    cols = [q[:, i] for i in range(4)] + [angles["roll"], angles["pitch"], angles["heading"]]
    return names, cols, [_EXACT] * 4 + ["%.5f"] * 3


def write_run_log(result, path: str | Path, inputs: RunLogInputs | None = None) -> Path:
    """Write the log of a :class:`biso_cosim.cosim.RunResult` as CSV (columns above), whole
    or not at all; ``inputs``: what the run fed its estimators (:func:`run_log_inputs`),
    whose columns the log then holds (without: the truth, readings and estimates only)."""
    path = Path(path)
    inputs = inputs or RunLogInputs()
    truth, imu = result.truth, result.imu
    names, cols, fmts = ["t_s"], [truth.t_s], ["%.4f"]
    n, c, f = _attitude_columns("true", truth.q_wb)
    names += n
    cols += c
    fmts += f
    names += ["pos_e_m", "pos_n_m", "pos_u_m", "speed_mps"]
    cols += [truth.pos_w[:, 0], truth.pos_w[:, 1], truth.pos_w[:, 2], truth.speed_mps]
    fmts += ["%.4f"] * 4
    if inputs.odometry_mps is not None:
        names.append(ODOMETRY_COLUMN)
        cols.append(inputs.odometry_mps)
        fmts.append(_EXACT)
    for key, attr in (("gyro", "gyro_b"), ("accel", "accel_b"), ("mag", "mag_b")):
        values = getattr(imu, attr)
        names += list(SENSOR_COLUMNS[key])
        cols += [values[:, i] for i in range(3)]
        fmts += [_EXACT] * 3
    for form, values in (("multiple", inputs.dtheta), ("sub", inputs.dtheta_sub)):
        if values is not None:
            names += list(increment_columns(form, values.shape[1]))
            cols += [values[:, j, a] for j in range(values.shape[1]) for a in range(3)]
            fmts += [_EXACT] * (3 * values.shape[1])
    names += ["imu_flags", "declination_deg"]
    cols += [imu.flags, np.full(truth.t_s.shape[0], result.site["declination_deg"])]
    fmts += ["%d", _EXACT]
    split = len(names)  # the receiver's columns come here
    for key, (q, flags) in result.estimates.items():
        n, c, f = _attitude_columns(key, q)
        names += n + [f"{key}_flags"]
        cols += c + [flags]
        fmts += f + ["%d"]
    table = np.column_stack([np.asarray(col, dtype=np.float64) for col in cols])
    with atomic_output(path) as temporary:  # a log is complete or absent
        if inputs.gnss is None:
            np.savetxt(temporary, table, fmt=fmts, delimiter=",", header=",".join(names), comments="")
        else:
            _write_with_fixes(temporary, table, fmts, names, split, inputs.gnss, inputs.gnss_rows)
    return path


def _write_with_fixes(path: Path, table: np.ndarray, fmts: list[str], names: list[str], split: int, fixes,
                      rows: np.ndarray) -> None:
    """The log with the receiver's columns after column ``split``: on each fix's row its
    values, elsewhere empty cells (the rows formatted as ``numpy.savetxt`` does)."""
    cells = ["," * (len(GNSS_COLUMNS) - 1)] * table.shape[0]
    fix_format = ",".join(_GNSS_FORMATS)
    values = np.column_stack([fixes.t_s, fixes.t_arrival_s, fixes.pos_w, fixes.vel_w,
                              np.asarray(fixes.valid, dtype=np.float64)])
    for row, fix in zip(rows.tolist(), values):
        cells[row] = fix_format % tuple(fix)
    head, tail = ",".join(fmts[:split]), ",".join(fmts[split:])
    header = ",".join(names[:split] + list(GNSS_COLUMNS) + names[split:])
    with open(path, "w") as handle:
        handle.write(header + "\n")
        for start in range(0, table.shape[0], 4096):
            lines = []
            for i in range(start, min(start + 4096, table.shape[0])):
                row = table[i]
                line = head % tuple(row[:split]) + "," + cells[i]
                lines.append(line + ("," + tail % tuple(row[split:]) if tail else "") + "\n")
            handle.writelines(lines)


def read_sensor_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Read gyro, accel, mag (and ``t_s`` if present) from a CSV with the columns above.

    Returns ``{"gyro": (N, 3), "accel": (N, 3), "mag": (N, 3), "t_s": (N,) or None}``.
    Errors name the file, the missing columns or the first bad line.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"input file {str(path)!r} does not exist")
    with path.open(newline="") as handle:
        reader = csv.reader(handle)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise ValueError(f"{path}: the file is empty") from None
        wanted = [c for cols in SENSOR_COLUMNS.values() for c in cols]
        missing = [c for c in wanted if c not in header]
        if missing:
            raise ValueError(f"{path}: missing column(s) {missing}; expected {wanted} (and optionally t_s)")
        index = {name: header.index(name) for name in wanted + (["t_s"] if "t_s" in header else [])}
        rows = []
        for line_no, row in enumerate(reader, start=2):
            if not row:
                continue
            try:
                rows.append([float(row[index[name]]) for name in index])
            except (ValueError, IndexError):
                raise ValueError(f"{path}, line {line_no}: expected numbers in columns {list(index)}") from None
    if not rows:
        raise ValueError(f"{path}: no samples after the header")
    data = np.asarray(rows)
    out = {}
    k = 0
    for key, cols in SENSOR_COLUMNS.items():
        out[key] = np.ascontiguousarray(data[:, k:k + 3])
        k += 3
    out["t_s"] = data[:, k] if "t_s" in index else None
    return out


def _log_rows(path: Path, names: tuple[str, ...] | list[str], what: str):
    """(line number, the cells of ``names``) of each data row of a CSV log; a missing
    column is a ValueError naming the file, ``what`` needs them and the columns."""
    with path.open(newline="") as handle:
        reader = csv.reader(handle)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise ValueError(f"{path}: the file is empty") from None
        missing = [c for c in names if c not in header]
        if missing:
            raise ValueError(f"{path}: {what} needs the column(s) {missing}, which the log does not have")
        index = [header.index(name) for name in names]
        for line_no, row in enumerate(reader, start=2):
            if row:
                try:
                    yield line_no, [row[i].strip() for i in index]
                except IndexError:
                    raise ValueError(f"{path}, line {line_no}: {len(row)} cells, the header names {len(header)}") from None


def read_log_columns(path: str | Path, names: tuple[str, ...] | list[str], what: str = "the estimate") -> np.ndarray:
    """The (N, len(names)) values of the named columns of a CSV log, every row a number;
    errors name the file, the missing columns or the first bad line."""
    path = Path(path)
    rows = []
    for line_no, cells in _log_rows(path, names, what):
        try:
            rows.append([float(c) for c in cells])
        except ValueError:
            raise ValueError(f"{path}, line {line_no}: {what} needs numbers in columns {list(names)}") from None
    return np.asarray(rows, dtype=np.float64).reshape(len(rows), len(names))


def read_gnss_fixes(path: str | Path):
    """The GNSS fixes of a run's log (:data:`GNSS_COLUMNS`, on the rows where they arrive) as
    :class:`biso_cosim.sensors.GnssFixes`, or None when the log has no fix columns. A row
    with some of a fix's cells empty, or a ``gnss_valid`` other than 0 or 1, is a
    ValueError naming the line."""
    from biso_cosim.sensors import GnssFixes

    path = Path(path)
    with path.open(newline="") as handle:
        header = [h.strip() for h in next(csv.reader(handle), [])]
    if not any(name in header for name in GNSS_COLUMNS):
        return None
    fixes = []
    for line_no, cells in _log_rows(path, GNSS_COLUMNS, "the GNSS fixes"):
        filled = [bool(c) for c in cells]
        if not any(filled):
            continue
        try:
            if not all(filled):
                raise ValueError
            values = [float(c) for c in cells]
            if values[-1] not in (0.0, 1.0):
                raise ValueError
        except ValueError:
            raise ValueError(f"{path}, line {line_no}: a GNSS fix needs a number in each of {list(GNSS_COLUMNS)} "
                             "(gnss_valid 0 or 1), or none of them on a row without a fix") from None
        fixes.append(values)
    table = np.asarray(fixes, dtype=np.float64).reshape(len(fixes), len(GNSS_COLUMNS))
    return GnssFixes.from_arrays(table[:, 0], table[:, 5:8], pos_w=table[:, 2:5], valid=table[:, 8] == 1.0,
                                 t_arrival_s=table[:, 1])


def write_estimates_csv(path: str | Path, q_wb: np.ndarray, flags: np.ndarray, t_s: np.ndarray | None,
                        prefix: str = "est") -> Path:
    """Write estimates: ``t_s`` (if known), the quaternion, the angles and the flags."""
    return write_estimates_table(path, {prefix: (q_wb, flags)}, t_s)


def write_estimates_table(path: str | Path, estimates: dict[str, tuple[np.ndarray, np.ndarray]],
                          t_s: np.ndarray | None) -> Path:
    """Write ``t_s`` (if known) and, for each label of ``estimates``, its quaternion
    (17 significant digits), angles and flags; whole or not at all."""
    path = Path(path)
    names, cols, fmts = [], [], []
    if t_s is not None:
        names, cols, fmts = ["t_s"], [t_s], ["%.6f"]
    for prefix, (q_wb, flags) in estimates.items():
        n, c, f = _attitude_columns(prefix, q_wb)
        names += n + [f"{prefix}_flags"]
        cols += c + [flags]
        fmts += [_EXACT] * 4 + f[4:] + ["%d"]
    with atomic_output(path) as temporary:
        np.savetxt(temporary, np.column_stack([np.asarray(col, dtype=np.float64) for col in cols]), fmt=fmts,
                   delimiter=",", header=",".join(names), comments="")
    return path
