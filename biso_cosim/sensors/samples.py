"""What the virtual MPU-9250 delivers: SI readings, raw registers, flags, increments.

`ImuSamples` holds the readings of one `MPU9250.simulate` call; `RawSamples` the register
values exactly as a driver reads them, with their byte layout; `raw_to_si` converts raw
registers (simulated, or read from a real chip) into SI body-axes readings.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from typing import Any, Mapping, Sequence

import numpy as np

from biso_cosim.sensors import _kernels as K
from biso_cosim.sensors.registers import Registers, chip_tables

__all__ = ["ImuFlag", "ImuSamples", "RawSamples", "SiReadings", "raw_to_si", "mounting_matrix", "AK8963_FROM_CHIP"]


class ImuFlag(enum.IntFlag):
    """Bits of `ImuSamples.flags`."""

    GYRO_SATURATED = K.FLAG_GYRO_SATURATED
    """A gyro axis was clipped at the full scale during the output interval."""
    ACCEL_SATURATED = K.FLAG_ACCEL_SATURATED
    """An accelerometer axis was clipped at the full scale during the output interval."""
    MAG_OVERFLOW = K.FLAG_MAG_OVERFLOW
    """AK8963 ST2.HOFL of the held sample: |x| + |y| + |z| >= 4912 µT, data not valid."""
    MAG_OVERRUN = K.FLAG_MAG_OVERRUN
    """AK8963 ST1.DOR: more than one AK8963 sample since the previous output (one was lost)."""
    MAG_INVALID = K.FLAG_MAG_INVALID
    """No AK8963 sample (powered down): ``mag_b`` is NaN."""


# AK8963 axes from the accel/gyro chip axes: m_x = a_y, m_y = a_x, m_z = -a_z (PS-MPU-9250A §9.1).
AK8963_FROM_CHIP = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def mounting_matrix(mounting: Any) -> np.ndarray:
    """Rotation matrix chip -> body from a (4,) quaternion ``q_body_chip``, a (3, 3) matrix or None.

    Raises ValueError if the input is not a rotation (quaternion norm or orthonormality
    and determinant off by more than 1e-6).
    """
    if mounting is None:
        return np.eye(3)
    m = np.asarray(mounting, dtype=np.float64)
    if not np.all(np.isfinite(m)):
        raise ValueError("mounting must be finite")
    if m.shape == (4,):
        w, x, y, z = (float(c) for c in m)
        # summed left to right, as the C sensor does (np.linalg.norm's reduction order depends
        # on the numpy build and moves the last bit)
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"mounting quaternion q_body_chip must have unit norm, got norm {norm:.9g}")
        w, x, y, z = w / norm, x / norm, y / norm, z / norm
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
    if m.shape == (3, 3):
        if np.max(np.abs(m @ m.T - np.eye(3))) > 1e-6 or np.linalg.det(m) < 0.0:
            raise ValueError("mounting matrix must be a rotation (orthonormal, determinant +1)")
        return m.copy()
    raise ValueError(f"mounting must be a (4,) quaternion q_body_chip, a (3, 3) rotation matrix or None, got shape {m.shape}")


class RawSamples:
    """Register values per output sample, as a driver reads them.

    Stored as two blocks in register order (cheap to produce and to concatenate):
    ``words`` (k, 10) int16 = ACCEL_X, ACCEL_Y, ACCEL_Z, TEMP, GYRO_X, GYRO_Y, GYRO_Z (the
    MPU-9250's 0x3B..0x48) and HX, HY, HZ (AK8963); ``status`` (k, 2) uint8 = ST1, ST2.

    Attributes (views):
        accel: (k, 3) int16 ACCEL_XOUT..ACCEL_ZOUT, chip axes.
        temp: (k,) int16 TEMP_OUT.
        gyro: (k, 3) int16 GYRO_XOUT..GYRO_ZOUT, chip axes.
        mag: (k, 3) int16 AK8963 HX, HY, HZ, AK8963 axes, before the ASA adjustment.
        st1: (k,) uint8 AK8963 ST1 (bit 0 DRDY, bit 1 DOR).
        st2: (k,) uint8 AK8963 ST2 (bit 3 HOFL, bit 4 BITM = 16-bit output).
    """

    __slots__ = ("words", "status")

    def __init__(self, words: np.ndarray, status: np.ndarray) -> None:
        self.words = words
        self.status = status

    @classmethod
    def from_fields(cls, accel, temp, gyro, mag, st1, st2) -> "RawSamples":
        """Build from the separate register arrays."""
        words = np.concatenate([np.asarray(accel), np.asarray(temp)[:, None], np.asarray(gyro), np.asarray(mag)], axis=1)
        return cls(words.astype(np.int16), np.stack([st1, st2], axis=1).astype(np.uint8))

    accel = property(lambda self: self.words[:, 0:3])
    temp = property(lambda self: self.words[:, 3])
    gyro = property(lambda self: self.words[:, 4:7])
    mag = property(lambda self: self.words[:, 7:10])
    st1 = property(lambda self: self.status[:, 0])
    st2 = property(lambda self: self.status[:, 1])

    def __len__(self) -> int:
        return self.words.shape[0]

    def mpu_bytes(self) -> np.ndarray:
        """(k, 14) uint8: registers 0x3B..0x48 (ACCEL_XOUT_H ... GYRO_ZOUT_L), big-endian."""
        return np.ascontiguousarray(self.words[:, :7]).astype(">i2").view(np.uint8).reshape(len(self), 14)

    def ak8963_bytes(self) -> np.ndarray:
        """(k, 8) uint8: AK8963 registers 0x02..0x09 (ST1, HXL, HXH, HYL, HYH, HZL, HZH, ST2),
        as they land in EXT_SENS_DATA_00..07; data little-endian."""
        out = np.empty((len(self), 8), dtype=np.uint8)
        out[:, 0] = self.st1
        out[:, 1:7] = np.ascontiguousarray(self.mag).astype("<i2").view(np.uint8).reshape(len(self), 6)
        out[:, 7] = self.st2
        return out

    @classmethod
    def from_bytes(cls, mpu_bytes: Any, ak8963_bytes: Any) -> "RawSamples":
        """Parse the two byte blocks of `mpu_bytes` and `ak8963_bytes` (e.g. from a real log)."""
        mb = np.ascontiguousarray(mpu_bytes, dtype=np.uint8)
        ab = np.ascontiguousarray(ak8963_bytes, dtype=np.uint8)
        if mb.ndim != 2 or mb.shape[1] != 14:
            raise ValueError(f"mpu_bytes must have shape (k, 14), got {mb.shape}")
        if ab.shape != (mb.shape[0], 8):
            raise ValueError(f"ak8963_bytes must have shape ({mb.shape[0]}, 8), got {ab.shape}")
        words = np.empty((mb.shape[0], 10), dtype=np.int16)
        words[:, :7] = mb.view(">i2").reshape(-1, 7)
        words[:, 7:] = ab[:, 1:7].copy().view("<i2").reshape(-1, 3)
        return cls(words, ab[:, [0, 7]].copy())

    @classmethod
    def concatenate(cls, parts: Sequence["RawSamples"]) -> "RawSamples":
        return cls(np.concatenate([p.words for p in parts]), np.concatenate([p.status for p in parts]))

    def __repr__(self) -> str:
        return f"RawSamples(k={len(self)})"


@dataclasses.dataclass
class ImuSamples:
    """Readings of one `MPU9250.simulate` call (k output samples, k may be 0).

    Attributes:
        t_s: (k,) time stamps in s on the input time axis: the instant the chip latches the
            sample into its output registers.
        gyro_b: (k, 3) rad/s, vehicle body axes (after the mounting rotation).
        accel_b: (k, 3) m/s², specific force (+g up at rest), body axes.
        mag_b: (k, 3) µT, body axes: the latest AK8963 sample (after the ASA adjustment
            and the axis mapping), held between its updates; NaN while powered down.
        mag_fresh: (k,) bool: a new AK8963 measurement since the previous output sample.
        temperature_c: (k,) on-chip temperature reading in °C.
        flags: (k,) int32 bitmask of `ImuFlag`.
        raw: the register values (`RawSamples`).
        dtheta, dv: (k, r, 3) with ``increments=r``: ``[:, j]`` holds the (j+1)-fold iterated
            integral of the angular rate (rad·s^j) / specific force (m/s·s^j) over the output
            interval (t_s - T, t_s], body axes; else None.
        dtheta_sub, dv_sub: (k, m, 3) with ``subintervals=m``: ordinary increments over the
            m equal parts of each output interval (they sum to ``dtheta[:, 0]``); else None.
    """

    t_s: np.ndarray
    gyro_b: np.ndarray
    accel_b: np.ndarray
    mag_b: np.ndarray
    mag_fresh: np.ndarray
    temperature_c: np.ndarray
    flags: np.ndarray
    raw: RawSamples
    dtheta: np.ndarray | None = None
    dv: np.ndarray | None = None
    dtheta_sub: np.ndarray | None = None
    dv_sub: np.ndarray | None = None

    def __len__(self) -> int:
        return self.t_s.shape[0]

    @classmethod
    def concatenate(cls, parts: Sequence["ImuSamples"]) -> "ImuSamples":
        """One `ImuSamples` from consecutive ones (e.g. the outputs of streaming calls)."""
        parts = list(parts)
        if not parts:
            raise ValueError("parts must hold at least one ImuSamples")
        values: dict[str, Any] = {}
        for f in dataclasses.fields(cls):
            items = [getattr(p, f.name) for p in parts]
            if f.name == "raw":
                values[f.name] = RawSamples.concatenate(items)
            elif all(v is None for v in items):
                values[f.name] = None
            elif any(v is None for v in items):
                raise ValueError(f"parts disagree on {f.name}: some have it, some do not")
            else:
                values[f.name] = np.concatenate(items)
        return cls(**values)

    def flagged(self, flag: ImuFlag) -> np.ndarray:
        """(k,) bool: samples that carry ``flag``."""
        return (self.flags & int(flag)) != 0


@dataclasses.dataclass
class SiReadings:
    """SI readings in vehicle body axes from raw registers (see `raw_to_si`)."""

    gyro_b: np.ndarray
    accel_b: np.ndarray
    mag_b: np.ndarray
    temperature_c: np.ndarray


def _rotate(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    # the kernel's expression order, so that the results agree bit for bit
    return np.stack([r[i, 0] * v[:, 0] + r[i, 1] * v[:, 1] + r[i, 2] * v[:, 2] for i in range(3)], axis=1)


def raw_to_si(
    raw: RawSamples,
    registers: Registers | Mapping[str, Any] | None = None,
    asa: Any = (128, 128, 128),
    mounting: Any = None,
) -> SiReadings:
    """Convert raw registers into SI readings in vehicle body axes.

    The conversion a driver does, usable on logs of a real chip (build ``raw`` with
    `RawSamples.from_bytes`):

    * gyro: ``code / S_g`` with S_g = 131, 65.5, 32.8, 16.4 LSB per °/s (GYRO_FS_SEL), in rad/s;
    * accel: ``code / S_a`` with S_a = 16384, 8192, 4096, 2048 LSB/g (ACCEL_FS_SEL), g = 9.80665;
    * temperature: ``code / 333.87 + 21`` °C;
    * magnetometer: ``code · R · ((ASA - 128)/256 + 1)`` µT with R = 0.15 (16-bit) or 0.6
      (14-bit) µT/LSB, then AK8963 axes to chip axes (chip x = m_y, y = m_x, z = -m_z);
    * then chip axes to body axes with the mounting rotation (``q_body_chip`` or matrix).

    Args:
        raw: register values.
        registers: the configuration the log was taken with (only the full-scale fields and
            the AK8963 BIT matter); None for the defaults.
        asa: the three fuse-ROM ASA bytes of the part (128 = no adjustment).
        mounting: rotation chip -> body, as for `MPU9250`.
    """
    reg = Registers.coerce(registers)
    asa_arr = np.asarray(asa)
    if asa_arr.shape != (3,) or not np.all((asa_arr >= 0) & (asa_arr <= 255)):
        raise ValueError(f"asa must be three integers in [0, 255], got {asa!r}")
    r_bc = mounting_matrix(mounting)
    temp_c = chip_tables()["temperature"]
    gyro_chip = raw.gyro.astype(np.float64) / reg.gyro_lsb_per_unit
    accel_chip = raw.accel.astype(np.float64) / reg.accel_lsb_per_unit
    adj = (asa_arr.astype(np.float64) - 128.0) / 256.0 + 1.0
    mag_ak = raw.mag.astype(np.float64) * reg.mag_resolution_ut * adj
    return SiReadings(
        gyro_b=_rotate(r_bc, gyro_chip),
        accel_b=_rotate(r_bc, accel_chip),
        mag_b=_rotate(r_bc @ AK8963_FROM_CHIP.T, mag_ak),
        temperature_c=raw.temp.astype(np.float64) / temp_c["sensitivity_lsb_per_c"] + temp_c["offset_c"],
    )
