"""biso_plus: the BISO structure with what a vehicle needs.

Same family as the faithful BISO (``biso.py``): the quaternion Poisson equation integrated
from the gyro, with a positional correction toward the attitude the accelerometer and the
magnetometer give. What it adds, each for a weakness DESIGN.md §5 and issue 4 name:

* **gyro-bias estimation**: a three-state Kalman filter (after VQF, Laidig & Seel 2023,
  §"bias estimation") whose measurement is the correction rate the positional correction
  applies, compared with the same low-pass seen by the accelerometer, so the low-pass inside
  the loop does not slow it down; at rest the measurement is the low-passed gyro itself
  (rest: the vehicle's speed ≈ 0 when a speed input is given; else the gyro and
  accelerometer steady and the rate small);
* **acceleration compensation**: with a speed input v (wheel odometry or GNSS) of a point r_v
  of the vehicle (rear axle: no sideslip there), the IMU's velocity is u = (v, 0, 0) − ω × r_v
  and the specific force is corrected by its acceleration ``u̇ + ω × u`` (longitudinal,
  centripetal and lever-arm terms; v̇ and ω̇ low-passed differences), so the tilt reference
  sees gravity;
* **disturbance-tolerant tilt reference**: the (compensated) specific force is low-pass
  filtered in a quasi-inertial frame I (the gyro's own strapdown frame, as VQF does: Laidig &
  Seel 2023), where gravity is constant and zero-mean accelerations average out without
  lag from the vehicle's rotation; samples whose |f| is far from g are down-weighted (gating);
* **magnetic disturbance detection**: the field's norm and dip (with the estimated tilt)
  against the expected field (learned while undisturbed, or given); a disturbed field is not
  used for heading, nor for learning the expected field;
* **hard-iron (offset) estimation**: ``m = R_Ibᵀ B_I + o`` is linear in the field in the
  I frame and the offset o, with R_Ib from the gyro strapdown alone (no feedback from the
  heading correction): a six-state Kalman filter with random walks, decimated, with its own
  innovation gate (a magnet is rejected there), learning only once the gyro bias is known;
  the offset prior keeps what level driving cannot observe (o_z against B_z) near 0;
* **decoupled corrections**: tilt about horizontal world axes from the accelerometer only,
  heading about Up from the magnetometer only, so a magnetic disturbance cannot tilt the
  estimate and an acceleration cannot turn its heading;
* **a cross-link without the renormalisation bias**: the paper's cross-link acts on the
  rotation-vector error ε (world frame), ``ω_c = K ε + k_p (1, 1, 1) × ε``, applied as a
  rotation: the estimate stays a unit quaternion, there are no norm dynamics, and the bias
  of ``λ − λ_k`` with renormalisation (DESIGN.md §5) is gone. A cross-link on rotations still
  leaves a second-order "coning" drift when the reference is very noisy (the noisy error
  spirals about (1, 1, 1)); measured, it is well below the renormalisation bias, and with
  the default k_p = 0 (chosen by measurement: the cross-link never improved accuracy) there
  is none (tests/test_estimator_plus.py).

The attitude is ``λ = q_c ∘ q_I``: q_I integrates the bias-corrected gyro exactly (held rate
over each sample interval), q_c (I → ENU) carries every correction.

Input policy as the faithful BISO (flags GYRO_INVALID, ACCEL_INVALID, MAG_INVALID,
UNINITIALIZED; the output is never NaN); a non-finite speed sample is ignored (no
compensation that sample). Optional full-scale ranges flag SATURATED and a saturated
accelerometer sample is not used for tilt.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators._base import (
    Estimator,
    accel_range_param,
    check_finite,
    gyro_range_param,
    layout_offsets,
    param,
    saturation_limits,
)
from biso_cosim.estimators._kernels import _input_checks, _qexp_fast
from biso_cosim.estimators.reference import _ref_vector
from biso_cosim.frames import _mat_from_q, _qmul, _qrot
from biso_cosim.units import DEG, G0

__all__ = ["BisoPlusParams", "BisoPlusEstimator"]

@dataclass(frozen=True)
class BisoPlusParams:
    """Parameters of biso_plus (each documented once, here). Defaults chosen by measurement
    on the shipped routes and the test motions (docs/estimators.md)."""

    # -- tilt
    tau_acc_s: float = param(
        3.0, symbol="τ_a", unit="s",
        doc="time constant of the low-pass of the specific force in the quasi-inertial frame I "
            "(without a speed input)", source="VQF τ_acc; measured (docs/estimators.md)")
    tau_acc_speed_s: float = param(
        1.0, symbol="τ_av", unit="s",
        doc="the same while a valid speed input compensates the vehicle's acceleration", source="measured")
    k_tilt: float = param(
        10.0, symbol="k_t", unit="1/s",
        doc="positional correction gain of tilt toward the low-passed gravity direction", source="measured")
    accel_gate: float = param(
        3.0, symbol="γ", unit="",
        doc="gating: a sample with ||f| − g| = d·g enters the low-pass with weight 1/(1 + (d/γ)²)",
        source="measured")
    # -- heading
    k_heading: float = param(
        0.05, symbol="k_h", unit="1/s",
        doc="positional correction gain of heading toward the magnetometer (at least 1/(t + τ_a) "
            "during the start)", source="measured")
    # -- cross-link
    k_p: float = param(
        0.0, symbol="k_p", unit="1/s",
        doc="cross-link gain: ω_c = K ε + k_p (1, 1, 1) × ε on the rotation-vector error (no bias)",
        source="Aleshkin et al. (2024) eq. (9), applied to the rotation error")
    # -- gyro bias
    bias_sigma_init_rad_s: float = param(
        0.5 * DEG, symbol="σ_b0", unit="rad/s",
        doc="initial standard deviation of the gyro bias estimate (larger biases are still "
            "learned, more slowly in motion, quickly at rest)", source="VQF biasSigmaInit; measured")
    bias_forgetting_s: float = param(
        100.0, symbol="T_b", unit="s",
        doc="time in which the bias variance grows by (0.1 °/s)² (random walk of the bias)",
        source="VQF biasForgettingTime")
    bias_sigma_motion_rad_s: float = param(
        0.1 * DEG, symbol="σ_bm", unit="rad/s",
        doc="steady-state uncertainty of the bias in motion (sets the measurement noise)",
        source="VQF biasSigmaMotion")
    bias_heading_factor: float = param(
        0.01, symbol="f_z", unit="",
        doc="weight of the heading correction in the bias estimate relative to tilt (0: the "
            "vertical bias is learned at rest only)", source="measured")
    bias_sigma_rest_rad_s: float = param(
        0.03 * DEG, symbol="σ_br", unit="rad/s",
        doc="steady-state uncertainty of the bias at rest", source="VQF biasSigmaRest")
    bias_limit_rad_s: float = param(
        10.0 * DEG, symbol="|b|max", unit="rad/s",
        doc="bound of the bias estimate (MPU-9250 ZRO tolerance ±5 °/s, doubled)", source="PS-MPU-9250A-01 §3.1")
    # -- rest
    rest_time_s: float = param(
        1.0, symbol="t_r", unit="s", doc="how long the rest conditions must hold", source="VQF restMinT (1.5 s)")
    rest_filter_tau_s: float = param(
        0.5, symbol="τ_r", unit="s", doc="low-pass of gyro and accelerometer for rest detection",
        source="VQF restFilterTau")
    rest_gyro_rad_s: float = param(
        2.0 * DEG, symbol="θ_ω", unit="rad/s",
        doc="rest: largest deviation of the gyro from its low-pass; the bias-corrected rate must "
            "stay below it plus 3σ of the bias estimate",
        source="VQF restThGyr")
    rest_accel_mps2: float = param(
        0.5, symbol="θ_a", unit="m/s²", doc="rest: largest deviation of the accelerometer from its low-pass",
        source="VQF restThAcc")
    rest_speed_mps: float = param(
        0.05, symbol="θ_v", unit="m/s", doc="rest with a speed input: largest |speed|", source="assumption")
    # -- magnetometer
    mag_norm_tol: float = param(
        0.1, symbol="θ_B", unit="", doc="disturbance: relative deviation of |m| from the expected norm",
        source="VQF magNormTh")
    mag_dip_tol_rad: float = param(
        10.0 * DEG, symbol="θ_δ", unit="rad", doc="disturbance: deviation of the dip from the expected dip",
        source="VQF magDipTh")
    mag_reject_max_s: float = param(
        60.0, symbol="t_B", unit="s",
        doc="after this long disturbed without a break, the present field is accepted as the new one",
        source="VQF magMaxRejectionTime")
    tau_field_s: float = param(
        20.0, symbol="τ_B", unit="s", doc="time constant of learning the expected field norm and dip",
        source="measured")
    field_norm_ut: float | None = param(
        None, symbol="|B|", unit="µT", doc="expected field norm (e.g. sensors.EarthField); None = learned", source="")
    dip_rad: float | None = param(
        None, symbol="δ", unit="rad", doc="expected dip (inclination, down positive); None = learned", source="")
    estimate_mag_offset: bool = param(
        True, symbol="", unit="", doc="estimate the magnetometer offset (hard iron) online", source="")
    mag_offset_sigma_ut: float = param(
        10.0, symbol="σ_o", unit="µT", doc="prior standard deviation of the magnetometer offset per axis",
        source="AK8963 zero-field offset (assumption of the sensor profile)")
    tau_mag_offset_s: float = param(
        3600.0, symbol="τ_o", unit="s", doc="time in which the offset may change by σ_o (its random walk)",
        source="assumption")
    mag_noise_ut: float = param(
        3.0, symbol="σ_m", unit="µT",
        doc="measurement noise of the offset estimator per axis (sensor noise plus model error)", source="measured")
    mag_offset_bias_sigma_rad_s: float = param(
        0.4 * DEG, symbol="σ_bo", unit="rad/s",
        doc="the offset is learned only while the gyro-bias uncertainty (each axis) is below this",
        source="measured")
    mag_offset_interval_s: float = param(
        0.1, symbol="Δt_o", unit="s", doc="interval between updates of the offset estimator", source="cost")
    declination_rad: float = param(0.0, symbol="D", unit="rad", doc="magnetic declination, east positive", source="")
    # -- speed input
    speed_point_b_m: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), symbol="r_v", unit="m",
        doc="where the speed is measured (e.g. the rear axle's centre) relative to the IMU, body axes",
        source="vehicle geometry")
    tau_speed_s: float = param(
        0.05, symbol="τ_v", unit="s", doc="low-pass of v̇ and ω̇ from differences", source="measured")
    gravity_mps2: float = param(G0, symbol="g", unit="m/s²", doc="gravity used by the gate", source="")
    # -- sensor
    gyro_range_rad_s: float | None = gyro_range_param()
    accel_range_mps2: float | None = accel_range_param()


STATE_LAYOUT = (
    ("initialized", 1), ("lam", 4), ("q_i", 4), ("q_c", 4), ("gyro_bias_b", 3), ("bias_cov", 9),
    ("accel_lp_i", 3), ("rot_lp", 9), ("rot_bias_lp", 3), ("gyro_hold", 3), ("rest_gyro_lp", 3),
    ("rest_accel_lp", 3), ("rest_time_s", 1), ("speed_prev", 1), ("dvdt", 1), ("speed_prev_ok", 1),
    ("gyro_prev", 3), ("angular_accel_lp", 3), ("mag_offset_b", 3), ("field_i", 3), ("offset_cov", 36),
    ("offset_count", 1), ("field_norm", 1), ("field_dip", 1), ("field_known", 1), ("mag_rejected_s", 1),
    ("time_s", 1), ("offset_started", 1), ("field_dip_cs", 2),
)
_S = layout_offsets(STATE_LAYOUT)
(_S_INIT, _S_LAM, _S_QI, _S_QC, _S_BIAS, _S_BP, _S_FLP, _S_RLP, _S_RBLP, _S_GYRO, _S_WLP, _S_ALP, _S_REST_T,
 _S_VPREV, _S_DVDT, _S_VOK, _S_WPREV, _S_WDOT, _S_OFF, _S_BI, _S_P, _S_OFF_K, _S_BNORM, _S_DIP, _S_FIELD_OK,
 _S_REJ_T, _S_TIME, _S_OFF_INIT, _S_DIP_CS) = (_S[name] for name, _ in STATE_LAYOUT)
_S_SIZE = _S["_size"]

_COEF_LAYOUT = (
    ("h", 1), ("a_acc", 1), ("a_accv", 1), ("k_t", 1), ("k_h", 1), ("k_p", 1), ("gate", 1), ("t0", 1),
    ("bias_p0", 1), ("bias_v", 1), ("bias_w_motion", 1), ("bias_w_vertical", 1), ("bias_w_rest", 1),
    ("bias_limit", 1), ("rest_time", 1), ("a_rest", 1), ("rest_w", 1), ("rest_a", 1), ("rest_v", 1),
    ("b_tol", 1), ("dip_tol", 1), ("reject_max", 1), ("a_field", 1), ("b_norm", 1), ("dip", 1),
    ("offset_on", 1), ("q_offset", 1), ("q_field", 1), ("r_mag", 1), ("offset_n", 1), ("decl", 1),
    ("cdh", 1), ("sdh", 1), ("r_v", 3), ("a_speed", 1), ("g", 1), ("gyro_range", 1), ("accel_range", 1),
    ("offset_bias2", 1), ("fs", 1), ("inv_gate_g", 1), ("dip_c", 1), ("dip_s", 1), ("cos_dip_tol", 1),
)
_C = layout_offsets(_COEF_LAYOUT)
(_C_H, _C_A_ACC, _C_A_ACCV, _C_KT, _C_KH, _C_KP, _C_GATE, _C_T0, _C_BP0, _C_BV, _C_BWM, _C_BWV, _C_BWR,
 _C_BLIM, _C_REST_N, _C_A_REST, _C_REST_W, _C_REST_A, _C_REST_V, _C_BTOL, _C_DTOL, _C_REJ_N, _C_A_FIELD,
 _C_BNORM, _C_DIP, _C_OFFSET, _C_Q_OFFSET, _C_Q_FIELD, _C_R_MAG, _C_OFF_N, _C_DECL, _C_CDH, _C_SDH, _C_RV,
 _C_A_SPEED, _C_G, _C_GRANGE, _C_ARANGE, _C_OFF_BIAS2, _C_FS, _C_INV_GATE_G, _C_DIP_C, _C_DIP_S, _C_COS_DTOL) = (
    _C[name] for name, _ in _COEF_LAYOUT)
_C_SIZE = _C["_size"]

_P0_FIELD = 100.0 ** 2  # variance (µT²) of the field in I before the first magnetometer sample
# random walk of the field in the I frame (µT²/s): I turns with the residual gyro bias
_FIELD_WALK_UT2_PER_S = 1.0


def _alpha(h: float, tau: float) -> float:
    """Per-sample gain of a first-order low-pass with time constant tau (1 at tau = 0)."""
    return 1.0 if tau == 0.0 else 1.0 - math.exp(-h / tau)


def _kalman_noise(sigma: float, v: float) -> float:
    """Measurement variance whose steady-state estimate variance with random walk v is σ² (VQF)."""
    p = sigma * sigma
    return p * p / v + p


def biso_plus_coefficients(p: BisoPlusParams, fs_hz: float) -> np.ndarray:
    """Validate ``p`` and derive the kernel's coefficients (raises ValueError / TypeError)."""
    h = 1.0 / fs_hz
    v = {}
    for name in ("tau_acc_s", "tau_acc_speed_s", "k_tilt", "k_heading", "k_p", "bias_limit_rad_s",
                 "rest_time_s", "rest_filter_tau_s", "rest_gyro_rad_s", "rest_accel_mps2", "rest_speed_mps",
                 "mag_reject_max_s", "tau_field_s", "mag_offset_interval_s", "tau_speed_s", "bias_heading_factor"):
        v[name] = check_finite(name, getattr(p, name), low=0.0)
    for name in ("accel_gate", "mag_norm_tol", "mag_dip_tol_rad", "gravity_mps2", "mag_noise_ut",
                 "mag_offset_sigma_ut", "tau_mag_offset_s", "bias_sigma_init_rad_s", "bias_forgetting_s",
                 "bias_sigma_motion_rad_s", "bias_sigma_rest_rad_s", "mag_offset_bias_sigma_rad_s"):
        v[name] = check_finite(name, getattr(p, name), low=0.0, low_open=True)
    if not isinstance(p.estimate_mag_offset, (bool, np.bool_)):
        raise TypeError(f"estimate_mag_offset must be True or False, got {p.estimate_mag_offset!r}")
    rv = np.asarray(p.speed_point_b_m, dtype=np.float64)
    if rv.shape != (3,) or not np.all(np.isfinite(rv)):
        raise ValueError(f"speed_point_b_m must be 3 finite numbers (m, body axes), got {p.speed_point_b_m!r}")
    decl = check_finite("declination_rad", p.declination_rad)

    c = np.zeros(_C_SIZE)
    c[_C_H] = h
    c[_C_A_ACC], c[_C_A_ACCV] = _alpha(h, v["tau_acc_s"]), _alpha(h, v["tau_acc_speed_s"])
    c[_C_KT], c[_C_KH], c[_C_KP], c[_C_GATE] = v["k_tilt"], v["k_heading"], v["k_p"], v["accel_gate"]
    c[_C_T0] = max(v["tau_acc_s"], h)
    # bias Kalman filter (VQF's design: variances in (rad/s)²)
    c[_C_BP0] = v["bias_sigma_init_rad_s"] ** 2
    c[_C_BV] = (0.1 * DEG) ** 2 * h / v["bias_forgetting_s"]
    c[_C_BWM] = _kalman_noise(v["bias_sigma_motion_rad_s"], c[_C_BV])
    c[_C_BWV] = c[_C_BWM] / max(v["bias_heading_factor"], 1e-10)
    c[_C_BWR] = _kalman_noise(v["bias_sigma_rest_rad_s"], c[_C_BV])
    c[_C_BLIM] = v["bias_limit_rad_s"]
    c[_C_REST_N], c[_C_A_REST] = v["rest_time_s"], _alpha(h, v["rest_filter_tau_s"])
    c[_C_REST_W], c[_C_REST_A], c[_C_REST_V] = v["rest_gyro_rad_s"], v["rest_accel_mps2"], v["rest_speed_mps"]
    c[_C_BTOL], c[_C_DTOL], c[_C_REJ_N] = v["mag_norm_tol"], v["mag_dip_tol_rad"], v["mag_reject_max_s"]
    c[_C_A_FIELD] = _alpha(h, v["tau_field_s"])
    c[_C_BNORM] = -1.0 if p.field_norm_ut is None else check_finite("field_norm_ut", p.field_norm_ut, low=0.0, low_open=True)
    c[_C_DIP] = np.nan if p.dip_rad is None else check_finite("dip_rad", p.dip_rad, low=-0.5 * math.pi, high=0.5 * math.pi)
    c[_C_OFFSET] = float(bool(p.estimate_mag_offset))
    c[_C_OFF_N] = max(1, int(round(v["mag_offset_interval_s"] * fs_hz)))
    dt_off = c[_C_OFF_N] * h
    c[_C_Q_OFFSET] = v["mag_offset_sigma_ut"] ** 2 / v["tau_mag_offset_s"] * dt_off
    c[_C_Q_FIELD] = _FIELD_WALK_UT2_PER_S * dt_off
    c[_C_R_MAG] = v["mag_noise_ut"] ** 2
    c[_C_OFF_BIAS2] = v["mag_offset_bias_sigma_rad_s"] ** 2
    c[_C_DECL], c[_C_CDH], c[_C_SDH] = decl, math.cos(0.5 * decl), math.sin(0.5 * decl)
    c[_C_RV:_C_RV + 3] = rv
    c[_C_A_SPEED] = _alpha(h, v["tau_speed_s"])
    c[_C_G] = v["gravity_mps2"]
    c[_C_GRANGE], c[_C_ARANGE] = saturation_limits(p)
    c[_C_FS] = fs_hz
    c[_C_INV_GATE_G] = 1.0 / (c[_C_G] * c[_C_GATE])
    if p.dip_rad is not None:
        c[_C_DIP_C], c[_C_DIP_S] = math.cos(c[_C_DIP]), math.sin(c[_C_DIP])
    # |δ| > θ_δ ⟺ cos δ < cos θ_δ for |δ| ≤ π (the dips lie in [−π/2, π/2]); θ_δ ≥ π: never
    c[_C_COS_DTOL] = math.cos(c[_C_DTOL]) if c[_C_DTOL] < math.pi else -2.0
    return c


def biso_plus_initial_state(q0: np.ndarray | None, params: BisoPlusParams) -> np.ndarray:
    st = np.zeros(_S_SIZE)
    st[_S_LAM] = st[_S_QI] = st[_S_QC] = 1.0
    st[_S_BP:_S_BP + 9] = (np.eye(3) * params.bias_sigma_init_rad_s ** 2).ravel()
    p = st[_S_P:_S_P + 36].reshape(6, 6)
    p[:3, :3] = np.eye(3) * _P0_FIELD
    p[3:, 3:] = np.eye(3) * params.mag_offset_sigma_ut ** 2
    if q0 is not None:
        st[_S_INIT] = 2.0
        st[_S_LAM:_S_LAM + 4] = q0
        st[_S_QI:_S_QI + 4] = q0
    return st


# --------------------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------------------


_A3, _A5, _A7, _A9, _A11 = 1.0 / 3.0, 1.0 / 5.0, 1.0 / 7.0, 1.0 / 9.0, 1.0 / 11.0


@jit(inline="always")
def _atan_series(t2):
    """atan(t)/t for t² ≤ 0.01 (error below 1e-12)."""
    return 1.0 - t2 * (_A3 - t2 * (_A5 - t2 * (_A7 - t2 * (_A9 - t2 * _A11))))


@jit(inline="always")
def _atan2(y, x):
    """atan2 with a series for small angles (|y| ≤ 0.1 x: error below 1e-12 rad), which
    covers nearly every correction step and avoids the library call."""
    if x > 0.0 and abs(y) <= 0.1 * x:
        t = y / x
        return t * _atan_series(t * t)
    return math.atan2(y, x)


@jit(inline="always")
def _angle_over_sine(s2, c):
    """atan2(s, c)/s for s = √s2 ≥ 0 (0 at s = 0): near s = 0 (s ≤ 0.1 c) the series
    (1/c)·atan(t)/t with t² = s2/c², one division and no square root."""
    if c > 0.0 and s2 <= 0.01 * c * c:
        i = 1.0 / c
        return i * _atan_series(s2 * i * i)
    if s2 > 0.0:
        s = math.sqrt(s2)
        return math.atan2(s, c) / s
    return 0.0


@jit(inline="always")
def _unit(w, x, y, z):
    """q/|q|; near |q| = 1 (|z| < 1e-6, z = |q|² − 1: products of unit quaternions) by
    1 − z/2 + 3z²/8 (dropped terms below 1e-18), without square root and division."""
    z2 = w * w + x * x + y * y + z * z - 1.0
    if abs(z2) < 1.0e-6:
        n = 1.0 - z2 * (0.5 - 0.375 * z2)
    else:
        n = 1.0 / math.sqrt(1.0 + z2)
    return w * n, x * n, y * n, z * n


@jit
def _offset_update(c, st, mx, my, mz):
    """One Kalman step of m = R_Ibᵀ B_I + o for x = (B_I, o), random walks on both.

    R_Ib comes from the gyro strapdown q_I alone. The three components are processed as
    scalar updates; an innovation beyond 5σ (a magnet nearby) skips the component.
    """
    qw, qx, qy, qz = st[_S_QI], st[_S_QI + 1], st[_S_QI + 2], st[_S_QI + 3]
    p = st[_S_P:_S_P + 36].reshape((6, 6))
    if st[_S_OFF_INIT] == 0.0:
        # start: B_I = R_Ib (m − o) with o ~ (0, σ_o² I): the field is known up to the offset
        st[_S_OFF_INIT] = 1.0
        st[_S_BI], st[_S_BI + 1], st[_S_BI + 2] = _qrot(qw, qx, qy, qz, mx, my, mz)
        r = _mat_from_q(qw, qx, qy, qz)
        so = p[3, 3]
        for i in range(3):
            for j in range(3):
                p[i, j] = so if i == j else 0.0
                p[i, 3 + j] = -so * r[3 * i + j]
                p[3 + j, i] = -so * r[3 * i + j]
        return
    for i in range(3):
        p[i, i] += c[_C_Q_FIELD]
        p[3 + i, 3 + i] += c[_C_Q_OFFSET]
    meas = (mx, my, mz)
    ph = np.empty(6)
    for comp in range(3):
        ex = 1.0 if comp == 0 else 0.0
        ey = 1.0 if comp == 1 else 0.0
        ez = 1.0 if comp == 2 else 0.0
        rx, ry, rz = _qrot(qw, qx, qy, qz, ex, ey, ez)  # body axis `comp` in I: row of R_Ibᵀ
        hrow = (rx, ry, rz, ex, ey, ez)
        for i in range(6):
            s = 0.0
            for j in range(6):
                s += p[i, j] * hrow[j]
            ph[i] = s
        den = c[_C_R_MAG]
        for i in range(6):
            den += hrow[i] * ph[i]
        r = meas[comp] - (rx * st[_S_BI] + ry * st[_S_BI + 1] + rz * st[_S_BI + 2] + st[_S_OFF + comp])
        if r * r > 25.0 * den:
            continue
        for i in range(3):
            st[_S_BI + i] += ph[i] * r / den
            st[_S_OFF + i] += ph[3 + i] * r / den
        for i in range(6):
            for j in range(6):
                p[i, j] -= ph[i] * ph[j] / den


@jit(inline="always")
def _bias_update(c, st, hm, e0, e1, e2, w0, w1, w2):
    """Kalman update of the gyro bias: measurement e = H (b − b̂) + noise, noise diag(w).

    ``hm`` is a 9-tuple (H row-major); written out in scalars, no allocation per sample.
    """
    b = _S_BP
    p00, p01, p02 = st[b], st[b + 1], st[b + 2]
    p11, p12, p22 = st[b + 4], st[b + 5], st[b + 8]
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = hm
    lim = c[_C_BLIM]
    e0, e1, e2 = min(max(e0, -lim), lim), min(max(e1, -lim), lim), min(max(e2, -lim), lim)
    # A = P Hᵀ (column j = P h_j); P is kept symmetric, its upper triangle is read
    a00 = p00 * h00 + p01 * h01 + p02 * h02
    a10 = p01 * h00 + p11 * h01 + p12 * h02
    a20 = p02 * h00 + p12 * h01 + p22 * h02
    a01 = p00 * h10 + p01 * h11 + p02 * h12
    a11 = p01 * h10 + p11 * h11 + p12 * h12
    a21 = p02 * h10 + p12 * h11 + p22 * h12
    a02 = p00 * h20 + p01 * h21 + p02 * h22
    a12 = p01 * h20 + p11 * h21 + p12 * h22
    a22 = p02 * h20 + p12 * h21 + p22 * h22
    # S = H A + W (symmetric: upper triangle)
    s00 = h00 * a00 + h01 * a10 + h02 * a20 + w0
    s01 = h00 * a01 + h01 * a11 + h02 * a21
    s02 = h00 * a02 + h01 * a12 + h02 * a22
    s11 = h10 * a01 + h11 * a11 + h12 * a21 + w1
    s12 = h10 * a02 + h11 * a12 + h12 * a22
    s22 = h20 * a02 + h21 * a12 + h22 * a22 + w2
    # S⁻¹ = adj(S)/det(S) (symmetric); K = A adj(S) first, the division by det beside it
    i00 = s11 * s22 - s12 * s12
    i01 = s02 * s12 - s01 * s22
    i02 = s01 * s12 - s02 * s11
    i11 = s00 * s22 - s02 * s02
    i12 = s01 * s02 - s00 * s12
    i22 = s00 * s11 - s01 * s01
    det = s00 * i00 + s01 * i01 + s02 * i02
    if not (det > 0.0):
        return
    inv = 1.0 / det
    k00 = a00 * i00 + a01 * i01 + a02 * i02
    k01 = a00 * i01 + a01 * i11 + a02 * i12
    k02 = a00 * i02 + a01 * i12 + a02 * i22
    k10 = a10 * i00 + a11 * i01 + a12 * i02
    k11 = a10 * i01 + a11 * i11 + a12 * i12
    k12 = a10 * i02 + a11 * i12 + a12 * i22
    k20 = a20 * i00 + a21 * i01 + a22 * i02
    k21 = a20 * i01 + a21 * i11 + a22 * i12
    k22 = a20 * i02 + a21 * i12 + a22 * i22
    st[_S_BIAS] = min(max(st[_S_BIAS] + (k00 * e0 + k01 * e1 + k02 * e2) * inv, -lim), lim)
    st[_S_BIAS + 1] = min(max(st[_S_BIAS + 1] + (k10 * e0 + k11 * e1 + k12 * e2) * inv, -lim), lim)
    st[_S_BIAS + 2] = min(max(st[_S_BIAS + 2] + (k20 * e0 + k21 * e1 + k22 * e2) * inv, -lim), lim)
    # P ← P − K (H P) = P − K Aᵀ (symmetric: the upper triangle, mirrored)
    q01 = p01 - (k00 * a10 + k01 * a11 + k02 * a12) * inv
    q02 = p02 - (k00 * a20 + k01 * a21 + k02 * a22) * inv
    q12 = p12 - (k10 * a20 + k11 * a21 + k12 * a22) * inv
    st[b] = p00 - (k00 * a00 + k01 * a01 + k02 * a02) * inv
    st[b + 4] = p11 - (k10 * a10 + k11 * a11 + k12 * a12) * inv
    st[b + 8] = p22 - (k20 * a20 + k21 * a21 + k22 * a22) * inv
    st[b + 1] = st[b + 3] = q01
    st[b + 2] = st[b + 6] = q02
    st[b + 5] = st[b + 7] = q12


@jit
def _biso_plus_start(c, st, gx, gy, gz, ax, ay, az, fn, mx, my, mz, acc_ok, mag_ok, speed, speed_given):
    """First sample: the attitude (unless q0 was given) and every filter start from it."""
    if st[_S_INIT] == 0.0:
        if speed_given and math.isfinite(speed):
            # centripetal part of the vehicle's acceleration (v̇ unknown yet): ω × (v, 0, 0)
            ax, ay, az = ax, ay - gz * speed, az + gy * speed
            fn = math.sqrt(ax * ax + ay * ay + az * az)
            if not fn > 0.0:
                ax, ay, az, fn = 0.0, 0.0, 1.0, 1.0
        q = _ref_vector(ax / fn, ay / fn, az / fn, mx, my, mz, mag_ok, 1.0, 0.0, 0.0, 0.0, c[_C_CDH], c[_C_SDH])
        for i in range(4):
            st[_S_LAM + i] = q[i]
            st[_S_QI + i] = q[i]
    st[_S_INIT] = 1.0
    qw, qx, qy, qz = st[_S_QI], st[_S_QI + 1], st[_S_QI + 2], st[_S_QI + 3]
    if acc_ok:
        st[_S_FLP], st[_S_FLP + 1], st[_S_FLP + 2] = _qrot(qw, qx, qy, qz, ax, ay, az)
    else:
        st[_S_FLP], st[_S_FLP + 1], st[_S_FLP + 2] = _qrot(qw, qx, qy, qz, 0.0, 0.0, c[_C_G])
    r = _mat_from_q(qw, qx, qy, qz)
    for i in range(9):
        st[_S_RLP + i] = r[i]
    g = (gx, gy, gz)
    a = (ax, ay, az)
    for i in range(3):
        st[_S_WLP + i] = g[i]
        st[_S_WPREV + i] = g[i]
        st[_S_ALP + i] = a[i] if acc_ok else 0.0
    st[_S_VPREV] = speed
    st[_S_VOK] = 1.0 if speed_given and math.isfinite(speed) else 0.0


@jit(inline="always")
def _biso_plus_step(c, st, gx, gy, gz, ax, ay, az, mx, my, mz, speed, speed_given, imu_flags):
    """Advance the state by one sample; returns the sample's flags. Never raises."""
    h = c[_C_H]
    flags, gx, gy, gz, acc_ok, f2, mag_ok, _, _, _, _ = _input_checks(
        gx, gy, gz, ax, ay, az, mx, my, mz, st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2], imu_flags,
        c[_C_GRANGE], c[_C_ARANGE])
    st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2] = gx, gy, gz
    if st[_S_INIT] != 1.0:
        if st[_S_INIT] == 0.0 and not acc_ok:
            return flags | fl.UNINITIALIZED
        _biso_plus_start(c, st, gx, gy, gz, ax, ay, az, math.sqrt(f2), mx, my, mz, acc_ok, mag_ok, speed,
                         speed_given)
        return flags
    st[_S_TIME] += h
    t = st[_S_TIME]

    # ---- gyro: bias-corrected strapdown of q_I over the interval (held rate)
    bx, by, bz = st[_S_BIAS], st[_S_BIAS + 1], st[_S_BIAS + 2]
    wx, wy, wz = gx - bx, gy - by, gz - bz
    eb = _qexp_fast(wx * h, wy * h, wz * h)
    # |q ∘ e| = |q| for a unit e: the normalisation factor comes from q before the product,
    # in parallel with e^{bh}, not after it on the chain of dependent operations
    qiw, qix, qiy, qiz = _unit(st[_S_QI], st[_S_QI + 1], st[_S_QI + 2], st[_S_QI + 3])
    qiw, qix, qiy, qiz = _qmul(qiw, qix, qiy, qiz, eb[0], eb[1], eb[2], eb[3])
    st[_S_QI], st[_S_QI + 1], st[_S_QI + 2], st[_S_QI + 3] = qiw, qix, qiy, qiz
    qcw, qcx, qcy, qcz = st[_S_QC], st[_S_QC + 1], st[_S_QC + 2], st[_S_QC + 3]
    lw, lx, ly, lz = _qmul(qcw, qcx, qcy, qcz, qiw, qix, qiy, qiz)

    # ---- speed: acceleration of the IMU from the speed v of the point r_v of the vehicle
    a_v = c[_C_A_SPEED]
    fs = c[_C_FS]
    st[_S_WDOT] += a_v * ((wx - st[_S_WPREV]) * fs - st[_S_WDOT])
    st[_S_WDOT + 1] += a_v * ((wy - st[_S_WPREV + 1]) * fs - st[_S_WDOT + 1])
    st[_S_WDOT + 2] += a_v * ((wz - st[_S_WPREV + 2]) * fs - st[_S_WDOT + 2])
    st[_S_WPREV], st[_S_WPREV + 1], st[_S_WPREV + 2] = wx, wy, wz
    v_ok = speed_given and math.isfinite(speed)
    comp_x = comp_y = comp_z = 0.0
    if v_ok:
        if st[_S_VOK] != 0.0:
            st[_S_DVDT] += a_v * ((speed - st[_S_VPREV]) * fs - st[_S_DVDT])
        st[_S_VPREV] = speed
        # IMU velocity u = (v, 0, 0) + ω × d, d = −r_v; acceleration u̇ + ω × u
        dx, dy, dz = -c[_C_RV], -c[_C_RV + 1], -c[_C_RV + 2]
        ux, uy, uz = speed + wy * dz - wz * dy, wz * dx - wx * dz, wx * dy - wy * dx
        qx_, qy_, qz_ = st[_S_WDOT], st[_S_WDOT + 1], st[_S_WDOT + 2]
        comp_x = st[_S_DVDT] + (qy_ * dz - qz_ * dy) + (wy * uz - wz * uy)
        comp_y = (qz_ * dx - qx_ * dz) + (wz * ux - wx * uz)
        comp_z = (qx_ * dy - qy_ * dx) + (wx * uy - wy * ux)
        flags |= fl.ACCEL_COMPENSATED
    st[_S_VOK] = 1.0 if v_ok else 0.0

    # ---- rest detection (steady gyro and accelerometer; with speed: standing still)
    ar = c[_C_A_REST]
    wl0 = st[_S_WLP] + ar * (gx - st[_S_WLP])
    wl1 = st[_S_WLP + 1] + ar * (gy - st[_S_WLP + 1])
    wl2 = st[_S_WLP + 2] + ar * (gz - st[_S_WLP + 2])
    st[_S_WLP], st[_S_WLP + 1], st[_S_WLP + 2] = wl0, wl1, wl2
    rest = False
    if acc_ok:
        al0 = st[_S_ALP] + ar * (ax - st[_S_ALP])
        al1 = st[_S_ALP + 1] + ar * (ay - st[_S_ALP + 1])
        al2 = st[_S_ALP + 2] + ar * (az - st[_S_ALP + 2])
        st[_S_ALP], st[_S_ALP + 1], st[_S_ALP + 2] = al0, al1, al2
        dw2 = (gx - wl0) ** 2 + (gy - wl1) ** 2 + (gz - wl2) ** 2
        da2 = (ax - al0) ** 2 + (ay - al1) ** 2 + (az - al2) ** 2
        thw = c[_C_REST_W]
        still = dw2 < thw * thw and da2 < c[_C_REST_A] * c[_C_REST_A]
        if still:
            # not turning either: the bias-corrected rate within the threshold plus 3σ of the bias
            thr = thw + 3.0 * math.sqrt(max(st[_S_BP], st[_S_BP + 4], st[_S_BP + 8]))
            rw2 = (wl0 - bx) ** 2 + (wl1 - by) ** 2 + (wl2 - bz) ** 2
            still = rw2 < thr * thr
        if v_ok:
            still = still and abs(speed) < c[_C_REST_V]
        st[_S_REST_T] = st[_S_REST_T] + h if still else 0.0
        rest = st[_S_REST_T] >= c[_C_REST_N]
    if rest:
        flags |= fl.REST

    # ---- tilt error: low-pass of the (compensated) specific force in I, gated
    ex = ey = ez = 0.0  # rotation-vector error of the estimate, world frame
    if acc_ok:
        fx, fy, fz = ax - comp_x, ay - comp_y, az - comp_z
        fnorm = math.sqrt(fx * fx + fy * fy + fz * fz)
        d = abs(fnorm - c[_C_G]) * c[_C_INV_GATE_G]
        weight = 1.0 / (1.0 + d * d)
        if weight < 0.5:
            flags |= fl.ACCEL_GATED
        alpha = c[_C_A_ACCV] if v_ok else c[_C_A_ACC]
        if h > alpha * (t + h):  # start: a running mean (as VQF), α = max(α, h/(t + h))
            alpha = h / (t + h)
        alpha *= weight
        fix, fiy, fiz = _qrot(qiw, qix, qiy, qiz, fx, fy, fz)
        fl0 = st[_S_FLP] + alpha * (fix - st[_S_FLP])
        fl1 = st[_S_FLP + 1] + alpha * (fiy - st[_S_FLP + 1])
        fl2 = st[_S_FLP + 2] + alpha * (fiz - st[_S_FLP + 2])
        st[_S_FLP], st[_S_FLP + 1], st[_S_FLP + 2] = fl0, fl1, fl2
        nx, ny, nz = _qrot(qcw, qcx, qcy, qcz, fl0, fl1, fl2)
        ang = _angle_over_sine(nx * nx + ny * ny, nz)
        ex, ey = ny * ang, -nx * ang  # rotate about n × up by the angle between n and up

    # ---- heading error from the magnetometer (offset removed), disturbance detection
    if mag_ok:
        # the offset is learned once the gyro bias is known (an unknown bias turns the I frame
        # and would pass for an offset); its own innovation gate rejects magnets, so the
        # norm/dip test below (which a wrong offset upsets) does not gate it
        if c[_C_OFFSET] != 0.0 and max(st[_S_BP], st[_S_BP + 4], st[_S_BP + 8]) < c[_C_OFF_BIAS2]:
            st[_S_OFF_K] += 1.0
            if st[_S_OFF_K] >= c[_C_OFF_N]:
                st[_S_OFF_K] = 0.0
                _offset_update(c, st, mx, my, mz)
        cx, cy, cz = mx - st[_S_OFF], my - st[_S_OFF + 1], mz - st[_S_OFF + 2]
        mwx, mwy, mwz = _qrot(lw, lx, ly, lz, cx, cy, cz)
        mh = math.sqrt(mwx * mwx + mwy * mwy)
        norm = math.sqrt(mh * mh + mwz * mwz)
        if st[_S_FIELD_OK] == 0.0:
            st[_S_BNORM] = norm if c[_C_BNORM] < 0.0 else c[_C_BNORM]
            if math.isnan(c[_C_DIP]):
                st[_S_DIP] = math.atan2(-mwz, mh)
                st[_S_DIP_CS], st[_S_DIP_CS + 1] = (mh / norm, -mwz / norm) if norm > 0.0 else (1.0, 0.0)
            else:
                st[_S_DIP], st[_S_DIP_CS], st[_S_DIP_CS + 1] = c[_C_DIP], c[_C_DIP_C], c[_C_DIP_S]
            st[_S_FIELD_OK] = 1.0
        # the dip δ_m = atan2(−m_U, m_H) against the expected δ: norm·(cos, sin)(δ_m − δ) from
        # (cos δ, sin δ) in the state, without an arctangent of the large dip angle
        c0, s0 = st[_S_DIP_CS], st[_S_DIP_CS + 1]
        dcos = mh * c0 - mwz * s0
        dsin = -mwz * c0 - mh * s0
        if abs(norm - st[_S_BNORM]) > c[_C_BTOL] * st[_S_BNORM] or dcos < c[_C_COS_DTOL] * norm:
            flags |= fl.MAG_DISTURBED
            st[_S_REJ_T] += h
            if st[_S_REJ_T] > c[_C_REJ_N]:  # disturbed for too long: take this as the new field
                st[_S_FIELD_OK] = 0.0
                st[_S_REJ_T] = 0.0
        else:
            st[_S_REJ_T] = 0.0
            af = c[_C_A_FIELD]
            if c[_C_BNORM] < 0.0:
                st[_S_BNORM] += af * (norm - st[_S_BNORM])
            if math.isnan(c[_C_DIP]):  # δ += α(δ_m − δ), and (cos δ, sin δ) turned with it
                e = af * _atan2(dsin, dcos)
                st[_S_DIP] += e
                ce, se = 1.0 - 0.5 * e * e, e * (1.0 - e * e * (1.0 / 6.0))
                st[_S_DIP_CS], st[_S_DIP_CS + 1] = c0 * ce - s0 * se, s0 * ce + c0 * se
            if mh > 0.0:
                # the field's azimuth (clockwise from north) minus D, from the horizontal field
                # turned by −D; turning the estimate about Up by it brings the field to D
                cd = c[_C_CDH] * c[_C_CDH] - c[_C_SDH] * c[_C_SDH]
                sd = 2.0 * c[_C_SDH] * c[_C_CDH]
                ez = _atan2(mwx * cd - mwy * sd, mwy * cd + mwx * sd)

    # ---- the correction ω_c = K ε + k_p n × ε as a rotation of q_c (world frame)
    kt = c[_C_KT]
    kh = c[_C_KH]
    if kh * (t + c[_C_T0]) < 1.0:  # start: heading follows the settling tilt, k_h = max(k_h, 1/(t + t0))
        kh = 1.0 / (t + c[_C_T0])
    kp = c[_C_KP]
    ux = kt * ex + kp * (ez - ey)
    uy = kt * ey + kp * (ex - ez)
    uz = kh * ez + kp * (ey - ex)
    if ux != 0.0 or uy != 0.0 or uz != 0.0:
        dq = _qexp_fast(ux * h, uy * h, uz * h)
        qcw, qcx, qcy, qcz = _unit(qcw, qcx, qcy, qcz)  # (as for q_I: off the chain)
        qcw, qcx, qcy, qcz = _qmul(dq[0], dq[1], dq[2], dq[3], qcw, qcx, qcy, qcz)
        st[_S_QC], st[_S_QC + 1], st[_S_QC + 2], st[_S_QC + 3] = qcw, qcx, qcy, qcz
        lw, lx, ly, lz = _qmul(qcw, qcx, qcy, qcz, qiw, qix, qiy, qiz)

    # ---- gyro bias: Kalman filter (VQF): the correction rate seen through the tilt low-pass
    bp0, bv = c[_C_BP0], c[_C_BV]
    if st[_S_BP] < bp0:
        st[_S_BP] += bv
    if st[_S_BP + 4] < bp0:
        st[_S_BP + 4] += bv
    if st[_S_BP + 8] < bp0:
        st[_S_BP + 8] += bv
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = _mat_from_q(lw, lx, ly, lz)  # body → world
    alpha = c[_C_A_ACCV] if v_ok else c[_C_A_ACC]
    j = _S_RLP
    h0 = st[j] + alpha * (r0 - st[j])
    h1 = st[j + 1] + alpha * (r1 - st[j + 1])
    h2 = st[j + 2] + alpha * (r2 - st[j + 2])
    h3 = st[j + 3] + alpha * (r3 - st[j + 3])
    h4 = st[j + 4] + alpha * (r4 - st[j + 4])
    h5 = st[j + 5] + alpha * (r5 - st[j + 5])
    h6 = st[j + 6] + alpha * (r6 - st[j + 6])
    h7 = st[j + 7] + alpha * (r7 - st[j + 7])
    h8 = st[j + 8] + alpha * (r8 - st[j + 8])
    st[j], st[j + 1], st[j + 2], st[j + 3], st[j + 4] = h0, h1, h2, h3, h4
    st[j + 5], st[j + 6], st[j + 7], st[j + 8] = h5, h6, h7, h8
    j = _S_RBLP
    rb0 = st[j] + alpha * ((r0 * bx + r1 * by + r2 * bz) - st[j])
    rb1 = st[j + 1] + alpha * ((r3 * bx + r4 * by + r5 * bz) - st[j + 1])
    rb2 = st[j + 2] + alpha * ((r6 * bx + r7 * by + r8 * bz) - st[j + 2])
    st[j], st[j + 1], st[j + 2] = rb0, rb1, rb2
    if rest:
        _bias_update(c, st, (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
                     wl0 - bx, wl1 - by, wl2 - bz, c[_C_BWR], c[_C_BWR], c[_C_BWR])
    elif acc_ok and t > c[_C_T0]:  # not during the start, while the low-pass settles
        e0 = rb0 - (h0 * bx + h1 * by + h2 * bz) - ux
        e1 = rb1 - (h3 * bx + h4 * by + h5 * bz) - uy
        e2 = rb2 - (h6 * bx + h7 * by + h8 * bz) - uz
        wv = c[_C_BWV] if ez != 0.0 else c[_C_BWV] * 1e6
        _bias_update(c, st, (h0, h1, h2, h3, h4, h5, h6, h7, h8), e0, e1, e2, c[_C_BWM], c[_C_BWM], wv)

    st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3] = _unit(lw, lx, ly, lz)
    return flags


@jit(error_model="numpy")
def _biso_plus_batch(c, st, gyro, accel, mag, speed, imu_flags, q_out, flags_out, bias_out):
    """``_biso_plus_step`` over every row; ``speed`` and ``imu_flags`` are empty when not given."""
    given = speed.shape[0] == gyro.shape[0] and speed.shape[0] > 0
    has_flags = imu_flags.shape[0] == gyro.shape[0]
    for i in range(gyro.shape[0]):
        v = speed[i] if given else np.nan
        sf = imu_flags[i] if has_flags else 0
        flags_out[i] = _biso_plus_step(c, st, gyro[i, 0], gyro[i, 1], gyro[i, 2], accel[i, 0], accel[i, 1],
                                       accel[i, 2], mag[i, 0], mag[i, 1], mag[i, 2], v, given, sf)
        q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3]
        bias_out[i, 0], bias_out[i, 1], bias_out[i, 2] = st[_S_BIAS], st[_S_BIAS + 1], st[_S_BIAS + 2]


class BisoPlusEstimator(Estimator):
    """biso_plus (see the module docstring). Optional per-sample input: ``speed_mps`` (k,),
    the vehicle's forward speed at ``speed_point_b_m`` (wheel odometry or GNSS); NaN = unknown."""

    method = "biso_plus"
    Params = BisoPlusParams
    state_layout = STATE_LAYOUT
    inputs = ("speed_mps", "imu_flags")
    estimates_bias = True

    def _coefficients(self, params: BisoPlusParams, fs_hz: float) -> np.ndarray:
        return biso_plus_coefficients(params, fs_hz)

    def _initial_state(self, q0: np.ndarray | None) -> np.ndarray:
        return biso_plus_initial_state(q0, self._params)

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias) -> None:
        _biso_plus_batch(coef, state, gyro, accel, mag, extra["speed_mps"], extra["imu_flags"], q_out, flags, bias)
