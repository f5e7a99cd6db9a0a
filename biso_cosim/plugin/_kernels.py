"""The plug-in's numba kernels on named records: check and convert a call's host truth
(``HostRows``: one tick's vectors or a block's rows) into the chip's inputs (``ChipRows``,
by the constant map ``HostMap``); the truth at the chip's sample instants and the clock
(``finish_ticks``). ``_tick.tick_kernel`` runs them inside the plug-in's compiled call,
the general path of ``imu_plugin.py`` one by one.

Kernels never raise: ``prepare`` returns a code naming the first bad input and its row, and
the wrapper (``imu_plugin.py``) turns it into the ValueError. The frames' scalar kernels
(``biso_cosim.frames._q*``) are the package's quaternion arithmetic inside kernels.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import types
from numba.extending import overload

from biso_cosim._numba import jit
from biso_cosim.frames import _qmul, _qrot, _qrot_inv

__all__ = ["HostMap", "HostRows", "ChipRows", "prepare", "finish_ticks", "truth_at_samples", "BAD_INPUTS",
           "QUAT_NORM_TOL", "TIME_TOL", "CLOCK_T0", "CLOCK_TICKS", "CLOCK_HAS_LAST", "CLOCK_SIZE", "LAST_SIZE"]

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
    return math.isfinite(_get(a, i, 0)) and math.isfinite(_get(a, i, 1)) and math.isfinite(_get(a, i, 2))


@jit
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


class HostMap(NamedTuple):
    """The plug-in's constant map from the host's truth to the chip's inputs: the host's
    conventions (``ned``, ``frd``, ``scalar_last``: ``HostFrames``), the chip's position
    ``r_b_m`` (3,) FLU from the reference point and whether it is away from it (``lever``),
    gravity ``g_enu`` (3,) m/s², the tick period ``tick_s`` and its rate ``tick_rate_hz``."""

    ned: bool
    frd: bool
    scalar_last: bool
    lever: bool
    r_b_m: np.ndarray
    g_enu: np.ndarray
    tick_s: float
    tick_rate_hz: float


class HostRows(NamedTuple):
    """One call's truth in the host's conventions (``ImuPlugin.step``'s arguments): ``t_s``
    a number (one tick) or (n,); the others (w,) for one tick or (n, w), and empty ((0,) or
    (0, w)) when not given; ``specific_force_b`` or, when it is empty, ``accel_w``;
    ``temperature_c`` (n,) or empty: then ``temperature_default_c`` for every row."""

    t_s: Any
    q_wb: np.ndarray
    omega_b: np.ndarray
    specific_force_b: np.ndarray
    accel_w: np.ndarray
    alpha_b: np.ndarray
    p_w: np.ndarray
    v_w: np.ndarray
    temperature_c: np.ndarray
    temperature_default_c: float


class ChipRows(NamedTuple):
    """The rows of ``HostRows`` in the package's frames, at the chip (``prepare``'s output):
    attitude (n, 4), body rate (n, 3), specific force at the chip (n, 3), the chip's position
    (n, 3) and the reference point's velocity (n, 3)."""

    q_wb: np.ndarray
    omega_b: np.ndarray
    specific_force_b: np.ndarray
    p_w: np.ndarray
    v_w: np.ndarray


# the plug-in's clock (``ImuPlugin``, float64): t₀ (the first tick's host time), ticks taken,
# whether ``last`` holds the previous tick; ``last`` (10,): its q_wb, ω_b and v_w, package frames
CLOCK_T0, CLOCK_TICKS, CLOCK_HAS_LAST = 0, 1, 2
CLOCK_SIZE = 3
LAST_SIZE = 10


def _count(t):
    """The number of rows of ``t_s`` (a number: 1)."""


@overload(_count, jit_options={"cache": True})
def _count_impl(t):
    if isinstance(t, types.Number):
        return lambda t: 1
    return lambda t: t.shape[0]


def _at(t, i):
    """Row i of ``t_s`` (a number: itself)."""


@overload(_at, jit_options={"cache": True})
def _at_impl(t, i):
    if isinstance(t, types.Number):
        return lambda t, i: float(t)
    return lambda t, i: t[i]


def _nrows(a, width):
    """The rows of ``a``: (n, w) n; (w,) one; empty none."""


@overload(_nrows, jit_options={"cache": True})
def _nrows_impl(a, width):
    if a.ndim == 1:
        return lambda a, width: a.shape[0] // width
    return lambda a, width: a.shape[0]


def _get(a, i, j):
    """Column j of row i of ``a`` ((n, w), or (w,): one row)."""


@overload(_get, jit_options={"cache": True})
def _get_impl(a, i, j):
    if a.ndim == 1:
        return lambda a, i, j: a[j]
    return lambda a, i, j: a[i, j]


@jit
def prepare(host, clock, last, given, out):
    """Check the host's truth rows ``given`` (``HostRows``) and write them in the package's
    frames, at the chip, into ``out`` (``ChipRows``).

    Row i is tick ``ticks + i``, due at ``t₀ + (ticks + i)·tick_s`` (``clock``; the first
    tick fixes t₀). ``specific_force_b`` (host body) or, when it is empty, ``accel_w`` (the
    reference point's acceleration, host world) with gravity ``g_enu``: f_b = q* ∘ (a − g) ∘ q.
    ``alpha_b`` (n, 3) or empty: angular acceleration (host body); empty: the slope
    (ω_i − ω_{i−1})/tick_s of the linear interpolation the chip applies between ticks (0 at
    the very first tick; ω_{−1} is ``last``'s). With ``lever``, the chip at r_b feels
    f + ω × (ω × r) + ω̇ × r and sits at p + q ∘ r ∘ q*. ``p_w``/``v_w`` or empty (zero).

    Returns (0, 0) or (code, row) of the first bad value (``BAD_INPUTS``); nothing but the
    output arrays is written.
    """
    ned, frd, scalar_last, lever, r_b, g_enu, tick_s = (host.ned, host.frd, host.scalar_last, host.lever, host.r_b_m,
                                                        host.g_enu, host.tick_s)
    t = given.t_s
    n = _count(t)
    q, omega, force, accel, alpha = given.q_wb, given.omega_b, given.specific_force_b, given.accel_w, given.alpha_b
    p, v, temp = given.p_w, given.v_w, given.temperature_c
    accel_mode = _nrows(force, 3) == 0
    have_alpha, have_p, have_v = _nrows(alpha, 3) > 0, _nrows(p, 3) > 0, _nrows(v, 3) > 0
    have_prev = clock[CLOCK_HAS_LAST] != 0.0
    tick0 = clock[CLOCK_TICKS]
    t0_s = clock[CLOCK_T0] if have_prev else _at(t, 0)
    q_out, omega_out, force_out, p_out, v_out = out.q_wb, out.omega_b, out.specific_force_b, out.p_w, out.v_w
    pwx, pwy, pwz = last[4], last[5], last[6]
    for i in range(n):
        ti = _at(t, i)
        if not math.isfinite(ti):
            return 1, i
        due = t0_s + (tick0 + i) * tick_s
        if ti < due - TIME_TOL * tick_s:
            return 2, i
        if ti > due + TIME_TOL * tick_s:
            return 3, i
        if scalar_last:
            w, x, y, z = _get(q, i, 3), _get(q, i, 0), _get(q, i, 1), _get(q, i, 2)
        else:
            w, x, y, z = _get(q, i, 0), _get(q, i, 1), _get(q, i, 2), _get(q, i, 3)
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
        wx, wy, wz = _body_to_flu(frd, _get(omega, i, 0), _get(omega, i, 1), _get(omega, i, 2))
        omega_out[i, 0], omega_out[i, 1], omega_out[i, 2] = wx, wy, wz
        if accel_mode:
            if not _finite3(accel, i):
                return 8, i
            ax, ay, az = _world_to_enu(ned, _get(accel, i, 0), _get(accel, i, 1), _get(accel, i, 2))
            fx, fy, fz = _qrot_inv(w, x, y, z, ax - g_enu[0], ay - g_enu[1], az - g_enu[2])
        else:
            if not _finite3(force, i):
                return 7, i
            fx, fy, fz = _body_to_flu(frd, _get(force, i, 0), _get(force, i, 1), _get(force, i, 2))
        if have_alpha:
            if not _finite3(alpha, i):
                return 9, i
            alx, aly, alz = _body_to_flu(frd, _get(alpha, i, 0), _get(alpha, i, 1), _get(alpha, i, 2))
        elif have_prev or i > 0:
            alx, aly, alz = (wx - pwx) / tick_s, (wy - pwy) / tick_s, (wz - pwz) / tick_s
        else:
            alx = aly = alz = 0.0
        pwx, pwy, pwz = wx, wy, wz
        if have_p:
            if not _finite3(p, i):
                return 10, i
            px, py, pz = _world_to_enu(ned, _get(p, i, 0), _get(p, i, 1), _get(p, i, 2))
        else:
            px = py = pz = 0.0
        if have_v:
            if not _finite3(v, i):
                return 11, i
            v_out[i, 0], v_out[i, 1], v_out[i, 2] = _world_to_enu(ned, _get(v, i, 0), _get(v, i, 1), _get(v, i, 2))
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
def finish_ticks(host, clock, last, given, chip, n, t_samples, q_true, speed, q_rows, v_rows):
    """After a checked call of n ticks (``prepare``'s ``chip`` rows) whose samples the chip
    latched at ``t_samples`` (its own axis): the truth at them (``truth_at_samples``, into
    ``q_true`` and ``speed`` (k, 4), (k,); ``q_rows``, ``v_rows`` (n + 1 or more, 4 and 3)
    scratch), then the clock advanced by the call's ticks and ``last`` set to its last tick. The first call fixes t₀ (``given``'s first time) and takes the
    tick before it as the first (the chip starts settled)."""
    if clock[CLOCK_HAS_LAST] == 0.0:
        clock[CLOCK_T0] = _at(given.t_s, 0)
        for c in range(4):
            last[c] = chip.q_wb[0, c]
        for c in range(3):
            last[4 + c] = chip.omega_b[0, c]
            last[7 + c] = chip.v_w[0, c]
    k = t_samples.shape[0]
    if k:  # the rows around the samples: the previous tick's, then this call's
        for c in range(4):
            q_rows[0, c] = last[c]
        for c in range(3):
            v_rows[0, c] = last[7 + c]
        for i in range(n):
            for c in range(4):
                q_rows[i + 1, c] = chip.q_wb[i, c]
            for c in range(3):
                v_rows[i + 1, c] = chip.v_w[i, c]
        truth_at_samples(t_samples, host.tick_s, host.tick_rate_hz, int(clock[CLOCK_TICKS]), q_rows[:n + 1],
                         v_rows[:n + 1], q_true, speed)
    for c in range(4):
        last[c] = chip.q_wb[n - 1, c]
    for c in range(3):
        last[4 + c] = chip.omega_b[n - 1, c]
        last[7 + c] = chip.v_w[n - 1, c]
    clock[CLOCK_TICKS] += n
    clock[CLOCK_HAS_LAST] = 1.0


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
