"""Analytic test motions with exact increments and multiple integrals.

The paper's algorithms are judged on coning and sculling (Litmanovich 2002, §2) and on
high-frequency harmonics in the sensor signals (pseudo-coning and pseudo-sculling, §6).
Here each signal is a sum of harmonics, so its sub-interval increments and multiple
integrals (1.14) are known in closed form and can be computed to double precision, with
no sampling error: the algorithms' own errors are then all that is measured.

The r-fold integral over [t0, t0 + T] of e^{iωt} is, by Cauchy's formula,
``e^{iωt0} I_r(iω)`` with ``I_r(z) = ∫₀^T (T − τ)^{r−1}/(r−1)! e^{zτ} dτ``; it is summed as a
power series for |zT| ≤ 2 (where the closed form ``(e^{zT} − Σ_{j<r} (zT)^j/j!)/z^r`` would
lose digits to cancellation) and in closed form above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["exp_multiple_integrals", "HarmonicSignal", "exact_cross_integral", "ConingMotion", "ScullingMotion",
           "bessel_j"]

_SERIES_LIMIT = 2.0
_SERIES_TERMS = 40  # 2**40 / 40! < 1e-35: the series is exact in double below the limit


def exp_multiple_integrals(z, T: float, r_max: int) -> np.ndarray:
    """``I_r(z)`` for r = 1..r_max, shape ``np.shape(z) + (r_max,)`` (complex).

    ``I_r(z) = ∫₀^T (T − τ)^{r−1}/(r−1)! e^{zτ} dτ``, the r-fold iterated integral of
    e^{zτ} over [0, T]; ``I_r(0) = T^r / r!``.
    """
    z = np.asarray(z, dtype=np.complex128)
    u = z * T
    out = np.empty(z.shape + (r_max,), dtype=np.complex128)
    small = np.abs(u) <= _SERIES_LIMIT
    for r in range(1, r_max + 1):
        # series (only its small-|u| entries are used): T^r Σ_j u^j / (j + r)!
        term = np.full(z.shape, 1.0 / math.factorial(r), dtype=np.complex128)
        series = term.copy()
        for j in range(1, _SERIES_TERMS):
            term = term * u / (j + r)
            series += term
        series *= T**r
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            head = sum(u**j / math.factorial(j) for j in range(r))
            closed = (np.exp(u) - head) / z**r
        out[..., r - 1] = np.where(small, series, closed)
    return out


@dataclass(frozen=True, eq=False)
class HarmonicSignal:
    """A 3-axis signal ``s(t) = mean + Re Σ_k amplitudes[k] e^{i rates[k] t}``.

    ``mean`` (3,); ``amplitudes`` (K, 3) complex; ``rates_rad_s`` (K,) angular frequencies.
    Units are those of the signal (rad/s for a gyro, m/s² for an accelerometer).
    """

    mean: np.ndarray
    amplitudes: np.ndarray
    rates_rad_s: np.ndarray

    @classmethod
    def of(cls, mean=(0.0, 0.0, 0.0), terms=()) -> HarmonicSignal:
        """From a mean and ``(amplitude_xyz, rate_rad_s)`` pairs."""
        amps = np.array([a for a, _ in terms], dtype=np.complex128).reshape(-1, 3)
        rates = np.array([w for _, w in terms], dtype=np.float64)
        return cls(np.asarray(mean, dtype=np.float64), amps, rates)

    def __call__(self, t) -> np.ndarray:
        """Values at times ``t`` (N,), shape (N, 3)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        phase = np.exp(1j * np.outer(t, self.rates_rad_s))  # (N, K)
        return self.mean + (phase @ self.amplitudes).real

    def multiple_integrals(self, t0, T: float, r_max: int) -> np.ndarray:
        """ΔΘ^r (or ΔV^r), r = 1..r_max, over [t0, t0 + T] for each start ``t0`` (N,):
        shape (N, r_max, 3), row r−1 the r-fold integral, eq. (1.14)."""
        t0 = np.atleast_1d(np.asarray(t0, dtype=np.float64))
        r = np.arange(1, r_max + 1)
        powers = np.array([T**k / math.factorial(k) for k in r])
        out = np.broadcast_to(powers[:, None] * self.mean, (t0.size, r_max, 3)).copy()
        if self.rates_rad_s.size:
            I = exp_multiple_integrals(1j * self.rates_rad_s, T, r_max)  # (K, r_max)
            phase = np.exp(1j * np.outer(t0, self.rates_rad_s))  # (N, K)
            out += np.einsum("nk,kr,kc->nrc", phase, I, self.amplitudes).real
        return out

    def sub_increments(self, t0, T: float, m: int) -> np.ndarray:
        """The m ordinary increments over [t0 + (j−1)T/m, t0 + jT/m], shape (N, m, 3)."""
        t0 = np.atleast_1d(np.asarray(t0, dtype=np.float64))
        h = T / m
        starts = (t0[:, None] + h * np.arange(m)).ravel()
        return self.multiple_integrals(starts, h, 1).reshape(t0.size, m, 3)


def exact_cross_integral(rate: HarmonicSignal, other: HarmonicSignal, t0, T: float, *,
                         displacement: bool = False) -> np.ndarray:
    """``∫₀^T ΔΘ(t0, t0 + τ) × other(t0 + τ) dτ`` for each start ``t0`` (N,), shape (N, 3).

    ΔΘ is the running integral of ``rate``: with ``other = rate`` this is twice the exact
    coning correction (1.12); with ``other`` the specific force, the exact sculling integral
    (1.8); with ``displacement=True`` the integrand is weighted by (T − τ), giving δS_s (5.4).
    Gauss-Legendre quadrature with enough nodes per oscillation to be exact in double.
    """
    t0 = np.atleast_1d(np.asarray(t0, dtype=np.float64))
    cycles = max(np.abs(rate.rates_rad_s).max(initial=0.0), np.abs(other.rates_rad_s).max(initial=0.0)) * T / (2 * np.pi)
    nodes, weights = np.polynomial.legendre.leggauss(int(40 + 24 * math.ceil(cycles)))
    tau, w = 0.5 * T * (nodes + 1.0), 0.5 * T * weights
    if displacement:
        w = w * (T - tau)
    out = np.zeros((t0.size, 3))
    for tj, wj in zip(tau, w):
        running = rate.multiple_integrals(t0, tj, 1)[:, 0]
        out += wj * np.cross(running, other(t0 + tj))
    return out


@dataclass(frozen=True)
class ConingMotion:
    """Coning of half-angle α at angular frequency ω_c about the z axis.

    ``q_wb(t)`` is the rotation by α about the axis (cos ω_c t, sin ω_c t, 0); its body rate
    is ``ω_b = (−ω_c sin α sin ω_c t, ω_c sin α cos ω_c t, −2 ω_c sin²(α/2))``: a constant
    rate along the cone axis z plus a rotating rate in the xy plane.
    """

    half_angle_rad: float
    rate_rad_s: float

    @property
    def omega_b(self) -> HarmonicSignal:
        a, w = self.half_angle_rad, self.rate_rad_s
        s = w * math.sin(a)
        return HarmonicSignal.of((0.0, 0.0, -2.0 * w * math.sin(0.5 * a) ** 2), [((1j * s, s, 0.0), w)])

    def q_wb(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        c, s = math.cos(0.5 * self.half_angle_rad), math.sin(0.5 * self.half_angle_rad)
        wt = self.rate_rad_s * t
        return np.stack([np.full_like(t, c), s * np.cos(wt), s * np.sin(wt), np.zeros_like(t)], axis=1)

    @property
    def error_scale(self) -> float:
        """sin²α·ω_c/2 (≈ α²ω_c/2), the unit of the drift formulas (2.12)-(4.14), rad/s."""
        return math.sin(self.half_angle_rad) ** 2 * self.rate_rad_s / 2

    def coning_integral_z(self, T: float) -> float:
        """The exact δΘ_c (1.12) of any interval along the cone axis:
        ½ sin²α (ω_c T − sin ω_c T)."""
        return 0.5 * math.sin(self.half_angle_rad) ** 2 * _x_minus_sin(self.rate_rad_s * T)


@dataclass(frozen=True)
class ScullingMotion:
    """Sculling: roll oscillation θ(t) = θ₀ sin ω₀t about x and specific force a₀ sin ω₀t
    along body y, in phase; it rectifies into a mean acceleration along world z.

    ``ω_b = (θ₀ ω₀ cos ω₀t, 0, 0)``, ``f_b = (0, a₀ sin ω₀t, 0)``, no gravity.
    """

    angle_amplitude_rad: float
    accel_amplitude_mps2: float
    rate_rad_s: float

    @property
    def omega_b(self) -> HarmonicSignal:
        return HarmonicSignal.of(terms=[((self.angle_amplitude_rad * self.rate_rad_s, 0.0, 0.0), self.rate_rad_s)])

    @property
    def specific_force_b(self) -> HarmonicSignal:
        return HarmonicSignal.of(terms=[((0.0, -1j * self.accel_amplitude_mps2, 0.0), self.rate_rad_s)])

    def q_wb(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        half = 0.5 * self.angle_amplitude_rad * np.sin(self.rate_rad_s * t)
        z = np.zeros_like(t)
        return np.stack([np.cos(half), np.sin(half), z, z], axis=1)

    @property
    def error_scale(self) -> float:
        """θ₀a₀/2, the unit of the sculling error formulas (2.6)-(4.12), m/s²."""
        return 0.5 * self.angle_amplitude_rad * self.accel_amplitude_mps2

    def sculling_integral_z_mean(self, T: float) -> float:
        """The exact δV_s (1.8) along z averaged over the phase of the interval:
        (θ₀ a₀ / 2)(T − sin(ω₀T)/ω₀)."""
        w = self.rate_rad_s
        return 0.5 * self.angle_amplitude_rad * self.accel_amplitude_mps2 * _x_minus_sin(w * T) / w

    def v_w(self, t) -> np.ndarray:
        """Exact world velocity from rest at t = 0 (Jacobi–Anger series), shape (N, 3)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        th, a0, w = self.angle_amplitude_rad, self.accel_amplitude_mps2, self.rate_rad_s
        wt = w * t
        # V̇_z = a₀ sin φ sin(θ₀ sin φ) = a₀ Σ_k J_{2k+1}(θ₀)[cos 2kφ − cos (2k+2)φ]
        vz = bessel_j(1, th) * (t - np.sin(2 * wt) / (2 * w))
        # V̇_y = a₀ sin φ cos(θ₀ sin φ) = a₀ J₀ sin φ + a₀ Σ_{k≥1} J_{2k}[sin(2k+1)φ − sin(2k−1)φ]
        vy = bessel_j(0, th) * (1 - np.cos(wt)) / w
        for k in range(1, 12):
            vz += bessel_j(2 * k + 1, th) * (np.sin(2 * k * wt) / (2 * k * w) - np.sin((2 * k + 2) * wt) / ((2 * k + 2) * w))
            j2k = bessel_j(2 * k, th)
            vy += j2k * ((1 - np.cos((2 * k + 1) * wt)) / ((2 * k + 1) * w) - (1 - np.cos((2 * k - 1) * wt)) / ((2 * k - 1) * w))
        return a0 * np.stack([np.zeros_like(t), vy, vz], axis=1)


def bessel_j(n: int, x: float) -> float:
    """Bessel function J_n(x) of integer order n ≥ 0 by its power series (|x| ≲ 5)."""
    half = 0.5 * x
    term = half**n / math.factorial(n)
    total = term
    for m in range(1, 60):
        term *= -half * half / (m * (m + n))
        total += term
        if abs(term) < 1e-18 * abs(total):
            break
    return total


def _x_minus_sin(x: float) -> float:
    """x − sin x without cancellation for small x."""
    if abs(x) > 0.5:
        return x - math.sin(x)
    x2 = x * x
    term = x * x2 / 6.0
    total = 0.0
    for k in range(1, 12):
        total += term
        term *= -x2 / ((2 * k + 2) * (2 * k + 3))
    return total
