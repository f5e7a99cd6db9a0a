"""Each error term of the model, one at a time, against its formula."""

import math

import numpy as np
import pytest

from biso_cosim.sensors import MPU9250, Profile
from biso_cosim.units import DEG, G0

IDEAL = Profile.load("ideal")


def _rest(n, omega=(0.0, 0.0, 0.0), force=(0.0, 0.0, G0), mag=(10.0, 20.0, -40.0)):
    return np.tile(omega, (n, 1)), np.tile(force, (n, 1)), np.tile(mag, (n, 1))


def test_temperature_slopes_of_bias_and_scale_factor():
    prof = IDEAL.replace(gyro__bias_tempco=0.48, gyro__scale_factor_tempco=0.064, accel__bias_tempco=1.5, accel__scale_factor_tempco=0.026)
    imu = MPU9250(prof, seed=7)
    e = imu.errors
    n = 2000
    temp = np.linspace(-10.0, 60.0, n)
    omega, force, mag = _rest(n, omega=(0.5, -0.3, 0.2), force=(1.0, -2.0, G0))
    s = imu.simulate(omega, force, mag, temp)
    dt = np.interp(s.t_s, np.arange(n) / 1000.0, temp)[:, None] - 25.0
    expect_g = omega[0] * (1 + e.gyro.scale_factor_tempco * dt) + e.gyro.bias_tempco * dt
    expect_a = force[0] * (1 + e.accel.scale_factor_tempco * dt) + e.accel.bias_tempco * dt
    np.testing.assert_allclose(s.gyro_b, expect_g, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(s.accel_b, expect_a, rtol=1e-12, atol=1e-15)
    # slopes drawn within the datasheet tolerances
    assert np.all(np.abs(e.gyro.bias_tempco) <= 0.48 * DEG)
    assert np.all(np.abs(e.accel.scale_factor_tempco) <= 0.026e-2)


def test_on_chip_temperature_sensor_codes_and_filter():
    imu = MPU9250("mpu9250", seed=0)  # quantized, filtered (DLPF_CFG = 3: 42 Hz)
    n = 3000
    temp = 30.0 + 0.01 * np.arange(n)  # 10 °C/s ramp
    s = imu.simulate(*_rest(n), temp)
    np.testing.assert_array_equal(s.raw.temp, np.round((s.temperature_c - 21.0) * 333.87).astype(np.int16))
    codes = (s.temperature_c - 21.0) * 333.87
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-9)  # whole steps of 1/333.87 °C
    # steady lag of a first-order 42 Hz filter at 1 kHz: a/(1-a) samples
    a = imu._cp[0]["temp_lp_a"]
    true_t = np.interp(s.t_s, np.arange(n) / 1000.0, temp)
    late = s.t_s > 1.0
    lag = (true_t[late] - s.temperature_c[late]) / 10.0
    np.testing.assert_allclose(lag, a / (1 - a) / 1000.0, atol=0.6 / 333.87 / 10.0)


def test_scale_cross_axis_nonlinearity_and_g_sensitivity():
    prof = IDEAL.replace(gyro__scale_factor=3.0, gyro__cross_axis=2.0, gyro__nonlinearity=0.1, gyro__g_sensitivity=0.1)
    imu = MPU9250(prof, seed=3)
    e = imu.errors.gyro
    fs = 250 * DEG
    omega = np.array([[200 * DEG, -150 * DEG, 30 * DEG]])
    force = np.array([[2.0, -1.0, G0]])
    s = imu.simulate(omega, force, np.ones((1, 3)))
    expect = e.sensitivity @ omega[0] + 2.5 * e.nonlinearity * fs * (omega[0] / fs) ** 3 + e.g_sensitivity @ force[0]
    np.testing.assert_allclose(s.gyro_b[0], expect, rtol=1e-12)
    # the nonlinearity's deviation from the best-fit line over ±FS is κ·FS at the ends
    u = np.linspace(-1, 1, 20001)
    cubic = 2.5 * u**3
    slope = np.polyfit(u, cubic, 1)
    assert np.max(np.abs(cubic - np.polyval(slope, u))) == pytest.approx(1.0, rel=1e-3)
    assert np.all(np.abs(np.diag(e.sensitivity) - 1) <= 0.03)
    off = e.sensitivity[~np.eye(3, dtype=bool)]
    assert np.all(np.abs(off) <= 0.02) and np.any(off != 0)


def test_turn_on_draws_follow_the_tolerances():
    draws = np.array([MPU9250("mpu9250", seed=s).errors.accel.bias for s in range(400)])
    tol = np.array([60.0, 60.0, 80.0]) * 1e-3 * G0
    assert np.all(np.abs(draws) <= tol)
    np.testing.assert_allclose(draws.std(axis=0), tol / 3 * 0.986, rtol=0.12)  # σ of N(0,(tol/3)²) cut at 3σ
    assert np.all(np.abs(draws.mean(axis=0)) < 3 * tol / 3 / math.sqrt(400))


def test_vehicle_hard_and_soft_iron():
    soft = np.array([[1.1, 0.05, 0.0], [0.05, 0.95, 0.0], [0.0, 0.0, 1.0]])
    hard = np.array([12.0, -7.0, 3.0])
    imu = MPU9250("ideal", hard_iron_ut=hard, soft_iron=soft)
    field = np.array([20.0, -5.0, -45.0])
    s = imu.simulate(*_rest(1, mag=field))
    np.testing.assert_allclose(s.mag_b[0], soft @ field + hard, rtol=1e-12)
    with pytest.raises(ValueError, match="soft_iron"):
        MPU9250(soft_iron=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="hard_iron_ut"):
        MPU9250(hard_iron_ut=[1.0, 2.0])


def test_mag_offset_noise_and_asa_residual():
    prof = IDEAL.replace(mag__offset=10.0, mag__noise=0.3, mag__asa_range=[150.0, 200.0], model__quantization=True)
    imu = MPU9250(prof, seed=9)
    n = 20000
    s = imu.simulate(*_rest(n, mag=(0.0, 0.0, 0.0)))
    fresh = s.mag_b[s.mag_fresh]
    # zero field: mean = offset (AK axes -> body: x_b = m_y, y_b = m_x, z_b = -m_z), std = noise
    off = imu.errors.mag.offset_ut
    adj_ratio = ((imu.asa - 128) / 256 + 1) / imu.errors.mag.sensitivity_factor
    expect = np.array([off[1] * adj_ratio[1], off[0] * adj_ratio[0], -off[2] * adj_ratio[2]])
    np.testing.assert_allclose(fresh.mean(axis=0), expect, atol=0.02)
    np.testing.assert_allclose(fresh.std(axis=0), 0.3, rtol=0.06)
    # the ASA code is the true factor rounded to 1/256
    assert np.all(np.abs(adj_ratio - 1) <= 0.5 / 256 / 1.09 + 1e-12)
