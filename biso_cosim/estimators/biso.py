"""BISO: the quaternion Poisson equation with cross-linked positional correction.

Aleshkin, Zdrazhevsky, Efremov, Skibin (2024), *Application of cross-linked positional
correction in a strapdown orientation system*, Izv. vuzov. Priborostroenie 67(8), 678–688.

The equation implemented (docs/design.md §5, "reading D" of eqs. (2), (8), (9))::

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
noisy, docs/design.md §5).

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
from typing import Any, NamedTuple

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators._base import (
    Estimator,
    GyroIncrements,
    accel_range_param,
    check_finite,
    gyro_range_param,
    layout_offsets,
    param,
    saturation_limits,
)
from biso_cosim.estimators._kernels import _input_checks, _qexp_fast
from biso_cosim.estimators.reference import REFERENCE_METHODS, _reference
from biso_cosim.frames import Q_FLU_FUR, Q_NUE_ENU, _qexp_rotvec, _qmul
from biso_cosim.strapdown._kernels import _batch_coning
from biso_cosim.strapdown.algorithms import check_rows, get_algorithm, list_algorithms, rotation_vector

__all__ = [
    "BisoParams",
    "BisoEstimator",
    "PAPER_K",
    "PAPER_K_P",
    "gains_from_cutoff",
    "correction_matrix",
    "stability",
    "geographic_rate",
    "EARTH_RATE",
    "WGS84_A",
    "WGS84_E2",
]

PAPER_K = 44.4
"""Positional correction gain k of the paper's car test, 1/s."""
PAPER_K_P = 25.64
"""Cross-link gain k_p of the paper's car test, 1/s."""
EARTH_RATE = 7.292115e-5
"""Earth's rotation rate Ω, rad/s (WGS-84)."""
WGS84_A = 6378137.0
"""Semi-major axis of the WGS-84 ellipsoid, m."""
WGS84_E2 = 6.69437999014e-3
"""First eccentricity squared of the WGS-84 ellipsoid."""

# Sign patterns of the cross-link matrix k_p of eq. (8): entry (i, j) multiplies k_pj.
# (12): eq. (9) as printed; (13): the alternative whose characteristic matrix the paper
# prints before eq. (13) (poles −k ± i k_p, −k ± i√3 k_p).
_PATTERNS = {
    12: np.array([[0, 1, 1, 1], [-1, 0, 1, -1], [-1, -1, 0, 1], [-1, 1, -1, 0]], dtype=float),
    13: np.array([[0, 1, 1, -1], [-1, 0, -1, -1], [-1, 1, 0, -1], [1, 1, -1, 0]], dtype=float),
}


def _gains_tuple(name: str, value: Any) -> tuple[float, ...]:
    if type(value) in (float, int):  # the common case without numpy (GainTuning sets gains every step)
        return (check_finite(name, value, low=0.0),) * 4
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
        source="text after eq. (12); docs/design.md §5")
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
        source="common practice; docs/design.md §5 (bias with cross-links)")
    reading: str = param(
        "D", symbol="", unit="",
        doc="'D': the factor 2 of 2λ̇ on the kinematics only (matches the paper's tuning); "
            "'L': literal, 2λ̇ on the whole right side (all gains halved)",
        source="docs/design.md §5")
    reference: str = param(
        "vector", symbol="", unit="",
        doc="construction of λ_k: 'vector' (TRIAD, singularity-free, trig-free) or "
            "'euler' (corrected eqs. (5)–(7))",
        source="eqs. (5)–(7); docs/design.md §5")
    declination_rad: float = param(
        0.0, symbol="D", unit="rad",
        doc="magnetic declination, east positive: true heading = magnetic heading + D",
        source="eq. (5)")
    latitude_rad: float | None = param(
        None, symbol="φ", unit="rad",
        doc="latitude for the term −½ω_g∘λ: Earth rate Ω(0, cos φ, sin φ) in ENU, plus the transport "
            "rate when the input velocity_enu_mps is given; None = no ω_g term (geographic frame "
            "taken as inertial)",
        source="eq. (1)")
    altitude_m: float = param(
        0.0, symbol="h", unit="m",
        doc="height above the WGS-84 ellipsoid, for the radii of curvature in the transport rate",
        source="eq. (1)")
    gyro_step: str = param(
        "hold", symbol="Φ", unit="",
        doc="attitude propagation over each sample interval: 'hold' (the gyro sample held over the "
            "interval, integrated exactly) or a coning algorithm of biso_cosim.strapdown ('one_sample', "
            "'two_sample', 'traditional3', 'traditional3_miller', 'smoothing', 'invariant'): the rotation "
            "vector Φ = ΔΘ + δΘ_c of the sensor's increments (input dtheta_b, in that algorithm's form) "
            "takes the place of ω h",
        source="Litmanovich (2002) eq. (1.11)")
    stability_rate_rad_s: float = param(
        5.0, symbol="|ω|max", unit="rad/s",
        doc="largest body rate at which non-equal gains or pattern 13 must keep all "
            "frozen-rate poles in the left half-plane (checked when the parameters are set)",
        source="Hurwitz analysis after eq. (13) (±4–5 rad/s in the paper)")
    gyro_range_rad_s: float | None = gyro_range_param()
    accel_range_mps2: float | None = accel_range_param()


def gains_from_cutoff(cutoff_hz: float, reading: str = "D") -> tuple[float, float]:
    """(k, k_p) whose poles −k ± i√3k_p have damping 1/√2 and natural frequency 2π f_c."""
    return _cutoff_gains(float(cutoff_hz), reading != "D")


@jit
def _cutoff_gains(cutoff_hz, doubled):
    """``gains_from_cutoff`` (``doubled``: reading "L"), for kernels too."""
    wn = 2.0 * math.pi * cutoff_hz
    k, kp = wn / math.sqrt(2.0), wn / math.sqrt(6.0)
    return (2.0 * k, 2.0 * kp) if doubled else (k, kp)


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


def correction_matrix(params: BisoParams, gains: tuple | None = None) -> np.ndarray:
    """G of λ̇ = … + G(λ − λ_k) on the paper's λ components (4×4), reading applied
    (``gains``: the ``_resolved_gains`` of ``params`` when already at hand)."""
    if params.pattern not in _PATTERNS:
        raise ValueError(f"pattern must be 12 or 13 (the paper's equations), got {params.pattern!r}")
    if params.reading not in ("D", "L"):
        raise ValueError(f"reading must be 'D' or 'L', got {params.reading!r}")
    k, kp = _resolved_gains(params) if gains is None else gains
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


def _radii(latitude_rad: float, altitude_m: float) -> tuple[float, float]:
    """(R_M + h, R_N + h): meridian and prime-vertical radii of curvature of WGS-84 plus height."""
    s2 = math.sin(latitude_rad) ** 2
    w = 1.0 - WGS84_E2 * s2
    return WGS84_A * (1.0 - WGS84_E2) / w ** 1.5 + altitude_m, WGS84_A / math.sqrt(w) + altitude_m


def geographic_rate(latitude_rad: float, velocity_enu_mps: Any = (0.0, 0.0, 0.0), altitude_m: float = 0.0) -> np.ndarray:
    """ω_g in ENU (rad/s): rate of the geographic frame, Earth rate plus transport rate,

    ``Ω(0, cos φ, sin φ) + (−v_N/(R_M + h), v_E/(R_N + h), v_E tan φ/(R_N + h))``

    with R_M, R_N the meridian and prime-vertical radii of WGS-84. ``velocity_enu_mps`` may be
    (3,) or (k, 3) (then the result is (k, 3)).
    """
    v = np.asarray(velocity_enu_mps, dtype=np.float64)
    rm, rn = _radii(latitude_rad, altitude_m)
    earth = EARTH_RATE * np.array([0.0, math.cos(latitude_rad), math.sin(latitude_rad)])
    transport = np.stack([-v[..., 1] / rm, v[..., 0] / rn, v[..., 0] * math.tan(latitude_rad) / rn], axis=-1)
    return earth + transport


# --------------------------------------------------------------------------------------
# Coefficients (flat array read by the kernel)
# --------------------------------------------------------------------------------------

MODE_NONE, MODE_CLOSED, MODE_GENERAL = 0, 1, 2

_COEF_LAYOUT = (
    ("mode", 1), ("h", 1), ("ref", 1), ("decl", 1), ("cdh", 1), ("sdh", 1),
    ("norm_e", 1),  # E = e^{2 g_n h} of the logistic norm flow (1: no norm term)
    ("norm_a", 1),  # (E − 1)/E
    ("renorm", 1),
    ("k", 1), ("k_p", 1),  # equal gains with the reading's factor (closed mode)
    ("ea", 4),  # e^{a'h}, a' = a − ½ω_g (closed mode, Earth rate only): quaternion of norm e^{−kh}
    ("eg", 4),  # e^{−½ω_g h}: free propagation on the left (Earth rate only)
    ("egi", 4),  # e^{+½ω_g h}: λ_k,i carried back to t_{i−1}
    ("wg", 3),  # Earth rate in ENU, rad/s (0 without latitude)
    ("g", 16),  # G in q_wb components, row-major (general mode)
    ("geo", 1),  # 1: latitude given (ω_g term on)
    ("inv_rm", 1), ("inv_rn", 1), ("tan_lat", 1),  # transport rate from the velocity input
    ("gyro_limit", 1), ("accel_limit", 1),
)
_C = layout_offsets(_COEF_LAYOUT)
(_C_MODE, _C_H, _C_REF, _C_DECL, _C_CDH, _C_SDH, _C_NORM_E, _C_NORM_A, _C_RENORM, _C_K, _C_KP, _C_EA, _C_EG,
 _C_EGI, _C_WG, _C_G, _C_GEO, _C_INV_RM, _C_INV_RN, _C_TAN_LAT, _C_GLIM, _C_ALIM) = (
    _C[name] for name, _ in _COEF_LAYOUT)
_C_SIZE = _C["_size"]


def biso_coefficients(params: BisoParams, fs_hz: float) -> np.ndarray:
    """Validate ``params`` and derive the kernel's coefficient array (raises ValueError)."""
    if not isinstance(params.renormalize, (bool, np.bool_)):
        raise TypeError(f"renormalize must be True or False, got {params.renormalize!r}")
    if params.reference not in REFERENCE_METHODS:
        raise ValueError(f"reference must be one of {REFERENCE_METHODS}, got {params.reference!r}")
    decl = check_finite("declination_rad", params.declination_rad)
    norm_gain = check_finite("norm_gain", params.norm_gain, low=0.0)
    altitude = check_finite("altitude_m", params.altitude_m, low=-1.0e4, high=1.0e6)
    check_finite("stability_rate_rad_s", params.stability_rate_rad_s, low=0.0)
    gyro_step_algorithm(params)
    glim, alim = saturation_limits(params)
    k, kp = _resolved_gains(params)
    g_gost = correction_matrix(params, (k, kp))
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

    c = np.zeros(_C_SIZE)
    wg = np.zeros(3)
    if params.latitude_rad is not None:
        lat = check_finite("latitude_rad", params.latitude_rad, low=-0.5 * math.pi, high=0.5 * math.pi)
        if abs(lat) > math.radians(89.9):
            raise ValueError(f"latitude_rad must be within ±89.9° (the transport rate has tan φ), got {lat!r}")
        wg = geographic_rate(lat)
        rm, rn = _radii(lat, altitude)
        c[_C_GEO], c[_C_INV_RM], c[_C_INV_RN], c[_C_TAN_LAT] = 1.0, 1.0 / rm, 1.0 / rn, math.tan(lat)

    scale = 0.5 if params.reading == "L" else 1.0
    c[_C_MODE], c[_C_H] = mode, h
    c[_C_REF] = REFERENCE_METHODS.index(params.reference)
    c[_C_DECL], c[_C_CDH], c[_C_SDH] = decl, math.cos(0.5 * decl), math.sin(0.5 * decl)
    e = 1.0 if params.renormalize else math.exp(2.0 * scale * norm_gain * h)
    c[_C_NORM_E], c[_C_NORM_A] = e, (e - 1.0) / e
    c[_C_RENORM] = float(bool(params.renormalize))
    c[_C_K], c[_C_KP] = scale * k[0], scale * kp[0]
    if wg.any():
        c[_C_EG:_C_EG + 4] = _qexp_rotvec(*(-wg * h))
        c[_C_EGI:_C_EGI + 4] = _qexp_rotvec(*(wg * h))
    else:  # no Earth or transport rate: the identity, without two kernel calls
        c[_C_EG] = c[_C_EGI] = 1.0
    c[_C_WG:_C_WG + 3] = wg
    _g_in_q(g_gost, _T_GOST, c[_C_G:_C_G + 16])
    c[_C_GLIM], c[_C_ALIM] = glim, alim
    if mode == MODE_CLOSED:
        c[_C_EA:_C_EA + 4] = _closed_transition(c[_C_K], c[_C_KP], wg[0], wg[1], wg[2], h)
    return c


_GAIN_NAMES = frozenset({"k", "k_p", "cutoff_hz"})
_PATTERN_12 = _PATTERNS[12]  # the closed-form correction's pattern (``_set_gains_in_place``)


def _set_gains_in_place(coef: np.ndarray, params: BisoParams, k: float, kp: float) -> None:
    """Closed-mode coefficients ``coef`` with the equal gains k, k_p of ``params`` (the
    entries ``biso_coefficients`` derives from the gains, by its expressions), in place:
    the arrays a co-simulation's period call reads stay the same (``biso_cosim.loop``)."""
    _write_equal_gains(coef, k, kp, params.reading == "L")


# --------------------------------------------------------------------------------------
# Kernels
# --------------------------------------------------------------------------------------


@jit
def _g_in_q(g, t, out):
    """out (16,) = (tᵀ g t) row-major: G of the paper's λ components in q_wb components."""
    for i in range(4):
        for j in range(4):
            total = 0.0
            for b in range(4):
                m = 0.0
                for a in range(4):
                    m += t[a, i] * g[a, b]
                total += m * t[b, j]
            out[4 * i + j] = total


@jit
def _set_closed_gains(c, k, kp, scale, pattern, t):
    """The entries of closed-mode coefficients ``c`` that depend on the equal gains k, k_p:
    as ``biso_coefficients`` derives them (``correction_matrix`` element by element)."""
    g = np.empty((4, 4))
    for a in range(4):
        for b in range(4):
            g[a, b] = scale * (-(k if a == b else 0.0) - pattern[a, b] * kp)
    _g_in_q(g, t, c[_C_G:_C_G + 16])
    c[_C_K] = scale * k
    c[_C_KP] = scale * kp
    q = _closed_transition(c[_C_K], c[_C_KP], c[_C_WG], c[_C_WG + 1], c[_C_WG + 2], c[_C_H])
    for i in range(4):
        c[_C_EA + i] = q[i]


@jit
def _write_equal_gains(coef, k, kp, reading_l):
    """``_set_gains_in_place``'s kernel (``reading_l``: the reading is "L"), for kernels too."""
    _set_closed_gains(coef, k, kp, 0.5 if reading_l else 1.0, _PATTERN_12, _T_GOST)


@jit(inline="always")
def _closed_transition(k, kp, wgx, wgy, wgz, h):
    """e^{a'h} for a = (−k, k_p, k_p, k_p), a' = a − ½ω_g (left multiplication):
    e^{−kh} (cos|v|h, sin|v|h v/|v|) with v = k_p(1, 1, 1) − ½ω_g."""
    d = math.exp(-k * h)
    q = _qexp_rotvec(2.0 * h * (kp - 0.5 * wgx), 2.0 * h * (kp - 0.5 * wgy), 2.0 * h * (kp - 0.5 * wgz))
    return d * q[0], d * q[1], d * q[2], d * q[3]


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
def _error_transition(c, wgx, wgy, wgz, bx, by, bz):
    """Φ = exp(h(G − ½L(ω_g) + R(b))) for the general mode (4×4)."""
    z = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            z[i, j] = c[_C_G + 4 * i + j]
    gx, gy, gz = -0.5 * wgx, -0.5 * wgy, -0.5 * wgz
    lm = ((0.0, -gx, -gy, -gz), (gx, 0.0, -gz, gy), (gy, gz, 0.0, -gx), (gz, -gy, gx, 0.0))
    rm = ((0.0, -bx, -by, -bz), (bx, 0.0, bz, -by), (by, -bz, 0.0, bx), (bz, by, -bx, 0.0))
    for i in range(4):
        for j in range(4):
            z[i, j] = (z[i, j] + lm[i][j] + rm[i][j]) * c[_C_H]
    return _expm_small(z)


# (1 − y)^{−½} = Σ c_k y^k, c_k = (2k)!/(4^k k!²)
_R1, _R2, _R3, _R4 = 0.5, 0.375, 0.3125, 0.2734375
_R5, _R6, _R7, _R8 = 0.24609375, 0.2255859375, 0.20947265625, 0.196380615234375


@jit(inline="always")
def _inv_sqrt_1m(y):
    """(1 − y)^{−½}; for |y| < 0.01 (|λ| within 0.5 % of 1: the norm of λ wanders by a few
    1e-3 with a noisy λ_k and the cross-link) the series to y⁸ (dropped terms below 2e-19),
    by Estrin's scheme (a short chain of dependent operations); beyond, 1/√(1 − y)."""
    if abs(y) < 0.01:
        y2 = y * y
        y4 = y2 * y2
        return (((1.0 + _R1 * y) + y2 * (_R2 + _R3 * y))
                + y4 * ((_R4 + _R5 * y) + y2 * (_R6 + _R7 * y) + y4 * _R8))
    return 1.0 / math.sqrt(1.0 - y)


@jit(inline="always")
def _norm_flow(e, a, lw, lx, ly, lz):
    """Exact flow over h of λ̇ = g_n λ(1 − |λ|²): λ·f with f² = E/(1 + |λ|²(E − 1)).

    With y = a(1 − |λ|²), a = (E − 1)/E, this is f = (1 − y)^{−½}: a series near |λ| = 1 (no
    division or square root on the recursion's chain), the formula itself far from it."""
    n2 = lw * lw + lx * lx + ly * ly + lz * lz
    y = a * (1.0 - n2)
    f = _inv_sqrt_1m(y) if abs(y) < 0.01 else math.sqrt(e / (1.0 + n2 * (e - 1.0)))
    return lw * f, lx * f, ly * f, lz * f


@jit(inline="always")
def _unit_output(lw, lx, ly, lz):
    """λ/|λ| (series of (1 + z)^{−½}, z = |λ|² − 1, near |λ| = 1)."""
    f = _inv_sqrt_1m(1.0 - (lw * lw + lx * lx + ly * ly + lz * lz))
    return lw * f, lx * f, ly * f, lz * f


# state layout: initialised (0 = no, 1 = running, 2 = q0 given, waiting for the first sample),
# λ (4), last valid gyro sample (3)
STATE_LAYOUT = (("initialized", 1), ("lam", 4), ("gyro_hold", 3))
_S = layout_offsets(STATE_LAYOUT)
_S_INIT, _S_LAM, _S_GYRO = _S["initialized"], _S["lam"], _S["gyro_hold"]
_S_SIZE = _S["_size"]


_BLOCK = 64  # samples per block of the two passes of _biso_batch
# scratch columns per sample of a block: e^{bh} (4), λ_k (4), |f|², what is usable (0 nothing,
# 1 the accelerometer, 2 λ_k is ready), the gyro sample used (3), the flags
_BUF_COLS = 14


@jit(error_model="numpy")
def _biso_batch(c, st, gyro, accel, mag, imu_flags, vel, q_out, flags_out, buf):
    """Advance the state over every row (the batch and the streaming paths are this loop).

    ``imu_flags`` (k,) and ``vel`` (k, 3) are empty when not given; ``buf`` is scratch space
    of shape (_BLOCK, _BUF_COLS) (kept by the estimator: no allocation per call). Nothing
    raises.

    Samples go in blocks of _BLOCK, each in two passes with the same arithmetic as one
    pass: first what does not depend on the estimate (input checks, e^{bh}, λ_k from the
    accelerometer and a usable field), which the processor overlaps across samples; then
    the recursion itself, whose chain of dependent operations sets the speed. The state is
    held in local variables and written back at the end."""
    n = gyro.shape[0]
    has_flags = imu_flags.shape[0] == n
    has_vel = vel.shape[0] == n and c[_C_GEO] != 0.0
    mode = int(c[_C_MODE])
    ref = int(c[_C_REF])
    h = c[_C_H]
    decl, cdh, sdh = c[_C_DECL], c[_C_CDH], c[_C_SDH]
    norm_e, norm_a, renorm = c[_C_NORM_E], c[_C_NORM_A], c[_C_RENORM] != 0.0
    glim, alim = c[_C_GLIM], c[_C_ALIM]
    geo = c[_C_GEO] != 0.0
    ea0, ea1, ea2, ea3 = c[_C_EA], c[_C_EA + 1], c[_C_EA + 2], c[_C_EA + 3]
    eg0, eg1, eg2, eg3 = c[_C_EG], c[_C_EG + 1], c[_C_EG + 2], c[_C_EG + 3]
    ei0, ei1, ei2, ei3 = c[_C_EGI], c[_C_EGI + 1], c[_C_EGI + 2], c[_C_EGI + 3]
    wgx, wgy, wgz = c[_C_WG], c[_C_WG + 1], c[_C_WG + 2]
    init = st[_S_INIT]
    lw, lx, ly, lz = st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3]
    hx, hy, hz = st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2]
    for start in range(0, n, _BLOCK):
        stop = min(start + _BLOCK, n)
        need_ref = mode != MODE_NONE or init != 1.0
        for i in range(start, stop):
            j = i - start
            sf = imu_flags[i] if has_flags else 0
            ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
            mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
            flags, gx, gy, gz, acc_ok, f2, mag_ok, ex, ey, ez, e2 = _input_checks(
                gyro[i, 0], gyro[i, 1], gyro[i, 2], ax, ay, az, mx, my, mz, hx, hy, hz, sf, glim, alim)
            hx, hy, hz = gx, gy, gz
            buf[j, 13] = flags
            buf[j, 0], buf[j, 1], buf[j, 2], buf[j, 3] = _qexp_fast(gx * h, gy * h, gz * h)  # e^{bh}, b = ½ω
            buf[j, 8] = f2
            buf[j, 9] = 0.0
            buf[j, 10], buf[j, 11], buf[j, 12] = gx, gy, gz
            if acc_ok:
                buf[j, 9] = 1.0
                if mag_ok and need_ref:
                    buf[j, 4], buf[j, 5], buf[j, 6], buf[j, 7] = _reference(
                        ref, ax, ay, az, f2, ex, ey, ez, e2, mx, my, mz, True, 1.0, 0.0, 0.0, 0.0, decl, cdh, sdh)
                    buf[j, 9] = 2.0
        for i in range(start, stop):
            j = i - start
            flags = int(buf[j, 13])
            usable = buf[j, 9]
            kw, kx, ky, kz = buf[j, 4], buf[j, 5], buf[j, 6], buf[j, 7]
            if init == 1.0:
                if has_vel:  # ω_g with the transport rate of this sample's velocity (unknown: 0)
                    ve, vn = vel[i, 0], vel[i, 1]
                    if not (math.isfinite(ve) and math.isfinite(vn)):
                        ve = vn = 0.0
                    wgx = c[_C_WG] - vn * c[_C_INV_RM]
                    wgy = c[_C_WG + 1] + ve * c[_C_INV_RN]
                    wgz = c[_C_WG + 2] + ve * c[_C_TAN_LAT] * c[_C_INV_RN]
                    ei0, ei1, ei2, ei3 = _qexp_fast(wgx * h, wgy * h, wgz * h)
                    eg0, eg1, eg2, eg3 = ei0, -ei1, -ei2, -ei3
                    if mode == MODE_CLOSED:
                        ea0, ea1, ea2, ea3 = _closed_transition(c[_C_K], c[_C_KP], wgx, wgy, wgz, h)
                eb0, eb1, eb2, eb3 = buf[j, 0], buf[j, 1], buf[j, 2], buf[j, 3]
                pw, px, py, pz = _qmul(lw, lx, ly, lz, eb0, eb1, eb2, eb3)  # λ_{i−1}∘e^{bh}
                if usable != 0.0 and mode != MODE_NONE:
                    if usable == 1.0:  # no usable field: λ_k keeps the heading of the propagated estimate
                        kw, kx, ky, kz = _reference(ref, accel[i, 0], accel[i, 1], accel[i, 2], buf[j, 8],
                                                    0.0, 0.0, 0.0, 0.0, mag[i, 0], mag[i, 1], mag[i, 2], False,
                                                    pw, px, py, pz, decl, cdh, sdh)
                    if kw * lw + kx * lx + ky * ly + kz * lz < 0.0:  # same hemisphere as λ
                        kw, kx, ky, kz = -kw, -kx, -ky, -kz
                    rw, rx, ry, rz = kw, kx, ky, kz
                    if geo:  # λ_k,i carried back to t_{i−1} on the left: e^{½ω_g h}∘λ_k,i
                        rw, rx, ry, rz = _qmul(ei0, ei1, ei2, ei3, kw, kx, ky, kz)
                    if mode == MODE_CLOSED:
                        # λ_i = λ_k,i + e^{a'h}∘(λ_{i−1}∘e^{bh} − e^{½ω_g h}∘λ_k,i)
                        dw, dx, dy, dz = _qmul(ea0, ea1, ea2, ea3, pw - rw, px - rx, py - ry, pz - rz)
                        lw, lx, ly, lz = kw + dw, kx + dx, ky + dy, kz + dz
                    else:
                        # e_{i−1} = λ_{i−1} − e^{½ω_g h}∘λ_k,i∘e^{−bh};  λ_i = λ_k,i + Φ e_{i−1}
                        qw, qx, qy, qz = _qmul(rw, rx, ry, rz, eb0, -eb1, -eb2, -eb3)
                        e0, e1, e2, e3 = lw - qw, lx - qx, ly - qy, lz - qz
                        phi = _error_transition(c, wgx, wgy, wgz, 0.5 * buf[j, 10], 0.5 * buf[j, 11], 0.5 * buf[j, 12])
                        lw = kw + phi[0, 0] * e0 + phi[0, 1] * e1 + phi[0, 2] * e2 + phi[0, 3] * e3
                        lx = kx + phi[1, 0] * e0 + phi[1, 1] * e1 + phi[1, 2] * e2 + phi[1, 3] * e3
                        ly = ky + phi[2, 0] * e0 + phi[2, 1] * e1 + phi[2, 2] * e2 + phi[2, 3] * e3
                        lz = kz + phi[3, 0] * e0 + phi[3, 1] * e1 + phi[3, 2] * e2 + phi[3, 3] * e3
                elif geo:
                    lw, lx, ly, lz = _qmul(eg0, eg1, eg2, eg3, pw, px, py, pz)
                else:
                    lw, lx, ly, lz = pw, px, py, pz
                if renorm:
                    f = 1.0 / math.sqrt(lw * lw + lx * lx + ly * ly + lz * lz)
                    lw, lx, ly, lz = lw * f, lx * f, ly * f, lz * f
                elif norm_e != 1.0:
                    lw, lx, ly, lz = _norm_flow(norm_e, norm_a, lw, lx, ly, lz)
            elif init == 2.0:  # q0 from reset(): it is the attitude at this first sample
                init = 1.0
            elif usable != 0.0:  # eq. (7): the first valid sample sets the attitude
                if usable == 1.0:
                    kw, kx, ky, kz = _reference(ref, accel[i, 0], accel[i, 1], accel[i, 2], buf[j, 8],
                                                0.0, 0.0, 0.0, 0.0, mag[i, 0], mag[i, 1], mag[i, 2], False,
                                                1.0, 0.0, 0.0, 0.0, decl, cdh, sdh)
                lw, lx, ly, lz = kw, kx, ky, kz
                init = 1.0
            else:  # nothing to initialise from yet
                flags |= fl.UNINITIALIZED
            flags_out[i] = flags
            q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = _unit_output(lw, lx, ly, lz)
    st[_S_INIT] = init
    st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3] = lw, lx, ly, lz
    st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2] = hx, hy, hz


def biso_initial_state(q0: np.ndarray | None) -> np.ndarray:
    st = np.zeros(_S_SIZE)
    st[_S_LAM] = 1.0
    if q0 is not None:
        st[_S_INIT] = 2.0
        st[_S_LAM:_S_LAM + 4] = q0
    return st


def gyro_step_algorithm(params: BisoParams):
    """The strapdown coning algorithm of ``gyro_step`` (``AlgorithmInfo``), None for 'hold'."""
    if params.gyro_step == "hold":
        return None
    try:
        return get_algorithm("coning", params.gyro_step)
    except (TypeError, ValueError):
        names = ", ".join(["hold"] + [a.name for a in list_algorithms("coning")])
        raise ValueError(f"gyro_step must be one of {names}; got {params.gyro_step!r}") from None


def rates_from_increments(step, dtheta_b: np.ndarray, gyro_b: np.ndarray, h: float) -> np.ndarray:
    """The rate the kernel integrates over each interval, Φ/h with Φ = ΔΘ + δΘ_c (Litmanovich
    2002, eq. (1.11)): held over the interval it turns λ by exactly Φ. Samples with non-finite
    increments keep their gyro reading (which then follows the gyro policy). The slow
    reference of ``_rates_from_increments`` (the strapdown package's ``rotation_vector``)."""
    out = np.array(gyro_b, dtype=np.float64, copy=True)
    ok = np.isfinite(dtheta_b).all(axis=(1, 2))
    if ok.any():
        out[ok] = rotation_vector(step.name, dtheta_b[ok], h) / h
    return out


@jit
def _rates_from_increments(algorithm, sum_rows, dtheta_b, gyro_b, h, out):
    """``rates_from_increments`` in a kernel, the same numbers bit for bit: into ``out`` (k, 3),
    Φ/h of each sample whose m increments ``dtheta_b`` (k, m, 3) are all finite, its gyro
    reading otherwise. ``algorithm`` the coning algorithm's id (``AlgorithmInfo.id``);
    ``sum_rows``: ΔΘ is the sum of the m rows (the "sub" form, summed from 0 as numpy's
    ``sum`` does), else ΔΘ¹, the first row (the "multiple" form). The coning correction
    (``_batch_coning``, per row) is written into ``out`` first."""
    _batch_coning(algorithm, dtheta_b, h, out)
    m = dtheta_b.shape[1]
    for i in range(gyro_b.shape[0]):
        finite = True
        for j in range(m):
            for a in range(3):
                if not math.isfinite(dtheta_b[i, j, a]):
                    finite = False
        for a in range(3):
            if not finite:
                out[i, a] = gyro_b[i, a]
                continue
            if sum_rows:
                total = 0.0
                for j in range(m):
                    total += dtheta_b[i, j, a]
            else:
                total = dtheta_b[i, 0, a]
            out[i, a] = (total + out[i, a]) / h


def gyro_increments(params: BisoParams) -> GyroIncrements | None:
    """The increments ``gyro_step`` integrates, None for 'hold': the algorithm's own form and
    rows, and a one-row algorithm (one_sample) takes ΔΘ¹, the whole interval's increment."""
    step = gyro_step_algorithm(params)
    if step is None:
        return None
    if step.form == "multiple" or step.m_dtheta == 1:
        return GyroIncrements("multiple", step.m_dtheta)
    return GyroIncrements("sub", step.m_dtheta)


class BisoLoopArrays(NamedTuple):
    """BISO's arrays in the co-simulation's period call (``BisoEstimator.loop_arrays``)."""

    coef: np.ndarray
    state: np.ndarray
    scratch: np.ndarray  # (_BLOCK, _BUF_COLS), ``_biso_batch``'s
    velocity_enu_mps: np.ndarray  # (0, 3): the loop gives no velocity
    q_wb: np.ndarray
    flags: np.ndarray
    # ``gyro_step``: the coning algorithm's id (-1: 'hold', the readings themselves), whether
    # it sums its increments (``_rates_from_increments``), whether it reads the multiple
    # integrals ``PeriodSamples.dtheta_b`` (else ``dtheta_sub_b``), how many rows (m), the
    # sample interval (s), and the rates Φ/h it makes (bound, 3)
    step_id: int
    step_sums: bool
    step_multiple: bool
    step_rows: int
    interval_s: float
    rates_b: np.ndarray


@jit
def _biso_loop(arrays, samples):
    """BISO on a period's samples (``biso_cosim.loop``): ``update`` with the sensor's flags
    as ``imu_flags``, without velocity, and with a coning-algorithm ``gyro_step`` the
    period's increments (``PeriodSamples.dtheta_b`` or ``dtheta_sub_b``) as ``dtheta_b``."""
    k = samples.gyro_b.shape[0]
    if arrays.step_id < 0:
        _biso_batch(arrays.coef, arrays.state, samples.gyro_b, samples.accel_b, samples.mag_b, samples.imu_flags,
                    arrays.velocity_enu_mps, arrays.q_wb[:k], arrays.flags[:k], arrays.scratch)
        return
    increments = samples.dtheta_b if arrays.step_multiple else samples.dtheta_sub_b
    rates = arrays.rates_b[:k]
    _rates_from_increments(arrays.step_id, arrays.step_sums, increments[:, :arrays.step_rows], samples.gyro_b,
                           arrays.interval_s, rates)
    _biso_batch(arrays.coef, arrays.state, rates, samples.accel_b, samples.mag_b, samples.imu_flags,
                arrays.velocity_enu_mps, arrays.q_wb[:k], arrays.flags[:k], arrays.scratch)


_NO_VELOCITY = np.empty((0, 3))
_NO_RATES = np.empty((0, 3))


class BisoEstimator(Estimator):
    """The faithful BISO estimator (see the module docstring). Build it with
    ``make_estimator("biso", fs_hz, **params)``; ``"positional"`` (k_p = 0) and
    ``"poisson"`` (no correction, eq. (2)) are the same class with fixed gains.

    Optional per-sample inputs: ``imu_flags`` (the sensor's flags: saturation, overflow),
    ``velocity_enu_mps`` (k, 3) for the transport rate (needs ``latitude_rad``) and
    ``dtheta_b`` (k, m, 3), the gyro's increments, required by a ``gyro_step`` other than
    'hold'. A sample whose increments are not finite falls back to its gyro reading."""

    method = "biso"
    Params = BisoParams
    state_layout = STATE_LAYOUT
    inputs = ("imu_flags", "velocity_enu_mps", "dtheta_b")

    def _coefficients(self, params: BisoParams, fs_hz: float) -> np.ndarray:
        return biso_coefficients(params, fs_hz)

    def set_params(self, **changes: Any) -> None:
        """Change parameters without touching the state (see ``Estimator.set_params``);
        equal gains of the closed form change in place (``_equal_gains``)."""
        if not self._equal_gains(changes):
            super().set_params(**changes)

    def retune(self, **changes: Any) -> None:
        """Change parameters while the estimator runs (see ``Estimator.retune``); equal
        gains of the closed form change in place (``_equal_gains``)."""
        if not self._equal_gains(changes):
            super().retune(**changes)

    def _equal_gains(self, changes: dict[str, Any]) -> bool:
        """The short path of a tuning loop's change, equal scalar gains (``k``, ``k_p`` or
        ``cutoff_hz``) of the closed-form correction (pattern 12, k > 0) to other such gains:
        only the coefficients that depend on the gains are derived again, in place, by the
        same expressions as ``biso_coefficients`` (the same numbers; tested), and the arrays
        stay the same (``arrays_version`` unchanged). Returns whether it applied."""
        if changes.keys() <= _GAIN_NAMES and self._coef[_C_MODE] == MODE_CLOSED:
            params = object.__new__(BisoParams)  # a frozen record: the copy's fields are set in its __dict__
            params.__dict__.update(self._params.__dict__, **changes)
            k, kp = params.k, params.k_p
            if (params.cutoff_hz is None and type(k) is float and type(kp) is float and 0.0 < k < math.inf
                    and 0.0 <= kp < math.inf):  # two valid scalars, checked in one expression
                self._params = params
                _set_gains_in_place(self._coef, params, k, kp)
                return True
            k, kp = _resolved_gains(params)  # validates them (the messages of the full path)
            if k[0] > 0.0 and len(set(k)) == 1 and len(set(kp)) == 1:
                self._params = params
                _set_gains_in_place(self._coef, params, k[0], kp[0])
                return True
        return False

    @property
    def closed_form(self) -> bool:
        """Whether the correction is the closed form (pattern 12, k > 0), whose equal gains
        ``retune`` changes in place."""
        return bool(self._coef[_C_MODE] == MODE_CLOSED)

    def _initial_state(self, q0: np.ndarray | None) -> np.ndarray:
        return biso_initial_state(q0)

    def _extra_inputs(self, inputs: dict[str, Any], k: int) -> dict[str, np.ndarray]:
        if inputs.get("velocity_enu_mps") is not None and self._params.latitude_rad is None:
            raise ValueError("velocity_enu_mps gives the transport rate, which needs latitude_rad "
                             "(set it with set_params, or leave the velocity out)")
        extra = super()._extra_inputs(inputs, k)
        step = gyro_step_algorithm(self._params)
        if step is None:
            if inputs.get("dtheta_b") is not None:
                raise ValueError("dtheta_b is used by gyro_step only; with gyro_step='hold' leave it out")
        elif inputs.get("dtheta_b") is None:
            raise ValueError(f"gyro_step={step.name!r} needs the gyro increments: pass dtheta_b ({k}, m, 3) "
                             f"({step.input_description})")
        else:
            check_rows(step, "dtheta_b", extra["dtheta_b"].shape[1], step.m_dtheta, "ΔΘ")
        return extra

    def _input_requirements(self) -> tuple:
        return self._params.gyro_step, self._params.latitude_rad is None

    @property
    def gyro_increments(self) -> GyroIncrements | None:
        """The increments ``gyro_step`` integrates (``dtheta_b``; see ``Estimator.gyro_increments``)."""
        return gyro_increments(self._params)

    loop_kernel = _biso_loop

    def loop_arrays(self, bound: int) -> BisoLoopArrays:
        """BISO's arrays in the period call (see ``Estimator.loop_arrays``); with a
        coning-algorithm ``gyro_step`` the kernel reads the period's increments in the form
        ``gyro_increments`` names."""
        if not hasattr(self, "_scratch"):
            self._scratch = np.empty((_BLOCK, _BUF_COLS))
        step, wanted = gyro_step_algorithm(self._params), gyro_increments(self._params)
        if step is None:
            return BisoLoopArrays(self._coef, self._state, self._scratch, _NO_VELOCITY, np.empty((bound, 4)),
                                  np.empty(bound, dtype=np.int64), -1, False, False, 0, 0.0, _NO_RATES)
        return BisoLoopArrays(self._coef, self._state, self._scratch, _NO_VELOCITY, np.empty((bound, 4)),
                              np.empty(bound, dtype=np.int64), int(step.id), step.form == "sub",
                              wanted.form == "multiple", wanted.m, 1.0 / self.fs_hz, np.empty((bound, 3)))

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias) -> None:
        step = gyro_step_algorithm(self._params)
        if step is not None:
            rates = np.empty(gyro.shape)
            _rates_from_increments(step.id, step.form == "sub", extra["dtheta_b"], gyro, 1.0 / self.fs_hz, rates)
            gyro = rates
        if not hasattr(self, "_scratch"):
            self._scratch = np.empty((_BLOCK, _BUF_COLS))
        _biso_batch(coef, state, gyro, accel, mag, extra["imu_flags"], extra["velocity_enu_mps"], q_out, flags,
                    self._scratch)
