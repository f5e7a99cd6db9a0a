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
"""Accelerometer sample non-finite, zero or absurd: no positional correction this sample."""

MAG_INVALID = 1 << 3
"""Magnetometer sample non-finite, zero or parallel to the specific force: heading is not
corrected (the correction keeps the estimate's own heading and corrects tilt only)."""

SATURATED = 1 << 4
"""An input axis is at or beyond the full scale declared in the parameters."""

ACCEL_GATED = 1 << 5
"""biso_plus: tilt correction suspended or down-weighted (|f| far from g, or after compensation)."""

MAG_DISTURBED = 1 << 6
"""biso_plus: magnetic disturbance detected (field norm or dip off the expected field)."""

REST = 1 << 7
"""biso_plus: rest detected; the gyro bias is being estimated from the raw gyro."""

ACCEL_COMPENSATED = 1 << 8
"""biso_plus: the specific force was corrected for vehicle acceleration from the speed input."""

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
}
"""Bit → name, for logs and CSV columns."""


def describe(flags: int) -> list[str]:
    """Names of the bits set in one flags value, lowest bit first."""
    flags = int(flags)
    return [name for bit, name in NAMES.items() if flags & bit]
