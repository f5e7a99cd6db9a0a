"""BISO: the quaternion Poisson equation with cross-linked positional correction.

Aleshkin, Zdrazhevsky, Efremov, Skibin (2024), *Application of cross-linked positional
correction in a strapdown orientation system*, Izv. vuzov. Priborostroenie 67(8), 678–688.

The equation implemented (DESIGN.md §5, "reading D" of eqs. (2), (8), (9))::

    λ̇ = ½ λ∘ω − ½ ω_g∘λ + g_n λ(1 − |λ|²) + G (λ − λ_k)

with λ = q_wb (body → ENU; the paper's λ = q_gb in GOST axes differs by constant rotations
that leave its cross-link axis (1, 1, 1) unchanged, ``frames.Q_NUE_ENU``), ω the gyro rate
in body axes, ω_g the rate of the geographic frame (Earth rate, zero by default), g_n the
norm-correction gain of eq. (2), λ_k the accelerometer + magnetometer attitude
(``reference.py``) and G the correction matrix ``−k − k_p`` of eq. (8):

* sign pattern (12) with equal gains: ``G(λ − λ_k) = a∘(λ − λ_k)``, a = (−k, k_p, k_p, k_p),
  poles ``−k ± i√3 k_p`` (double) for any rate: the error decays as e^{−kt} whatever ω(t);
* sign pattern (13), or per-channel gains k_i, k_pi on the paper's λ components: a general
  4×4 matrix, checked for stability when the parameters are set.

The paper prints ``2λ̇ = …`` for the whole right side ("reading L"); its gains k = 44.4,
k_p = 25.64 ("two Butterworth LPFs, 0–10 Hz") match poles −k ± i√3 k_p, i.e. the factor 2
on the kinematics only ("reading D", the default). ``reading="L"`` halves the gains.

Discretisation (exact error dynamics at any rate)
-------------------------------------------------
Over each sample interval (t_{i−1}, t_i] the gyro rate is held at the current sample ω_i
(zero-order hold) and λ_k is held *moving with the gyro*: λ_k(t) solves the uncorrected
eq. (1) and equals λ_k,i at t_i. The error e = λ − λ_k then obeys the linear error dynamics
exactly, ė = a'∘e + e∘b with a' = a − ½ω_g (left multiplication) and b = ½ω_i (right
multiplication). Left and right multiplications commute, so for pattern (12) with equal
gains the step is closed-form and cheap (three quaternion products)::

    λ_i = λ_k,i + e^{a'h}∘(λ_{i−1}∘e^{bh} − e^{½ω_g h}∘λ_k,i)

The discrete error follows e_i = e^{a'h}∘e_{i−1}∘e^{bh}, the exact solution of the continuous
error dynamics at 100 Hz as at 1 kHz (discrete poles e^{ph} of the continuous poles p); when
the sensors agree with each other (perfect gyro, λ_k = truth) the estimate stays on the
truth at any rate of rotation, where a plain hold of λ_k would lag by about |ω|h/2. Other
gains use e_i = exp(h(G − ½L(ω_g) + R(b))) e_{i−1} with a 4×4 matrix exponential (Taylor
series with scaling and squaring). The norm term g_n λ(1 − |λ|²), tiny next to k, follows as
a second sub-step with its exact (logistic) flow, |λ|² → |λ|²E/(1 + |λ|²(E − 1)), E = e^{2g_n h}.

State and output
----------------
The state holds λ unnormalised (its norm is part of the dynamics through the norm term);
the output is λ/|λ|. ``renormalize=True`` instead divides λ by its norm after every step
(what many implementations do; with the cross-link it biases the estimate when λ_k is
noisy, DESIGN.md §5).

Input policy (per sample, never an exception): a non-finite gyro sample (or |ω| > 1e4
rad/s) is replaced by the last valid one (zero before any), flag GYRO_INVALID; a non-finite
or zero accelerometer sample skips the correction (gyro propagation only), flag
ACCEL_INVALID; an unusable magnetometer sample corrects tilt only, keeping the estimate's
heading, flag MAG_INVALID. Before the first valid accelerometer sample the output is the
identity, flag UNINITIALIZED. The output is never NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators._base import Estimator, check_finite, param
from biso_cosim.estimators.reference import (
    MAX_ACCEL,
    MAX_MAG,
    MAX_RATE,
    MIN_ACCEL,
    MIN_MAG,
    REFERENCE_METHODS,
    _mag_usable,
    _reference,
    _vec_norm_ok,
    _vec_ok,
)
from biso_cosim.frames import Q_FLU_FUR, Q_NUE_ENU, _qexp_rotvec, _qmul

__all__ = [
    "BisoParams",
    "BisoEstimator",
    "PAPER_K",
    "PAPER_K_P",
    "gains_from_cutoff",
    "correction_matrix",
    "stability",
    "EARTH_RATE",
]

PAPER_K = 44.4
"""Positional correction gain k of the paper's car test, 1/s."""
PAPER_K_P = 25.64
"""Cross-link gain k_p of the paper's car test, 1/s."""
EARTH_RATE = 7.292115e-5
"""Earth's rotation rate Ω, rad/s (WGS-84)."""

# Sign patterns of the cross-link matrix k_p of eq. (8): entry (i, j) multiplies k_pj.
# (12): eq. (9) as printed; (13): the alternative whose characteristic matrix the paper
# prints before eq. (13) (poles −k ± i k_p, −k ± i√3 k_p).
_PATTERNS = {
    12: np.array([[0, 1, 1, 1], [-1, 0, 1, -1], [-1, -1, 0, 1], [-1, 1, -1, 0]], dtype=float),
    13: np.array([[0, 1, 1, -1], [-1, 0, -1, -1], [-1, 1, 0, -1], [1, 1, -1, 0]], dtype=float),
}


def _gains_tuple(name: str, value: Any) -> tuple[float, ...]:
    arr = np.atleast_1d(np.asarray(value, dtype=np.float64))
    if arr.shape not in ((1,), (4,)):
        raise ValueError(f"{name} must be a number or 4 numbers (one per λ channel), got shape {arr.shape}")
    for i, x in enumerate(arr):
        check_finite(f"{name}[{i}]" if arr.size == 4 else name, x, low=0.0)
    return tuple(float(x) for x in np.broadcast_to(arr, (4,)))


@dataclass(frozen=True)
class BisoParams:
    """Parameters of the faithful BISO estimator (each documented once, here)."""

    k: float | tuple[float, float, float, float] | None = param(
        None, symbol="k, k_i", unit="1/s",
        doc="positional correction gain, one value or one per λ channel (i = 0..3); "
            "None = 44.4 (the paper) unless cutoff_hz is given",
        source="eqs. (8), (9); car test")
    k_p: float | tuple[float, float, float, float] | None = param(
        None, symbol="k_p, k_pi", unit="1/s",
        doc="cross-link gain, one value or one per λ channel; None = 25.64 (the paper) unless "
            "cutoff_hz is given; 0 = positional correction without cross-links",
        source="eqs. (8), (9); car test")
    cutoff_hz: float | None = param(
        None, symbol="f_c", unit="Hz",
        doc="tune by the Butterworth design frequency instead of k, k_p: ω_n = 2π f_c, "
            "poles −k ± i√3 k_p with k = ω_n/√2, k_p = ω_n/√6 (10 Hz gives the paper's gains); "
            "the −3 dB point of λ_k → λ is about 1.27 f_c",
        source="text after eq. (12); DESIGN.md §5")
    pattern: int = param(
        12, symbol="", unit="",
        doc="sign pattern of the cross-links: 12 (eq. (9), poles −k ± i√3k_p, double) or 13 "
            "(poles −k ± ik_p, −k ± i√3k_p)",
        source="eqs. (12), (13)")
    norm_gain: float = param(
        1.0, symbol="g_n", unit="1/s",
        doc="gain of the norm-correction term g_n λ(1 − |λ|²); 0 switches it off",
        source="eq. (2)")
    renormalize: bool = param(
        False, symbol="", unit="",
        doc="divide λ by |λ| after every step instead of (in addition to) the norm term",
        source="common practice; DESIGN.md §5 (bias with cross-links)")
    reading: str = param(
        "D", symbol="", unit="",
        doc="'D': the factor 2 of 2λ̇ on the kinematics only (matches the paper's tuning); "
            "'L': literal, 2λ̇ on the whole right side (all gains halved)",
        source="DESIGN.md §5")
    reference: str = param(
        "vector", symbol="", unit="",
        doc="construction of λ_k: 'vector' (TRIAD, singularity-free, trig-free) or "
            "'euler' (corrected eqs. (5)–(7))",
        source="eqs. (5)–(7); DESIGN.md §5")
    declination_rad: float = param(
        0.0, symbol="D", unit="rad",
        doc="magnetic declination, east positive: true heading = magnetic heading + D",
        source="eq. (5)")
    latitude_rad: float | None = param(
        None, symbol="φ", unit="rad",
        doc="latitude for the Earth-rate term −½ω_g∘λ, ω_g = Ω(0, cos φ, sin φ) in ENU; "
            "None = no Earth rate",
        source="eq. (1)")
    stability_rate_rad_s: float = param(
        5.0, symbol="|ω|max", unit="rad/s",
        doc="largest body rate at which non-equal gains or pattern 13 must keep all "
            "frozen-rate poles in the left half-plane (checked when the parameters are set)",
        source="Hurwitz analysis after eq. (13) (±4–5 rad/s in the paper)")


def gains_from_cutoff(cutoff_hz: float, reading: str = "D") -> tuple[float, float]:
    """(k, k_p) whose poles −k ± i√3k_p have damping 1/√2 and natural frequency 2π f_c."""
    wn = 2.0 * math.pi * cutoff_hz
    k, kp = wn / math.sqrt(2.0), wn / math.sqrt(6.0)
    return (k, kp) if reading == "D" else (2.0 * k, 2.0 * kp)


def _resolved_gains(p: BisoParams) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Per-channel (k_i, k_pi) as the user means them (before the reading's factor ½)."""
    if p.cutoff_hz is not None:
        if p.k is not None or p.k_p is not None:
            raise ValueError("give either cutoff_hz or k and k_p, not both")
        fc = check_finite("cutoff_hz", p.cutoff_hz, low=0.0, low_open=True)
        k, kp = gains_from_cutoff(fc, p.reading)
        return (k,) * 4, (kp,) * 4
    k = _gains_tuple("k", PAPER_K if p.k is None else p.k)
    kp = _gains_tuple("k_p", PAPER_K_P if p.k_p is None else p.k_p)
    return k, kp


def correction_matrix(params: BisoParams) -> np.ndarray:
    """G of λ̇ = … + G(λ − λ_k) on the paper's λ components (4×4), reading applied."""
    if params.pattern not in _PATTERNS:
        raise ValueError(f"pattern must be 12 or 13 (the paper's equations), got {params.pattern!r}")
    if params.reading not in ("D", "L"):
        raise ValueError(f"reading must be 'D' or 'L', got {params.reading!r}")
    k, kp = _resolved_gains(params)
    g = -np.diag(k) - _PATTERNS[params.pattern] * np.asarray(kp)[None, :]
    return 0.5 * g if params.reading == "L" else g


def _left(a) -> np.ndarray:
    """Matrix of q ↦ a∘q."""
    w, x, y, z = a
    return np.array([[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]], dtype=float)


def _right(b) -> np.ndarray:
    """Matrix of q ↦ q∘b."""
    w, x, y, z = b
    return np.array([[w, -x, -y, -z], [x, w, z, -y], [y, -z, w, x], [z, y, -x, w]], dtype=float)


# λ = T q with T = L(Q_NUE_ENU) R(Q_FLU_FUR) (orthogonal): G in our q_wb components is TᵀGT.
_T_GOST = _left(Q_NUE_ENU) @ _right(Q_FLU_FUR)


def _rate_directions() -> np.ndarray:
    """Unit rate directions for the frozen-rate stability check: axes, face and body diagonals."""
    d = [v for v in np.array(np.meshgrid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1])).reshape(3, -1).T if np.any(v)]
    d = np.array(d, dtype=float)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def stability(params: BisoParams, rates_rad_s: np.ndarray | None = None) -> dict[str, Any]:
    """Stability facts of the correction: poles at rest, worst real part over body rates.

    Returns ``{"poles_at_rest", "max_real_at_rest", "max_real_rotating", "worst_rate_b",
    "contractive"}``. ``contractive`` (symmetric part of G negative definite) guarantees
    exponential decay of the error for any ω(t); equal gains with pattern 12 have it.
    The rates checked are ``rates_rad_s`` (m, 3) in the paper's body axes, or the 26
    axis/diagonal directions at 12 magnitudes up to ``params.stability_rate_rad_s``.
    """
    g = correction_matrix(params)
    poles = np.linalg.eigvals(g)
    if rates_rad_s is None:
        mags = np.linspace(0.0, params.stability_rate_rad_s, 12)[1:]
        rates_rad_s = (mags[:, None, None] * _rate_directions()[None]).reshape(-1, 3)
    worst, worst_rate = -np.inf, np.zeros(3)
    for w in np.atleast_2d(rates_rad_s):
        re = np.linalg.eigvals(g + 0.5 * _right((0.0, *w))).real.max()
        if re > worst:
            worst, worst_rate = re, np.asarray(w, dtype=float)
    sym = 0.5 * (g + g.T)
    return {
        "poles_at_rest": poles,
        "max_real_at_rest": float(poles.real.max()),
        "max_real_rotating": float(worst),
        "worst_rate_b": worst_rate,
        "contractive": bool(np.linalg.eigvalsh(sym).max() < 0.0),
    }


# --------------------------------------------------------------------------------------
# Coefficients (flat array read by the kernel)
# --------------------------------------------------------------------------------------

MODE_NONE, MODE_CLOSED, MODE_GENERAL = 0, 1, 2

_C_MODE, _C_H, _C_REF, _C_DECL, _C_CDH, _C_SDH, _C_NORM_E, _C_RENORM = range(8)
_C_EA = 8  # e^{a'h}, a' = a − ½ω_g (closed mode): quaternion of norm e^{−kh}
_C_EG = 12  # e^{−½ω_g h}: free propagation on the left (unit quaternion)
_C_EGI = 16  # e^{+½ω_g h}: λ_k,i carried back to t_{i−1} (unit quaternion)
_C_WG = 20  # −½ω_g in ENU (general mode)
_C_G = 23  # G in q_wb components, 16 values row-major
_C_SIZE = 39


def biso_coefficients(params: BisoParams, fs_hz: float) -> np.ndarray:
    """Validate ``params`` and derive the kernel's coefficient array (raises ValueError)."""
    if not isinstance(params.renormalize, (bool, np.bool_)):
        raise TypeError(f"renormalize must be True or False, got {params.renormalize!r}")
    if params.reference not in REFERENCE_METHODS:
        raise ValueError(f"reference must be one of {REFERENCE_METHODS}, got {params.reference!r}")
    decl = check_finite("declination_rad", params.declination_rad)
    norm_gain = check_finite("norm_gain", params.norm_gain, low=0.0)
    check_finite("stability_rate_rad_s", params.stability_rate_rad_s, low=0.0)
    g_gost = correction_matrix(params)
    k, kp = _resolved_gains(params)
    h = 1.0 / fs_hz

    equal = len(set(k)) == 1 and len(set(kp)) == 1
    if not any(k) and not any(kp):
        mode = MODE_NONE
    elif equal and params.pattern == 12:
        if k[0] == 0.0:
            raise ValueError(f"k = 0 with k_p = {kp[0]} is not asymptotically stable (poles ±i√3k_p); use k > 0")
        mode = MODE_CLOSED
    else:
        mode = MODE_GENERAL
        st = stability(params)
        if st["max_real_at_rest"] >= 0.0:
            raise ValueError(
                f"unstable gains: the poles at rest {np.round(st['poles_at_rest'], 3).tolist()} "
                "must all have negative real parts (eq. (10) with ω = 0)")
        if st["max_real_rotating"] >= 0.0:
            raise ValueError(
                f"unstable gains: at the body rate {np.round(st['worst_rate_b'], 3).tolist()} rad/s "
                f"(paper axes) a pole has real part {st['max_real_rotating']:.4g} >= 0 "
                f"(checked up to stability_rate_rad_s = {params.stability_rate_rad_s})")

    wg = np.zeros(3)
    if params.latitude_rad is not None:
        lat = check_finite("latitude_rad", params.latitude_rad, low=-0.5 * math.pi, high=0.5 * math.pi)
        wg = EARTH_RATE * np.array([0.0, math.cos(lat), math.sin(lat)])

    scale = 0.5 if params.reading == "L" else 1.0
    c = np.zeros(_C_SIZE)
    c[_C_MODE], c[_C_H] = mode, h
    c[_C_REF] = REFERENCE_METHODS.index(params.reference)
    c[_C_DECL], c[_C_CDH], c[_C_SDH] = decl, math.cos(0.5 * decl), math.sin(0.5 * decl)
    c[_C_NORM_E] = 1.0 if params.renormalize else math.exp(2.0 * scale * norm_gain * h)
    c[_C_RENORM] = float(bool(params.renormalize))
    c[_C_EG:_C_EG + 4] = _qexp_rotvec(*(-wg * h))
    c[_C_EGI:_C_EGI + 4] = _qexp_rotvec(*(wg * h))
    c[_C_WG:_C_WG + 3] = -0.5 * wg
    c[_C_G:_C_G + 16] = (_T_GOST.T @ g_gost @ _T_GOST).ravel()
    if mode == MODE_CLOSED:
        # a = (−k, k_p, k_p, k_p); e^{a'h} = e^{−kh} (cos|v|h, sin|v|h v/|v|), v = a_v − ½ω_g
        kk, kpp = scale * k[0], scale * kp[0]
        v = np.array([kpp, kpp, kpp]) - 0.5 * wg
        c[_C_EA:_C_EA + 4] = math.exp(-kk * h) * np.array(_qexp_rotvec(*(2.0 * v * h)))
    return c


# --------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------


@jit
def _expm_small(z):
    """exp(z) of a small square matrix: Taylor series (order 14) with scaling and squaring."""
    n = z.shape[0]
    norm = 0.0
    for i in range(n):
        row = 0.0
        for j in range(n):
            row += abs(z[i, j])
        norm = max(norm, row)
    squarings = 0
    while norm > 0.25:
        norm *= 0.5
        squarings += 1
    zs = z * (0.5 ** squarings)
    e = np.eye(n)
    for order in range(14, 0, -1):  # Horner: I + Z(I + Z/2(I + …))
        e = np.eye(n) + (zs @ e) / order
    for _ in range(squarings):
        e = e @ e
    return e


@jit
def _error_transition(c, bx, by, bz):
    """Φ = exp(h(G − ½L(ω_g) + R(b))) for the general mode (4×4)."""
    z = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            z[i, j] = c[_C_G + 4 * i + j]
    gx, gy, gz = c[_C_WG], c[_C_WG + 1], c[_C_WG + 2]
    lm = ((0.0, -gx, -gy, -gz), (gx, 0.0, -gz, gy), (gy, gz, 0.0, -gx), (gz, -gy, gx, 0.0))
    rm = ((0.0, -bx, -by, -bz), (bx, 0.0, bz, -by), (by, -bz, 0.0, bx), (bz, by, -bx, 0.0))
    for i in range(4):
        for j in range(4):
            z[i, j] = (z[i, j] + lm[i][j] + rm[i][j]) * c[_C_H]
    return _expm_small(z)


@jit
def _qexp_fast(rx, ry, rz):
    """e^{(0, r)/2}: the rotation by |r| about r. For |r| ≤ 0.1 rad (every gyro step below
    20 rad/s at 200 Hz) a Taylor series to the 8th power is exact to rounding (next terms
    < 3e-20) and needs no trigonometry; beyond, sin and cos."""
    t2 = rx * rx + ry * ry + rz * rz
    if t2 <= 0.01:
        x = 0.25 * t2  # (|r|/2)²
        c = 1.0 - x / 2.0 * (1.0 - x / 12.0 * (1.0 - x / 30.0 * (1.0 - x / 56.0)))
        s = 0.5 * (1.0 - x / 6.0 * (1.0 - x / 20.0 * (1.0 - x / 42.0 * (1.0 - x / 72.0))))
        return c, s * rx, s * ry, s * rz
    return _qexp_rotvec(rx, ry, rz)


@jit
def _biso_propagate(c, mode, correct, lw, lx, ly, lz, kw, kx, ky, kz, gx, gy, gz):
    """One step of the linear part (see the module docstring); λ_k = (kw, …) when ``correct``."""
    h = c[_C_H]
    eb = _qexp_fast(gx * h, gy * h, gz * h)  # e^{bh}, b = ½ω
    p = _qmul(lw, lx, ly, lz, eb[0], eb[1], eb[2], eb[3])  # λ_{i−1}∘e^{bh}
    if not correct:
        if c[_C_EG] == 1.0:
            return p
        return _qmul(c[_C_EG], c[_C_EG + 1], c[_C_EG + 2], c[_C_EG + 3], p[0], p[1], p[2], p[3])
    if c[_C_EGI] == 1.0:  # no Earth rate: e^{½ω_g h} = 1
        r = (kw, kx, ky, kz)
    else:
        r = _qmul(c[_C_EGI], c[_C_EGI + 1], c[_C_EGI + 2], c[_C_EGI + 3], kw, kx, ky, kz)
    if mode == MODE_CLOSED:
        d = _qmul(c[_C_EA], c[_C_EA + 1], c[_C_EA + 2], c[_C_EA + 3],
                  p[0] - r[0], p[1] - r[1], p[2] - r[2], p[3] - r[3])
        return kw + d[0], kx + d[1], ky + d[2], kz + d[3]
    # general: e_{i−1} = λ_{i−1} − e^{½ω_g h}∘λ_k,i∘e^{−bh}; λ_i = λ_k,i + Φ e_{i−1}
    q = _qmul(r[0], r[1], r[2], r[3], eb[0], -eb[1], -eb[2], -eb[3])
    e0, e1, e2, e3 = lw - q[0], lx - q[1], ly - q[2], lz - q[3]
    phi = _error_transition(c, 0.5 * gx, 0.5 * gy, 0.5 * gz)
    return (kw + phi[0, 0] * e0 + phi[0, 1] * e1 + phi[0, 2] * e2 + phi[0, 3] * e3,
            kx + phi[1, 0] * e0 + phi[1, 1] * e1 + phi[1, 2] * e2 + phi[1, 3] * e3,
            ky + phi[2, 0] * e0 + phi[2, 1] * e1 + phi[2, 2] * e2 + phi[2, 3] * e3,
            kz + phi[3, 0] * e0 + phi[3, 1] * e1 + phi[3, 2] * e2 + phi[3, 3] * e3)


@jit
def _norm_substep(c, lw, lx, ly, lz):
    """Exact flow of λ̇ = g_n λ(1 − |λ|²) over h, or division by |λ| when renormalising."""
    n2 = lw * lw + lx * lx + ly * ly + lz * lz
    if c[_C_RENORM] != 0.0:
        f = 1.0 / math.sqrt(n2)
    else:
        e = c[_C_NORM_E]
        if e == 1.0:
            return lw, lx, ly, lz
        # f² = E/(1 + |λ|²(E − 1)) = 1 + x; near |λ| = 1 a series replaces the square root
        x = (e - 1.0) * (1.0 - n2) / (1.0 + n2 * (e - 1.0))
        f = 1.0 + 0.5 * x - 0.125 * x * x if abs(x) < 1e-6 else math.sqrt(1.0 + x)
    return lw * f, lx * f, ly * f, lz * f


# state layout: initialised (0 = no, 1 = running, 2 = q0 given, waiting for the first sample),
# λ (4), last valid gyro sample (3)
_S_INIT, _S_LAM, _S_GYRO = 0, 1, 5
_S_SIZE = 8
STATE_LAYOUT = (("initialized", 1), ("lam", 4), ("gyro_hold", 3))


@jit
def _input_checks(st, g_idx, gx, gy, gz, ax, ay, az, mx, my, mz):
    """Validity of one sample; replaces an invalid gyro by the held one (st[g_idx:g_idx+3])."""
    flags = 0
    if _vec_ok(gx, gy, gz, 0.0, MAX_RATE) or (gx == 0.0 and gy == 0.0 and gz == 0.0):
        st[g_idx], st[g_idx + 1], st[g_idx + 2] = gx, gy, gz
    else:
        gx, gy, gz = st[g_idx], st[g_idx + 1], st[g_idx + 2]
        flags |= fl.GYRO_INVALID
    acc_ok, fn = _vec_norm_ok(ax, ay, az, MIN_ACCEL, MAX_ACCEL)
    mag_ok = False
    if acc_ok:
        mag_ok = _vec_ok(mx, my, mz, MIN_MAG, MAX_MAG) and _mag_usable(ax, ay, az, mx, my, mz)
    else:
        flags |= fl.ACCEL_INVALID
    if not mag_ok:
        flags |= fl.MAG_INVALID
    return flags, gx, gy, gz, acc_ok, fn, mag_ok


@jit(inline="always")
def _biso_step_impl(c, st, gx, gy, gz, ax, ay, az, mx, my, mz, ref_method):
    """Advance the state by one sample; returns the sample's flags. Never raises.

    ``ref_method`` is a compile-time constant in the callers below (inlined), so the unused
    λ_k construction is compiled out (a runtime switch costs about 30 ns per sample)."""
    flags, gx, gy, gz, acc_ok, fn, mag_ok = _input_checks(st, _S_GYRO, gx, gy, gz, ax, ay, az, mx, my, mz)
    lw, lx, ly, lz = st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3]
    mode = int(c[_C_MODE])
    init = st[_S_INIT]
    if init == 2.0:  # q0 from reset(): it is the attitude at this first sample
        st[_S_INIT] = 1.0
        return flags
    correct = acc_ok and mode != MODE_NONE
    kw, kx, ky, kz = 1.0, 0.0, 0.0, 0.0
    if init == 0.0 or correct:
        if not acc_ok:  # nothing to initialise from yet
            return flags | fl.UNINITIALIZED
        # without a usable field, λ_k keeps the heading of the gyro-propagated estimate
        hw, hx, hy, hz = lw, lx, ly, lz
        if not mag_ok and init != 0.0:
            h = c[_C_H]
            eb = _qexp_rotvec(gx * h, gy * h, gz * h)
            hw, hx, hy, hz = _qmul(lw, lx, ly, lz, eb[0], eb[1], eb[2], eb[3])
        kw, kx, ky, kz = _reference(ref_method, ax, ay, az, fn, mx, my, mz, mag_ok,
                                    hw, hx, hy, hz, c[_C_DECL], c[_C_CDH], c[_C_SDH])
        if init == 0.0:  # eq. (7): the first valid sample sets the attitude
            st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3] = kw, kx, ky, kz
            st[_S_INIT] = 1.0
            return flags
        if kw * lw + kx * lx + ky * ly + kz * lz < 0.0:  # same hemisphere as λ
            kw, kx, ky, kz = -kw, -kx, -ky, -kz
    lam = _biso_propagate(c, mode, correct, lw, lx, ly, lz, kw, kx, ky, kz, gx, gy, gz)
    lam = _norm_substep(c, lam[0], lam[1], lam[2], lam[3])
    st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3] = lam
    return flags


@jit
def _biso_step_vector(c, st, gx, gy, gz, ax, ay, az, mx, my, mz):
    return _biso_step_impl(c, st, gx, gy, gz, ax, ay, az, mx, my, mz, 0)


@jit
def _biso_step_euler(c, st, gx, gy, gz, ax, ay, az, mx, my, mz):
    return _biso_step_impl(c, st, gx, gy, gz, ax, ay, az, mx, my, mz, 1)


@jit
def _biso_step(c, st, gx, gy, gz, ax, ay, az, mx, my, mz):
    """One sample (for callers that step sample by sample, e.g. an FMU): flags."""
    if c[_C_REF] == 0.0:
        return _biso_step_vector(c, st, gx, gy, gz, ax, ay, az, mx, my, mz)
    return _biso_step_euler(c, st, gx, gy, gz, ax, ay, az, mx, my, mz)


@jit
def _write_output(st, i, q_out):
    """q_out[i] = λ/|λ| (the identity before initialisation, as λ is then)."""
    lw, lx, ly, lz = st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3]
    n = 1.0 / math.sqrt(lw * lw + lx * lx + ly * ly + lz * lz)
    q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = lw * n, lx * n, ly * n, lz * n


@jit
def _biso_batch(c, st, gyro, accel, mag, q_out, flags_out):
    """The per-sample step over every row (the batch and streaming paths are this loop)."""
    if c[_C_REF] == 0.0:
        for i in range(gyro.shape[0]):
            flags_out[i] = _biso_step_vector(c, st, gyro[i, 0], gyro[i, 1], gyro[i, 2], accel[i, 0], accel[i, 1],
                                             accel[i, 2], mag[i, 0], mag[i, 1], mag[i, 2])
            _write_output(st, i, q_out)
    else:
        for i in range(gyro.shape[0]):
            flags_out[i] = _biso_step_euler(c, st, gyro[i, 0], gyro[i, 1], gyro[i, 2], accel[i, 0], accel[i, 1],
                                            accel[i, 2], mag[i, 0], mag[i, 1], mag[i, 2])
            _write_output(st, i, q_out)


def biso_initial_state(q0: np.ndarray | None) -> np.ndarray:
    st = np.zeros(_S_SIZE)
    st[_S_LAM] = 1.0
    if q0 is not None:
        st[_S_INIT] = 2.0
        st[_S_LAM:_S_LAM + 4] = q0
    return st


class BisoEstimator(Estimator):
    """The faithful BISO estimator (see the module docstring). Build it with
    ``make_estimator("biso", fs_hz, **params)``; ``"positional"`` (k_p = 0) and
    ``"poisson"`` (no correction, eq. (2)) are the same class with fixed gains."""

    method = "biso"
    Params = BisoParams
    state_layout = STATE_LAYOUT

    def _coefficients(self, params: BisoParams, fs_hz: float) -> np.ndarray:
        return biso_coefficients(params, fs_hz)

    def _initial_state(self, q0: np.ndarray | None) -> np.ndarray:
        return biso_initial_state(q0)

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias) -> None:
        _biso_batch(coef, state, gyro, accel, mag, q_out, flags)
