"""Analytic test motions: exact multiple integrals (against mpmath and repeated summation),
body rates consistent with the attitudes, exact sculling velocity."""

import math

import mpmath
import numpy as np
import pytest
from scipy import integrate, special

from biso_cosim import frames
from biso_cosim.strapdown.motions import (
    ConingMotion,
    HarmonicSignal,
    ScullingMotion,
    bessel_j,
    exp_multiple_integrals,
)


@pytest.mark.parametrize("omega", [0.0, 1e-6, 0.3, 1.99, 2.01, 40.0, 3000.0])
def test_exp_multiple_integrals_against_mpmath(omega):
    """Against the closed form (e^{zT} − Σ_{j<r} (zT)^j/j!)/z^r in 80-digit arithmetic."""
    T = 1.0 if omega < 100 else 0.2
    got = exp_multiple_integrals(1j * omega, T, 4)
    with mpmath.workdps(80):
        z = mpmath.mpc(0, omega)
        for r in range(1, 5):
            if omega == 0.0:
                ref = mpmath.mpf(T) ** r / mpmath.factorial(r)
            else:
                head = sum((z * T) ** j / mpmath.factorial(j) for j in range(r))
                ref = (mpmath.exp(z * T) - head) / z**r
            ref = complex(ref)
            # double precision of e^{iωT} limits the relative accuracy to ~eps·ωT
            assert abs(got[r - 1] - ref) <= 4e-16 * max(1.0, omega * T) * abs(ref)


def test_multiple_integrals_are_the_limit_of_repeated_summation():
    """The paper's premise (3.3): ΔΘ^r formed by r-fold summation of high-rate samples."""
    sig = HarmonicSignal.of((0.2, -0.1, 0.3), [((1.0, 0.5j, -0.3), 2 * np.pi * 7.0), ((0.1j, 0.2, 0.4), 2 * np.pi * 31.0)])
    t0, T = 0.137, 0.05
    exact = sig.multiple_integrals([t0], T, 4)[0]
    errors = []
    for n in (400, 800):
        dt = T / n
        # midpoint-rule running sums: each level integrates the previous one
        level = sig(t0 + (np.arange(n) + 0.5) * dt)
        sums = []
        for r in range(4):
            cum = np.cumsum(level, axis=0) * dt
            sums.append(cum[-1])
            level = np.vstack([np.zeros(3), cum[:-1]]) + 0.5 * np.diff(np.vstack([np.zeros(3), cum]), axis=0)
        errors.append(np.abs(np.array(sums) - exact).max())
    assert errors[1] < errors[0] / 3.5  # second-order convergence to the exact values
    assert errors[1] < 1e-7


def test_sub_increments_partition_the_interval():
    sig = HarmonicSignal.of((0.1, 0, 0), [((1.0, 2.0, 3.0j), 50.0)])
    sub = sig.sub_increments([0.3, 1.1], 0.06, 3)
    whole = sig.multiple_integrals([0.3, 1.1], 0.06, 1)[:, 0]
    np.testing.assert_allclose(sub.sum(axis=1), whole, rtol=1e-14, atol=1e-17)
    np.testing.assert_allclose(sub[:, 1], sig.multiple_integrals([0.32, 1.12], 0.02, 1)[:, 0], rtol=1e-13)


def _body_rate_from_attitude(q_of_t, t, h=1e-6):
    """ω_b = 2 q* ∘ q̇ by central differences."""
    dq = (q_of_t(t + h) - q_of_t(t - h)) / (2 * h)
    return 2 * frames.quat_multiply(frames.quat_conjugate(q_of_t(t)), dq)[:, 1:]


def test_coning_motion_rate_and_exact_coning_integral():
    m = ConingMotion(half_angle_rad=0.3, rate_rad_s=5.0)
    t = np.linspace(0, 2, 7)
    np.testing.assert_allclose(m.omega_b(t), _body_rate_from_attitude(m.q_wb, t), atol=1e-8)
    # δΘ_c (1.12) along z by quadrature of ½ ΔΘ(t_k, t) × ω
    T, t0 = 0.2, 0.7
    def integrand(tau):
        alpha = m.omega_b.multiple_integrals([t0], tau, 1)[0, 0] if tau > 0 else np.zeros(3)
        return 0.5 * np.cross(alpha, m.omega_b(t0 + tau)[0])[2]
    ref, _ = integrate.quad(integrand, 0, T, epsabs=1e-15, epsrel=1e-13)
    assert m.coning_integral_z(T) == pytest.approx(ref, rel=1e-10)
    # the series branch of x − sin x
    small = ConingMotion(0.1, 1.0)
    assert small.coning_integral_z(0.01) == pytest.approx(0.5 * math.sin(0.1) ** 2 * float(mpmath.mpf("0.01") - mpmath.sin("0.01")), rel=1e-14)


def test_sculling_motion_rate_velocity_and_mean_sculling():
    m = ScullingMotion(angle_amplitude_rad=0.4, accel_amplitude_mps2=3.0, rate_rad_s=7.0)
    t = np.linspace(0, 1.3, 5)
    np.testing.assert_allclose(m.omega_b(t), _body_rate_from_attitude(m.q_wb, t), atol=1e-8)
    # exact velocity against quadrature of C(t) f_b(t)
    def a_w(s):
        return frames.quat_rotate(m.q_wb(s)[0], m.specific_force_b(s)[0])
    for tt in (0.3, 1.7):
        ref = [integrate.quad(lambda s: a_w(s)[i], 0, tt, epsabs=1e-13, limit=200)[0] for i in range(3)]
        np.testing.assert_allclose(m.v_w(tt)[0], ref, atol=1e-11)
    # phase mean of (1.8) along z
    T = 0.1
    phases = np.arange(8) * (2 * np.pi / m.rate_rad_s) / 8
    vals = []
    for t0 in phases:
        def integrand(tau):
            alpha = m.omega_b.multiple_integrals([t0], tau, 1)[0, 0] if tau > 0 else np.zeros(3)
            return np.cross(alpha, m.specific_force_b(t0 + tau)[0])[2]
        vals.append(integrate.quad(integrand, 0, T, epsabs=1e-15)[0])
    assert m.sculling_integral_z_mean(T) == pytest.approx(np.mean(vals), rel=1e-10)


@pytest.mark.parametrize("n", [0, 1, 2, 5, 12])
def test_bessel_against_scipy(n):
    for x in (0.0, 1e-3, 0.4, 2.5):
        assert bessel_j(n, x) == pytest.approx(special.jv(n, x), rel=1e-13, abs=1e-300)


@pytest.mark.parametrize("displacement", [False, True])
def test_exact_cross_integral_against_quadrature(displacement):
    from biso_cosim.strapdown.motions import exact_cross_integral

    rate = HarmonicSignal.of((0.1, -0.3, 0.2), [((1.0, 0.5j, -0.3), 40.0), ((0.2j, 0.1, 0.6), 170.0)])
    force = HarmonicSignal.of((0.0, 0.5, 9.8), [((2.0j, -1.0, 0.4), 63.0)])
    t0, T = 0.21, 0.09
    got = exact_cross_integral(rate, force, [t0], T, displacement=displacement)[0]

    def integrand(tau, i):
        alpha = rate.multiple_integrals([t0], tau, 1)[0, 0] if tau > 0 else np.zeros(3)
        w = (T - tau) if displacement else 1.0
        return w * np.cross(alpha, force(t0 + tau)[0])[i]

    ref = [integrate.quad(integrand, 0, T, args=(i,), epsabs=1e-14, epsrel=1e-12, limit=200)[0] for i in range(3)]
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-15)
