"""Numba kernels of the vehicle layer: packing and interpolation of the truth."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.routes._kernels import LOCATE_AHEAD, LOCATE_BACK, _locate
from biso_cosim.vehicle.drivetrain import _drivetrain_controls


class TruthLayout(NamedTuple):
    """Where each quantity sits in a packed truth row (``sim.Truth``): the first column of
    each, its width in ``TRUTH_WIDTHS``. Kernels index rows by these names (numba freezes a
    global named tuple of ints into constants), never by bare numbers."""

    t_s: int  # time, s
    omega_b: int  # angular rate, body axes, rad/s (3)
    specific_force_b: int  # specific force, body axes, m/s² (3)
    q_wb: int  # attitude, body to ENU, scalar first (4)
    pos_w: int  # IMU site position, ENU, m (3)
    vel_w: int  # IMU site velocity, ENU, m/s (3)
    speed_mps: int  # forward speed of the rear axle, m/s
    wheel_rates: int  # wheel spin rates fl, fr, rl, rr, rad/s (4)
    steer_rad: int  # bicycle steering angle, rad, left positive
    width: int  # columns in a row


TRUTH_WIDTHS = {"t_s": 1, "omega_b": 3, "specific_force_b": 3, "q_wb": 4, "pos_w": 3, "vel_w": 3, "speed_mps": 1,
                "wheel_rates": 4, "steer_rad": 1}
"""Columns each quantity of ``TruthLayout`` spans, in row order."""


def _layout() -> TruthLayout:
    starts, column = [], 0
    for width in TRUTH_WIDTHS.values():
        starts.append(column)
        column += width
    return TruthLayout(*starts, column)


TRUTH_LAYOUT = _layout()
"""The packed truth row: t_s 0, omega_b 1:4, specific_force_b 4:7, q_wb 7:11, pos_w 11:14,
vel_w 14:17, speed_mps 17, wheel_rates 18:22, steer_rad 22; width 23."""


def truth_columns(name: str) -> int | slice:
    """The column (width 1) or column slice of quantity ``name`` in a packed truth row."""
    start, width = getattr(TRUTH_LAYOUT, name), TRUTH_WIDTHS[name]
    return start if width == 1 else slice(start, start + width)


@jit(inline="always")
def _row_value(before, rows, i, c):
    """Column c of row i of ``before`` followed by ``rows`` (without joining them)."""
    nb = before.shape[0]
    return before[i, c] if i < nb else rows[i - nb, c]


@jit
def _interpolate_rows(before, rows, t0_s, rate_hz, t_s, quat_col, out):
    """Rows of ``before`` followed by ``rows`` (uniform in time from ``t0_s`` at ``rate_hz``;
    ``before`` may be empty) at the times ``t_s``.

    Linear interpolation of every column except the quaternion at ``quat_col:quat_col+4``,
    which is interpolated on the shorter arc and normalised (nlerp: at 1 ms spacing it equals
    slerp to far below 1e-9 rad). Times outside the rows are clamped to the first/last row.
    """
    n = before.shape[0] + rows.shape[0]
    width = rows.shape[1]
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
                out[k, c] = _row_value(before, rows, lo, c)
            continue
        if frac > 1.0:
            frac = 1.0
        for c in range(width):
            out[k, c] = (1.0 - frac) * _row_value(before, rows, lo, c) + frac * _row_value(before, rows, lo + 1, c)
        dot = 0.0
        for c in range(quat_col, quat_col + 4):
            dot += _row_value(before, rows, lo, c) * _row_value(before, rows, lo + 1, c)
        sign = -1.0 if dot < 0.0 else 1.0
        norm = 0.0
        for c in range(quat_col, quat_col + 4):
            v = (1.0 - frac) * _row_value(before, rows, lo, c) + frac * sign * _row_value(before, rows, lo + 1, c)
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


# ---- the scripted driver (biso_cosim.vehicle.driver documents the method) -------------
# state[...]
S_INDEX, S_S, S_CROSS, S_VCMD, S_INTEGRAL, S_STEER, S_NEXT, S_FLOOR, S_DWELL, S_HOLD, S_TIME, S_FINISHED = range(12)
STATE_SIZE = 12
# params[...]
(P_LMIN, P_TLA, P_LMAX, P_STEER_RATE, P_KP, P_KI, P_STOP_DIST, P_STOP_SPEED, P_CREEP, P_HOLD_RAMP,
 P_WHEELBASE, P_MAX_STEER, P_MASS, P_RADIUS, P_MAX_DRIVE, P_BRAKE_KV, P_MAX_BRAKE, P_DT, P_DECEL, P_ACCEL,
 P_WAIT, P_LENGTH, P_POWER, P_DRAG_K, P_ROLL_A) = range(25)
PARAMS_SIZE = 25


# _history_rows' outcomes
HISTORY_READ, HISTORY_WARNED, HISTORY_STALE = 0, 1, 2


@jit
def _history_rows(history, layout, n, t_start, warnings, sensordata, rows):
    """The sensordata of the last n steps, which started at time t_start, as rows (n,
    nsensordata) oldest first, from MuJoCo's history buffer. ``layout`` (nsensor, 4): each
    sensor's history address, number of samples, sensordata address and dimension; a
    sensor's history is [user slot, index of the newest sample, times (nsample), values
    (nsample, dim)], a ring, each value stamped with the time of its step's start.

    Returns HISTORY_READ, or, with rows unfinished, HISTORY_WARNED after a MuJoCo warning
    (``warnings``, MjData.warning.number, zero before the steps: MuJoCo may reset the data,
    the history with it) or HISTORY_STALE when the rings do not hold these steps: an oldest
    stamp other than t_start, or a newest row other than the current ``sensordata`` (the
    clock was set back since the rings started: MuJoCo then does not advance them). The
    warning counters are cleared, as MuJoCo's rollout clears them."""
    warned = False
    for i in range(warnings.shape[0]):
        if warnings[i] != 0:
            warned = True
            warnings[i] = 0
    if warned:
        return HISTORY_WARNED
    for s in range(layout.shape[0]):
        adr, nsample, col, dim = layout[s, 0], layout[s, 1], layout[s, 2], layout[s, 3]
        newest = int(history[adr + 1])
        times = adr + 2
        values = times + nsample
        if history[times + (newest - (n - 1)) % nsample] != t_start:
            return HISTORY_STALE
        for j in range(n):
            slot = (newest - (n - 1) + j) % nsample
            for c in range(dim):
                rows[j, col + c] = history[values + slot * dim + c]
    for c in range(sensordata.shape[0]):  # the last step's values are what MjData holds now
        if rows[n - 1, c] != sensordata[c]:
            return HISTORY_STALE
    return HISTORY_READ


@jit
def _wheel_odometry(packed, wheel_radius_m, out):
    """Rear-axle speed (m/s) of each packed truth row from the undriven front wheels into
    out: ½(fl + fr spin rate)·radius·cos(steering)."""
    fl, fr, steer = TRUTH_LAYOUT.wheel_rates, TRUTH_LAYOUT.wheel_rates + 1, TRUTH_LAYOUT.steer_rad
    for i in range(packed.shape[0]):
        out[i] = 0.5 * (packed[i, fl] + packed[i, fr]) * wheel_radius_m * math.cos(packed[i, steer])


@jit
def _index_at(ps, s):
    i = np.searchsorted(ps, s, side="right") - 1
    return min(max(i, 0), ps.shape[0] - 1)


@jit
def _track(px, py, ps, state, x, y):
    """Progress along the path and cross-track error, never before the last passed stop."""
    n = px.shape[0]
    hint = int(state[S_INDEX])
    lo = max(hint - LOCATE_BACK, int(state[S_FLOOR]), 0)
    hi = min(hint + LOCATE_AHEAD, n - 1)
    i, s, cross = _locate(px, py, ps, x, y, lo, hi)
    state[S_INDEX] = i
    state[S_S] = s
    state[S_CROSS] = cross


@jit
def _track_axle(px, py, ps, state, sensordata, axle_x):
    """``_track`` at the rear axle's position in MuJoCo's ``sensordata`` (x, y at ``axle_x``)."""
    _track(px, py, ps, state, sensordata[axle_x], sensordata[axle_x + 1])


@jit
def _drive_period(px, py, ps, pheading, v_free, direction, stop_s, stop_index, stop_dwell, stop_cusp, p, state,
                  sensordata, layout, ctrl, actuators, drivetrain, out):
    """A control period of the scripted driver from MuJoCo's ``sensordata`` straight into
    ``ctrl``: what ``VehicleSim._measure`` reads (the same expressions), ``_driver_command``,
    and ``VehicleSim.apply``. ``layout``: sensordata indices of the IMU quaternion's w, the
    rear axle's x, its forward speed, the first wheel rate, and the number of wheels;
    ``actuators`` and ``drivetrain``: as ``_apply_controls``'."""
    i = layout[0]
    w, x, y, z = sensordata[i], sensordata[i + 1], sensordata[i + 2], sensordata[i + 3]
    yaw = math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))
    wheels = 0.0
    for j in range(layout[3], layout[3] + layout[4]):
        wheels += sensordata[j]
    _driver_command(px, py, ps, pheading, v_free, direction, stop_s, stop_index, stop_dwell, stop_cusp, p, state,
                    sensordata[layout[1]], sensordata[layout[1] + 1], yaw, sensordata[layout[2]],
                    wheels / layout[4], out)
    _apply_controls(ctrl, actuators, out[0], out[1], out[2], sensordata[layout[3]:layout[3] + layout[4]], drivetrain)


@jit
def _brake_command(per_wheel_nm, brake_kv, wheel_rate):
    """The command u of each wheel's brake, a damper (torque = kv·u·ω, car.xml), that asks
    ``per_wheel_nm`` at the wheels' mean spin rate ``wheel_rate`` (rad/s, taken as at least
    0.5 so that a stopped car holds); not clamped: above 1 the actuator cannot give it."""
    return per_wheel_nm / (brake_kv * max(abs(wheel_rate), 0.5))


@jit
def _apply_controls(ctrl, actuators, steer_rad, drive, brake, wheel_rates, drivetrain):
    """A command into MuJoCo's ``ctrl``; ``actuators``: the ctrl indices of steering, drive,
    the driving resistances, then the brakes (each wheel's brake takes the same command).
    The drive command becomes the drivetrain's torque and the resistances' force at the
    wheel spin rates ``wheel_rates`` (fl, fr, rl, rr) with the coefficients ``drivetrain``
    (``vehicle.drivetrain``: the one place where every caller's drive goes through it)."""
    ctrl[actuators[0]] = steer_rad
    ctrl[actuators[1]], ctrl[actuators[2]] = _drivetrain_controls(drivetrain, drive, wheel_rates)
    for j in range(3, actuators.shape[0]):
        ctrl[actuators[j]] = brake


@jit
def _driver_command(px, py, ps, pheading, v_free, direction, stop_s, stop_index, stop_dwell, stop_cusp,
                    p, state, x, y, yaw, speed, wheel_speed, out):
    """One control period of the scripted driver: out = (steer_rad, drive, brake)."""
    dt = p[P_DT]
    _track(px, py, ps, state, x, y)
    state[S_TIME] += dt
    if state[S_TIME] <= p[P_WAIT]:
        out[0], out[1], out[2] = 0.0, 0.0, 1.0
        return
    index = int(state[S_INDEX])
    s_now = state[S_S]
    d = float(direction[index])
    k = int(state[S_NEXT])

    # steering: pure pursuit from the direction of travel, goal continued straight beyond a
    # cusp or the end
    lookahead = min(p[P_LMIN] + p[P_TLA] * abs(speed), p[P_LMAX])
    s_goal = s_now + lookahead
    limit = stop_s[k] if (stop_cusp[k] or math.isinf(stop_dwell[k])) else p[P_LENGTH]
    if s_goal <= limit:
        g = _index_at(ps, s_goal)
        gx, gy = px[g], py[g]
    else:
        g = _index_at(ps, limit)
        heading = pheading[max(g - 1, 0)]
        extra = s_goal - limit
        gx, gy = px[g] + extra * math.cos(heading), py[g] + extra * math.sin(heading)
    dx, dy = gx - x, gy - y
    c, s = math.cos(yaw) * d, math.sin(yaw) * d
    ahead, left = c * dx + s * dy, -s * dx + c * dy
    distance = max(math.hypot(ahead, left), 1e-3)
    alpha = math.atan2(left, ahead)
    target_steer = d * math.atan(2.0 * p[P_WHEELBASE] * math.sin(alpha) / distance)
    target_steer = min(max(target_steer, -p[P_MAX_STEER]), p[P_MAX_STEER])
    step = p[P_STEER_RATE] * dt
    state[S_STEER] += min(max(target_steer - state[S_STEER], -step), step)

    # speed: free-flow target capped before the next stop, signed by the direction
    to_stop = stop_s[k] - s_now
    if to_stop < p[P_STOP_DIST] and abs(speed) < p[P_STOP_SPEED]:
        state[S_DWELL] += dt
        state[S_VCMD] = 0.0
        state[S_INTEGRAL] = 0.0
        if state[S_DWELL] >= stop_dwell[k]:
            state[S_NEXT] = k + 1
            state[S_FLOOR] = stop_index[k]
            state[S_DWELL] = 0.0
            state[S_HOLD] = 0.0
            index = max(index, int(stop_index[k]))  # the first command after a cusp is for the new direction
            state[S_INDEX] = index
            d = float(direction[index])
        else:
            state[S_FINISHED] = 1.0 if math.isinf(stop_dwell[k]) else 0.0
            state[S_HOLD] = min(state[S_HOLD] + dt / p[P_HOLD_RAMP], 1.0)
            out[0], out[1], out[2] = state[S_STEER], 0.0, state[S_HOLD]
            return
    room = max(to_stop, 0.0)
    target = d * min(v_free[index], math.sqrt(2.0 * p[P_DECEL] * room), room / p[P_CREEP])
    previous = state[S_VCMD]
    # speeding up at accel, at most at the car's full-throttle acceleration at the command's speed
    v_abs = abs(previous)
    faster = min(p[P_ACCEL], max(p[P_POWER] / max(v_abs, 1.0) - p[P_DRAG_K] * v_abs * v_abs - p[P_ROLL_A], 0.0))
    if d > 0:  # the rate limits apply to the magnitude: speeding up at accel, slowing at decel
        down, up = p[P_DECEL], faster
    else:
        down, up = faster, p[P_DECEL]
    state[S_VCMD] += min(max(target - previous, -down * dt), up * dt)
    feedforward = (state[S_VCMD] - previous) / dt
    error = state[S_VCMD] - speed
    accel_cmd = feedforward + p[P_KP] * error + p[P_KI] * state[S_INTEGRAL]

    # actuators: drive when pushing along the direction of travel, else brake all four wheels
    torque = p[P_MASS] * accel_cmd * p[P_RADIUS]
    if torque * d >= 0.0:
        drive = torque / p[P_MAX_DRIVE]
        brake = 0.0
        # beyond the peak torque, or beyond what the engine's power gives at this speed
        saturated = abs(drive) > 1.0 or abs(torque) > p[P_MASS] * p[P_RADIUS] * p[P_POWER] / max(abs(speed), 1.0)
        drive = min(max(drive, -1.0), 1.0)
    else:
        drive = 0.0
        per_wheel = abs(torque) / 4.0
        brake = _brake_command(per_wheel, p[P_BRAKE_KV], wheel_speed)
        saturated = brake > 1.0 or per_wheel > p[P_MAX_BRAKE]
        brake = min(brake, 1.0)
    state[S_HOLD] = brake
    if not saturated:  # no integration while the actuator saturates (anti-windup)
        state[S_INTEGRAL] += error * dt
    out[0], out[1], out[2] = state[S_STEER], drive, brake
