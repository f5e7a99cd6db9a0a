"""GNSS-aided attitude after Ibrahim & Lukyanov (2020): complementary and Kalman variants.

M. A. Ibrahim, V. V. Lukyanov, *Algorithms and configuration of an attitude system on MEMS
sensors*, Herald of the Bauman MSTU, Ser. Instrument Engineering, 2020, no. 2, pp. 44–58
(seed 002; docs/design.md §6 for the reconstruction of the OCR).

The tilt (pitch ϑ, roll γ) of a gyro-integrated attitude is corrected with the difference
between the acceleration the GNSS velocity shows and the accelerometer's specific force
rotated into the geographic frame; heading comes from a magnetometer with hard- and
soft-iron compensation, blended with the kinematic heading. Two variants:

``gnss_complementary`` (:class:`GnssComplementaryEstimator`)
    the paper's system without a Kalman filter: kinematics (4), first-order tilt correction
    (7) with time constant T1, magnetic heading (5), complementary heading filter (6) with T2.
``gnss_kalman`` (:class:`GnssKalmanEstimator`)
    the five-state Kalman filter X = [Δϑ, Δγ, Δω_x, Δω_y, Δω_z] (tilt errors and gyro
    drifts), measurement matrix [−N | 0], R from the GNSS and accelerometer noise; the same
    heading channel.

Use::

    est = make_estimator("gnss_kalman", fs_hz=200.0, declination_rad=D)
    out = est.update(gyro_b, accel_b, mag_b, gnss=fixes)   # fixes: sensors.gnss.GnssFixes
    out.q_wb, out.flags, out.gyro_bias_b, out.tilt_sigma_rad, out.updates

Frames and the paper's quantities
---------------------------------
The paper works in GOST 20058 axes: geographic x North, y Up, z East; body x forward, y up,
z right; heading ψ about Up, positive from North toward West, then pitch ϑ (nose up), then
roll γ (right side down): C_gb = R_y(ψ) R_z(ϑ) R_x(γ). Ours (``frames``): ENU, body x
forward, y left, z up; ψ = yaw − π/2, ϑ = −pitch, γ = roll; a body rate (ω_x, ω_y, ω_z)
of ours is (ω_x, ω_z, −ω_y) in the paper's body axes. Vectors in the geographic frame are
kept in ENU components (N-U-E is a cyclic permutation of E-N-U, so cross products agree).
The drift states Δω are in the paper's body axes; ``gyro_bias_b`` reports them in ours.

Kinematics (4) is the Euler-angle form of q̇ = ½ q∘ω. The attitude is carried as a
quaternion, integrated exactly for the gyro rate held over each sample interval (no
singularity at ϑ = ±90°, and a perfect gyro keeps a perfect attitude at any rate); the
Euler angles are used where the paper's equations need them: the linearised error model
(the A and B coefficients of docs/design.md §6) and the tilt corrections, which change ϑ and γ
and keep ψ. Vehicles stay far from ϑ = ±90°; beyond ``max_pitch_rad`` no tilt correction
is made (updates of kind ``rejected_geometry``) and the error model is evaluated at the limit.

The open points of docs/design.md §6, decided
----------------------------------------
1. **Heading sign.** The printed field vector T_y = (H cos ψ_m, −Z, −H sin ψ_m) in
   (forward, up, right) axes only holds for ψ_m measured clockwise, whereas the paper's
   Euler heading ψ is positive toward West. We read ψ_m of (5) as the compass heading
   (clockwise from magnetic North), true heading = ψ_m + D (declination, east positive), and
   the paper's ψ = −(ψ_m + D). :func:`magnetic_heading` implements (5) literally in that
   reading; the kernel computes the same angle as ψ_m = atan2(T_E, T_N) of the compensated
   field rotated by the estimate (tests: the two agree; a level car heading East reads 90°).
2. **Gravity.** Added on the GNSS side: the measurement compares the specific force the GNSS
   implies, f_g = A_GNSS + g·e_Up, with Ĉ_gb f_b; g = ``gravity_mps2`` (9.80665 m/s², as the
   simulated world). The vertical row then compares ≈ g with ≈ g and carries little tilt
   information; the horizontal rows carry it.
3. **A_GNSS from velocity, filtered.** A_GNSS is the difference of two GNSS velocities at
   least ``window_s`` apart, divided by their time difference (never twice-differenced
   position); the accelerometer side is the mean of Ĉf over exactly the same interval of
   validity: a ring of running sums ∫Ĉf dt, ∫N dt (midpoint rule: IMU sample i stands for
   (t_i − h/2, t_i + h/2], shifted back by ``imu_delay_s``) is interpolated at the fixes' times
   of validity, so the receiver's latency is compensated and both sides pass through the
   same moving-average filter (no lag between them). With
   white velocity noise σ_v the window's noise is √2·σ_v/T; consecutive windows share a fix
   and so are negatively correlated, which the Kalman filter ignores (its NIS and the
   estimated-vs-actual σ are reported by ``reproduce ibrahim2020``).
4. **Drift model.** Each drift is a first-order Gauss–Markov process, Δω̇ = −Δω/τ_d + w,
   stationary σ_d (rows −1/T of the paper's F); between updates the estimated drift decays as
   e^{−t/τ_d}. The drift about the body's Up axis enters the tilt only through sin γ, cos ϑ
   terms: unobservable at level (rank 4 of 5, docs/design.md §6); it keeps its prior.
5. **N.** N = ∂(Ĉ_gb f_b)/∂(ϑ, γ) = [a × f_g, x_b × f_g], a the horizontal axis to the right
   of the heading (the pitch axis), x_b the body's forward axis: z ≈ −N ΔΓ − N_0 Δψ + noise
   with N_0 = e_Up × f_g. ``heading_coupling="none"`` (default) leaves the heading error out
   of N and adds its variance σ_ψ² N_0 N_0ᵀ to R; ``"magnetic"`` uses N + N_0 [P1 P2], P1 and
   P2 the sensitivities of the magnetic heading to tilt errors (Δψ_m = P0 + P1 Δϑ + P2 Δγ of
   the paper), which holds once the heading filter has settled (t ≫ T2).
6. **Closed loop.** After each update the estimated tilt errors are removed from the
   attitude's ϑ and γ, the estimated drift is added to the gyro correction, and the error
   state restarts at zero (its covariance stays). The stored sums of Ĉf are re-expressed
   with the corrected attitude (S ← S + (ΣN − ΣN_now)·δ), so the next window sees only the
   residual error. The complementary variant is closed-loop by construction.
7. **Discretisation.** The covariance is propagated every IMU sample with F evaluated at the
   current attitude and bias-corrected rate: Φ = I + F h + ½F²h², Q_d = Q h + ½(F Q + Q Fᵀ)h²
   (Van Loan's integral to second order, multiplied out in F's block form; relative error
   below (‖F‖h)³, about 1e-7 of P at 200 Hz for ‖F‖ ≈ 1/s; tested against scipy's matrix
   exponential). Q: gyro white noise (density N_g) through
   the rate coefficients of (4), drift rows 2σ_d²/τ_d. Updates use the Joseph form; an
   innovation whose NIS exceeds ``gate`` is refused (flag GNSS_REJECTED).
8. **Complementary correction (7).** Per window, Δ̂ = −M z with M = (NᵀN)⁻¹Nᵀ (MN = E),
   and ϑ, γ move by −(1 − e^{−T/T1}) Δ̂: the exact step of the first-order loop
   Γ̇ = Γ̇_kinematic − (Γ − Γ_measured)/T1 for a measurement held over the window T.
9. **Heading (6).** ψ_s = T2p/(1 + T2p) ψ_k + 1/(1 + T2p) ψ_m in feedback form: every
   sample with a usable magnetometer reading the heading moves by (1 − e^{−h/T2}) of
   wrap(ψ_m − ψ), a rotation about Up (tilt unchanged). Tilt for (5) is the estimate's own
   (the tilt matrix C_n), not the accelerometer's.

Time, fixes and fall-backs
--------------------------
The n-th IMU sample of the stream is at t_0 + n/fs (``t0_s``, default 0). A fix is used at
the first IMU sample at or after its ``t_arrival_s`` (fixes arriving after the last sample of
a call wait in the state for the next call, at most 16); its ``t_s`` (time of validity) places
it in the ring, which covers the last second. Without a valid fix for ``max_interval_s``
(no ``gnss`` given, an outage, rejected fixes) every sample is flagged GNSS_UNAIDED and the
estimator falls back to ``unaided``: ``"gravity"`` (default) takes A_GNSS = 0, i.e. the
accelerometer's specific force as gravity, over windows of ``window_s``, with T1_unaided
(complementary) or the noise ``unaided_accel_sigma_mps2`` (Kalman): bounded, but tilted by
sustained accelerations; ``"gyro"`` makes no tilt correction at all (the paper's
autonomous mode: drift). The first fix after a gap only anchors the next window.

Input policy
------------
* IMU samples, per sample, never an exception: a non-finite gyro sample (or |ω| > 1e4 rad/s)
  is replaced by the last valid one (GYRO_INVALID); a non-finite or zero accelerometer sample
  by the last valid one in the sums, and the first valid one initialises (ACCEL_INVALID,
  UNINITIALIZED before it); an unusable magnetometer sample skips the heading correction
  (MAG_INVALID). The output is never NaN.
* GNSS, per call, checked before anything changes (``ValueError``/``TypeError`` naming the
  field): ``gnss`` must be a :class:`~biso_cosim.sensors.gnss.GnssFixes`; times must be
  finite, ``t_s`` strictly increasing within and across calls (out-of-order or repeated
  fixes are an error: the stream is wrong), ``t_arrival_s >= t_s`` and not decreasing, at
  most 16 fixes left waiting. Fixes with ``valid = False`` are outages (no flag); a fix
  marked valid with a non-finite velocity, or older than the ring, is refused and flagged
  GNSS_REJECTED (it is listed in ``updates``).
* ``mag_soft_iron`` must be invertible (condition number below 1e8): ``ValueError`` when
  the parameters are set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np

from biso_cosim.estimators import _gnss_kernels as K
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators._base import (
    Estimate,
    Estimator,
    accel_range_param,
    as_samples,
    check_finite,
    gyro_range_param,
    param,
    saturation_limits,
)
from biso_cosim.sensors.gnss import GnssFixes
from biso_cosim.units import DEG, DEG_PER_S, G0, MICRO_G

__all__ = [
    "GnssComplementaryParams",
    "GnssKalmanParams",
    "GnssComplementaryEstimator",
    "GnssKalmanEstimator",
    "GnssAidedEstimate",
    "GnssLoopArrays",
    "UPDATE_DTYPE",
    "UPDATE_KINDS",
    "gnss_coefficients",
    "GNSS_UPDATE",
    "GNSS_UNAIDED",
    "GNSS_REJECTED",
    "FLAG_NAMES",
    "euler_rates",
    "error_matrix",
    "magnetic_heading",
    "docs_tables",
]

# The per-sample flags these estimators add (defined with the others in ``flags``).
GNSS_UPDATE, GNSS_UNAIDED, GNSS_REJECTED = fl.GNSS_UPDATE, fl.GNSS_UNAIDED, fl.GNSS_REJECTED
FLAG_NAMES = {bit: fl.NAMES[bit] for bit in (GNSS_UPDATE, GNSS_UNAIDED, GNSS_REJECTED)}

UPDATE_DTYPE = np.dtype([
    ("t_s", "f8"), ("t_applied_s", "f8"), ("kind", "i1"), ("interval_s", "f8"),
    ("innovation_w", "f8", (3,)), ("innovation_sigma_w", "f8", (3,)), ("nis", "f8"),
    ("correction_roll_rad", "f8"), ("correction_pitch_rad", "f8")])
"""One row per fix used or refused (and per unaided reference window) in an ``update`` call:
time of validity, IMU sample time at which it was used, ``kind`` (index into
``UPDATE_KINDS``), window length, innovation z (ENU, m/s²), its predicted σ and the NIS
(Kalman variant; NaN otherwise), the roll and pitch corrections applied (rad)."""

UPDATE_KINDS = K.KIND_NAMES
"""Names of the ``kind`` column: gnss, unaided, anchor, rejected_nonfinite,
rejected_too_old, rejected_gate, rejected_geometry."""

_UNAIDED = ("coast", "gravity", "gyro")
_COUPLING = ("none", "magnetic")


@dataclass(frozen=True, slots=True)
class GnssAidedEstimate(Estimate):
    """Output of one ``update`` call of a GNSS-aided estimator (k samples).

    Adds to :class:`Estimate`: ``tilt_sigma_rad`` (k, 2) the filter's 1σ of roll and pitch
    (Kalman variant; None for the complementary one) and ``updates``, the fixes used or
    refused in this call (structured array, :data:`UPDATE_DTYPE`).
    """

    tilt_sigma_rad: np.ndarray | None = None
    updates: np.ndarray | None = None


# --------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _GnssAidedParams:
    """What both variants share (each parameter documented once, here)."""

    t2_s: float = param(
        10.0, symbol="T2", unit="s",
        doc="time constant of the complementary heading filter: magnetic heading low-passed, kinematic "
            "heading high-passed; math.inf = gyro heading only", source="eq. (6); measured (docs/gnss.md)")
    mag_hard_iron_ut: tuple[float, float, float] | None = param(
        None, symbol="P_m", unit="µT", doc="hard iron: field offset in body axes; None = zero", source="eq. (5)")
    mag_soft_iron: tuple[tuple[float, float, float], ...] | None = param(
        None, symbol="E + M_m", unit="",
        doc="soft-iron matrix (3×3, body axes), the sensor sees (E + M_m)·B + P_m; None = identity; must be "
            "invertible", source="eq. (5)")
    declination_rad: float = param(
        0.0, symbol="D", unit="rad", doc="magnetic declination, east positive: true heading = magnetic + D",
        source="eq. (5)")
    gravity_mps2: float = param(
        G0, symbol="g", unit="m/s²", doc="gravity added to the GNSS acceleration (Up)",
        source="docs/design.md §6; the simulated world's gravity")
    window_s: float = param(
        1.0, symbol="T_w", unit="s",
        doc="shortest time between the two fixes whose velocity difference forms A_GNSS (and the window of "
            "the unaided reference)", source="measured (docs/gnss.md)")
    max_interval_s: float = param(
        3.0, symbol="T_max", unit="s",
        doc="longest such time; without a valid fix for this long the estimator is unaided (flag GNSS_UNAIDED)",
        source="assumption")
    unaided: str = param(
        "coast", symbol="", unit="",
        doc="fall-back without GNSS: 'coast' (gyro alone for coast_s after the last fix, then 'gravity'), "
            "'gravity' (A_GNSS = 0: the specific force taken as gravity) or 'gyro' (no tilt correction, the "
            "paper's autonomous mode)", source="our choice, measured (docs/gnss.md)")
    coast_s: float = param(
        60.0, symbol="T_c", unit="s",
        doc="with unaided = 'coast': how long the gyro alone carries the tilt after the last valid fix",
        source="measured (docs/gnss.md)")
    heading_coupling: str = param(
        "none", symbol="", unit="",
        doc="N without ('none': heading error variance added to R) or with ('magnetic': N + N0·[P1 P2]) the "
            "magnetic heading's dependence on tilt errors", source="docs/design.md §6; measured")
    max_pitch_rad: float = param(
        80.0 * DEG, symbol="ϑ_max", unit="rad",
        doc="no tilt correction beyond this |pitch| (the Euler-angle error model is singular at 90°)",
        source="our choice")
    t0_s: float = param(
        0.0, symbol="t_0", unit="s", doc="time of the first IMU sample on the GNSS clock (sample n at t_0 + n/fs)",
        source="")
    imu_delay_s: float = param(
        0.0, symbol="d", unit="s",
        doc="how late the accelerometer samples are behind their time stamps (e.g. the MPU-9250 DLPF group "
            "delay, 4.88 ms at A_DLPF_CFG = 3): the sums are aligned with the GNSS times of validity by it",
        source="MPU-9250 register map, ACCEL_CONFIG2 table")
    gyro_range_rad_s: float | None = gyro_range_param()
    accel_range_mps2: float | None = accel_range_param()


@dataclass(frozen=True)
class GnssComplementaryParams(_GnssAidedParams):
    """Parameters of ``gnss_complementary`` (the paper's system without a Kalman filter)."""

    t1_s: float = param(
        3.0, symbol="T1", unit="s", doc="time constant of the tilt correction toward the GNSS-aided tilt",
        source="eq. (7); measured (docs/gnss.md)")
    t1_unaided_s: float = param(
        60.0, symbol="T1u", unit="s", doc="the same for the unaided gravity reference",
        source="measured without GNSS on loop600 and banked_oval (docs/gnss.md)")


@dataclass(frozen=True)
class GnssKalmanParams(_GnssAidedParams):
    """Parameters of ``gnss_kalman`` (the five-state Kalman filter)."""

    gyro_noise_density: float = param(
        0.01 * DEG_PER_S, symbol="N_g", unit="rad/s/√Hz", doc="gyro white noise (angle random walk)",
        source="MPU-9250 PS §3.1: 0.01 °/s/√Hz")
    drift_sigma_rad_s: float = param(
        0.05 * DEG_PER_S, symbol="σ_d", unit="rad/s", doc="stationary σ of each gyro drift (Gauss–Markov)",
        source="assumption: the residual of a start-up calibration (sensor profile mpu9250_calibrated)")
    drift_tau_s: float = param(
        300.0, symbol="τ_d", unit="s", doc="correlation time of the gyro drifts (rows −1/τ_d of F)",
        source="assumption")
    angle_sigma0_rad: float = param(
        2.0 * DEG, symbol="σ_Γ0", unit="rad", doc="initial σ of pitch and roll (alignment from the accelerometer)",
        source="assumption")
    gnss_vel_sigma_mps: tuple[float, float] = param(
        (0.042, 0.06), symbol="σ_v", unit="m/s",
        doc="σ of a GNSS velocity per axis (horizontal, vertical): a window of length T has 2σ_v²/T²",
        source="sensors.gnss consumer profile (u-blox M8 class)")
    accel_noise_density: float = param(
        300.0 * MICRO_G, symbol="N_a", unit="m/s²/√Hz", doc="accelerometer white noise: a window has N_a²/T",
        source="MPU-9250 PS §3.2: 300 µg/√Hz")
    accel_sigma_mps2: float = param(
        0.05, symbol="σ_a", unit="m/s²",
        doc="floor of the measurement noise per axis: accelerometer bias, vibration, timing",
        source="assumption: 5 mg, the calibrated residual bias")
    heading_sigma_rad: float = param(
        2.0 * DEG, symbol="σ_ψ", unit="rad",
        doc="σ of the heading error seen through N0 = e_Up × f (heading_coupling = 'none')", source="assumption")
    unaided_accel_sigma_mps2: float = param(
        3.0, symbol="σ_u", unit="m/s²",
        doc="σ of the vehicle's acceleration for the unaided gravity reference (which corrects tilt only)",
        source="measured without GNSS on loop600 and banked_oval (docs/gnss.md)")
    gate: float = param(
        16.27, symbol="χ²", unit="", doc="largest normalised innovation squared accepted (3 dof, 99.9 %)",
        source="χ² table")


# --------------------------------------------------------------------------------------
# Coefficients
# --------------------------------------------------------------------------------------


def _vector3(name: str, value: Any) -> np.ndarray:
    v = np.zeros(3) if value is None else np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers (µT, body axes) or None, got {value!r}")
    return v


def _soft_iron_inverse(value: Any) -> np.ndarray:
    m = np.eye(3) if value is None else np.asarray(value, dtype=np.float64)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ValueError(f"mag_soft_iron must be a finite 3×3 matrix or None, got {value!r}")
    cond = np.linalg.cond(m)
    if not cond < 1e8:
        raise ValueError(f"mag_soft_iron is singular (condition number {cond:.3g}): the soft-iron matrix E + M_m "
                         "must be invertible to compensate the field")
    return np.linalg.inv(m)


def _choice(name: str, value: Any, options: tuple[str, ...]) -> int:
    if value not in options:
        raise ValueError(f"{name} must be one of {options}, got {value!r}")
    return options.index(value)


def gnss_coefficients(p: _GnssAidedParams, fs_hz: float) -> np.ndarray:
    """Validate the parameters and derive the kernel's coefficient array (ValueError/TypeError)."""
    kalman = isinstance(p, GnssKalmanParams)
    h = 1.0 / fs_hz
    c = np.zeros(K.C_SIZE)
    c[K.C_MODE] = K.MODE_KALMAN if kalman else K.MODE_COMPLEMENTARY
    c[K.C_H] = h
    c[K.C_T0] = check_finite("t0_s", p.t0_s)
    c[K.C_G] = check_finite("gravity_mps2", p.gravity_mps2, low=0.0, low_open=True)
    t2 = float(p.t2_s)
    if not (t2 > 0.0):
        raise ValueError(f"t2_s must be > 0 s (math.inf: no magnetic heading correction), got {p.t2_s!r}")
    c[K.C_KHEAD] = 0.0 if math.isinf(t2) else 1.0 - math.exp(-h / t2)
    decl = check_finite("declination_rad", p.declination_rad)
    c[K.C_DECL], c[K.C_CDH], c[K.C_SDH] = decl, math.cos(0.5 * decl), math.sin(0.5 * decl)
    c[K.C_SOFT:K.C_SOFT + 9] = _soft_iron_inverse(p.mag_soft_iron).ravel()
    c[K.C_HARD:K.C_HARD + 3] = _vector3("mag_hard_iron_ut", p.mag_hard_iron_ut)
    window = check_finite("window_s", p.window_s, low=0.0, low_open=True)
    c[K.C_WINDOW] = window
    c[K.C_MAXINT] = check_finite("max_interval_s", p.max_interval_s, low=window)
    c[K.C_UNAIDED] = _choice("unaided", p.unaided, _UNAIDED)
    c[K.C_COAST] = check_finite("coast_s", p.coast_s, low=0.0)
    c[K.C_COUPLING] = _choice("heading_coupling", p.heading_coupling, _COUPLING)
    c[K.C_COSLIM] = math.cos(check_finite("max_pitch_rad", p.max_pitch_rad, low=0.0, high=0.5 * math.pi - 1e-3,
                                          low_open=True))
    c[K.C_DELAY] = check_finite("imu_delay_s", p.imu_delay_s, low=0.0, high=0.1)
    c[K.C_RING] = math.ceil((K.MAX_FIX_AGE_S + c[K.C_DELAY]) * fs_hz) + 2
    c[K.C_GLIM], c[K.C_ALIM] = saturation_limits(p)
    c[K.C_INV_T1] = c[K.C_INV_T1U] = 0.0
    c[K.C_P0A] = c[K.C_P0D] = 1.0
    if kalman:
        assert isinstance(p, GnssKalmanParams)
        c[K.C_QG] = check_finite("gyro_noise_density", p.gyro_noise_density, low=0.0) ** 2
        sd = check_finite("drift_sigma_rad_s", p.drift_sigma_rad_s, low=0.0)
        tau = check_finite("drift_tau_s", p.drift_tau_s, low=0.0, low_open=True)
        c[K.C_INVTD], c[K.C_QD], c[K.C_DECAY] = 1.0 / tau, 2.0 * sd * sd / tau, math.exp(-h / tau)
        c[K.C_P0A] = check_finite("angle_sigma0_rad", p.angle_sigma0_rad, low=0.0, low_open=True) ** 2
        c[K.C_P0D] = max(sd * sd, 1e-30)
        sv = np.asarray(p.gnss_vel_sigma_mps, dtype=np.float64)
        if sv.shape != (2,) or not np.all(np.isfinite(sv)) or np.any(sv < 0):
            raise ValueError(f"gnss_vel_sigma_mps must be two numbers >= 0 (horizontal, vertical), got "
                             f"{p.gnss_vel_sigma_mps!r}")
        c[K.C_VV:K.C_VV + 3] = sv[0] ** 2, sv[0] ** 2, sv[1] ** 2
        c[K.C_NA2] = check_finite("accel_noise_density", p.accel_noise_density, low=0.0) ** 2
        c[K.C_FL2] = check_finite("accel_sigma_mps2", p.accel_sigma_mps2, low=0.0) ** 2
        c[K.C_HV] = check_finite("heading_sigma_rad", p.heading_sigma_rad, low=0.0) ** 2
        c[K.C_UV] = check_finite("unaided_accel_sigma_mps2", p.unaided_accel_sigma_mps2, low=0.0,
                                 low_open=True) ** 2
        c[K.C_GATE] = check_finite("gate", p.gate, low=0.0, low_open=True)
        if c[K.C_VV] + c[K.C_NA2] + c[K.C_FL2] == 0.0:
            raise ValueError("gnss_vel_sigma_mps, accel_noise_density and accel_sigma_mps2 are all zero: "
                             "the measurement noise R must be positive")
    else:
        assert isinstance(p, GnssComplementaryParams)
        c[K.C_INV_T1] = 1.0 / check_finite("t1_s", p.t1_s, low=0.0, low_open=True)
        c[K.C_INV_T1U] = 1.0 / check_finite("t1_unaided_s", p.t1_unaided_s, low=0.0, low_open=True)
    return c


# --------------------------------------------------------------------------------------
# The estimators
# --------------------------------------------------------------------------------------


class _GnssAided(Estimator):
    """The streaming wrapper shared by both variants (see the module docstring)."""

    inputs: ClassVar[tuple[str, ...]] = ("gnss", "imu_flags")

    def _coefficients(self, params: _GnssAidedParams, fs_hz: float) -> np.ndarray:
        return gnss_coefficients(params, fs_hz)

    def _initial_state(self, q0: np.ndarray | None) -> np.ndarray:
        ring_len = int(self._coef[K.C_RING])
        self.state_layout = K.STATE_PARTS + (("ring", ring_len * K.RING_COLS),)
        st = np.zeros(K.S_SIZE + ring_len * K.RING_COLS)
        st[K.S_LAM] = 1.0
        st[K.S_LAST_AIDED] = st[K.S_LAST_FIX] = K.NEVER
        st[K.S_P:K.S_P + 25] = np.diag([self._coef[K.C_P0A]] * 2 + [self._coef[K.C_P0D]] * 3).ravel()
        if q0 is not None:
            st[K.S_INIT] = 2.0
            st[K.S_LAM:K.S_LAM + 4] = q0
        return st

    def _fix_rows(self, gnss: Any, k: int) -> tuple[np.ndarray, float | None]:
        """Check ``gnss`` and merge it with the fixes waiting in the state (raises, changes nothing)."""
        st = self._state
        n_pending = int(st[K.S_PEND_N])
        pending = st[K.S_PEND:K.S_PEND + K.FIX_COLS * n_pending].reshape(-1, K.FIX_COLS)
        if gnss is None:
            return (pending.copy() if n_pending else _NO_FIXES), None
        if not isinstance(gnss, GnssFixes):
            raise TypeError(f"gnss must be a GnssFixes (biso_cosim.sensors.gnss) or None, got {type(gnss).__name__}")
        t = np.asarray(gnss.t_s, dtype=np.float64)
        m = t.shape[0] if t.ndim == 1 else -1
        if m < 0:
            raise ValueError(f"gnss.t_s must have shape (m,), got {t.shape}")
        ta = np.asarray(gnss.t_arrival_s, dtype=np.float64)
        vel = np.asarray(gnss.vel_w, dtype=np.float64)
        valid = np.asarray(gnss.valid, dtype=np.bool_)
        for name, a, shape in (("t_arrival_s", ta, (m,)), ("vel_w", vel, (m, 3)), ("valid", valid, (m,))):
            if a.shape != shape:
                raise ValueError(f"gnss.{name} must have shape {shape} like gnss.t_s, got {a.shape}")
        if m == 0:
            return (pending.copy() if n_pending else _NO_FIXES), None
        # one vectorised test per rule; the index is looked for only to report a failure
        if not (np.isfinite(t).all() and np.isfinite(ta).all()):
            name, a = ("t_s", t) if not np.isfinite(t).all() else ("t_arrival_s", ta)
            i = int(np.flatnonzero(~np.isfinite(a))[0])
            raise ValueError(f"gnss.{name} must be finite: fix {i} is {a[i]!r} (nothing was processed)")
        if m > 1 and not (t[1:] > t[:-1]).all():
            i = int(np.flatnonzero(t[1:] <= t[:-1])[0]) + 1
            raise ValueError(f"gnss.t_s must increase: fix {i} (t = {t[i]!r} s) is not after fix {i - 1} "
                             f"(t = {t[i - 1]!r} s) (nothing was processed)")
        if not t[0] > st[K.S_LAST_FIX]:
            raise ValueError(f"gnss.t_s must continue the stream: fix 0 (t = {t[0]!r} s) is not after the last fix "
                             f"already given (t = {st[K.S_LAST_FIX]!r} s); pass each fix once (nothing was processed)")
        if not (ta >= t).all():
            i = int(np.flatnonzero(ta < t)[0])
            raise ValueError(f"gnss.t_arrival_s must not precede t_s: fix {i} arrives at {ta[i]!r} s, before its "
                             f"time of validity {t[i]!r} s")
        if not valid.all():
            t, ta, vel = t[valid], ta[valid], vel[valid]
        rows = np.empty((n_pending + t.shape[0], K.FIX_COLS))
        rows[:n_pending] = pending
        new = rows[n_pending:]
        new[:, 0], new[:, 1], new[:, 2:5] = t, ta, vel
        new[:, 5] = np.isfinite(vel).all(axis=1)
        if rows.shape[0] > 1 and not (rows[1:, 1] >= rows[:-1, 1]).all():
            raise ValueError("gnss.t_arrival_s must not decrease (within a call and after the fixes still waiting)")
        t_last = self._coef[K.C_T0] + (st[K.S_N] + k - 1) / self.fs_hz
        if rows.shape[0] and (k == 0 or rows[-1, 1] > t_last + 1e-9):
            waiting = rows.shape[0] if k == 0 else int(np.count_nonzero(rows[:, 1] > t_last + 1e-9))
            if waiting > K.PENDING_CAPACITY:
                raise ValueError(f"gnss: {waiting} fixes arrive after the last IMU sample of this call "
                                 f"(t = {t_last:.6g} s); at most {K.PENDING_CAPACITY} may wait: pass fixes with the "
                                 "samples they arrive in")
        return rows, float(gnss.t_s[-1])

    def update(self, gyro_b: Any, accel_b: Any, mag_b: Any, *, gnss: Any = None, **inputs: Any) -> GnssAidedEstimate:
        """Process k IMU samples (gyro rad/s, accelerometer m/s², magnetometer µT; (k, 3) each,
        body axes, at ``fs_hz``) and the GNSS fixes ``gnss`` of the same span (or None);
        optionally the sensor's flags per sample, ``imu_flags`` (saturation, AK8963 overflow).

        Returns the attitude after each sample with flags, the drift estimate and σ (Kalman
        variant) and the fixes used. Wrong shapes, types or GNSS time stamps raise before
        anything changes; see the module docstring for the policies.
        """
        gyro, accel, mag = as_samples(("gyro_b", gyro_b), ("accel_b", accel_b), ("mag_b", mag_b))
        k = gyro.shape[0]
        extra = self._extra_inputs(inputs, k)
        fx, last_t = self._fix_rows(gnss, k)
        kalman = self._coef[K.C_MODE] == K.MODE_KALMAN
        q_out = np.empty((k, 4))
        flags = np.empty(k, dtype=np.int64)
        bias = np.empty((k if kalman else 0, 3))
        sigma = np.empty((k if kalman else 0, 2))
        window = self._coef[K.C_WINDOW]
        capacity = fx.shape[0] + int(math.ceil(k / (window * self.fs_hz))) + 2
        upd = np.empty((capacity, K.UPD_COLS))
        rows = K._gnss_batch(self._coef, self._state, gyro, accel, mag, extra["imu_flags"], fx, q_out, flags, bias,
                             sigma, upd)
        if last_t is not None:
            self._state[K.S_LAST_FIX] = last_t
        return GnssAidedEstimate(q_out, flags, bias if kalman else None, sigma if kalman else None,
                                 _updates_record(upd[:rows]))

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias) -> None:  # pragma: no cover
        raise NotImplementedError("GNSS-aided estimators run through update()")

    # -- in the co-simulation's period call (biso_cosim.loop) ---------------------------

    loop_kernel = K.gnss_loop
    loop_views = False  # (the updates record is made for each period)

    def loop_arrays(self, bound: int) -> "GnssLoopArrays":
        """The arrays of ``loop_kernel`` (see ``Estimator.loop_arrays``): coefficients and
        state, the outputs of ``update`` for up to ``bound`` samples, and room for the update
        rows of a period (the fixes of the loop's receiver: at most 10 Hz, a sensor of at
        least 4 Hz, so fewer than 3 per sample, plus those waiting and the unaided windows;
        a period that needs more is refused loudly, see ``loop_estimate``)."""
        kalman = self._coef[K.C_MODE] == K.MODE_KALMAN
        windows = int(math.ceil(bound / (self._coef[K.C_WINDOW] * self.fs_hz)))
        room = 2 * K.PENDING_CAPACITY + 4 * bound + windows + 2
        return GnssLoopArrays(self._coef, self._state, self.fs_hz, np.empty((bound, 4)),
                              np.empty(bound, dtype=np.int64), np.empty((bound if kalman else 0, 3)),
                              np.empty((bound if kalman else 0, 2)), np.empty((room, K.UPD_COLS)),
                              np.zeros(3, dtype=np.int64))

    def loop_estimate(self, arrays: "GnssLoopArrays", k: int) -> GnssAidedEstimate:
        """The estimate of the last period call's k samples, as ``update`` returns it (the
        updates record made from the call's rows); raises what ``update`` would have raised
        on the period's fixes (the call then changed nothing of the estimator)."""
        fault = arrays.counts[K.LOOP_FAULT]
        if fault:
            value = int(arrays.counts[K.LOOP_FAULT + 1])
            if fault == K.LOOP_FAULT_STREAM:
                raise ValueError(f"{self.method}: gnss.t_s must continue the stream: the period's first fix is not "
                                 f"after the last fix already given (t = {self._state[K.S_LAST_FIX]!r} s); the receiver and "
                                 "the estimator are not in step (a state restored into one of them alone?)")
            if fault == K.LOOP_FAULT_WAITING:
                raise ValueError(f"{self.method}: gnss: {value} fixes arrive after the last IMU sample of the period; "
                                 f"at most {K.PENDING_CAPACITY} may wait")
            raise RuntimeError(f"{self.method}: a period needs {value} update rows, more than the "
                               f"{arrays.updates.shape[0]} of the loop's arrays")
        kalman = self._coef[K.C_MODE] == K.MODE_KALMAN
        return GnssAidedEstimate(arrays.q_wb[:k], arrays.flags[:k], arrays.gyro_bias_b[:k] if kalman else None,
                                 arrays.tilt_sigma_rad[:k] if kalman else None,
                                 _updates_record(arrays.updates[:arrays.counts[K.LOOP_ROWS]]))


class GnssLoopArrays(NamedTuple):
    """A GNSS-aided estimator's arrays in the period call (``loop_arrays``)."""

    coef: np.ndarray
    state: np.ndarray
    fs_hz: float
    q_wb: np.ndarray
    flags: np.ndarray
    gyro_bias_b: np.ndarray  # (bound, 3) Kalman, (0, 3) complementary
    tilt_sigma_rad: np.ndarray  # (bound, 2) Kalman, (0, 2) complementary
    updates: np.ndarray  # (room, UPD_COLS) rows of the updates record
    counts: np.ndarray  # (3,) int64: the update rows of the last call; a fault and its value (``K.LOOP_*``)


_NO_FIXES = np.empty((0, K.FIX_COLS))  # (never written: the kernel only reads fixes)


_NO_UPDATES = np.empty(0, dtype=UPDATE_DTYPE)
_NO_UPDATES.flags.writeable = False


def _updates_record(rows: np.ndarray) -> np.ndarray:
    if not rows.shape[0]:
        return _NO_UPDATES  # (most calls: shared, read-only)
    out = np.empty(rows.shape[0], dtype=UPDATE_DTYPE)
    out["t_s"], out["t_applied_s"], out["kind"], out["interval_s"] = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
    out["innovation_w"], out["innovation_sigma_w"], out["nis"] = rows[:, 4:7], rows[:, 7:10], rows[:, 10]
    out["correction_roll_rad"], out["correction_pitch_rad"] = rows[:, 11], rows[:, 12]
    return out


class GnssComplementaryEstimator(_GnssAided):
    """Ibrahim & Lukyanov (2020) without a Kalman filter: tilt correction (7) with T1, heading (5)–(6)."""

    method = "gnss_complementary"
    Params = GnssComplementaryParams
    state_layout = K.STATE_PARTS


class GnssKalmanEstimator(_GnssAided):
    """Ibrahim & Lukyanov (2020) with the five-state Kalman filter (tilt errors, gyro drifts)."""

    method = "gnss_kalman"
    Params = GnssKalmanParams
    state_layout = K.STATE_PARTS
    estimates_bias = True


# --------------------------------------------------------------------------------------
# The paper's equations as plain functions (documentation, tests)
# --------------------------------------------------------------------------------------


def euler_rates(theta: float, gamma: float, omega: Any) -> np.ndarray:
    """Eq. (4): (γ̇, ϑ̇, ψ̇) from pitch ϑ, roll γ and the body rate ω in the paper's body axes
    (x forward, y up, z right), Earth rate neglected (eq. (3))::

        γ̇ = ω_x − tan ϑ (ω_y cos γ − ω_z sin γ),  ϑ̇ = ω_y sin γ + ω_z cos γ,
        ψ̇ = (ω_y cos γ − ω_z sin γ) / cos ϑ
    """
    wx, wy, wz = np.asarray(omega, dtype=np.float64)
    a = wy * math.cos(gamma) - wz * math.sin(gamma)
    return np.array([wx - math.tan(theta) * a, wy * math.sin(gamma) + wz * math.cos(gamma), a / math.cos(theta)])


def error_matrix(theta: float, gamma: float, omega: Any, drift_tau_s: float) -> np.ndarray:
    """F of Ẋ = F X + G w, X = [Δϑ, Δγ, Δω_x, Δω_y, Δω_z] (eq. (4) linearised, docs/design.md §6)."""
    wx, wy, wz = np.asarray(omega, dtype=np.float64)
    sg, cg, tt, ct = math.sin(gamma), math.cos(gamma), math.tan(theta), math.cos(theta)
    a1 = wy * cg - wz * sg
    f = np.zeros((5, 5))
    f[0] = [0.0, a1, 0.0, sg, cg]
    f[1] = [-a1 / (ct * ct), tt * (wy * sg + wz * cg), 1.0, -tt * cg, tt * sg]
    f[2:, 2:] = -np.eye(3) / drift_tau_s
    return f


def magnetic_heading(mag_b: Any, roll: Any, pitch: Any, *, hard_iron_ut: Any = None, soft_iron: Any = None,
                     declination_rad: float = 0.0) -> np.ndarray:
    """True compass heading (rad, clockwise from North) by eq. (5) as read here (decision 1).

    ``T_y = C_nᵀ (E + M_m)⁻¹ (T_c − P_m)`` with T_c the magnetometer reading in the paper's
    body axes and C_n the tilt matrix R_z(ϑ) R_x(γ); then ψ_m = atan2(−T_y3, T_y1) clockwise
    from magnetic North, plus D. ``mag_b`` (n, 3) µT in our body axes; ``roll``, ``pitch``
    (n,) rad in ours (ISO 8855).
    """
    m = np.atleast_2d(np.asarray(mag_b, dtype=np.float64))
    hard = _vector3("hard_iron_ut", hard_iron_ut)
    corrected = (m - hard) @ _soft_iron_inverse(soft_iron).T
    # paper body axes (x forward, y up, z right)
    tc = np.stack([corrected[:, 0], corrected[:, 2], -corrected[:, 1]], axis=1)
    theta, gamma = -np.asarray(pitch, dtype=np.float64), np.asarray(roll, dtype=np.float64)
    out = np.empty(tc.shape[0])
    for i in range(tc.shape[0]):
        th, ga = np.broadcast_to(theta, out.shape)[i], np.broadcast_to(gamma, out.shape)[i]
        rz = np.array([[math.cos(th), -math.sin(th), 0.0], [math.sin(th), math.cos(th), 0.0], [0.0, 0.0, 1.0]])
        rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(ga), -math.sin(ga)], [0.0, math.sin(ga), math.cos(ga)]])
        ty = (rz @ rx) @ tc[i]  # body → level axes (forward, up, right), i.e. C_nᵀ applied to T_c
        out[i] = math.atan2(-ty[2], ty[0])
    return np.mod(out + declination_rad, 2.0 * math.pi)


def docs_tables() -> dict[str, str]:
    """The Markdown tables of docs/gnss.md, by marker: the consumer receiver profile and the
    parameters of both estimators (one source each; a test keeps the page in sync)."""
    from biso_cosim.estimators._base import param_markdown
    from biso_cosim.sensors.gnss import gnss_profile_table

    rows = ["| field | symbol | unit | value | meaning | source |", "|---|---|---|---|---|---|"]
    rows += [f"| `{r['name']}` | {r['symbol']} | {r['unit']} | `{r['value']!r}` | {r['doc']} | {r['source']} |"
             for r in gnss_profile_table("consumer")]
    return {"gnss-consumer": "\n".join(rows), "gnss-complementary": param_markdown(GnssComplementaryParams),
            "gnss-kalman": param_markdown(GnssKalmanParams)}
