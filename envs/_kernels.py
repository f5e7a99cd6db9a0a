"""Jitted kernels of the environments' own per-step work (arrays in, arrays out, no user
errors: the environments validate first). Each has a plain NumPy twin in the tests."""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.frames import _qmul, _qnormalize

__all__ = ["_inside", "_push_window", "_angle", "_angles_to", "_mean_angle", "_dead_reckon", "_route_ahead"]


@jit
def _push_window(values, gyro, accel, mag, fresh):
    """Shift the (n, 11) IMU window up by the k new samples (or as many as fit) and write
    them last: gyro, accel, mag (a non-finite row reads 0 and is not fresh), mag_fresh, new=1.
    Rows kept from before get new = 0."""
    n = values.shape[0]
    k = gyro.shape[0]
    take = min(k, n)
    keep = n - take
    for i in range(keep):  # ascending: row i + take is read before it is overwritten
        for j in range(11):
            values[i, j] = values[i + take, j]
        values[i, 10] = 0.0
    for r in range(take):
        i, src = keep + r, k - take + r
        finite = True
        for j in range(3):
            values[i, j] = gyro[src, j]
            values[i, 3 + j] = accel[src, j]
            if not math.isfinite(mag[src, j]):
                finite = False
        for j in range(3):
            values[i, 6 + j] = mag[src, j] if finite else 0.0
        values[i, 9] = 1.0 if (fresh[src] and finite) else 0.0
        values[i, 10] = 1.0


@jit
def _inside(a, low, high):
    """Whether low[i] <= a[i] <= high[i] for every i (False for NaN)."""
    for i in range(a.shape[0]):
        if not (low[i] <= a[i] <= high[i]):
            return False
    return True


@jit
def _angle(p, q):
    """Rotation angle (rad, [0, π]) between the attitudes of quaternions p and q of any
    non-zero length (the expression of ``frames.quat_angle_between``, bit for bit)."""
    pw, px, py, pz = _qnormalize(p[0], p[1], p[2], p[3])
    qw, qx, qy, qz = _qnormalize(q[0], q[1], q[2], q[3])
    d = _qmul(pw, -px, -py, -pz, qw, qx, qy, qz)
    return 2.0 * math.atan2(math.sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3]), abs(d[0]))


@jit
def _angles_to(p1, p2, q):
    """(_angle(p1, q), _angle(p2, q)) in one call."""
    return _angle(p1, q), _angle(p2, q)


@jit
def _mean_angle(p, q):
    """Mean over the rows of the angle between p[i] and q[i] ((k, 4) each, k > 0)."""
    total = 0.0
    for i in range(p.shape[0]):
        total += _angle(p[i], q[i])
    return total / p.shape[0]


@jit
def _dead_reckon(q, wheel_rates, speed_scale, dt, pose):
    """Advance the 2-D pose (x, y, yaw) over k samples: each moves it by dt·v·(horizontal
    forward axis of q_wb), v = speed_scale·(front-left + front-right wheel rate); the yaw
    becomes that of the last sample's forward axis."""
    fx = 1.0
    fy = 0.0
    for i in range(q.shape[0]):
        w, x, y, z = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        fx = 1.0 - 2.0 * (y * y + z * z)
        fy = 2.0 * (x * y + w * z)
        v = speed_scale * (wheel_rates[i, 0] + wheel_rates[i, 1])
        pose[0] += dt * v * fx
        pose[1] += dt * v * fy
    if q.shape[0]:
        pose[2] = math.atan2(fy, fx)


@jit
def _route_ahead(path_x, path_y, path_s, s, offsets, x, y, yaw, out):
    """Points of the path at arc lengths s + offsets (the last sample at or before each,
    clamped to the path), relative to (x, y), in the frame turned by yaw: out (P, 2)."""
    c, sn = math.cos(yaw), math.sin(yaw)
    n = path_s.shape[0]
    j = max(np.searchsorted(path_s, s + offsets[0], side="right") - 1, 0)
    for i in range(offsets.shape[0]):  # offsets ascending: walk on from there
        target = s + offsets[i]
        while j + 1 < n and path_s[j + 1] <= target:
            j += 1
        dx, dy = path_x[j] - x, path_y[j] - y
        out[i, 0] = c * dx + sn * dy
        out[i, 1] = -sn * dx + c * dy
