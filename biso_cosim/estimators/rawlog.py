"""Raw MPU-9250 register logs: their CSV format, the conversion to estimator inputs, and the
sensor flags the raw registers show.

A raw log holds, per output sample, the ten 16-bit words a driver reads (ACCEL_X/Y/Z, TEMP,
GYRO_X/Y/Z of the MPU-9250, in chip axes; HX, HY, HZ of the AK8963, in its own axes) and the
AK8963 status bytes ST1 and ST2 (``biso_cosim.sensors.RawSamples``). Turning it into what the
estimators take needs the configuration it was logged with: the full-scale selections
(GYRO_FS_SEL, ACCEL_FS_SEL), the AK8963 resolution (CNTL1.BIT, also shown per sample by
ST2.BITM), the part's fuse-ROM sensitivity adjustment ASA, and the mounting of the chip in
the vehicle (``q_body_chip``). ``raw_inputs`` applies them with ``sensors.raw_to_si`` (the
AK8963 axis mapping m_x = a_y, m_y = a_x, m_z = −a_z included) and derives ``imu_flags``:

* GYRO_SATURATED / ACCEL_SATURATED: a word at a full-scale code (−32768 or +32767);
* MAG_OVERFLOW: ST2.HOFL (|x| + |y| + |z| ≥ 4912 µT): that field sample is not valid;
* MAG_OVERRUN: ST1.DOR (an AK8963 sample was skipped);
* MAG_INVALID: no AK8963 measurement yet (rows before the first with ST1.DRDY); their field
  is NaN.

The flags are those of ``ImuSamples.flags`` of the simulated chip, except that a saturation
the ADC saw before the low-pass filter without the output code reaching full scale cannot
be seen in the words. Applied to the simulated chip's registers, ``raw_inputs`` reproduces
its SI readings bit for bit.

CSV format (``write_raw_csv``, ``read_raw_csv``)::

    # biso-cosim raw MPU-9250 log
    # gyro_fs_sel = 0
    # accel_fs_sel = 1
    # mag_bit16 = 1
    # asa = 176 177 165
    # mounting = 1 0 0 0
    # fs_hz = 200
    t_s,accel_x_raw,accel_y_raw,accel_z_raw,temp_raw,gyro_x_raw,gyro_y_raw,gyro_z_raw,mag_x_raw,mag_y_raw,mag_z_raw,ak_st1,ak_st2
    0.000000,-12,40,8190,1021,3,-7,1,1205,-340,-2710,1,16

Comment lines before the column names give the configuration, one ``key = value`` each,
all optional: ``gyro_fs_sel``, ``accel_fs_sel`` (register values 0…3; default 0 and 1, the
sensor model's defaults), ``mag_bit16`` (1/0; default: from ST2.BITM), ``asa`` (three bytes;
default 128 128 128, no adjustment), ``mounting`` (``q_body_chip`` w x y z, or the 3×3
rotation chip → body row by row; default identity), ``fs_hz`` (sample rate; default from
``t_s``). Columns: the ten words as signed integers, ``ak_st1`` and ``ak_st2`` as bytes
(0…255), and optionally ``t_s`` in seconds; other columns are ignored.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from biso_cosim.estimators import flags as fl

__all__ = ["RAW_WORD_COLUMNS", "RAW_STATUS_COLUMNS", "RawInputs", "RawLog", "imu_flags_from_raw", "raw_inputs",
           "read_raw_csv", "write_raw_csv", "is_raw_header"]

RAW_WORD_COLUMNS = ("accel_x_raw", "accel_y_raw", "accel_z_raw", "temp_raw", "gyro_x_raw", "gyro_y_raw",
                    "gyro_z_raw", "mag_x_raw", "mag_y_raw", "mag_z_raw")
"""CSV columns of ``RawSamples.words``, in register order (chip axes; AK8963 axes for mag)."""
RAW_STATUS_COLUMNS = ("ak_st1", "ak_st2")
"""CSV columns of the AK8963 status bytes ST1 (bit 0 DRDY, bit 1 DOR) and ST2 (bit 3 HOFL, bit 4 BITM)."""
HEADER_TITLE = "biso-cosim raw MPU-9250 log"
HEADER_KEYS = ("gyro_fs_sel", "accel_fs_sel", "mag_bit16", "asa", "mounting", "fs_hz")

_ST1_DRDY, _ST1_DOR = 0x01, 0x02
_ST2_HOFL, _ST2_BITM = 0x08, 0x10
_CODE_MIN, _CODE_MAX = -32768, 32767


@dataclass(frozen=True, eq=False)
class RawInputs:
    """Estimator inputs from a raw log: SI readings in body axes and the sensor's flags."""

    gyro_b: np.ndarray
    """(k, 3) rad/s."""
    accel_b: np.ndarray
    """(k, 3) m/s², specific force."""
    mag_b: np.ndarray
    """(k, 3) µT; NaN where the AK8963 had no measurement yet (MAG_INVALID)."""
    imu_flags: np.ndarray
    """(k,) int64, ``biso_cosim.sensors.ImuFlag`` bits (see the module docstring)."""
    temperature_c: np.ndarray
    """(k,) on-chip temperature, °C."""
    mag_bit16: bool
    """The AK8963 resolution used (16 bit: 0.15 µT/LSB, 14 bit: 0.6 µT/LSB)."""


def _mag_valid(st1: np.ndarray) -> np.ndarray:
    """Rows from the first AK8963 data-ready on (before it the data registers hold nothing)."""
    return np.cumsum((st1 & _ST1_DRDY) != 0) > 0


def imu_flags_from_raw(raw: Any) -> np.ndarray:
    """(k,) int64 sensor flags shown by the raw registers (module docstring)."""
    words = np.asarray(raw.words)
    st1, st2 = np.asarray(raw.st1), np.asarray(raw.st2)
    at_limit = (words == _CODE_MIN) | (words == _CODE_MAX)
    out = np.zeros(words.shape[0], dtype=np.int64)
    out[at_limit[:, 4:7].any(axis=1)] |= fl.IMU_GYRO_SATURATED
    out[at_limit[:, 0:3].any(axis=1)] |= fl.IMU_ACCEL_SATURATED
    out[(st2 & _ST2_HOFL) != 0] |= fl.IMU_MAG_OVERFLOW
    out[(st1 & _ST1_DOR) != 0] |= fl.IMU_MAG_OVERRUN
    out[~_mag_valid(st1)] |= fl.IMU_MAG_INVALID
    return out


def _mag_bit16(raw: Any, given: bool | None) -> bool:
    """The AK8963 resolution: ST2.BITM of the rows with data, checked against ``given``."""
    valid = _mag_valid(np.asarray(raw.st1))
    bitm = (np.asarray(raw.st2)[valid] & _ST2_BITM) != 0
    if bitm.size and bitm.any() != bitm.all():
        row = int(np.flatnonzero(valid)[np.flatnonzero(bitm != bitm[0])[0]])
        raise ValueError(f"raw log: ST2.BITM (AK8963 16-bit output) changes at sample {row}; "
                         "a log must keep one magnetometer resolution")
    if given is not None and bitm.size and bool(bitm[0]) != given:
        raise ValueError(f"registers say mag_bit16={given}, but ST2.BITM of the log says "
                         f"{16 if bitm[0] else 14}-bit output: correct the configuration")
    if given is not None:
        return given
    return bool(bitm[0]) if bitm.size else True


def raw_inputs(raw: Any, registers: Any = None, asa: Any = None, mounting: Any = None) -> RawInputs:
    """Estimator inputs from raw registers (``sensors.RawSamples``, e.g. ``RawSamples.from_bytes``
    of a real chip's log, or ``ImuSamples.raw`` of the simulated one).

    ``registers``: ``sensors.Registers`` or a dict with ``gyro_fs_sel``, ``accel_fs_sel`` and
    optionally ``mag_bit16`` (default: from ST2.BITM; a contradiction is a ValueError);
    ``asa``: the three fuse-ROM bytes (default 128, no adjustment); ``mounting``: rotation
    chip → body (``q_body_chip`` or a 3×3 matrix; default identity).
    """
    from biso_cosim.sensors import RawSamples, Registers, raw_to_si

    if not isinstance(raw, RawSamples):
        raise TypeError(f"raw must be a biso_cosim.sensors.RawSamples, got {type(raw).__name__}")
    if isinstance(registers, Registers):
        reg = registers
        given_bit16 = registers.mag_bit16
    else:
        if registers is not None and not isinstance(registers, Mapping):
            raise TypeError(f"registers must be a Registers, a dict or None, got {type(registers).__name__}")
        fields = dict(registers or {})
        given_bit16 = fields.pop("mag_bit16", None)
        if given_bit16 is not None:
            given_bit16 = bool(given_bit16)
        reg = Registers.coerce(fields)
    bit16 = _mag_bit16(raw, given_bit16)
    if reg.mag_bit16 != bit16:
        reg = dataclasses.replace(reg, mag_bit16=bit16)
    si = raw_to_si(raw, reg, (128, 128, 128) if asa is None else asa, mounting)
    flags = imu_flags_from_raw(raw)
    mag = si.mag_b
    invalid = (flags & fl.IMU_MAG_INVALID) != 0
    if invalid.any():
        mag = mag.copy()
        mag[invalid] = np.nan
    return RawInputs(si.gyro_b, si.accel_b, mag, flags, si.temperature_c, bit16)


# --------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class RawLog:
    """A raw log read from CSV: the registers, the time stamps and the configuration found."""

    raw: Any
    """``sensors.RawSamples``."""
    t_s: np.ndarray | None
    registers: dict[str, Any] = field(default_factory=dict)
    """``gyro_fs_sel``, ``accel_fs_sel``, ``mag_bit16`` as far as the header gives them."""
    asa: tuple[int, int, int] | None = None
    mounting: np.ndarray | None = None
    fs_hz: float | None = None


def is_raw_header(columns: list[str]) -> bool:
    """Whether CSV column names are those of a raw log (any word or status column present: a
    raw log that lacks some is then reported as such)."""
    return any(c in columns for c in RAW_WORD_COLUMNS + RAW_STATUS_COLUMNS)


def _numbers(text: str) -> list[str]:
    return text.replace(",", " ").split()


def parse_header_value(key: str, text: str, where: str) -> Any:
    """The value of one configuration key (header line or command-line option); ValueError names it."""
    try:
        if key in ("gyro_fs_sel", "accel_fs_sel"):
            value = int(text)
            if not 0 <= value <= 3:
                raise ValueError
            return value
        if key == "mag_bit16":
            value = text.strip().lower()
            if value in ("1", "true", "16"):
                return True
            if value in ("0", "false", "14"):
                return False
            raise ValueError
        if key == "asa":
            value = tuple(int(x) for x in _numbers(text))
            if len(value) != 3 or not all(0 <= x <= 255 for x in value):
                raise ValueError
            return value
        if key == "mounting":
            value = np.array([float(x) for x in _numbers(text)])
            if value.size not in (4, 9) or not np.all(np.isfinite(value)):
                raise ValueError
            return value if value.size == 4 else value.reshape(3, 3)
        if key == "fs_hz":
            value = float(text)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError
            return value
    except ValueError:
        pass
    else:
        raise ValueError(f"{where}: unknown key {key!r}; known: {', '.join(HEADER_KEYS)}")
    expected = {
        "gyro_fs_sel": "an integer 0..3 (GYRO_FS_SEL)",
        "accel_fs_sel": "an integer 0..3 (ACCEL_FS_SEL)",
        "mag_bit16": "1 (16-bit) or 0 (14-bit)",
        "asa": "three integers 0..255 (the AK8963 fuse-ROM ASA bytes)",
        "mounting": "4 numbers q_body_chip (w x y z) or 9 (rotation chip -> body, row by row)",
        "fs_hz": "a positive sample rate in Hz",
    }[key]
    raise ValueError(f"{where}: {key} must be {expected}, got {text.strip()!r}")


def read_raw_csv(path: str | Path) -> RawLog:
    """Read a raw log (format in the module docstring). Errors name the file and the line."""
    from biso_cosim.sensors import RawSamples

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"input file {str(path)!r} does not exist")
    header: dict[str, Any] = {}
    with path.open(newline="") as handle:
        line_no = 0
        columns = None
        for line in handle:
            line_no += 1
            text = line.strip()
            if not text:
                continue
            if text.startswith("#"):
                body = text.lstrip("#").strip()
                key, sep, value = body.partition("=")
                if sep:
                    key = key.strip()
                    header[key] = parse_header_value(key, value, f"{path}, line {line_no}")
                continue
            columns = [c.strip() for c in next(csv.reader([text]))]
            break
        if columns is None:
            raise ValueError(f"{path}: no column names (the file is empty or holds only comments)")
        missing = [c for c in RAW_WORD_COLUMNS + RAW_STATUS_COLUMNS if c not in columns]
        if missing:
            raise ValueError(f"{path}: missing raw column(s) {missing}; a raw log has "
                             f"{list(RAW_WORD_COLUMNS + RAW_STATUS_COLUMNS)} (and optionally t_s)")
        index = [columns.index(c) for c in RAW_WORD_COLUMNS + RAW_STATUS_COLUMNS]
        t_index = columns.index("t_s") if "t_s" in columns else None
        ints, times = [], []
        for row in csv.reader(handle):
            line_no += 1
            if not row or (len(row) == 1 and not row[0].strip()):
                continue
            try:
                ints.append([int(row[i]) for i in index])
                if t_index is not None:
                    times.append(float(row[t_index]))
            except (ValueError, IndexError):
                raise ValueError(f"{path}, line {line_no}: expected integers in the raw columns"
                                 f"{' and a number in t_s' if t_index is not None else ''}") from None
    if not ints:
        raise ValueError(f"{path}: no samples after the column names")
    data = np.asarray(ints, dtype=np.int64)
    words, status = data[:, :10], data[:, 10:]
    for name, block, low, high in (("word", words, _CODE_MIN, _CODE_MAX), ("status byte", status, 0, 255)):
        bad = np.argwhere((block < low) | (block > high))
        if bad.size:
            r, col = bad[0]
            cols = RAW_WORD_COLUMNS if name == "word" else RAW_STATUS_COLUMNS
            raise ValueError(f"{path}: sample {r}, {cols[col]} = {block[r, col]} is not a {name} "
                             f"({low}..{high})")
    raw = RawSamples(words.astype(np.int16), status.astype(np.uint8))
    registers = {k: header[k] for k in ("gyro_fs_sel", "accel_fs_sel", "mag_bit16") if k in header}
    return RawLog(raw, np.asarray(times) if t_index is not None else None, registers, header.get("asa"),
                  header.get("mounting"), header.get("fs_hz"))


def write_raw_csv(path: str | Path, raw: Any, *, t_s: Any = None, registers: Any = None, asa: Any = None,
                  mounting: Any = None, fs_hz: float | None = None) -> Path:
    """Write raw registers as a raw log, with the configuration in the header (what is given)."""
    from biso_cosim.sensors import Registers

    path = Path(path)
    lines = [f"# {HEADER_TITLE}"]
    if registers is not None:
        reg = Registers.coerce(registers)
        lines += [f"# gyro_fs_sel = {reg.gyro_fs_sel}", f"# accel_fs_sel = {reg.accel_fs_sel}",
                  f"# mag_bit16 = {int(reg.mag_bit16)}"]
    if asa is not None:
        lines.append("# asa = " + " ".join(str(int(x)) for x in np.asarray(asa).ravel()))
    if mounting is not None:
        lines.append("# mounting = " + " ".join(repr(float(x)) for x in np.asarray(mounting, dtype=float).ravel()))
    if fs_hz is not None:
        lines.append(f"# fs_hz = {float(fs_hz)!r}")
    names = list(RAW_WORD_COLUMNS + RAW_STATUS_COLUMNS)
    cols: list[np.ndarray] = [np.asarray(raw.words, dtype=np.int64), np.asarray(raw.status, dtype=np.int64)]
    fmt = ["%d"] * 12
    table = np.column_stack(cols)
    if t_s is not None:
        t = np.asarray(t_s, dtype=np.float64)
        if t.shape != (table.shape[0],):
            raise ValueError(f"t_s must have shape ({table.shape[0]},) like raw, got {t.shape}")
        names.insert(0, "t_s")
        fmt.insert(0, "%.9f")
        table = np.column_stack([t, table])
    lines.append(",".join(names))
    np.savetxt(path, table, fmt=fmt, delimiter=",", header="\n".join(lines), comments="")
    return path
