"""Recordings with a reference attitude, read from open formats into one record.

Formats (found by ``find_recordings`` in a folder):

``broad-hdf5``  BROAD's published trials (``data_hdf5/NN_name.hdf5``; Laidig et al. 2021):
                datasets ``imu_gyr`` (N, 3) rad/s, ``imu_acc`` (N, 3) m/s², ``imu_mag`` (N, 3) µT,
                ``opt_quat`` (N, 4) w, x, y, z (IMU axes → ENU, magnetic north, NaN rows are
                optical dropouts), ``movement`` (N,) scored samples, ``sampling_rate`` (Hz);
                ``opt_pos`` is not needed. Needs ``h5py`` (extra ``score``).
``npz``         the same keys in a NumPy ``.npz`` (the BROAD subset of ``shared/data/broad_dev``);
                without ``sampling_rate`` the rate is ``fs_hz`` (``--fs``), or for files named like
                BROAD's trials (``NN_undisturbed_…``, ``NN_disturbed_…``) BROAD's 2000/7 Hz;
                ``movement`` may be left out (all scored).
``run-log``     a ``log.csv`` of ``biso-cosim run`` (with its ``summary.json``), or any CSV with the
                sensor columns of :mod:`biso_cosim.logs` and the reference ``true_qw`` … ``true_qz``:
                the truth is the reference, every sample is scored unless a ``movement`` column
                (0/1) says otherwise, the sample rate comes from ``t_s`` (or ``summary.json``),
                the declination from the ``declination_deg`` column.

A rate the recording carries is never overridden by ``fs_hz``.

Every recording is in its sensor's own axes (BROAD: the IMU's; a run log: the vehicle body's
x forward, y left, z up) and its reference maps them to ENU.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Recording", "find_recordings", "read_folder", "read_recording", "read_broad_hdf5", "read_npz",
           "read_run_log", "is_run_log", "broad_groups", "BROAD_RATE_HZ", "RECORDING_SUFFIXES"]

BROAD_RATE_HZ = 2000.0 / 7.0
"""Sample rate of every BROAD trial (Laidig et al. 2021, §2)."""

RECORDING_SUFFIXES = (".hdf5", ".h5", ".npz", ".csv")

_BROAD_NAME = re.compile(r"^\d{2}_(undisturbed|disturbed)_")


@dataclass(frozen=True, eq=False)
class Recording:
    """Sensor samples (sensor axes, SI), the reference attitude and the samples to score."""

    name: str
    path: str
    format: str
    fs_hz: float
    gyro_b: np.ndarray          # (N, 3) rad/s
    accel_b: np.ndarray         # (N, 3) m/s², specific force
    mag_b: np.ndarray           # (N, 3) µT
    q_ref: np.ndarray           # (N, 4) w, x, y, z, sensor → ENU; NaN rows: no reference
    movement: np.ndarray        # (N,) bool, the samples scored
    declination_rad: float = 0.0  # of the reference's north (0: the reference is magnetic north)
    groups: tuple[str, ...] = ("all_trials",)

    def __len__(self) -> int:
        return int(self.gyro_b.shape[0])

    @property
    def t_s(self) -> np.ndarray:
        return np.arange(len(self)) / self.fs_hz


def broad_groups(name: str) -> tuple[str, ...]:
    """BROAD's groups of a trial from its name (the rule its ``trials.json`` follows):
    ``all_trials``; ``undisturbed`` with motion (rotation/translation/combined), speed
    (slow/fast) and breaks (with_breaks/no_breaks); or ``disturbed`` with its disturbance
    (tapping, vibration, stationary_magnet, attached_magnet, office_environment, mixed)."""
    groups = ["all_trials"]
    m = _BROAD_NAME.match(name)
    if not m:
        return tuple(groups)
    groups.append(m.group(1))
    rest = name[m.end():]
    if m.group(1) == "undisturbed":
        groups += [w for w in ("rotation", "translation", "combined") if w in rest]
        groups += [w for w in ("slow", "fast") if rest.startswith(w)]
        groups.append("with_breaks" if "with_breaks" in rest else "no_breaks")
    else:
        for token, group in (("tapping", "tapping"), ("phone_vibration", "vibration"),
                             ("stationary_magnet", "stationary_magnet"), ("attached_magnet", "attached_magnet"),
                             ("office", "office_environment"), ("mixed", "mixed")):
            if rest.startswith(token):
                groups.append(group)
    return tuple(groups)


def _rows(path: Path, key: str, value, width: int) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.ndim == 2 and a.shape[0] == width and a.shape[1] != width:
        a = a.T  # stored column-major (MATLAB-style)
    if a.ndim != 2 or a.shape[1] != width:
        raise ValueError(f"{path}: {key} must have shape (N, {width}), got {a.shape}")
    return np.ascontiguousarray(a)


def _movement(path: Path, value, n: int) -> np.ndarray:
    if value is None:
        return np.ones(n, dtype=bool)
    m = np.asarray(value).reshape(-1)
    if m.shape != (n,):
        raise ValueError(f"{path}: movement must have {n} entries (one per sample), got {np.asarray(value).shape}")
    return m.astype(bool)


def _rate(path: Path, value, fs_hz: float | None) -> float:
    if value is not None:
        rate = float(np.asarray(value).reshape(-1)[0])
    elif fs_hz is not None:
        rate = float(fs_hz)
    elif _BROAD_NAME.match(path.stem):
        rate = BROAD_RATE_HZ
    else:
        raise ValueError(f"{path}: no sampling_rate in the file; give the sample rate (--fs HZ)")
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"{path}: the sample rate must be a positive number, got {rate!r}")
    return rate


def _from_arrays(path: Path, fmt: str, get, fs_hz: float | None, groups: tuple[str, ...] | None) -> Recording:
    missing = [k for k in ("imu_gyr", "imu_acc", "imu_mag", "opt_quat") if get(k) is None]
    if missing:
        raise ValueError(f"{path}: missing {', '.join(missing)} (expected BROAD's keys imu_gyr, imu_acc, imu_mag, "
                         f"opt_quat, movement, sampling_rate)")
    gyro = _rows(path, "imu_gyr", get("imu_gyr"), 3)
    n = gyro.shape[0]
    arrays = {"imu_acc": _rows(path, "imu_acc", get("imu_acc"), 3), "imu_mag": _rows(path, "imu_mag", get("imu_mag"), 3),
              "opt_quat": _rows(path, "opt_quat", get("opt_quat"), 4)}
    for key, a in arrays.items():
        if a.shape[0] != n:
            raise ValueError(f"{path}: {key} has {a.shape[0]} rows but imu_gyr has {n}")
    return Recording(name=path.stem, path=str(path), format=fmt, fs_hz=_rate(path, get("sampling_rate"), fs_hz),
                     gyro_b=gyro, accel_b=arrays["imu_acc"], mag_b=arrays["imu_mag"], q_ref=arrays["opt_quat"],
                     movement=_movement(path, get("movement"), n), groups=groups or broad_groups(path.stem))


def read_broad_hdf5(path: str | Path, fs_hz: float | None = None, groups: tuple[str, ...] | None = None) -> Recording:
    """One BROAD trial from its published HDF5 file (datasets at the top level or in one group)."""
    path = Path(path)
    try:
        import h5py
    except ImportError:
        raise ValueError(f"{path}: reading HDF5 needs h5py (pip install 'biso_cosim[score]')") from None
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        raise ValueError(f"{path}: not a readable HDF5 file ({exc})") from None
    with handle as f:
        node = f
        if "imu_gyr" not in f and len(f.keys()) == 1 and isinstance(f[next(iter(f.keys()))], h5py.Group):
            node = f[next(iter(f.keys()))]

        def get(key):
            if key in node:
                return node[key][()]
            return node.attrs.get(key)
        return _from_arrays(path, "broad-hdf5", get, fs_hz, groups)


def read_npz(path: str | Path, fs_hz: float | None = None, groups: tuple[str, ...] | None = None) -> Recording:
    """One recording from a NumPy ``.npz`` with BROAD's keys (``shared/data/broad_dev`` format)."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable .npz file ({exc})") from None
    with data:
        values = {k: data[k] for k in data.files}
    return _from_arrays(path, "npz", values.get, fs_hz, groups)


_TRUTH = ("true_qw", "true_qx", "true_qy", "true_qz")


def _csv_header(path: Path) -> list[str]:
    with path.open() as handle:
        for line in handle:
            if line.strip() and not line.startswith("#"):
                return [h.strip() for h in line.split(",")]
    raise ValueError(f"{path}: the file is empty")


def is_run_log(path: str | Path) -> bool:
    """Whether a CSV has the sensor and reference columns ``read_run_log`` needs."""
    from biso_cosim.logs import SENSOR_COLUMNS

    header = set(_csv_header(Path(path)))
    need = [c for cols in SENSOR_COLUMNS.values() for c in cols] + list(_TRUTH)
    return all(c in header for c in need)


def read_run_log(path: str | Path, fs_hz: float | None = None, groups: tuple[str, ...] | None = None) -> Recording:
    """A run's ``log.csv`` (or any CSV with the sensor columns and ``true_qw`` … ``true_qz``)."""
    from biso_cosim.logs import SENSOR_COLUMNS

    path = Path(path)
    header = _csv_header(path)
    sensor = [c for cols in SENSOR_COLUMNS.values() for c in cols]
    missing = [c for c in sensor + list(_TRUTH) if c not in header]
    if missing:
        raise ValueError(f"{path}: missing column(s) {missing}; a recording CSV needs {sensor} and the "
                         f"reference {list(_TRUTH)} (a run's log.csv has them)")
    wanted = sensor + list(_TRUTH) + [c for c in ("t_s", "declination_deg", "movement") if c in header]
    cols = [header.index(c) for c in wanted]
    try:
        table = np.loadtxt(path, delimiter=",", skiprows=1, usecols=cols, ndmin=2, comments="#")
    except ValueError as exc:
        raise ValueError(f"{path}: expected numbers in columns {wanted} ({exc})") from None
    if table.shape[0] == 0:
        raise ValueError(f"{path}: no samples after the header")
    col = {name: table[:, i] for i, name in enumerate(wanted)}
    rate = None
    summary = path.parent / "summary.json"
    if "t_s" in col and table.shape[0] > 1:
        dt = np.diff(col["t_s"])
        step = float(np.median(dt))
        if not step > 0 or np.any(np.abs(dt - step) > 0.01 * step):
            raise ValueError(f"{path}: t_s must increase evenly (resample the log, or give the sample rate --fs HZ)")
        rate = 1.0 / step
    if rate is None and summary.is_file():
        rate = json.loads(summary.read_text()).get("sensor", {}).get("output_rate_hz")
    if rate is None:
        rate = fs_hz
    if rate is None:
        raise ValueError(f"{path}: no t_s column and no summary.json: give the sample rate (--fs HZ)")
    name = path.parent.name if path.name == "log.csv" else path.stem
    decl = col.get("declination_deg")
    def three(key: str) -> np.ndarray:
        return np.ascontiguousarray(np.column_stack([col[c] for c in SENSOR_COLUMNS[key]]))
    return Recording(
        name=name, path=str(path), format="run-log", fs_hz=_rate(path, None, rate), gyro_b=three("gyro"),
        accel_b=three("accel"), mag_b=three("mag"), q_ref=np.column_stack([col[c] for c in _TRUTH]),
        movement=_movement(path, None if "movement" not in col else col["movement"] != 0, table.shape[0]),
        declination_rad=0.0 if decl is None else math.radians(float(decl[0])), groups=groups or ("all_trials",))


def read_recording(path: str | Path, fs_hz: float | None = None, groups: tuple[str, ...] | None = None) -> Recording:
    """Read one recording; the format follows from the suffix (``.hdf5``/``.h5``, ``.npz``, ``.csv``)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"recording {str(path)!r} does not exist")
    suffix = path.suffix.lower()
    if suffix in (".hdf5", ".h5"):
        return read_broad_hdf5(path, fs_hz, groups)
    if suffix == ".npz":
        return read_npz(path, fs_hz, groups)
    if suffix == ".csv":
        return read_run_log(path, fs_hz, groups)
    raise ValueError(f"{path}: unknown recording format {suffix!r}; expected one of {', '.join(RECORDING_SUFFIXES)}")


def _trials_json_groups(folder: Path) -> dict[str, tuple[str, ...]]:
    """Groups from a BROAD ``trials.json`` in the folder, if it has them."""
    spec = folder / "trials.json"
    if not spec.is_file():
        return {}
    try:
        trials = json.loads(spec.read_text()).get("trials", {})
    except (ValueError, AttributeError):
        return {}
    return {name: tuple(info["groups"]) for name, info in trials.items()
            if isinstance(info, dict) and isinstance(info.get("groups"), list)}


def find_recordings(folder: str | Path) -> list[Path]:
    """The recordings in ``folder``, sorted by name: ``*.hdf5``, ``*.h5``, ``*.npz``, CSVs with the
    recording columns, and the ``log.csv`` of each sub-folder (a folder of runs). ``folder`` may
    also be one run's folder or one file."""
    folder = Path(folder)
    if folder.is_file():
        return [folder]
    if not folder.is_dir():
        raise FileNotFoundError(f"DIR: {str(folder)!r} is not a directory")
    found = [p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in (".hdf5", ".h5", ".npz")]
    found += [p for p in folder.glob("*.csv") if p.is_file() and is_run_log(p)]
    found += [p / "log.csv" for p in folder.iterdir() if p.is_dir() and (p / "log.csv").is_file()]
    return sorted(found, key=lambda p: (p.parent.name if p.name == "log.csv" else p.stem, str(p)))


def read_folder(folder: str | Path, fs_hz: float | None = None):
    """Yield every recording of ``folder`` (see ``find_recordings``), BROAD groups from a
    ``trials.json`` beside them where there is one. Raises ValueError if there is none."""
    paths = find_recordings(folder)
    if not paths:
        raise ValueError(f"DIR: no recordings found in {str(folder)!r} (expected *.hdf5, *.h5, *.npz with "
                         f"BROAD's keys, or a run's log.csv)")
    for path in paths:
        groups = _trials_json_groups(path.parent).get(path.stem)
        yield read_recording(path, fs_hz, groups)
