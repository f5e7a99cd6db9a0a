"""The co-simulation's one period pipeline (``biso_cosim.loop``): an estimator joins it by
declaring its kernel and arrays in its own module (here a user's, defined in this file),
and every registered estimator gives the same numbers on the fast path as on the general
path (``CoSimulation.fast_path = False``), bit for bit."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from biso_cosim._numba import jit
from biso_cosim.cosim import CoSimulation, EstimatorSpec
from biso_cosim.estimators import Estimator, LoopArrays, estimator_names, param
from biso_cosim.loop import PeriodWork


# ---- a user's own estimator: gyro integration on the unit sphere, eq. (2) of Aleshkin 2024
@dataclass(frozen=True)
class GyroOnlyParams:
    rate_scale: float = param(1.0, symbol="s", unit="1", doc="scale applied to the gyro readings")


@jit
def _gyro_only_batch(coef, state, gyro, q_out, flags_out):
    """q ← q ⊗ exp(½ s ω h), the exact rotation of a rate held over the interval."""
    h, s = coef[0], coef[1]
    w, x, y, z = state[0], state[1], state[2], state[3]
    for i in range(gyro.shape[0]):
        gx, gy, gz = s * gyro[i, 0] * h, s * gyro[i, 1] * h, s * gyro[i, 2] * h
        angle = math.sqrt(gx * gx + gy * gy + gz * gz)
        c = math.cos(0.5 * angle)
        f = 0.5 if angle == 0.0 else math.sin(0.5 * angle) / angle
        dw, dx, dy, dz = c, f * gx, f * gy, f * gz
        w, x, y, z = (w * dw - x * dx - y * dy - z * dz, w * dx + x * dw + y * dz - z * dy,
                      w * dy - x * dz + y * dw + z * dx, w * dz + x * dy - y * dx + z * dw)
        q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = w, x, y, z
        flags_out[i] = 0
    state[0], state[1], state[2], state[3] = w, x, y, z


@jit
def _gyro_only_loop(arrays, samples):
    k = samples.gyro_b.shape[0]
    _gyro_only_batch(arrays.coef, arrays.state, samples.gyro_b, arrays.q_wb[:k], arrays.flags[:k])


class GyroOnly(Estimator):
    method = "gyro_only"
    Params = GyroOnlyParams
    state_layout = (("q_wb", 4),)
    loop_kernel = _gyro_only_loop  # (loop_arrays: Estimator's LoopArrays of coef, state, outputs)

    def _coefficients(self, params, fs_hz):
        return np.array([1.0 / fs_hz, params.rate_scale])

    def _initial_state(self, q0):
        return np.array([1.0, 0.0, 0.0, 0.0]) if q0 is None else np.array(q0, dtype=float)

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias):
        _gyro_only_batch(coef, state, gyro, q_out, flags)

    @property
    def initialized(self):
        return True


def _pair(**options):
    fast = CoSimulation("figure8", **options)
    general = CoSimulation("figure8", **options)
    general.fast_path = False
    return fast, general


def _assert_same_run(a, b):
    assert np.array_equal(a.imu.gyro_b, b.imu.gyro_b) and np.array_equal(a.truth.packed, b.truth.packed)
    assert list(a.estimates) == list(b.estimates)
    for key, (q, flags) in a.estimates.items():
        assert np.array_equal(q, b.estimates[key][0]) and np.array_equal(flags, b.estimates[key][1]), key


def test_a_users_estimator_defined_here_joins_the_period_call():
    mine = GyroOnly(200.0, GyroOnlyParams(rate_scale=1.0))
    fast = CoSimulation("figure8", duration_s=3.0, seed=1, estimators=[mine, "biso"])
    q0 = fast.vehicle.current_truth().q_wb[0]  # (the sensor's first sample is at the first step)
    mine.reset(q0=q0)
    assert fast.loop_estimators == ("gyro_only", "biso")
    result = fast.run()
    twin = GyroOnly(200.0)
    twin.reset(q0=q0)
    general = CoSimulation("figure8", duration_s=3.0, seed=1, estimators=[twin, "biso"])
    general.fast_path = False
    _assert_same_run(result, general.run())
    # the stream in the loop is the estimator's own batch over the same samples
    again = GyroOnly(200.0)
    again.reset(q0=q0)
    np.testing.assert_array_equal(again.update(result.imu.gyro_b, result.imu.accel_b, result.imu.mag_b).q_wb,
                                  result.estimates["gyro_only"][0])
    # and, with no correction, it is the true attitude's integral: within the gyro's errors
    angle = 2 * np.arccos(np.clip(np.abs(np.sum(result.estimates["gyro_only"][0] * result.truth.q_wb, axis=1)), 0, 1))
    assert np.degrees(angle).max() < 1.0


@pytest.mark.parametrize("name", estimator_names())
def test_fast_path_equals_general_path_for_every_registered_estimator(name):
    fast, general = _pair(duration_s=3.0, seed=5, estimators=[name], keep_log=True)
    in_loop = fast.loop_estimators
    assert in_loop == ((name,) if "gnss" not in name else ())  # (GNSS fixes: by update after the call)
    for _ in range(60):
        a, b = fast.step(), general.step()
        assert np.array_equal(a[0].gyro_b, b[0].gyro_b) and np.array_equal(a[1].packed, b[1].packed)
        assert np.array_equal(a[2][name].q_wb, b[2][name].q_wb) and np.array_equal(a[2][name].flags, b[2][name].flags)
    _assert_same_run(fast.run(), general.run())


def test_attached_work_runs_once_per_period_on_either_path():
    """A consumer's kernel sees each period's samples and its estimator's q_wb once, the same
    on both paths."""

    @jit
    def count(samples, q, arrays):
        k = samples.gyro_b.shape[0]
        arrays[0][0] += 1
        arrays[0][1] += k
        if k:
            for j in range(4):
                arrays[1][j] = q[0][k - 1, j]

    seen = []
    for fast_path in (True, False):
        sim = CoSimulation("figure8", duration_s=2.0, seed=0, estimators=["biso"], keep_log=False,
                           reuse_outputs=True)
        sim.fast_path = fast_path
        arrays = (np.zeros(2, dtype=np.int64), np.zeros(4))
        sim.attach(PeriodWork(count, arrays, ("biso",)))
        for _ in range(30):
            samples, _, out = sim.step()
            assert np.array_equal(arrays[1], out["biso"].q_wb[-1])
        seen.append((arrays[0].copy(), arrays[1].copy()))
    assert seen[0][0][0] == 30 and seen[0][0][1] == 30 * 4
    assert np.array_equal(seen[0][0], seen[1][0]) and np.array_equal(seen[0][1], seen[1][1])
    with pytest.raises(ValueError, match="no estimator 'nope'"):
        sim.attach(PeriodWork(count, arrays, ("nope",)))


@pytest.mark.parametrize("name, changes", [("biso", {"cutoff_hz": 1.5}), ("biso", {"pattern": 13}),
                                           ("biso_plus", {"k_tilt": 3.0, "tau_acc_s": 2.0}),
                                           ("dcm_pi", {"kp_rp": 0.5})])
def test_retune_gives_set_params_numbers_and_keeps_the_loops_arrays(name, changes):
    """``retune`` is ``set_params``' result (record, coefficients, the stream after it, bit
    for bit), written into the arrays the period call holds: no new plan is needed."""
    from biso_cosim.estimators import describe_estimator, make_estimator

    known = {row["name"] for row in describe_estimator(name)["params"]}
    changes = {k: v for k, v in changes.items() if k in known}
    assert changes, f"{name}: none of {sorted(changes)} is a parameter"
    rng = np.random.default_rng(1)
    gyro, accel, mag = rng.normal(0, 0.1, (50, 3)), rng.normal(0, 0.2, (50, 3)) + (0, 0, 9.81), \
        rng.normal(0, 1, (50, 3)) + (20.0, 0, -40.0)
    a, b = make_estimator(name, 200.0), make_estimator(name, 200.0)
    a.update(gyro, accel, mag), b.update(gyro, accel, mag)
    coef, version = a.coefficients, a.arrays_version
    a.retune(**changes)
    b.set_params(**changes)
    assert a.params == b.params and a.coefficients.tobytes() == b.coefficients.tobytes()
    assert a.arrays_version == version and not np.array_equal(a.coefficients, coef)
    assert np.array_equal(a.update(gyro, accel, mag).q_wb, b.update(gyro, accel, mag).q_wb)
