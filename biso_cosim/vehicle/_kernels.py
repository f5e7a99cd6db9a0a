"""Numba kernels of the vehicle layer: packing and interpolation of the truth."""

from __future__ import annotations

import math

from biso_cosim._numba import jit


@jit
def _interpolate_rows(rows, t0_s, rate_hz, t_s, quat_col, out):
    """Rows of ``rows`` (uniform in time from ``t0_s`` at ``rate_hz``) at the times ``t_s``.

    Linear interpolation of every column except the quaternion at ``quat_col:quat_col+4``,
    which is interpolated on the shorter arc and normalised (nlerp: at 1 ms spacing it equals
    slerp to far below 1e-9 rad). Times outside the rows are clamped to the first/last row.
    """
    n, width = rows.shape
    for k in range(t_s.shape[0]):
        pos = (t_s[k] - t0_s) * rate_hz
        lo = int(math.floor(pos + 1e-9))
        if lo < 0:
            lo = 0
        if lo > n - 1:
            lo = n - 1
        frac = pos - lo
        if frac < 1e-9 or lo == n - 1:
            for c in range(width):
                out[k, c] = rows[lo, c]
            continue
        if frac > 1.0:
            frac = 1.0
        for c in range(width):
            out[k, c] = (1.0 - frac) * rows[lo, c] + frac * rows[lo + 1, c]
        dot = 0.0
        for c in range(quat_col, quat_col + 4):
            dot += rows[lo, c] * rows[lo + 1, c]
        sign = -1.0 if dot < 0.0 else 1.0
        norm = 0.0
        for c in range(quat_col, quat_col + 4):
            v = (1.0 - frac) * rows[lo, c] + frac * sign * rows[lo + 1, c]
            out[k, c] = v
            norm += v * v
        norm = math.sqrt(norm)
        for c in range(quat_col, quat_col + 4):
            out[k, c] /= norm


@jit
def _pack_rows(buf, gather, first_step, rate_hz, out):
    """Truth rows from MuJoCo sensor rows: column 0 the time of each row's step, then the
    sensordata columns ``gather`` (see ``VehicleSim._gather``)."""
    for k in range(buf.shape[0]):
        out[k, 0] = (first_step + k) / rate_hz
        for c in range(gather.shape[0]):
            out[k, c + 1] = buf[k, gather[c]]
