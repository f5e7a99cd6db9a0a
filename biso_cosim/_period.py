"""Jitted glue of a co-simulation period (``biso_cosim.cosim``): from MuJoCo's sensor rows to
the MPU-9250's samples and the truth at them, and BISO and BISO+ estimators on the samples,
in one call, where the pieces cost a Python call each (and, in the loop, several
microseconds each: the physics between periods evicts them from the caches)."""

from __future__ import annotations

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators.biso import _biso_batch
from biso_cosim.estimators.biso_plus import _biso_plus_batch
from biso_cosim.sensors._kernels import _simulate
from biso_cosim.sensors.magnetic import _rotate_into_body
from biso_cosim.vehicle._kernels import HISTORY_READ, TRUTH_LAYOUT, _history_rows, _interpolate_rows, _pack_rows, _wheel_odometry

__all__ = ["_sense_period", "_sense_estimate_period", "_sensor_inputs", "_period_samples"]

# Positions in the period kernel's arguments (``_sense_period``'s order; ``CoSimulation``
# lists them, ``_PeriodPlan`` and ``_period_samples`` read them): the sample outputs are
# floats, words, status bytes, flags from _ARG_OUT on.
_ARG_T_START, _ARG_FIRST_STEP, _ARG_BEFORE, _ARG_PACKED, _ARG_OUT, _ARG_AT, _ARG_ODOMETRY, _ARG_FLAGS = (
    2, 7, 10, 20, 21, 25, 27, 28)
_ARG_STATUS_BYTES, _ARG_SAMPLE_FLAGS = _ARG_OUT + 2, _ARG_OUT + 3  # (numba indexes a tuple by a constant)


@jit
def _sensor_inputs(packed, field_enu_ut, omega_b, force_b, mag_b):
    """From truth rows packed as ``Truth`` packs them (``TRUTH_LAYOUT``): the body rate and
    the specific force as contiguous (n, 3) rows, and the Earth's field ``field_enu_ut`` (µT,
    ENU, the same everywhere) rotated into each row's attitude (``MagneticEnvironment.field_b``'s
    kernel). Returns whether every position is finite (``field_b`` refuses positions that are not)."""
    w, f, q, p = TRUTH_LAYOUT.omega_b, TRUTH_LAYOUT.specific_force_b, TRUTH_LAYOUT.q_wb, TRUTH_LAYOUT.pos_w
    for k in range(packed.shape[0]):
        for a in range(3):
            omega_b[k, a] = packed[k, w + a]
            force_b[k, a] = packed[k, f + a]
    return _rotate_into_body(packed[:, q:q + 4], packed[:, p:p + 3], field_enu_ut, mag_b)


@jit
def _sense_period(history, layout, t_start, warnings, sensordata, rows, gather, first_step, rate_hz, field_enu_ut, before,
                  cp, ch, cs, chs, temp_default, order, nsub, t_shift_s, quat_col, packed, floats, words, status_bytes,
                  flags, at, wheel_radius_m, odometry, flags64):
    """A control period's sensing in one call, the steps ``CoSimulation._sense`` takes one
    Python call each: MuJoCo's sensordata ``rows``, read first from its sensor ``history``
    when that is not empty (``VehicleSim._step_period``: ``_history_rows`` with ``layout``,
    ``t_start``, ``warnings``, ``sensordata``), the truth rows packed from them
    (``VehicleSim._truth``), the MPU-9250's inputs (``_sensor_inputs``), the chip itself
    (``sensors._kernels._simulate``, writing ``floats``, ``words``, ``status_bytes``,
    ``flags``), its time stamps shifted by ``t_shift_s``, the truth at them (``Truth.at``,
    from the row ``before`` the period when given) into ``at``, when ``odometry`` is not
    empty the wheel odometry at them into it (``CoSimulation._odometry_mps``), and the
    samples' flags as int64 (the estimators' ``imu_flags``) into ``flags64``.

    Returns (status, k): -1 and the number of samples on success; the chip's status when it
    refused the rows (a row index, or -2), or -3 for a position that is not finite (then
    nothing has changed but the packed truth); -4 when the samples' time stamps leave the
    rows (the sensor and the physics out of step); -5 and ``_history_rows``' outcome when
    the history does not hold the rows (nothing has changed: ``VehicleSim._restep``).
    """
    if history.shape[0]:
        outcome = _history_rows(history, layout, rows.shape[0], t_start, warnings, sensordata, rows)
        if outcome != HISTORY_READ:
            return -5, outcome
    _pack_rows(rows, gather, first_step, rate_hz, packed)
    n = packed.shape[0]
    inputs = np.empty((3, n, 3))
    if not _sensor_inputs(packed, field_enu_ut, inputs[0], inputs[1], inputs[2]):
        return -3, 0
    status, k = _simulate(cp, ch, cs, chs, inputs[0], inputs[1], inputs[2], np.empty(0), temp_default, order, nsub,
                          floats, words, status_bytes, flags)
    if status != -1:
        return status, k
    t_s = floats[:k]
    if t_shift_s != 0.0:
        for i in range(k):
            t_s[i] -= t_shift_s
    t0_s = before[0, 0] if before.shape[0] else packed[0, 0]
    if k and (t_s[0] < t0_s - 1e-9 or t_s[k - 1] > packed[n - 1, 0] + 1e-9):
        return -4, k
    if k:
        _interpolate_rows(before, packed, t0_s, rate_hz, t_s, quat_col, at[:k])
        if odometry.shape[0]:
            _wheel_odometry(at[:k], wheel_radius_m, odometry[:k])
    for i in range(k):
        flags64[i] = flags[i]
    return -1, k


@jit
def _sample_rows(floats, bound, k):
    """The gyro, accel and mag rows (k, 3) of the first k samples in the chip's ``floats``
    output for up to ``bound`` samples (its column blocks, as ``MPU9250._samples`` reads them)."""
    return (floats[bound:bound + 3 * k].reshape((k, 3)), floats[4 * bound:4 * bound + 3 * k].reshape((k, 3)),
            floats[7 * bound:7 * bound + 3 * k].reshape((k, 3)))


@jit
def _sense_estimate_period(history, layout, t_start, warnings, sensordata, rows, gather, first_step, rate_hz, field_enu_ut,
                           before, cp, ch, cs, chs, temp_default, order, nsub, t_shift_s, quat_col, packed, floats,
                           words, status_bytes, flags, at, wheel_radius_m, odometry, flags64, no_velocity, scratch,
                           coef_a, state_a, q_a, flags_a, coef_b, state_b, q_b, flags_b,
                           coef_c, state_c, q_c, flags_c, bias_c):
    """``_sense_period``, then on its samples up to two BISO estimators (a, b) and one BISO+
    (c), each given by its ``coef`` and ``state`` arrays (advanced in place; an empty
    ``coef`` skips it) and writing the first k rows of its outputs ``q``, ``flags`` (and
    ``bias``). Each runs as its ``update`` does with the co-simulation's inputs: BISO on the
    sensor's flags as ``imu_flags``, without velocity, ``gyro_step="hold"``
    (``_biso_batch``, ``scratch`` its scratch space); BISO+ also on the wheel odometry as
    ``speed_mps`` (``_biso_plus_batch``). They run only when the sensing succeeded (status
    -1), so a period that is refused or stepped again has changed none of them."""
    status, k = _sense_period(history, layout, t_start, warnings, sensordata, rows, gather, first_step, rate_hz,
                              field_enu_ut, before, cp, ch, cs, chs, temp_default, order, nsub, t_shift_s, quat_col,
                              packed, floats, words, status_bytes, flags, at, wheel_radius_m, odometry, flags64)
    if status != -1:
        return status, k
    gyro, accel, mag = _sample_rows(floats, flags.shape[0], k)
    if coef_a.shape[0]:
        _biso_batch(coef_a, state_a, gyro, accel, mag, flags64[:k], no_velocity, q_a[:k], flags_a[:k], scratch)
    if coef_b.shape[0]:
        _biso_batch(coef_b, state_b, gyro, accel, mag, flags64[:k], no_velocity, q_b[:k], flags_b[:k], scratch)
    if coef_c.shape[0]:
        _biso_plus_batch(coef_c, state_c, gyro, accel, mag, odometry[:k], flags64[:k], q_c[:k], flags_c[:k],
                         bias_c[:k])
    return status, k


@jit
def _period_samples(period, k):
    """The first k samples of the period kernel's call with the arguments ``period`` (status
    -1), as ``MPU9250._samples`` and ``Truth.at`` view them: gyro, accel, mag (k, 3), the
    fresh-magnetometer bytes (k,) (``mag_fresh`` as uint8) and the truth at them (k, 23)."""
    gyro, accel, mag = _sample_rows(period[_ARG_OUT], period[_ARG_SAMPLE_FLAGS].shape[0], k)
    return gyro, accel, mag, period[_ARG_STATUS_BYTES][:k, 0], period[_ARG_AT][:k]
