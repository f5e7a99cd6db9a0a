"""Per-sample pieces shared by the estimator kernels: input validity and saturation, the
quaternion exponential of one gyro step, the attitude from an up and an east direction.

Every function here is ``inline="always"``: numba pastes it into the calling kernel, so the
whole per-sample update compiles to one function body with its state in registers (a call
between separately compiled numba functions costs a status check and a round trip of the
arguments through memory on every sample). Kernels of other modules may import them:

* ``_input_checks``: validity of one (gyro, accelerometer, magnetometer) sample, the
  sensor's own flags and the declared full scales, with the estimators' common policy;
* ``_gyro_ok``, ``_accel_ok``, ``_mag_ok``: the single tests it is made of;
* ``_qexp_fast``: e^{(0, r)/2}, the rotation by the vector r, trig-free for small steps;
* ``_q_from_up_east``: q_wb from the up and east directions in body axes (Shepperd's method
  without normalising the rows first).
"""

from __future__ import annotations

import math

from biso_cosim._numba import jit
from biso_cosim.estimators import flags as fl

__all__ = ["MAX_RATE", "MIN_ACCEL", "MAX_ACCEL", "MIN_MAG", "MAX_MAG", "MAG_PARALLEL_SIN", "SATURATION_FRACTION"]

# Validity limits of one input sample (beyond any MEMS full scale, below float overflow).
MAX_RATE = 1.0e4  # rad/s
MIN_ACCEL, MAX_ACCEL = 1.0e-6, 1.0e6  # m/s²
MIN_MAG, MAX_MAG = 1.0e-6, 1.0e7  # µT
MAG_PARALLEL_SIN = 1.0e-6
"""sin of the angle between the field and the specific force below which the field gives no heading."""
SATURATION_FRACTION = 0.999
"""An axis at or beyond this fraction of a declared full scale counts as saturated."""

# Taylor coefficients of cos(θ) and sin(θ)/θ in x = θ², θ = |r|/2 (reciprocals precomputed:
# a division costs several multiplications and the divider is shared by the whole update).
_C2, _C4, _C6, _C8 = 1.0 / 2.0, 1.0 / 24.0, 1.0 / 720.0, 1.0 / 40320.0
_S2, _S4, _S6, _S8 = 1.0 / 6.0, 1.0 / 120.0, 1.0 / 5040.0, 1.0 / 362880.0
# Below this x the terms in x² of both series are under 2⁻⁵⁴ (x²/24 < 2⁻⁵⁴ for x < 3.6e-8), less
# than half an ulp of 1 − x/2 or 1 − x/6 ∈ (0.5, 1]: adding them does not change the rounded sum,
# so the first-order form is the same number (|r| < 3.4e-4 rad: a correction step, a gyro step at rest).
_X_FIRST = 3.0e-8


@jit(inline="always")
def _gyro_ok(x, y, z):
    """Finite and |ω| < MAX_RATE (a NaN or an infinity fails the comparison: |ω|² is one then)."""
    n2 = x * x + y * y + z * z
    return n2 < MAX_RATE * MAX_RATE


@jit(inline="always")
def _accel_ok(x, y, z):
    """(ok, |f|²): finite and MIN_ACCEL < |f| < MAX_ACCEL (as _gyro_ok: no separate finiteness test)."""
    n2 = x * x + y * y + z * z
    return n2 > MIN_ACCEL * MIN_ACCEL and n2 < MAX_ACCEL * MAX_ACCEL, n2


@jit(inline="always")
def _mag_ok(x, y, z):
    """(ok, |m|²): finite and MIN_MAG < |m| < MAX_MAG (as _gyro_ok)."""
    n2 = x * x + y * y + z * z
    return n2 > MIN_MAG * MIN_MAG and n2 < MAX_MAG * MAX_MAG, n2


@jit(inline="always")
def _beyond(x, y, z, limit):
    """Any axis of a finite sample at or beyond ``limit`` (inf: never, and not tested: no full
    scale declared is the common case)."""
    return limit < math.inf and (abs(x) >= limit or abs(y) >= limit or abs(z) >= limit)


@jit(inline="always")
def _input_checks(gx, gy, gz, ax, ay, az, mx, my, mz, hx, hy, hz, imu_flags, gyro_limit, accel_limit):
    """The common input policy of every estimator, for one sample.

    ``(hx, hy, hz)`` is the last valid gyro sample; ``imu_flags`` the sensor's flag bits for
    this sample (``flags.IMU_*``, 0 if unknown); the limits are SATURATION_FRACTION of the
    declared full scales (inf: none). Returns ``(flags, gx, gy, gz, acc_ok, f2, mag_ok, ex,
    ey, ez, e2)``: the gyro sample to use (the held one if this one is invalid; it is also
    the new held sample), whether the accelerometer and magnetometer samples may be used,
    |f|², and E = m × f with |E|² (the unnormalised east direction when mag_ok).

    * gyro non-finite or |ω| ≥ MAX_RATE: the held sample, GYRO_INVALID; saturated (an axis
      at full scale, or the sensor says so): used as it is, SATURATED;
    * accelerometer non-finite, |f| ≤ MIN_ACCEL or ≥ MAX_ACCEL, or saturated: not used,
      ACCEL_INVALID (and SATURATED when saturated);
    * magnetometer non-finite, |m| ≤ MIN_MAG or ≥ MAX_MAG, reported invalid or overflowed
      by the sensor (AK8963 HOFL: SATURATED too), or parallel to f (no heading in it), or
      the accelerometer sample not used: not used, MAG_INVALID.
    """
    flags = 0
    if _gyro_ok(gx, gy, gz):
        if _beyond(gx, gy, gz, gyro_limit) or (imu_flags & fl.IMU_GYRO_SATURATED):
            flags |= fl.SATURATED
    else:
        gx, gy, gz = hx, hy, hz
        flags |= fl.GYRO_INVALID
    acc_ok, f2 = _accel_ok(ax, ay, az)
    if acc_ok and (_beyond(ax, ay, az, accel_limit) or (imu_flags & fl.IMU_ACCEL_SATURATED)):
        acc_ok = False
        flags |= fl.SATURATED
    if not acc_ok:
        flags |= fl.ACCEL_INVALID
    ex = my * az - mz * ay
    ey = mz * ax - mx * az
    ez = mx * ay - my * ax
    e2 = ex * ex + ey * ey + ez * ez
    mag_ok, m2 = _mag_ok(mx, my, mz)
    if imu_flags & fl.IMU_MAG_OVERFLOW:
        flags |= fl.SATURATED
        mag_ok = False
    if imu_flags & fl.IMU_MAG_INVALID:
        mag_ok = False
    mag_ok = mag_ok and acc_ok and e2 > (MAG_PARALLEL_SIN * MAG_PARALLEL_SIN) * m2 * f2
    if not mag_ok:
        flags |= fl.MAG_INVALID
    return flags, gx, gy, gz, acc_ok, f2, mag_ok, ex, ey, ez, e2


@jit(inline="always")
def _qexp_fast(rx, ry, rz):
    """e^{(0, r)/2}: the rotation by |r| about r. For |r| ≤ 0.1 rad (every gyro step below
    20 rad/s at 200 Hz) a Taylor series to the 8th power is exact to rounding (next terms
    < 3e-20) and needs no trigonometry; beyond, sin and cos. Below |r| ≈ 3.4e-4 rad its
    first-order part alone rounds to the same numbers (_X_FIRST)."""
    t2 = rx * rx + ry * ry + rz * rz
    if t2 <= 0.01:
        x = 0.25 * t2  # (|r|/2)²
        if x <= _X_FIRST:  # the terms in x² change neither sum: the same numbers, sooner
            s = 0.5 * (1.0 - x * _S2)
            return 1.0 - x * _C2, s * rx, s * ry, s * rz
        x2 = x * x
        # Estrin's scheme: half the chain of dependent operations of Horner's
        c = (1.0 - x * _C2) + x2 * ((_C4 - x * _C6) + x2 * _C8)
        s = 0.5 * ((1.0 - x * _S2) + x2 * ((_S4 - x * _S6) + x2 * _S8))
        return c, s * rx, s * ry, s * rz
    angle = math.sqrt(t2)
    s = math.sin(0.5 * angle) / angle
    return math.cos(0.5 * angle), s * rx, s * ry, s * rz


@jit(inline="always")
def _q_from_up_east(fx, fy, fz, f2, ex, ey, ez, e2):
    """q_wb whose world Up is along f and world East along e, both in body axes, e ⊥ f, any
    non-zero lengths (|f|², |e|² given); w ≥ 0 where the trace case is taken.

    The rows of R_wb are E/|E|, N/(|f||E|), f/|f| with N = f × E; Shepperd's method is run
    on s·R_wb = (E|f|, N, f|E|), s = |f||E|: of the four expressions of q (from the trace
    or a diagonal element), the one whose leading term T = s(1 + …) is largest is scaled by
    1/(2√(sT)). Two square roots of the inputs (independent), one for the result and one
    division, instead of normalising each row first; the case is chosen by selections, not
    branches (attitudes that change case often, as in tumbling, cost no mispredictions).
    """
    fn = math.sqrt(f2)
    en = math.sqrt(e2)
    s = fn * en
    r00, r01, r02 = ex * fn, ey * fn, ez * fn
    r10, r11, r12 = fy * ez - fz * ey, fz * ex - fx * ez, fx * ey - fy * ex
    r20, r21, r22 = fx * en, fy * en, fz * en
    t0 = s + (r00 + r11 + r22)
    t1 = s + (r00 - r11 - r22)
    t2 = s + (r11 - r00 - r22)
    t3 = s + (r22 - r00 - r11)
    d21, d02, d10 = r21 - r12, r02 - r20, r10 - r01
    s01, s02, s12 = r01 + r10, r02 + r20, r12 + r21
    # case 0: (t0, d21, d02, d10); 1: (d21, t1, s01, s02); 2: (d02, s01, t2, s12); 3: (d10, s02, s12, t3)
    c23 = t3 > t2
    t23 = t3 if c23 else t2
    w23 = d10 if c23 else d02
    x23 = s02 if c23 else s01
    y23 = s12 if c23 else t2
    z23 = t3 if c23 else s12
    c01 = t1 > t0
    t01 = t1 if c01 else t0
    w01 = d21 if c01 else t0
    x01 = t1 if c01 else d21
    y01 = s01 if c01 else d02
    z01 = s02 if c01 else d10
    c = t23 > t01
    t = t23 if c else t01
    i = 0.5 / math.sqrt(s * t)
    return ((w23 if c else w01) * i, (x23 if c else x01) * i, (y23 if c else y01) * i,
            (z23 if c else z01) * i)


@jit(inline="always")
def _rotate_true_north(cdh, sdh, w, x, y, z):
    """(cos D/2, 0, 0, −sin D/2) ∘ q: an attitude relative to magnetic north → true north
    (the world turned by −D about Up; D east positive)."""
    return cdh * w + sdh * z, cdh * x + sdh * y, cdh * y - sdh * x, cdh * z - sdh * w
