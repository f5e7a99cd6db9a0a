"""What every registered estimator promises: streaming = batch bit for bit, whole-state
get/set, the NaN policy (no NaN out), refusals that lose nothing, the registry."""

import pickle

import numpy as np
import pytest

from biso_cosim import frames as fr
from biso_cosim import motions as mo
from biso_cosim.sensors import GYRO_SATURATED
from biso_cosim.estimators import (
    describe_estimator,
    estimate_attitude,
    estimator_names,
    flags as fl,
    make_estimator,
)

NAMES = estimator_names()


def _samples(n=400, seed=7):
    rng = np.random.default_rng(seed)
    m = mo.make_motion("shake", n / 200.0, 200.0, seed=seed)
    gyro = m.omega_b + [0.01, -0.02, 0.015] + 0.02 * rng.normal(size=(n, 3))
    accel = m.specific_force_b + 0.2 * rng.normal(size=(n, 3))
    mag = m.mag_b + rng.normal(size=(n, 3))
    gyro[7] = np.nan
    accel[11] = [np.inf, 0, 0]
    accel[12] = 0.0
    mag[20] = np.nan
    mag[21] = 0.0
    speed = np.abs(rng.normal(5.0, 0.1, size=n))
    speed[30] = np.nan
    return m, gyro, accel, mag, speed


def _inputs(est, speed, sl=slice(None)):
    return {"speed_mps": speed[sl]} if "speed_mps" in est.inputs else {}


@pytest.mark.parametrize("name", NAMES)
def test_any_chunking_is_bit_identical(name):
    _, gyro, accel, mag, speed = _samples()
    est = make_estimator(name, 200.0)
    whole = est.update(gyro, accel, mag, **_inputs(est, speed))
    est = make_estimator(name, 200.0)
    rng = np.random.default_rng(1)
    parts, i = [], 0
    while i < len(gyro):
        n = int(rng.integers(0, 9))
        sl = slice(i, i + n)
        parts.append(est.update(gyro[sl], accel[sl], mag[sl], **_inputs(est, speed, sl)))
        i += n
    np.testing.assert_array_equal(np.concatenate([p.q_wb for p in parts]), whole.q_wb)
    np.testing.assert_array_equal(np.concatenate([p.flags for p in parts]), whole.flags)
    if whole.gyro_bias_b is not None:
        np.testing.assert_array_equal(np.concatenate([p.gyro_bias_b for p in parts]), whole.gyro_bias_b)


@pytest.mark.parametrize("name", NAMES)
def test_output_is_finite_unit_and_flags_follow_the_policy(name):
    _, gyro, accel, mag, speed = _samples()
    est = make_estimator(name, 200.0)
    out = est.update(gyro, accel, mag, **_inputs(est, speed))
    assert np.all(np.isfinite(out.q_wb))
    np.testing.assert_allclose(np.linalg.norm(out.q_wb, axis=1), 1.0, atol=1e-12)
    assert out.flags[7] & fl.GYRO_INVALID
    assert out.flags[11] & fl.ACCEL_INVALID and out.flags[12] & fl.ACCEL_INVALID
    assert out.flags[20] & fl.MAG_INVALID and out.flags[21] & fl.MAG_INVALID
    assert out.flags.dtype == np.int64


@pytest.mark.parametrize("name", NAMES)
def test_state_round_trip(name):
    _, gyro, accel, mag, speed = _samples()
    est = make_estimator(name, 200.0)
    est.update(gyro[:200], accel[:200], mag[:200], **_inputs(est, speed, slice(0, 200)))
    snap = pickle.loads(pickle.dumps(est.get_state()))
    rest = est.update(gyro[200:], accel[200:], mag[200:], **_inputs(est, speed, slice(200, None)))
    other = make_estimator(name, 200.0)
    other.set_state(snap)
    again = other.update(gyro[200:], accel[200:], mag[200:], **_inputs(other, speed, slice(200, None)))
    np.testing.assert_array_equal(again.q_wb, rest.q_wb)
    np.testing.assert_allclose(np.linalg.norm(snap.q_wb), 1.0)


@pytest.mark.parametrize("name", NAMES)
def test_refused_calls_lose_nothing(name):
    _, gyro, accel, mag, speed = _samples(60)
    est, ref = make_estimator(name, 200.0), make_estimator(name, 200.0)
    for e in (est, ref):
        e.update(gyro[:30], accel[:30], mag[:30], **_inputs(e, speed, slice(0, 30)))
    with pytest.raises(ValueError):
        est.update(gyro[30:], accel[30:], mag[30:40])
    with pytest.raises(ValueError):
        est.update(gyro[30:].T, accel[30:], mag[30:])
    with pytest.raises(TypeError):
        est.update(gyro[30:], accel[30:], mag[30:], temperature=np.zeros(30))
    if "speed_mps" in est.inputs:
        with pytest.raises(ValueError, match="speed_mps"):
            est.update(gyro[30:], accel[30:], mag[30:], speed_mps=np.zeros(5))
    np.testing.assert_array_equal(est.update(gyro[30:], accel[30:], mag[30:], **_inputs(est, speed, slice(30, None))).q_wb,
                                  ref.update(gyro[30:], accel[30:], mag[30:], **_inputs(ref, speed, slice(30, None))).q_wb)


@pytest.mark.parametrize("name", NAMES)
def test_reset_with_q0_and_perfect_sensors_track_the_truth(name):
    m = mo.make_motion("rotation", 3.0, 200.0, omega_b=(0.3, -0.2, 0.25))
    est = make_estimator(name, 200.0)
    est.reset(q0=m.q_wb[0])
    kw = {"speed_mps": np.zeros(len(m))} if "speed_mps" in est.inputs else {}
    out = est.update(m.omega_b, m.specific_force_b, m.mag_b, **kw)
    np.testing.assert_allclose(out.q_wb[0], m.q_wb[0])
    # DCM integrates to first order; the others are exact for held rates
    tol = 5e-3 if name == "dcm_pi" else 1e-6
    assert np.max(fr.quat_angle_between(out.q_wb, m.q_wb)) < tol


@pytest.mark.parametrize("name", NAMES)
def test_estimate_attitude_equals_update_and_describe_lists_params(name):
    _, gyro, accel, mag, _ = _samples(100)
    q = estimate_attitude(gyro, accel, mag, 200.0, method=name)
    np.testing.assert_array_equal(q, make_estimator(name, 200.0).update(gyro, accel, mag).q_wb)
    full = estimate_attitude(gyro, accel, mag, 200.0, method=name, full_output=True)
    np.testing.assert_array_equal(full.q_wb, q)
    info = describe_estimator(name)
    assert info["summary"] and all(r["unit"] is not None and r["doc"] for r in info["params"])


# --------------------------------------------------------------------------------------
# saturation and the sensor's own flags (input imu_flags), for every estimator
# --------------------------------------------------------------------------------------


def test_imu_flag_bits_are_the_sensor_package_bits():
    from biso_cosim.sensors import ImuFlag

    assert (fl.IMU_GYRO_SATURATED, fl.IMU_ACCEL_SATURATED, fl.IMU_MAG_OVERFLOW, fl.IMU_MAG_OVERRUN,
            fl.IMU_MAG_INVALID) == (ImuFlag.GYRO_SATURATED, ImuFlag.ACCEL_SATURATED, ImuFlag.MAG_OVERFLOW,
                                    ImuFlag.MAG_OVERRUN, ImuFlag.MAG_INVALID)


def _clean(n=200):
    m = mo.make_motion("rotation", n / 200.0, 200.0, omega_b=(0.2, -0.3, 0.4))
    return m, m.omega_b.copy(), m.specific_force_b.copy(), m.mag_b.copy()


@pytest.mark.parametrize("name", NAMES)
def test_saturated_samples_are_flagged_and_not_used(name):
    """A sample the sensor flags (imu_flags) or that reaches a declared full scale: a saturated
    accelerometer or overflowed magnetometer sample is treated as a missing one (the same
    attitude as with NaN there), a saturated gyro sample is used as it is; all are flagged."""
    m, gyro, accel, mag = _clean()
    sat = np.zeros(len(m), dtype=np.int64)
    sat[50] = fl.IMU_ACCEL_SATURATED
    sat[60] = fl.IMU_MAG_OVERFLOW
    sat[70] = fl.IMU_GYRO_SATURATED
    sat[80] = fl.IMU_MAG_INVALID | fl.IMU_MAG_OVERRUN
    out = make_estimator(name, 200.0).update(gyro, accel, mag, imu_flags=sat)
    nan_accel, nan_mag = accel.copy(), mag.copy()
    nan_accel[50] = np.nan
    nan_mag[[60, 80]] = np.nan
    ref = make_estimator(name, 200.0).update(gyro, nan_accel, nan_mag)
    np.testing.assert_array_equal(out.q_wb, ref.q_wb)
    assert out.flags[50] & fl.SATURATED and out.flags[50] & fl.ACCEL_INVALID and out.flags[50] & fl.MAG_INVALID
    assert out.flags[60] & fl.SATURATED and out.flags[60] & fl.MAG_INVALID and not out.flags[60] & fl.ACCEL_INVALID
    assert out.flags[70] & fl.SATURATED and not out.flags[70] & (fl.GYRO_INVALID | fl.ACCEL_INVALID)
    assert out.flags[80] & fl.MAG_INVALID and not out.flags[80] & fl.SATURATED
    others = np.setdiff1d(np.arange(len(m)), [50, 60, 70, 80])
    assert not np.any(out.flags[others] & (fl.SATURATED | fl.ACCEL_INVALID | fl.MAG_INVALID))
    # the same from declared full scales: an axis at ≥ 99.9 % of it
    accel[50] = [39.2, 0.0, 1.0]
    gyro[70] = [-4.36, 0.0, 0.0]
    ranged = make_estimator(name, 200.0, accel_range_mps2=39.2266, gyro_range_rad_s=4.3633).update(
        gyro, accel, mag)
    assert ranged.flags[50] & fl.SATURATED and ranged.flags[50] & fl.ACCEL_INVALID
    assert ranged.flags[70] & fl.SATURATED and not ranged.flags[70] & fl.GYRO_INVALID
    assert not np.any(ranged.flags[np.setdiff1d(np.arange(len(m)), [50, 70])] & fl.SATURATED)


@pytest.mark.parametrize("name", NAMES)
def test_bad_imu_flags_are_refused_and_lose_nothing(name):
    m, gyro, accel, mag = _clean(40)
    est, ref = make_estimator(name, 200.0), make_estimator(name, 200.0)
    for bad, err in (([1] * 39, ValueError), (np.full(40, -1), ValueError), (np.full(40, 0.5), ValueError),
                     (np.array(["a"] * 40), TypeError), (np.full(40, 2**31), ValueError),
                     (np.full(40, 2**64 - 1, dtype=np.uint64), ValueError), (np.full(40, 2.0**31), ValueError),
                     (np.full(40, -1, dtype=np.int8), ValueError)):
        with pytest.raises(err, match="imu_flags"):
            est.update(gyro, accel, mag, imu_flags=bad)
    ok = est.update(gyro, accel, mag, imu_flags=np.zeros(40))  # whole floats (a CSV column) are fine
    np.testing.assert_array_equal(ok.q_wb, ref.update(gyro, accel, mag).q_wb)
    with pytest.raises(ValueError, match="gyro_range_rad_s"):
        make_estimator(name, 200.0, gyro_range_rad_s=0.0)


@pytest.mark.parametrize("name", NAMES)
def test_prechecked_path_equals_update_bit_for_bit(name):
    """The co-simulation's checked-once path (Estimator.update_prechecked) gives what
    update gives, chunk by chunk, from the same state."""
    _, gyro, accel, mag, speed = _samples()
    flags = np.zeros(len(gyro), dtype=np.int64)
    flags[40:44] = int(GYRO_SATURATED)  # the sensor's bits, as the co-simulation passes them
    a, b = make_estimator(name, 200.0), make_estimator(name, 200.0)
    for start in range(0, len(gyro), 4):
        sl = slice(start, start + 4)
        extra = _inputs(a, speed, sl) | ({"imu_flags": flags[sl].copy()} if "imu_flags" in a.inputs else {})
        want = a.update(gyro[sl], accel[sl], mag[sl], **extra)
        got = b.update_prechecked(gyro[sl].copy(), accel[sl].copy(), mag[sl].copy(), extra)
        assert np.array_equal(got.q_wb, want.q_wb) and np.array_equal(got.flags, want.flags)
        assert (got.gyro_bias_b is None) == (want.gyro_bias_b is None)
        if got.gyro_bias_b is not None:
            assert np.array_equal(got.gyro_bias_b, want.gyro_bias_b)
    assert a.get_state() == b.get_state()


def test_prechecked_path_checks_again_when_the_parameters_change_the_inputs():
    """After set_params changes what an input must be (BISO's gyro_step needs dtheta_b), the
    next call is checked again: refused with update's message, nothing changed."""
    _, gyro, accel, mag, _ = _samples()
    est = make_estimator("biso", 200.0)
    est.update_prechecked(gyro[:4].copy(), accel[:4].copy(), mag[:4].copy(), {})
    state = est.get_state()
    est.set_params(gyro_step="two_sample")
    with pytest.raises(ValueError, match="needs the gyro increments: pass dtheta_b"):
        est.update_prechecked(gyro[4:8].copy(), accel[4:8].copy(), mag[4:8].copy(), {})
    assert est.get_state() == state
