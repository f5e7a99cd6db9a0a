"""The run log (``log.csv``) and the sensor-log columns that ``biso-cosim estimate`` reads.

One row per sensor output sample. Columns, in order:

| column | unit | what |
|---|---|---|
| ``t_s`` | s | sample time stamp |
| ``true_qw``, ``true_qx``, ``true_qy``, ``true_qz`` | 1 | true ``q_wb`` (body → ENU) |
| ``true_roll_deg``, ``true_pitch_deg``, ``true_heading_deg`` | ° | true angles (ISO 8855; heading clockwise from North) |
| ``pos_e_m``, ``pos_n_m``, ``pos_u_m`` | m | IMU position in the route's local ENU frame |
| ``speed_mps`` | m/s | forward speed of the rear axle (truth) |
| ``odometry_mps`` | m/s | the wheel odometry fed to estimators that take a speed (front wheels' spin × radius × cos steer), when the run had such an estimator |
| ``gyro_x_rad_s`` … ``gyro_z_rad_s`` | rad/s | gyro reading, body axes |
| ``accel_x_m_s2`` … ``accel_z_m_s2`` | m/s² | accelerometer reading (specific force), body axes |
| ``mag_x_ut`` … ``mag_z_ut`` | µT | magnetometer reading, body axes |
| ``imu_flags`` | | sensor flag bits (saturation, overflow) |
| ``declination_deg`` | ° | magnetic declination at the site, east positive (the same in every row) |
| ``<est>_qw`` … ``<est>_qz`` | 1 | each estimator's ``q_wb`` |
| ``<est>_roll_deg``, ``<est>_pitch_deg``, ``<est>_heading_deg`` | ° | its angles |
| ``<est>_flags`` | | its flag bits |

The sensor readings, the odometry and the declination are written with 17 significant
digits (the doubles the estimators were fed, exactly). Body axes are x forward, y left, z up. The sensor columns are also the input format of
``biso-cosim estimate`` (``t_s``, ``imu_flags`` and ``declination_deg`` optional there), so an
estimator can be re-run on a log.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from biso_cosim.metrics import attitude_angles_deg
from biso_cosim.output import atomic_output

__all__ = ["SENSOR_COLUMNS", "write_run_log", "read_sensor_csv", "write_estimates_csv", "write_estimates_table"]

# what the estimators were fed is written with 17 significant digits: read back, it is the
# same double, so that ``biso-cosim estimate`` on the log repeats the run's estimates exactly
_EXACT = "%.17g"

SENSOR_COLUMNS = {
    "gyro": ("gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s"),
    "accel": ("accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2"),
    "mag": ("mag_x_ut", "mag_y_ut", "mag_z_ut"),
}


def _attitude_columns(prefix: str, q: np.ndarray) -> tuple[list[str], list[np.ndarray], list[str]]:
    angles = attitude_angles_deg(q)
    names = [f"{prefix}_q{c}" for c in "wxyz"] + [f"{prefix}_{a}_deg" for a in ("roll", "pitch", "heading")]
    cols = [q[:, i] for i in range(4)] + [angles["roll"], angles["pitch"], angles["heading"]]
    return names, cols, [_EXACT] * 4 + ["%.5f"] * 3


def write_run_log(result, path: str | Path, odometry_mps: np.ndarray | None = None) -> Path:
    """Write the log of a :class:`biso_cosim.cosim.RunResult` as CSV (columns above), whole
    or not at all; ``odometry_mps``: the wheel odometry the run fed its estimators, one
    value per sample (the ``odometry_mps`` column), when it had one."""
    path = Path(path)
    truth, imu = result.truth, result.imu
    names, cols, fmts = ["t_s"], [truth.t_s], ["%.4f"]
    n, c, f = _attitude_columns("true", truth.q_wb)
    names += n
    cols += c
    fmts += f
    names += ["pos_e_m", "pos_n_m", "pos_u_m", "speed_mps"]
    cols += [truth.pos_w[:, 0], truth.pos_w[:, 1], truth.pos_w[:, 2], truth.speed_mps]
    fmts += ["%.4f"] * 4
    if odometry_mps is not None:
        names.append("odometry_mps")
        cols.append(odometry_mps)
        fmts.append(_EXACT)
    for key, attr in (("gyro", "gyro_b"), ("accel", "accel_b"), ("mag", "mag_b")):
        values = getattr(imu, attr)
        names += list(SENSOR_COLUMNS[key])
        cols += [values[:, i] for i in range(3)]
        fmts += [_EXACT] * 3
    names += ["imu_flags", "declination_deg"]
    cols += [imu.flags, np.full(truth.t_s.shape[0], result.site["declination_deg"])]
    fmts += ["%d", _EXACT]
    for key, (q, flags) in result.estimates.items():
        n, c, f = _attitude_columns(key, q)
        names += n + [f"{key}_flags"]
        cols += c + [flags]
        fmts += f + ["%d"]
    table = np.column_stack([np.asarray(col, dtype=np.float64) for col in cols])
    with atomic_output(path) as temporary:  # a log is complete or absent
        np.savetxt(temporary, table, fmt=fmts, delimiter=",", header=",".join(names), comments="")
    return path


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
