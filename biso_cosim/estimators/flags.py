"""Per-sample flags of every estimator: one integer bitmask per output sample.

A flag says what the estimator did with that sample, so that a log explains itself. The
faithful ``biso`` and the baselines raise only the input flags (all zero on valid data);
``biso_plus`` also reports gating, disturbances and rest.
"""

from __future__ import annotations

UNINITIALIZED = 1 << 0
"""No attitude yet (no valid accelerometer sample so far); the output is the identity."""

GYRO_INVALID = 1 << 1
"""Gyro sample non-finite or beyond 1e4 rad/s: propagated with the last valid gyro sample."""

ACCEL_INVALID = 1 << 2
"""Accelerometer sample not used: non-finite, zero, absurd (beyond 1e6 m/s²) or saturated.
No positional correction from it this sample."""

MAG_INVALID = 1 << 3
"""Magnetometer sample not used: non-finite, zero, absurd, parallel to the specific force,
reported invalid or overflowed by the sensor, or the accelerometer sample not used. Heading
is not corrected (tilt only, keeping the estimate's own heading)."""

SATURATED = 1 << 4
"""An input axis is at or beyond 99.9 % of a declared full scale (parameters
``gyro_range_rad_s``, ``accel_range_mps2``), or the sensor flags it (input ``imu_flags``:
gyro or accelerometer saturated, AK8963 overflow). A saturated gyro sample is still used; a
saturated accelerometer or magnetometer sample is not (ACCEL_INVALID, MAG_INVALID)."""

ACCEL_GATED = 1 << 5
"""biso_plus: tilt correction suspended or down-weighted (|f| far from g, or after compensation)."""

MAG_DISTURBED = 1 << 6
"""biso_plus: magnetic disturbance detected (field norm or dip off the expected field)."""

REST = 1 << 7
"""biso_plus: rest detected; the gyro bias is being estimated from the raw gyro."""

ACCEL_COMPENSATED = 1 << 8
"""biso_plus: the specific force was corrected for vehicle acceleration from the speed input."""

GNSS_UPDATE = 1 << 9
"""gnss_*: a GNSS fix (or, unaided, the gravity reference) corrected the tilt at this sample."""

GNSS_UNAIDED = 1 << 10
"""gnss_*: no usable GNSS fix for ``max_interval_s``; the estimator runs on its fall-back."""

GNSS_REJECTED = 1 << 11
"""gnss_*: a fix arriving at this sample was refused (non-finite, too old, gate, geometry)."""

# Bits of the optional per-sample input ``imu_flags``: the sensor's own flags, the values of
# ``biso_cosim.sensors.ImuFlag`` (kept here so that the estimators need not import the sensor
# package; a test checks that they agree).
IMU_GYRO_SATURATED = 1
IMU_ACCEL_SATURATED = 2
IMU_MAG_OVERFLOW = 4
IMU_MAG_OVERRUN = 8
IMU_MAG_INVALID = 16

NAMES = {
    UNINITIALIZED: "uninitialized",
    GYRO_INVALID: "gyro_invalid",
    ACCEL_INVALID: "accel_invalid",
    MAG_INVALID: "mag_invalid",
    SATURATED: "saturated",
    ACCEL_GATED: "accel_gated",
    MAG_DISTURBED: "mag_disturbed",
    REST: "rest",
    ACCEL_COMPENSATED: "accel_compensated",
    GNSS_UPDATE: "gnss_update",
    GNSS_UNAIDED: "gnss_unaided",
    GNSS_REJECTED: "gnss_rejected",
}
"""Bit → name, for logs and CSV columns."""


def describe(flags: int) -> list[str]:
    """Names of the bits set in one flags value, lowest bit first."""
    flags = int(flags)
    return [name for bit, name in NAMES.items() if flags & bit]
