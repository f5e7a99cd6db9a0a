"""Multiple-integral increments ΔΘ^r, ΔV^r (Litmanovich 2002, eq. 1.14) and sub-interval increments."""

import math

import numpy as np
import pytest

from biso_cosim.frames import quat_from_euler, quat_to_matrix
from biso_cosim.sensors import MPU9250, Profile

FS = 1000.0


def _linear_truth(n, alpha, beta, fs=FS):
    t = np.arange(n) / fs
    return t, alpha[None, :] + beta[None, :] * t[:, None]


def _exact_linear(alpha, beta, t_end, T, r):
    """r-fold iterated integral over (t_end − T, t_end] of α + β t (per axis)."""
    t0 = t_end - T
    return (alpha + beta * t0) * T**r / math.factorial(r) + beta * T ** (r + 1) / math.factorial(r + 1)


@pytest.mark.parametrize("registers", [{}, {"smplrt_div": 9}, {"accel_fchoice_b": 1, "smplrt_div": 3}])
def test_linear_motion_gives_exact_iterated_integrals(registers):
    mounting = quat_from_euler(0.4, -0.3, 2.0)
    imu = MPU9250("ideal", registers=registers, mounting=mounting)
    T = 1.0 / imu.output_rate_hz
    alpha_w, beta_w = np.array([0.3, -0.2, 0.5]), np.array([1.0, 2.0, -0.5])
    alpha_f, beta_f = np.array([1.0, 0.5, 9.8]), np.array([-3.0, 1.0, 0.2])
    n = 400
    _, omega = _linear_truth(n, alpha_w, beta_w)
    _, force = _linear_truth(n, alpha_f, beta_f)
    s = imu.simulate(omega, force, np.ones((n, 3)), increments=4, subintervals=3)
    assert s.dtheta.shape == (len(s), 4, 3) and s.dtheta_sub.shape == (len(s), 3, 3)
    for k in range(1, len(s)):  # k = 0 holds the constant pre-history (checked below)
        for r in range(1, 5):
            np.testing.assert_allclose(s.dtheta[k, r - 1], _exact_linear(alpha_w, beta_w, s.t_s[k], T, r), rtol=1e-9, atol=1e-15)
            np.testing.assert_allclose(s.dv[k, r - 1], _exact_linear(alpha_f, beta_f, s.t_s[k], T, r), rtol=1e-9, atol=1e-15)
        for j in range(3):
            t_hi = s.t_s[k] - T + (j + 1) * T / 3
            np.testing.assert_allclose(s.dtheta_sub[k, j], _exact_linear(alpha_w, beta_w, t_hi, T / 3, 1), rtol=1e-9)
    np.testing.assert_allclose(s.dtheta_sub.sum(axis=1), s.dtheta[:, 0], rtol=1e-12, atol=1e-15)
    # the output at t = 0: the truth before it is its first value
    for r in range(1, 5):
        np.testing.assert_allclose(s.dtheta[0, r - 1], omega[0] * T**r / math.factorial(r), rtol=1e-12)


def test_sinusoid_is_within_the_trapezoid_error_bound():
    """A rate sin(wt): the polyline of 1 kHz samples integrates it to the trapezoid bound
    T·h²·w²/12 for ΔΘ¹ and T²·h²·w²/12 for ΔΘ² (a 7 Hz rate at h = 1 ms: ~1.6e-4 relative)."""
    freq, h = 7.0, 1e-3
    imu = MPU9250("ideal", registers={"smplrt_div": 9})
    n = 300
    t = np.arange(n) * h
    w = 2 * np.pi * freq
    omega = np.stack([np.sin(w * t), np.cos(w * t), 0 * t], axis=1)
    s = imu.simulate(omega, np.zeros((n, 3)), np.ones((n, 3)), increments=2)
    T = 1.0 / imu.output_rate_hz
    t1, t0 = s.t_s[1:], s.t_s[1:] - T
    exact1 = (np.cos(w * t0) - np.cos(w * t1)) / w  # ∫ sin
    exact2 = (T * np.cos(w * t0) - (np.sin(w * t1) - np.sin(w * t0)) / w) / w  # ∫∫ sin
    err1 = np.max(np.abs(s.dtheta[1:, 0, 0] - exact1))
    err2 = np.max(np.abs(s.dtheta[1:, 1, 0] - exact2))
    assert 0.1 * T * h**2 * w**2 / 12 < err1 <= T * h**2 * w**2 / 12
    assert err2 <= T**2 * h**2 * w**2 / 12


def test_increments_see_the_errors_of_the_part():
    """A constant bias b adds b·T^r/r! to every ΔΘ^r (gyro at rest, no DLPF in the increments)."""
    prof = Profile.load("ideal").replace(gyro__bias_initial=3.0)
    imu = MPU9250(prof, seed=2)
    b = imu.errors.gyro.bias
    n = 200
    s = imu.simulate(np.zeros((n, 3)), np.zeros((n, 3)), np.ones((n, 3)), increments=3)
    T = 1.0 / imu.output_rate_hz
    for r in range(1, 4):
        np.testing.assert_allclose(s.dtheta[:, r - 1], np.tile(b * T**r / math.factorial(r), (len(s), 1)), rtol=1e-9)
    # and the SI readings carry the same bias
    np.testing.assert_allclose(s.gyro_b, np.tile(b, (len(s), 1)), rtol=1e-9)


def test_increments_match_a_plain_reference():
    """The kernel's repeated summation against a direct quadrature of the polyline.

    The same part at ODR = 1 kHz hands out its internal samples themselves (no filter, no
    quantization in this profile; the noise stream does not depend on the ODR)."""
    prof = Profile.load("ideal").replace(gyro__noise_density=0.01)
    imu = MPU9250(prof, seed=1, registers={"smplrt_div": 4})
    n = 101
    s = imu.simulate(np.zeros((n, 3)), np.zeros((n, 3)), np.ones((n, 3)), increments=4, subintervals=2)
    samples = MPU9250(prof, seed=1, registers={"smplrt_div": 0}).simulate(np.zeros((n, 3)), np.zeros((n, 3)), np.ones((n, 3))).gyro_b
    T, h = 0.005, 0.001
    tau = np.linspace(0.0, T, 5001)
    for k in range(1, len(s)):
        pts = samples[5 * k - 5 : 5 * k + 1]  # the polyline over (t_k − T, t_k]
        w = np.stack([np.interp(tau, np.arange(6) * h, pts[:, a]) for a in range(3)], axis=1)
        for r in range(1, 5):
            kernel = (T - tau) ** (r - 1) / math.factorial(r - 1)
            scale = np.abs(pts).max() * T**r / math.factorial(r)
            np.testing.assert_allclose(s.dtheta[k, r - 1], np.trapezoid(kernel[:, None] * w, tau, axis=0), rtol=0, atol=1e-6 * scale)
        half = tau <= T / 2
        np.testing.assert_allclose(s.dtheta_sub[k, 0], np.trapezoid(w[half], tau[half], axis=0), rtol=0, atol=1e-6 * np.abs(pts).max() * T)
