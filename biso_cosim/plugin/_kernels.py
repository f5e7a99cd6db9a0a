"""The plug-in's numba kernels: check and convert a block of host truth rows; the truth at
the chip's sample instants.

Kernels never raise: ``prepare`` returns a code naming the first bad input and its row, and
the wrapper (``imu_plugin.py``) turns it into the ValueError. The frames' scalar kernels
(``biso_cosim.frames._q*``) are the package's quaternion arithmetic inside kernels.
"""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.frames import _qmul, _qrot, _qrot_inv

__all__ = ["prepare", "truth_at_samples", "BAD_INPUTS", "QUAT_NORM_TOL", "TIME_TOL"]

QUAT_NORM_TOL = 1e-5
"""A given attitude quaternion must have |q| within 1 ± this (float32 hosts give ~1e-7)."""

TIME_TOL = 1e-3
"""A tick's time may differ from t₀ + k·tick_s by at most this fraction of tick_s."""

# codes returned by ``prepare`` (0: all rows good)
BAD_INPUTS = {
    1: "t_s", 2: "t_s", 3: "t_s", 4: "q_wb", 5: "q_wb", 6: "omega_b", 7: "specific_force_b", 8: "accel_w",
    9: "alpha_b", 10: "p_w", 11: "v_w", 12: "temperature_c",
}

_S = math.sqrt(0.5)


@jit
def _world_to_enu(ned, x, y, z):
    if ned:
        return y, x, -z
    return x, y, z


@jit
def _body_to_flu(frd, x, y, z):
    if frd:
        return x, -y, -z
    return x, y, z


@jit
def _finite3(a, i):
    return math.isfinite(a[i, 0]) and math.isfinite(a[i, 1]) and math.isfinite(a[i, 2])


@jit
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@jit
def prepare(codes, r_b, g_enu, tick_s, t0_s, tick0, prev_omega, t, q, omega, force, accel, alpha, p, v, temp,
            q_out, omega_out, force_out, p_out, v_out):
    """Check the host's truth rows and write them in the package's frames, at the chip.

    ``codes`` = (ned, frd, scalar_last, accel_mode, lever, have_prev). Row i is tick
    ``tick0 + i``, due at ``t0_s + (tick0 + i)·tick_s``. ``force`` (specific force, host body)
    or, with accel_mode, ``accel`` (the reference point's acceleration, host world) with
    gravity ``g_enu``: f_b = q* ∘ (a − g) ∘ q. ``alpha`` (n, 3) or empty: angular
    acceleration (host body); empty: the slope (ω_i − ω_{i−1})/tick_s of the linear
    interpolation the chip applies between ticks (0 at the very first tick). With lever, the
    chip at r_b (FLU, from the reference point) feels f + ω × (ω × r) + ω̇ × r and sits at
    p + q ∘ r ∘ q*. ``p``/``v`` (n, 3) or empty (zero); ``temp`` (n,) or empty.

    Returns (0, 0) or (code, row) of the first bad value (``BAD_INPUTS``); nothing but the
    output arrays is written.
    """
    ned, frd, last, accel_mode, lever, have_prev = codes[0], codes[1], codes[2], codes[3], codes[4], codes[5]
    n = t.shape[0]
    pwx, pwy, pwz = prev_omega[0], prev_omega[1], prev_omega[2]
    for i in range(n):
        ti = t[i]
        if not math.isfinite(ti):
            return 1, i
        due = t0_s + (tick0 + i) * tick_s
        if ti < due - TIME_TOL * tick_s:
            return 2, i
        if ti > due + TIME_TOL * tick_s:
            return 3, i
        if last:
            w, x, y, z = q[i, 3], q[i, 0], q[i, 1], q[i, 2]
        else:
            w, x, y, z = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        if not (math.isfinite(w) and math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            return 4, i
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        if abs(norm - 1.0) > QUAT_NORM_TOL:
            return 5, i
        if ned:
            w, x, y, z = _qmul(0.0, _S, _S, 0.0, w, x, y, z)
        if frd:
            w, x, y, z = _qmul(w, x, y, z, 0.0, 1.0, 0.0, 0.0)
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / norm, x / norm, y / norm, z / norm
        q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = w, x, y, z
        if not _finite3(omega, i):
            return 6, i
        wx, wy, wz = _body_to_flu(frd, omega[i, 0], omega[i, 1], omega[i, 2])
        omega_out[i, 0], omega_out[i, 1], omega_out[i, 2] = wx, wy, wz
        if accel_mode:
            if not _finite3(accel, i):
                return 8, i
            ax, ay, az = _world_to_enu(ned, accel[i, 0], accel[i, 1], accel[i, 2])
            fx, fy, fz = _qrot_inv(w, x, y, z, ax - g_enu[0], ay - g_enu[1], az - g_enu[2])
        else:
            if not _finite3(force, i):
                return 7, i
            fx, fy, fz = _body_to_flu(frd, force[i, 0], force[i, 1], force[i, 2])
        if alpha.shape[0] > 0:
            if not _finite3(alpha, i):
                return 9, i
            alx, aly, alz = _body_to_flu(frd, alpha[i, 0], alpha[i, 1], alpha[i, 2])
        elif have_prev or i > 0:
            alx, aly, alz = (wx - pwx) / tick_s, (wy - pwy) / tick_s, (wz - pwz) / tick_s
        else:
            alx = aly = alz = 0.0
        pwx, pwy, pwz = wx, wy, wz
        if p.shape[0] > 0:
            if not _finite3(p, i):
                return 10, i
            px, py, pz = _world_to_enu(ned, p[i, 0], p[i, 1], p[i, 2])
        else:
            px = py = pz = 0.0
        if v.shape[0] > 0:
            if not _finite3(v, i):
                return 11, i
            v_out[i, 0], v_out[i, 1], v_out[i, 2] = _world_to_enu(ned, v[i, 0], v[i, 1], v[i, 2])
        else:
            v_out[i, 0] = v_out[i, 1] = v_out[i, 2] = 0.0
        if temp.shape[0] > 0 and not math.isfinite(temp[i]):
            return 12, i
        if lever:
            # rigid body: a_chip = a_ref + ω̇ × r + ω × (ω × r), all in body axes
            cx, cy, cz = _cross(wx, wy, wz, r_b[0], r_b[1], r_b[2])
            ccx, ccy, ccz = _cross(wx, wy, wz, cx, cy, cz)
            tx, ty, tz = _cross(alx, aly, alz, r_b[0], r_b[1], r_b[2])
            fx, fy, fz = fx + ccx + tx, fy + ccy + ty, fz + ccz + tz
            rx, ry, rz = _qrot(w, x, y, z, r_b[0], r_b[1], r_b[2])
            px, py, pz = px + rx, py + ry, pz + rz
        force_out[i, 0], force_out[i, 1], force_out[i, 2] = fx, fy, fz
        p_out[i, 0], p_out[i, 1], p_out[i, 2] = px, py, pz
    return 0, 0


@jit
def truth_at_samples(t_samples, tick_s, input_rate_hz, first_row, q_rows, v_rows, q_out, speed_out):
    """Attitude and forward speed of the reference point at each sample instant.

    ``q_rows``/``v_rows`` hold the tick before the block (row 0) and the block's ticks; tick
    ``first_row + j`` is row j. A sample at t lies on (t_{j−1}, t_j] with j the first tick at
    or after t; its truth is the normalised linear interpolation (on the shorter arc) at
    ``frac = (t − t_j)/tick_s + 1`` between the rows of ticks j − 1 and j, as
    fmu/imu_plugin.py forms it; the velocity is interpolated linearly and rotated into the
    body: its x component is the forward speed.
    """
    for k in range(t_samples.shape[0]):
        ts = t_samples[k]
        j = int(math.ceil(ts * input_rate_hz - 1e-6))
        t_j = j / input_rate_hz
        frac = (ts - t_j) / tick_s + 1.0
        frac = min(max(frac, 0.0), 1.0)
        # row of tick j (row r - 1 is tick j - 1), kept inside the rows given
        r = min(max(j - first_row + 1, 1), q_rows.shape[0] - 1)
        a0, a1, a2, a3 = q_rows[r - 1, 0], q_rows[r - 1, 1], q_rows[r - 1, 2], q_rows[r - 1, 3]
        b0, b1, b2, b3 = q_rows[r, 0], q_rows[r, 1], q_rows[r, 2], q_rows[r, 3]
        if a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 < 0.0:
            b0, b1, b2, b3 = -b0, -b1, -b2, -b3
        c0 = (1.0 - frac) * a0 + frac * b0
        c1 = (1.0 - frac) * a1 + frac * b1
        c2 = (1.0 - frac) * a2 + frac * b2
        c3 = (1.0 - frac) * a3 + frac * b3
        norm = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2 + c3 * c3)
        c0, c1, c2, c3 = c0 / norm, c1 / norm, c2 / norm, c3 / norm
        q_out[k, 0], q_out[k, 1], q_out[k, 2], q_out[k, 3] = c0, c1, c2, c3
        vx = (1.0 - frac) * v_rows[r - 1, 0] + frac * v_rows[r, 0]
        vy = (1.0 - frac) * v_rows[r - 1, 1] + frac * v_rows[r, 1]
        vz = (1.0 - frac) * v_rows[r - 1, 2] + frac * v_rows[r, 2]
        speed_out[k] = _qrot_inv(c0, c1, c2, c3, vx, vy, vz)[0]
