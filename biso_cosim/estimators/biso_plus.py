"""biso_plus: the BISO structure with what a vehicle needs.

Same family as the faithful BISO (``biso.py``): the quaternion Poisson equation integrated
from the gyro, with a positional correction toward the attitude the accelerometer and the
magnetometer give. What it adds, each for a weakness docs/design.md §5 and issue 4 name:

* **gyro-bias estimation**: a three-state Kalman filter (after VQF, Laidig & Seel 2023,
  §"bias estimation") whose measurement is the correction rate the positional correction
  applies, compared with the same low-pass seen by the accelerometer, so the low-pass inside
  the loop does not slow it down; at rest the measurement is the low-passed gyro itself
  (rest: the vehicle's speed ≈ 0 when a speed input is given; else the gyro and
  accelerometer steady and the rate small);
* **acceleration compensation**: with a speed input v (wheel odometry or GNSS) of a point r_v
  of the vehicle (the rear axle's centre), the IMU's velocity is u = (v, v_y, 0) − ω × r_v
  and the specific force is corrected by its acceleration ``u̇ + ω × u`` (longitudinal,
  centripetal and lever-arm terms; v̇, v̇_y and ω̇ low-passed differences), so the tilt
  reference sees gravity. The axle's sideslip v_y = −(D_r/g₀) |v| f_y: a tyre's slip angle grows
  with its lateral force (steady-state single-track model, Gillespie 1992, ch. 6), and the
  lateral specific force f_y is that force per mass, on a banked road too; D_r = 0 (the
  default) is a point that does not slide sideways. **Wheel slip**: a wheel's speed is the
  vehicle's only while it rolls on the road. Unloaded over bumps (wheel hop on corrugations,
  14 Hz at 12 m/s on 0.8 m waves) a driven wheel spins up under the drive torque and is pulled
  back to the road's speed when it lands, at tens of m/s², which the vehicle does not feel;
  compensated, each pulse tilts the reference by v̇/g, and the gate (a horizontal error a
  changes |f| by only about a²/2g) passes the long moderate spin-ups and down-weights the
  short sharp landings, so the weighted low-pass leans forward: 11° of pitch RMS on rough_road
  (docs/vehicle.md). Where v̇ and the accelerometer's forward specific force (both
  low-passed) differ by more than a slope's gravity can explain (a_s), and for t_s after, the
  speed is carried on by the accelerometer's forward acceleration with the estimate's gravity
  removed, and the longitudinal axis has no say in the tilt. **Beyond the tyres' linear range**
  (horizontal specific force √(f_x² + f_y²) > a_l, and for t_l after) the slip angles leave
  the model (saturated tyres slide without bound, the front wheels' odometry leaves the rear
  axle's speed), the sideslip's velocity and rate enter the compensation wrong by m/s², and
  the compensated specific force has no say in the tilt: the gyro carries it (docs/vehicle.md,
  "At the limit");
* **disturbance-tolerant tilt reference**: the (compensated) specific force is low-pass
  filtered in a quasi-inertial frame I (the gyro's own strapdown frame, as VQF does: Laidig &
  Seel 2023), where gravity is constant and zero-mean accelerations average out without
  lag from the vehicle's rotation; samples whose |f| is far from g are down-weighted (gating);
  without a speed input (a general AHRS: handheld motion, BROAD, Laidig et al. 2021) the
  low-pass is second order (VQF's Butterworth: fast translations put specific force of a few
  Hz into the tilt reference, which a first order passes 10x more) and ungated (the
  uncompensated |f| leaves g for the whole of a long motion, and a gate froze the correction);
* **magnetic disturbance detection**: the field's norm and dip (with the estimated tilt)
  against the expected field (learned while undisturbed, or given); a disturbed field is not
  used for heading, nor for learning the expected field; without a speed input the heading
  gain is also weighted as by a measurement variance σ_h² + κ D + (|B| |ω| τ_m)², with D a
  low-pass of (|m − o| − |B|)² (a magnet near the sensor changes the norm where it turns the
  field, below the rejection threshold too) and an optional time-skew term under rotation;
* **hard-iron (offset) estimation**: ``m = R_Ibᵀ B_I + o`` is linear in the field in the
  I frame and the offset o, with R_Ib from the gyro strapdown alone (no feedback from the
  heading correction): a six-state Kalman filter with random walks, decimated, with its own
  innovation gate (a magnet is rejected there), learning only once the gyro bias is known;
  the offset prior keeps what level driving cannot observe (o_z against B_z) near 0; the
  learned offset is used only while it makes the field's norm steadier than the raw field's
  (without a speed input: a norm test over the last Θ_o of rotation): the vector model also
  takes a field that changes along the path or lags the gyro for an offset, which a
  calibrated sensor in a lab does not have (BROAD);
* **decoupled corrections**: tilt about horizontal world axes from the accelerometer only,
  heading about Up from the magnetometer only, so a magnetic disturbance cannot tilt the
  estimate and an acceleration cannot turn its heading;
* **a cross-link without the renormalisation bias**: the paper's cross-link acts on the
  rotation-vector error ε (world frame), ``ω_c = K ε + k_p (1, 1, 1) × ε``, applied as a
  rotation: the estimate stays a unit quaternion, there are no norm dynamics, and the bias
  of ``λ − λ_k`` with renormalisation (docs/design.md §5) is gone. A cross-link on rotations still
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
    tilt_lp_order: int = param(
        2, symbol="n_a", unit="",
        doc="order of the low-pass of the specific force in I without a speed input: 1 (first order, "
            "as with a speed input) or 2 (Butterworth, −40 dB/decade: the specific force of fast "
            "handheld translations, a few Hz, is attenuated 100x per decade instead of 10x)",
        source="VQF (Laidig & Seel 2023) §3.2, second-order filter of the accelerometer in I")
    accel_gate_free: float | None = param(
        None, symbol="γ_f", unit="",
        doc="the gate γ without a speed input; None = no gate (the uncompensated |f| departs from g "
            "during all of a long motion, and a gate would freeze the tilt correction then)",
        source="measured (BROAD, docs/estimators.md)")
    # -- heading
    k_heading: float = param(
        0.05, symbol="k_h", unit="1/s",
        doc="positional correction gain of heading toward the magnetometer (at least 1/(t + τ_a) "
            "during the start)", source="measured")
    mag_heading_noise_ut: float = param(
        10.0, symbol="σ_h", unit="µT",
        doc="nominal noise of the field in the heading correction: without a speed input k_h is "
            "scaled by σ_h²/(σ_h² + κ D + (|B| |ω| τ_m)²), a measurement variance inflated by a "
            "disturbance and by fast rotation", source="measured with κ (only κ/σ_h² and τ_m/σ_h matter)")
    mag_disturbance_gain: float = param(
        30.0, symbol="κ", unit="",
        doc="weight of the disturbance measure D = LP[(|m − o| − |B|)²] (µT²) in the heading "
            "variance: a field that is not the expected one (a magnet, a room's inhomogeneous field, "
            "an offset or soft iron not yet known) changes its norm wherever it deflects its direction",
        source="measured: BROAD dev 2.41° at 100, 2.51° at 30; simulated tumble 1.58x / 1.45x VQF "
               "(docs/estimators.md)")
    tau_mag_disturbance_s: float = param(
        0.2, symbol="τ_D", unit="s",
        doc="time constant of the low-pass of the disturbance measure D (short: a magnet's approach "
            "takes a fraction of a second, and D should follow it)",
        source="measured")
    mag_time_skew_s: float = param(
        0.0, symbol="τ_m", unit="s",
        doc="effective time skew of the magnetometer against the gyro (AK8963 sampling at 100 Hz or "
            "below, read late): under a rotation ω the field it reports is off by about |B| |ω| τ_m; "
            "0 = not modelled (measured on BROAD: 0.01–0.02 s raises the mean error; compensating the "
            "skew instead helps the fast-rotation trial and costs more on the combined and magnet ones)",
        source="AK8963 datasheet §6.4 (measurement time); measured (docs/estimators.md)")
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
    bias_heading_factor_free: float = param(
        0.1, symbol="f_zf", unit="",
        doc="f_z without a speed input, where the heading correction's measurement variance is also "
            "divided by the heading's weight (σ_h²/(σ_h² + κ D + …)) and the heading's start (k_h raised "
            "to 1/(t + τ_a), a convergence, not a bias) is not used: a handheld sensor may never rest, "
            "and a vertical bias b left to the heading loop turns the heading by b/k_h (6° at 0.3 °/s)",
        source="measured (docs/estimators.md)")
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
    mag_offset_test_angle_rad: float = param(
        2.0 * math.pi, symbol="Θ_o", unit="rad",
        doc="norm test of the learned offset o: o is used only while the field's norm with it, |m − o|, "
            "varies less than the raw norm |m|. A real offset makes |m| change with the attitude (by the "
            "field's direction in body axes · o) and leaves |m − o| steady; an offset the vector model "
            "m = R_Ibᵀ B_I + o took from a field that is not uniform (a room's gradient along a translation) "
            "or not simultaneous with the gyro (a lagging field under fast rotation) need not, and then the "
            "raw field is used. Both variances are low-passed over the last Θ_o of rotation (a window in "
            "angle: without rotation the norm cannot tell an offset, and the decision is held). Without a "
            "speed input only: a vehicle's field along the road is uniform at the scale of its motion and its "
            "turns are slow, so the vector model holds, while level driving shows the norm only the "
            "horizontal offset's projection, of the order of the noise; 0 = o always used",
        source="one turn (chosen, not fitted); measured on BROAD (docs/estimators.md)")
    mag_offset_shrink_ut: float = param(
        1.0, symbol="σ_s", unit="µT",
        doc="while the norm test uses the learned offset o, o is shrunk toward 0 by |o|²/(|o|² + σ_s²): an "
            "offset as small as σ_s cannot be told from what the vector model takes for one at a nearly "
            "fixed attitude (a room's gradient felt along a hand's translation, in step with its turns: "
            "0.7–1.2 µT on BROAD's translation trials), while a large one (a phone's 2.4 µT, an attached "
            "magnet's 27 µT) is used nearly whole. Without a speed input and with the norm test only; "
            "0 = o used whole",
        source="the apparent offset of BROAD's translation trials and the residual offset of its calibrated "
               "IMU (0.2–0.9 µT), not fitted (docs/estimators.md)")
    declination_rad: float = param(0.0, symbol="D", unit="rad", doc="magnetic declination, east positive", source="")
    # -- speed input
    speed_point_b_m: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0), symbol="r_v", unit="m",
        doc="where the speed is measured (e.g. the rear axle's centre) relative to the IMU, body axes",
        source="vehicle geometry")
    tau_speed_s: float = param(
        0.05, symbol="τ_v", unit="s", doc="low-pass of v̇ and ω̇ from differences", source="measured")
    speed_slip_accel_mps2: float = param(
        3.0, symbol="a_s", unit="m/s²",
        doc="wheel slip: the largest difference between the speed input's v̇ and the accelerometer's "
            "forward specific force f_x (both low-passed, τ_v) while the wheel rolls on the road (gravity "
            "along the vehicle's x on a slope, g sin θ, and the lever-arm terms). Beyond it the speed is "
            "not the vehicle's (a wheel unloaded over a bump, spun up by the drive torque or pulled back to "
            "the road's speed when it lands; a locked wheel): until t_s after the last such sample the "
            "vehicle's speed is carried on by the accelerometer's forward acceleration (the estimate's "
            "gravity removed), which then has no say in the tilt (flag ACCEL_GATED)",
        source="g sin 18° (a 32 % grade, steeper than public roads); measured (docs/vehicle.md, rough_road)")
    speed_slip_hold_s: float = param(
        0.5, symbol="t_s", unit="s",
        doc="how long after the last sample beyond a_s the speed input stays unused for v̇ (the wheel's "
            "spin-up and landing settle)", source="measured: 0.25-1 s alike (docs/vehicle.md)")
    rear_slip_gradient_rad_per_g: float = param(
        0.0, symbol="D_r", unit="rad",
        doc="slip angle of the axle at r_v per g of lateral specific force: the point's velocity is taken "
            "as (v, −(D_r/g₀) |v| f_y, 0) in body axes, f_y the accelerometer's lateral specific force "
            "low-passed (τ_v), instead of (v, 0, 0); 0: the point does not slide sideways (kinematic "
            "steering)",
        source="steady-state single-track model, α_r = W_r/C_αr per g (Gillespie 1992, ch. 6): the axle's "
               "load over its cornering stiffness; the reference car's rear axle with magic_formula tyres "
               "0.078 (4.45 °/g; 4.6-4.9 °/g on the ISO 4138 circle, docs/vehicle.md)")
    linear_accel_mps2: float = param(
        0.0, symbol="a_l", unit="m/s²",
        doc="the tyres' linear range: while the horizontal specific force √(f_x² + f_y²) (the tyres' "
            "force per mass, low-passed τ_v) is beyond it, and for t_l after, the compensated specific "
            "force has no say in the tilt (weight 0, flag ACCEL_GATED; the gyro carries the tilt): beyond "
            "the linear range the axles' slip angles leave the single-track model D_r f_y (they grow "
            "without bound as the tyres saturate), the front wheels' odometry leaves the rear axle's "
            "speed (front slip angle, braking slip), and the sideslip's velocity and rate, unknown, enter "
            "the compensation at several m/s²; 0: no limit (the guard off)",
        source="where a rear tyre's secant cornering stiffness F_y/α has fallen 10 % below K_yα at its "
               "static load (Magic Formula, Pacejka 2012 §4.3; the single-track model's linear range: "
               "Gillespie 1992, ch. 6): the reference car with magic_formula tyres 6.13 m/s² (0.63 g) on a "
               "dry road, 4.29 wet (vehicle.tyres.linear_accel_mps2; docs/vehicle.md, At the limit)")
    linear_hold_s: float = param(
        1.0, symbol="t_l", unit="s",
        doc="how long after the last sample beyond a_l the compensated specific force stays out of the "
            "tilt: the sideslip built in a slide decays, and between two slides the other way |f| passes "
            "through the linear range for a fraction of a second while the sideslip swings over",
        source="measured: 0.5 s let those swings in, 1-3 s alike (docs/vehicle.md)")
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
    ("time_s", 1), ("offset_started", 1), ("field_dip_cs", 2), ("accel_bw_i", 6), ("accel_bw_ready", 1),
    ("mag_disturbance", 1), ("heading_start_s", 1), ("tilt_corr_start", 2), ("speed_slip_s", 1),
    ("speed_held", 1), ("forward_accel_lp", 1), ("lateral_accel_lp", 1), ("lateral_speed_prev", 1),
    ("lateral_dvdt", 1), ("offset_norm_test", 4), ("linear_limit_s", 1),
)
_S = layout_offsets(STATE_LAYOUT)
(_S_INIT, _S_LAM, _S_QI, _S_QC, _S_BIAS, _S_BP, _S_FLP, _S_RLP, _S_RBLP, _S_GYRO, _S_WLP, _S_ALP, _S_REST_T,
 _S_VPREV, _S_DVDT, _S_VOK, _S_WPREV, _S_WDOT, _S_OFF, _S_BI, _S_P, _S_OFF_K, _S_BNORM, _S_DIP, _S_FIELD_OK,
 _S_REJ_T, _S_TIME, _S_OFF_INIT, _S_DIP_CS, _S_BW, _S_BW_OK, _S_MDIST, _S_HEAD_T, _S_TILT_CORR, _S_SLIP_T,
 _S_VHELD, _S_FXLP, _S_FYLP, _S_VYPREV, _S_DVYDT, _S_OTEST, _S_LIM_T) = (_S[name] for name, _ in STATE_LAYOUT)
_S_SIZE = _S["_size"]

_COEF_LAYOUT = (
    ("h", 1), ("a_acc", 1), ("a_accv", 1), ("k_t", 1), ("k_h", 1), ("k_p", 1), ("gate", 1), ("t0", 1),
    ("bias_p0", 1), ("bias_v", 1), ("bias_w_motion", 1), ("bias_w_vertical", 1), ("bias_w_rest", 1),
    ("bias_limit", 1), ("rest_time", 1), ("a_rest", 1), ("rest_w", 1), ("rest_a", 1), ("rest_v", 1),
    ("b_tol", 1), ("dip_tol", 1), ("reject_max", 1), ("a_field", 1), ("b_norm", 1), ("dip", 1),
    ("offset_on", 1), ("q_offset", 1), ("q_field", 1), ("r_mag", 1), ("offset_n", 1), ("decl", 1),
    ("cdh", 1), ("sdh", 1), ("r_v", 3), ("a_speed", 1), ("g", 1), ("gyro_range", 1), ("accel_range", 1),
    ("offset_bias2", 1), ("fs", 1), ("inv_gate_g", 1), ("dip_c", 1), ("dip_s", 1), ("cos_dip_tol", 1),
    ("acc_bw", 5), ("inv_gate_free_g", 1), ("r_head", 1), ("kappa", 1), ("a_dist", 1), ("tau_m2", 1),
    ("bias_w_vertical_free", 1), ("slip_accel", 1), ("slip_hold", 1), ("rear_slip", 1),
    ("inv_offset_test", 1), ("linear_accel2", 1), ("linear_hold", 1), ("offset_shrink2", 1),
)
_C = layout_offsets(_COEF_LAYOUT)
(_C_H, _C_A_ACC, _C_A_ACCV, _C_KT, _C_KH, _C_KP, _C_GATE, _C_T0, _C_BP0, _C_BV, _C_BWM, _C_BWV, _C_BWR,
 _C_BLIM, _C_REST_N, _C_A_REST, _C_REST_W, _C_REST_A, _C_REST_V, _C_BTOL, _C_DTOL, _C_REJ_N, _C_A_FIELD,
 _C_BNORM, _C_DIP, _C_OFFSET, _C_Q_OFFSET, _C_Q_FIELD, _C_R_MAG, _C_OFF_N, _C_DECL, _C_CDH, _C_SDH, _C_RV,
 _C_A_SPEED, _C_G, _C_GRANGE, _C_ARANGE, _C_OFF_BIAS2, _C_FS, _C_INV_GATE_G, _C_DIP_C, _C_DIP_S, _C_COS_DTOL,
 _C_BW, _C_INV_GATE_FREE, _C_R_HEAD, _C_KAPPA, _C_A_DIST, _C_TAU_M2, _C_BWVF, _C_SLIP_A, _C_SLIP_HOLD,
 _C_REAR_SLIP, _C_INV_OTEST, _C_LIN2, _C_LIN_HOLD, _C_OFF_SHRINK2) = (
    _C[name] for name, _ in _COEF_LAYOUT)
_C_SIZE = _C["_size"]

_P0_FIELD = 100.0 ** 2  # variance (µT²) of the field in I before the first magnetometer sample
# random walk of the field in the I frame (µT²/s): I turns with the residual gyro bias
_FIELD_WALK_UT2_PER_S = 1.0


def _alpha(h: float, tau: float) -> float:
    """Per-sample gain of a first-order low-pass with time constant tau (1 at tau = 0)."""
    return 1.0 if tau == 0.0 else 1.0 - math.exp(-h / tau)


def _butterworth2(h: float, tau: float) -> tuple[float, float, float, float, float]:
    """(b0, b1, b2, a1, a2) of the second-order Butterworth low-pass whose cut-off is
    f_c = √2/(2π τ) (the −3 dB point of VQF's choice, so that its step settles like a first
    order of time constant τ), discretised bilinearly with pre-warping at f_c (VQF, Laidig &
    Seel 2023, filterCoeffs): y_k = b0 x_k + b1 x_{k−1} + b2 x_{k−2} − a1 y_{k−1} − a2 y_{k−2}."""
    fc = math.sqrt(2.0) / (2.0 * math.pi * tau)
    cw = math.tan(math.pi * fc * h)
    d = cw * cw + math.sqrt(2.0) * cw + 1.0
    b0 = cw * cw / d
    return b0, 2.0 * b0, b0, 2.0 * (cw * cw - 1.0) / d, (1.0 - math.sqrt(2.0) * cw + cw * cw) / d


def _kalman_noise(sigma: float, v: float) -> float:
    """Measurement variance whose steady-state estimate variance with random walk v is σ² (VQF)."""
    p = sigma * sigma
    return p * p / v + p


_NON_NEGATIVE = ("tau_acc_s", "tau_acc_speed_s", "k_tilt", "k_heading", "k_p", "bias_limit_rad_s",
                 "rest_time_s", "rest_filter_tau_s", "rest_gyro_rad_s", "rest_accel_mps2", "rest_speed_mps",
                 "mag_reject_max_s", "tau_field_s", "mag_offset_interval_s", "tau_speed_s", "bias_heading_factor",
                 "mag_disturbance_gain", "tau_mag_disturbance_s", "mag_time_skew_s",
                 "bias_heading_factor_free", "speed_slip_hold_s", "rear_slip_gradient_rad_per_g",
                 "mag_offset_test_angle_rad", "linear_accel_mps2", "linear_hold_s", "mag_offset_shrink_ut")
"""The real parameters that must be finite and >= 0."""
_POSITIVE = ("accel_gate", "mag_norm_tol", "mag_dip_tol_rad", "gravity_mps2", "mag_noise_ut",
             "mag_offset_sigma_ut", "tau_mag_offset_s", "bias_sigma_init_rad_s", "bias_forgetting_s",
             "bias_sigma_motion_rad_s", "bias_sigma_rest_rad_s", "mag_offset_bias_sigma_rad_s",
             "mag_heading_noise_ut", "speed_slip_accel_mps2")
"""The real parameters that must be finite and > 0."""

# The parameter record as the jitted derivation reads it (``biso_plus_values``): the real
# parameters above, the declination, then what the record's other fields give (None as NaN,
# or -1 for the field norm, as in the coefficients), and the sample rate.
_V_INDEX = {name: i for i, name in enumerate((*_NON_NEGATIVE, *_POSITIVE, "declination_rad"))}
_V_N_NONNEG, _V_N_POS = len(_NON_NEGATIVE), len(_POSITIVE)
_V_DECL = len(_V_INDEX) - 1
_V_ORDER, _V_GATE_FREE, _V_BNORM, _V_DIP, _V_OFFSET = range(_V_DECL + 1, _V_DECL + 6)
_V_RV = _V_DECL + 6
_V_GRANGE, _V_ARANGE, _V_FS = _V_RV + 3, _V_RV + 4, _V_RV + 5
_V_SIZE = _V_FS + 1
_V_INDEX_TAU_ACC = _V_INDEX["tau_acc_s"]
_V_TAU_ACCV = _V_INDEX["tau_acc_speed_s"]
_V_KT = _V_INDEX["k_tilt"]
_V_KH = _V_INDEX["k_heading"]
_V_KP = _V_INDEX["k_p"]
_V_GATE = _V_INDEX["accel_gate"]
_V_BS_INIT = _V_INDEX["bias_sigma_init_rad_s"]
_V_B_FORGET = _V_INDEX["bias_forgetting_s"]
_V_BS_MOTION = _V_INDEX["bias_sigma_motion_rad_s"]
_V_B_HEAD = _V_INDEX["bias_heading_factor"]
_V_B_HEAD_FREE = _V_INDEX["bias_heading_factor_free"]
_V_BS_REST = _V_INDEX["bias_sigma_rest_rad_s"]
_V_BLIM = _V_INDEX["bias_limit_rad_s"]
_V_REST_T = _V_INDEX["rest_time_s"]
_V_REST_TAU = _V_INDEX["rest_filter_tau_s"]
_V_REST_W = _V_INDEX["rest_gyro_rad_s"]
_V_REST_A = _V_INDEX["rest_accel_mps2"]
_V_REST_V = _V_INDEX["rest_speed_mps"]
_V_BTOL = _V_INDEX["mag_norm_tol"]
_V_DTOL = _V_INDEX["mag_dip_tol_rad"]
_V_REJ = _V_INDEX["mag_reject_max_s"]
_V_TAU_FIELD = _V_INDEX["tau_field_s"]
_V_OFF_INTERVAL = _V_INDEX["mag_offset_interval_s"]
_V_OFF_SIGMA = _V_INDEX["mag_offset_sigma_ut"]
_V_TAU_OFF = _V_INDEX["tau_mag_offset_s"]
_V_MAG_NOISE = _V_INDEX["mag_noise_ut"]
_V_OFF_BIAS = _V_INDEX["mag_offset_bias_sigma_rad_s"]
_V_TAU_SPEED = _V_INDEX["tau_speed_s"]
_V_G = _V_INDEX["gravity_mps2"]
_V_HEAD_NOISE = _V_INDEX["mag_heading_noise_ut"]
_V_KAPPA = _V_INDEX["mag_disturbance_gain"]
_V_TAU_DIST = _V_INDEX["tau_mag_disturbance_s"]
_V_SKEW = _V_INDEX["mag_time_skew_s"]
_V_SLIP_A = _V_INDEX["speed_slip_accel_mps2"]
_V_SLIP_HOLD = _V_INDEX["speed_slip_hold_s"]
_V_REAR_SLIP = _V_INDEX["rear_slip_gradient_rad_per_g"]
_V_OTEST = _V_INDEX["mag_offset_test_angle_rad"]
_V_OSHRINK = _V_INDEX["mag_offset_shrink_ut"]
_V_LIN = _V_INDEX["linear_accel_mps2"]
_V_LIN_HOLD = _V_INDEX["linear_hold_s"]


_alpha_jit = jit(inline="always")(_alpha)
_butterworth2_jit = jit(inline="always")(_butterworth2)
_kalman_noise_jit = jit(inline="always")(_kalman_noise)


def biso_plus_values(p: BisoPlusParams, fs_hz: float) -> np.ndarray:
    """The parameter record ``p`` (one ``biso_plus_coefficients`` accepted) as the vector
    ``biso_plus_derive`` reads."""
    v = np.empty(_V_SIZE)
    for name, i in _V_INDEX.items():
        v[i] = float(getattr(p, name))
    v[_V_ORDER] = float(p.tilt_lp_order)
    v[_V_GATE_FREE] = np.nan if p.accel_gate_free is None else float(p.accel_gate_free)
    v[_V_BNORM] = -1.0 if p.field_norm_ut is None else float(p.field_norm_ut)
    v[_V_DIP] = np.nan if p.dip_rad is None else float(p.dip_rad)
    v[_V_OFFSET] = float(bool(p.estimate_mag_offset))
    v[_V_RV:_V_RV + 3] = np.asarray(p.speed_point_b_m, dtype=np.float64)
    v[_V_GRANGE], v[_V_ARANGE] = saturation_limits(p)
    v[_V_FS] = fs_hz
    return v


@jit(error_model="numpy")
def biso_plus_derive(v, c):
    """``biso_plus_coefficients`` in numba, from the vector of ``biso_plus_values``: the
    coefficients written into ``c`` (the same numbers bit for bit, tested), or, when a real
    parameter is not finite or out of its bounds, nothing written and its index in ``v``
    returned (-1: written). ``BisoPlusEstimator.retune``'s kernel (``Estimator.retune_kernel``)."""
    for i in range(_V_DECL + 1):
        x = v[i]
        if not math.isfinite(x) or (i < _V_N_NONNEG and x < 0.0) or (_V_N_NONNEG <= i < _V_DECL and x <= 0.0):
            return i
    fs_hz = v[_V_FS]
    h = 1.0 / fs_hz
    # squares as CPython computes x ** 2 (libm's pow): numba turns a constant exponent into
    # x * x, which can differ in the last bit; an exponent known only at run time stays pow
    two = 2.0 + 0.0 * fs_hz
    tau_acc = v[_V_INDEX_TAU_ACC]
    c[:] = 0.0
    c[_C_H] = h
    c[_C_A_ACC], c[_C_A_ACCV] = _alpha_jit(h, tau_acc), _alpha_jit(h, v[_V_TAU_ACCV])
    c[_C_KT], c[_C_KH], c[_C_KP], c[_C_GATE] = v[_V_KT], v[_V_KH], v[_V_KP], v[_V_GATE]
    c[_C_T0] = max(tau_acc, h)
    c[_C_BP0] = v[_V_BS_INIT] ** two
    c[_C_BV] = (0.1 * DEG) ** two * h / v[_V_B_FORGET]
    c[_C_BWM] = _kalman_noise_jit(v[_V_BS_MOTION], c[_C_BV])
    c[_C_BWV] = c[_C_BWM] / max(v[_V_B_HEAD], 1e-10)
    c[_C_BWVF] = c[_C_BWM] / max(v[_V_B_HEAD_FREE], 1e-10)
    c[_C_BWR] = _kalman_noise_jit(v[_V_BS_REST], c[_C_BV])
    c[_C_BLIM] = v[_V_BLIM]
    c[_C_REST_N], c[_C_A_REST] = v[_V_REST_T], _alpha_jit(h, v[_V_REST_TAU])
    c[_C_REST_W], c[_C_REST_A], c[_C_REST_V] = v[_V_REST_W], v[_V_REST_A], v[_V_REST_V]
    c[_C_BTOL], c[_C_DTOL], c[_C_REJ_N] = v[_V_BTOL], v[_V_DTOL], v[_V_REJ]
    c[_C_A_FIELD] = _alpha_jit(h, v[_V_TAU_FIELD])
    c[_C_BNORM] = v[_V_BNORM]
    c[_C_DIP] = v[_V_DIP]
    c[_C_OFFSET] = v[_V_OFFSET]
    c[_C_OFF_N] = max(1, int(round(v[_V_OFF_INTERVAL] * fs_hz)))
    dt_off = c[_C_OFF_N] * h
    c[_C_Q_OFFSET] = v[_V_OFF_SIGMA] ** two / v[_V_TAU_OFF] * dt_off
    c[_C_Q_FIELD] = _FIELD_WALK_UT2_PER_S * dt_off
    c[_C_R_MAG] = v[_V_MAG_NOISE] ** two
    c[_C_OFF_BIAS2] = v[_V_OFF_BIAS] ** two
    decl = v[_V_DECL]
    c[_C_DECL], c[_C_CDH], c[_C_SDH] = decl, math.cos(0.5 * decl), math.sin(0.5 * decl)
    c[_C_RV], c[_C_RV + 1], c[_C_RV + 2] = v[_V_RV], v[_V_RV + 1], v[_V_RV + 2]
    c[_C_A_SPEED] = _alpha_jit(h, v[_V_TAU_SPEED])
    c[_C_G] = v[_V_G]
    c[_C_GRANGE], c[_C_ARANGE] = v[_V_GRANGE], v[_V_ARANGE]
    c[_C_FS] = fs_hz
    c[_C_INV_GATE_G] = 1.0 / (c[_C_G] * c[_C_GATE])
    if not math.isnan(v[_V_DIP]):
        c[_C_DIP_C], c[_C_DIP_S] = math.cos(c[_C_DIP]), math.sin(c[_C_DIP])
    c[_C_COS_DTOL] = math.cos(c[_C_DTOL]) if c[_C_DTOL] < math.pi else -2.0
    if v[_V_ORDER] == 2.0 and tau_acc > 0.0:
        b0, b1, b2, a1, a2 = _butterworth2_jit(h, tau_acc)
        c[_C_BW], c[_C_BW + 1], c[_C_BW + 2], c[_C_BW + 3], c[_C_BW + 4] = b0, b1, b2, a1, a2
    c[_C_INV_GATE_FREE] = 0.0 if math.isnan(v[_V_GATE_FREE]) else 1.0 / (c[_C_G] * v[_V_GATE_FREE])
    c[_C_R_HEAD] = v[_V_HEAD_NOISE] ** two
    c[_C_KAPPA] = v[_V_KAPPA]
    c[_C_A_DIST] = _alpha_jit(h, v[_V_TAU_DIST])
    c[_C_TAU_M2] = v[_V_SKEW] ** two
    c[_C_SLIP_A], c[_C_SLIP_HOLD], c[_C_REAR_SLIP] = v[_V_SLIP_A], v[_V_SLIP_HOLD], v[_V_REAR_SLIP] / G0
    c[_C_INV_OTEST] = 0.0 if v[_V_OTEST] == 0.0 else 1.0 / v[_V_OTEST]
    c[_C_LIN2], c[_C_LIN_HOLD] = v[_V_LIN] * v[_V_LIN], v[_V_LIN_HOLD]
    c[_C_OFF_SHRINK2] = v[_V_OSHRINK] * v[_V_OSHRINK]
    return -1


def biso_plus_coefficients(p: BisoPlusParams, fs_hz: float) -> np.ndarray:
    """Validate ``p`` and derive the kernel's coefficients (raises ValueError / TypeError)."""
    h = 1.0 / fs_hz
    v = {}
    for name in _NON_NEGATIVE:
        v[name] = check_finite(name, getattr(p, name), low=0.0)
    for name in _POSITIVE:
        v[name] = check_finite(name, getattr(p, name), low=0.0, low_open=True)
    if not isinstance(p.estimate_mag_offset, (bool, np.bool_)):
        raise TypeError(f"estimate_mag_offset must be True or False, got {p.estimate_mag_offset!r}")
    rv = np.asarray(p.speed_point_b_m, dtype=np.float64)
    if rv.shape != (3,) or not np.all(np.isfinite(rv)):
        raise ValueError(f"speed_point_b_m must be 3 finite numbers (m, body axes), got {p.speed_point_b_m!r}")
    decl = check_finite("declination_rad", p.declination_rad)
    if p.tilt_lp_order not in (1, 2) or isinstance(p.tilt_lp_order, bool):
        raise ValueError(f"tilt_lp_order must be 1 or 2, got {p.tilt_lp_order!r}")
    gate_free = (None if p.accel_gate_free is None else
                 check_finite("accel_gate_free", p.accel_gate_free, low=0.0, low_open=True))

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
    c[_C_BWVF] = c[_C_BWM] / max(v["bias_heading_factor_free"], 1e-10)
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
    # without a speed input: the Butterworth low-pass (b0, b1, b2, a1, a2; all 0: first order), the
    # gate (0: none) and the heading variance σ_h² + κ D + (|B| |ω| τ_m)²
    if p.tilt_lp_order == 2 and v["tau_acc_s"] > 0.0:
        c[_C_BW:_C_BW + 5] = _butterworth2(h, v["tau_acc_s"])
    c[_C_INV_GATE_FREE] = 0.0 if gate_free is None else 1.0 / (c[_C_G] * gate_free)
    c[_C_R_HEAD] = v["mag_heading_noise_ut"] ** 2
    c[_C_KAPPA] = v["mag_disturbance_gain"]
    c[_C_A_DIST] = _alpha(h, v["tau_mag_disturbance_s"])
    c[_C_TAU_M2] = v["mag_time_skew_s"] ** 2
    c[_C_SLIP_A], c[_C_SLIP_HOLD] = v["speed_slip_accel_mps2"], v["speed_slip_hold_s"]
    c[_C_REAR_SLIP] = v["rear_slip_gradient_rad_per_g"] / G0  # rad per m/s²
    # the offset's norm test: 1/Θ_o (0: off, the offset always used)
    theta = v["mag_offset_test_angle_rad"]
    c[_C_INV_OTEST] = 0.0 if theta == 0.0 else 1.0 / theta
    # its shrink toward 0 while used: σ_s² (0: o whole)
    c[_C_OFF_SHRINK2] = v["mag_offset_shrink_ut"] * v["mag_offset_shrink_ut"]
    # the tyres' linear range: a_l² (0: no limit)
    c[_C_LIN2], c[_C_LIN_HOLD] = v["linear_accel_mps2"] * v["linear_accel_mps2"], v["linear_hold_s"]
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


@jit(error_model="numpy")
def _offset_update(c, st, mx, my, mz):
    """One Kalman step of m = R_Ibᵀ B_I + o for x = (B_I, o), random walks on both.

    R_Ib comes from the gyro strapdown q_I alone (``st`` holds q_I of this sample). The three
    components are processed as scalar updates; an innovation beyond 5σ (a magnet nearby)
    skips the component. Written out on the flat state: no reshape and no scratch array
    (it runs every ``offset_n``-th sample inside the kernel's loop).
    """
    qw, qx, qy, qz = st[_S_QI], st[_S_QI + 1], st[_S_QI + 2], st[_S_QI + 3]
    k = _S_P  # P (6×6, row-major, symmetric) at st[k + 6i + j]
    if st[_S_OFF_INIT] == 0.0:
        # start: B_I = R_Ib (m − o) with o ~ (0, σ_o² I): the field is known up to the offset
        st[_S_OFF_INIT] = 1.0
        st[_S_BI], st[_S_BI + 1], st[_S_BI + 2] = _qrot(qw, qx, qy, qz, mx, my, mz)
        r = _mat_from_q(qw, qx, qy, qz)
        so = st[k + 21]  # P[3, 3]
        for i in range(3):
            for j in range(3):
                st[k + 6 * i + j] = so if i == j else 0.0
                st[k + 6 * i + 3 + j] = -so * r[3 * i + j]
                st[k + 6 * (3 + j) + i] = -so * r[3 * i + j]
        return
    for i in range(3):
        st[k + 7 * i] += c[_C_Q_FIELD]
        st[k + 7 * (3 + i)] += c[_C_Q_OFFSET]
    meas = (mx, my, mz)
    for comp in range(3):
        ex = 1.0 if comp == 0 else 0.0
        ey = 1.0 if comp == 1 else 0.0
        ez = 1.0 if comp == 2 else 0.0
        rx, ry, rz = _qrot(qw, qx, qy, qz, ex, ey, ez)  # body axis `comp` in I: row of R_Ibᵀ
        # P hᵀ for h = (rx, ry, rz, e_comp) summed in the order of the row; the terms with the zero
        # entries of e_comp add exactly nothing (±0 to a sum that is not −0, having started at +0)
        e = k + 3 + comp  # P[0, 3 + comp]
        ph = (
            0.0 + st[k] * rx + st[k + 1] * ry + st[k + 2] * rz + st[e],
            0.0 + st[k + 6] * rx + st[k + 7] * ry + st[k + 8] * rz + st[e + 6],
            0.0 + st[k + 12] * rx + st[k + 13] * ry + st[k + 14] * rz + st[e + 12],
            0.0 + st[k + 18] * rx + st[k + 19] * ry + st[k + 20] * rz + st[e + 18],
            0.0 + st[k + 24] * rx + st[k + 25] * ry + st[k + 26] * rz + st[e + 24],
            0.0 + st[k + 30] * rx + st[k + 31] * ry + st[k + 32] * rz + st[e + 30],
        )
        den = c[_C_R_MAG] + rx * ph[0] + ry * ph[1] + rz * ph[2] + ph[3 + comp]
        r = meas[comp] - (rx * st[_S_BI] + ry * st[_S_BI + 1] + rz * st[_S_BI + 2] + st[_S_OFF + comp])
        if r * r > 25.0 * den:
            continue
        for i in range(3):
            st[_S_BI + i] += ph[i] * r / den
            st[_S_OFF + i] += ph[3 + i] * r / den
        # P ← P − (P hᵀ)(P hᵀ)ᵀ/den; P is exactly symmetric (so is every update), so the new
        # p_ij is also the new p_ji: the upper triangle, mirrored
        for i in range(6):
            for j in range(i, 6):
                v = st[k + 6 * i + j] - ph[i] * ph[j] / den
                st[k + 6 * i + j] = v
                st[k + 6 * j + i] = v


@jit(inline="always")
def _bias_update(bx, by, bz, p00, p01, p02, p11, p12, p22, hm, e0, e1, e2, w0, w1, w2, lim):
    """Kalman update of the gyro bias b̂ (covariance P, symmetric: its upper triangle):
    measurement e = H (b − b̂) + noise, noise diag(w), each e clipped to ±lim.

    ``hm`` is a 9-tuple (H row-major). Scalars in and out (the kernel keeps them in
    registers): returns (updated, b̂, P upper triangle); unchanged if S is not positive.
    """
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = hm
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
        return False, bx, by, bz, p00, p01, p02, p11, p12, p22
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
    bx = min(max(bx + (k00 * e0 + k01 * e1 + k02 * e2) * inv, -lim), lim)
    by = min(max(by + (k10 * e0 + k11 * e1 + k12 * e2) * inv, -lim), lim)
    bz = min(max(bz + (k20 * e0 + k21 * e1 + k22 * e2) * inv, -lim), lim)
    # P ← P − K (H P) = P − K Aᵀ
    return (True, bx, by, bz,
            p00 - (k00 * a00 + k01 * a01 + k02 * a02) * inv,
            p01 - (k00 * a10 + k01 * a11 + k02 * a12) * inv,
            p02 - (k00 * a20 + k01 * a21 + k02 * a22) * inv,
            p11 - (k10 * a10 + k11 * a11 + k12 * a12) * inv,
            p12 - (k10 * a20 + k11 * a21 + k12 * a22) * inv,
            p22 - (k20 * a20 + k21 * a21 + k22 * a22) * inv)


@jit
def _biso_plus_start(c, st, gx, gy, gz, ax, ay, az, fn, mx, my, mz, acc_ok, mag_ok, speed, speed_given):
    """First sample: the attitude (unless q0 was given) and every filter start from it."""
    fy = ay if acc_ok else 0.0  # the lateral specific force, before the centripetal part below
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
    v_ok = speed_given and math.isfinite(speed)
    st[_S_VOK] = 1.0 if v_ok else 0.0
    st[_S_VHELD] = speed if v_ok else 0.0
    st[_S_FXLP] = ax if acc_ok else 0.0
    st[_S_FYLP] = fy
    st[_S_VYPREV] = -c[_C_REAR_SLIP] * abs(speed) * fy if v_ok else 0.0


@jit(error_model="numpy")
def _biso_plus_batch(c, st, gyro, accel, mag, speed, imu_flags, q_out, flags_out, bias_out):
    """Advance the state over every row (the batch and the streaming paths are this loop);
    ``speed`` and ``imu_flags`` are empty when not given. Never raises.

    Until the first attitude is set, samples go through ``_biso_plus_start`` on the state
    array; then the state is held in local variables (registers: no stores and reloads of
    the state array between the steps of a sample, no reference counting of arrays passed to
    inlined helpers) and written back at the end. The offset filter (every ``offset_n``-th
    magnetometer sample) keeps its part of the state in the array."""
    n = gyro.shape[0]
    given = speed.shape[0] == n and n > 0
    has_flags = imu_flags.shape[0] == n
    grange, arange = c[_C_GRANGE], c[_C_ARANGE]

    # ---- until initialised: the attitude (unless q0 was given) and every filter start from the
    # first usable sample
    i0 = 0
    while i0 < n and st[_S_INIT] != 1.0:
        v = speed[i0] if given else np.nan
        sf = imu_flags[i0] if has_flags else 0
        ax, ay, az = accel[i0, 0], accel[i0, 1], accel[i0, 2]
        mx, my, mz = mag[i0, 0], mag[i0, 1], mag[i0, 2]
        flags, gx, gy, gz, acc_ok, f2, mag_ok, _, _, _, _ = _input_checks(
            gyro[i0, 0], gyro[i0, 1], gyro[i0, 2], ax, ay, az, mx, my, mz,
            st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2], sf, grange, arange)
        st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2] = gx, gy, gz
        if st[_S_INIT] == 0.0 and not acc_ok:
            flags |= fl.UNINITIALIZED
        else:
            _biso_plus_start(c, st, gx, gy, gz, ax, ay, az, math.sqrt(f2), mx, my, mz, acc_ok, mag_ok, v, given)
        flags_out[i0] = flags
        for k in range(4):
            q_out[i0, k] = st[_S_LAM + k]
        for k in range(3):
            bias_out[i0, k] = st[_S_BIAS + k]
        i0 += 1
    if i0 >= n:
        return

    # ---- coefficients
    h, fs = c[_C_H], c[_C_FS]
    a_acc, a_accv, a_v, ar, af = c[_C_A_ACC], c[_C_A_ACCV], c[_C_A_SPEED], c[_C_A_REST], c[_C_A_FIELD]
    dx, dy, dz = -c[_C_RV], -c[_C_RV + 1], -c[_C_RV + 2]  # d = −r_v
    thw = c[_C_REST_W]
    thw2, tha2 = thw * thw, c[_C_REST_A] * c[_C_REST_A]
    rest_n, rest_v = c[_C_REST_N], c[_C_REST_V]
    g, inv_gate_g = c[_C_G], c[_C_INV_GATE_G]
    offset_on, off_bias2, off_n = c[_C_OFFSET] != 0.0, c[_C_OFF_BIAS2], c[_C_OFF_N]
    inv_otest, off_shrink2 = c[_C_INV_OTEST], c[_C_OFF_SHRINK2]
    c_bnorm, c_dip, c_dipc, c_dips = c[_C_BNORM], c[_C_DIP], c[_C_DIP_C], c[_C_DIP_S]
    learn_norm, learn_dip = c_bnorm < 0.0, math.isnan(c_dip)
    btol, cos_dtol, rej_n = c[_C_BTOL], c[_C_COS_DTOL], c[_C_REJ_N]
    # (cos D, sin D): the horizontal field turned by −D
    cd = c[_C_CDH] * c[_C_CDH] - c[_C_SDH] * c[_C_SDH]
    sd = 2.0 * c[_C_SDH] * c[_C_CDH]
    kt, kh0, kp, t0 = c[_C_KT], c[_C_KH], c[_C_KP], c[_C_T0]
    bp0, bv, bwm, bwv, bwr, blim = c[_C_BP0], c[_C_BV], c[_C_BWM], c[_C_BWV], c[_C_BWR], c[_C_BLIM]
    bwvf = c[_C_BWVF]
    bw_b0, bw_b1, bw_b2, bw_a1, bw_a2 = c[_C_BW], c[_C_BW + 1], c[_C_BW + 2], c[_C_BW + 3], c[_C_BW + 4]
    bw_on = bw_b0 != 0.0
    inv_gate_free = c[_C_INV_GATE_FREE]
    r_head, kappa, a_dist, tau_m2 = c[_C_R_HEAD], c[_C_KAPPA], c[_C_A_DIST], c[_C_TAU_M2]
    slip_a, slip_hold, rear_slip = c[_C_SLIP_A], c[_C_SLIP_HOLD], c[_C_REAR_SLIP]
    lin2, lin_hold = c[_C_LIN2], c[_C_LIN_HOLD]
    lin_on = lin2 > 0.0

    # ---- state into locals
    lw, lx, ly, lz = st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3]
    qiw, qix, qiy, qiz = st[_S_QI], st[_S_QI + 1], st[_S_QI + 2], st[_S_QI + 3]
    qcw, qcx, qcy, qcz = st[_S_QC], st[_S_QC + 1], st[_S_QC + 2], st[_S_QC + 3]
    bx, by, bz = st[_S_BIAS], st[_S_BIAS + 1], st[_S_BIAS + 2]
    j = _S_BP
    p00, p01, p02, p10, p11, p12, p20, p21, p22 = (st[j], st[j + 1], st[j + 2], st[j + 3], st[j + 4], st[j + 5],
                                                   st[j + 6], st[j + 7], st[j + 8])
    flp0, flp1, flp2 = st[_S_FLP], st[_S_FLP + 1], st[_S_FLP + 2]
    j = _S_RLP
    rlp0, rlp1, rlp2, rlp3, rlp4, rlp5, rlp6, rlp7, rlp8 = (st[j], st[j + 1], st[j + 2], st[j + 3], st[j + 4],
                                                            st[j + 5], st[j + 6], st[j + 7], st[j + 8])
    rblp0, rblp1, rblp2 = st[_S_RBLP], st[_S_RBLP + 1], st[_S_RBLP + 2]
    hgx, hgy, hgz = st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2]
    wl0, wl1, wl2 = st[_S_WLP], st[_S_WLP + 1], st[_S_WLP + 2]
    al0, al1, al2 = st[_S_ALP], st[_S_ALP + 1], st[_S_ALP + 2]
    rest_t, vprev, dvdt, vok_prev = st[_S_REST_T], st[_S_VPREV], st[_S_DVDT], st[_S_VOK]
    wpx, wpy, wpz = st[_S_WPREV], st[_S_WPREV + 1], st[_S_WPREV + 2]
    wdx, wdy, wdz = st[_S_WDOT], st[_S_WDOT + 1], st[_S_WDOT + 2]
    ox, oy, oz = st[_S_OFF], st[_S_OFF + 1], st[_S_OFF + 2]
    off_k, bnorm, dip, field_ok, rej_t = st[_S_OFF_K], st[_S_BNORM], st[_S_DIP], st[_S_FIELD_OK], st[_S_REJ_T]
    dipc, dips = st[_S_DIP_CS], st[_S_DIP_CS + 1]
    t = st[_S_TIME]
    j = _S_BW
    bs0, bs1, bs2, bs3, bs4, bs5 = st[j], st[j + 1], st[j + 2], st[j + 3], st[j + 4], st[j + 5]
    bw_ok, mdist, head_t = st[_S_BW_OK], st[_S_MDIST], st[_S_HEAD_T]
    tcx, tcy = st[_S_TILT_CORR], st[_S_TILT_CORR + 1]
    slip_t, vheld, fxlp, fylp = st[_S_SLIP_T], st[_S_VHELD], st[_S_FXLP], st[_S_FYLP]
    vyprev, dvydt = st[_S_VYPREV], st[_S_DVYDT]
    lim_t = st[_S_LIM_T]
    dtol2 = c[_C_DTOL] * c[_C_DTOL]

    # from 0, the samples of the start skipped: an index known to be non-negative needs no
    # wraparound of negative indices at each array access
    for i in range(n):
        if i < i0:
            continue
        v = speed[i] if given else np.nan
        sf = imu_flags[i] if has_flags else 0
        ax, ay, az = accel[i, 0], accel[i, 1], accel[i, 2]
        mx, my, mz = mag[i, 0], mag[i, 1], mag[i, 2]
        flags, gx, gy, gz, acc_ok, f2, mag_ok, _, _, _, _ = _input_checks(
            gyro[i, 0], gyro[i, 1], gyro[i, 2], ax, ay, az, mx, my, mz, hgx, hgy, hgz, sf, grange, arange)
        hgx, hgy, hgz = gx, gy, gz
        t += h

        # ---- gyro: bias-corrected strapdown of q_I over the interval (held rate)
        wx, wy, wz = gx - bx, gy - by, gz - bz
        eb0, eb1, eb2, eb3 = _qexp_fast(wx * h, wy * h, wz * h)
        # |q ∘ e| = |q| for a unit e: the normalisation factor comes from q before the product,
        # in parallel with e^{bh}, not after it on the chain of dependent operations
        qiw, qix, qiy, qiz = _unit(qiw, qix, qiy, qiz)
        qiw, qix, qiy, qiz = _qmul(qiw, qix, qiy, qiz, eb0, eb1, eb2, eb3)
        lw, lx, ly, lz = _qmul(qcw, qcx, qcy, qcz, qiw, qix, qiy, qiz)

        # ---- speed: acceleration of the IMU from the speed v of the point r_v of the vehicle
        wdx += a_v * ((wx - wpx) * fs - wdx)
        wdy += a_v * ((wy - wpy) * fs - wdy)
        wdz += a_v * ((wz - wpz) * fs - wdz)
        wpx, wpy, wpz = wx, wy, wz
        v_ok = given and math.isfinite(v)
        comp_x = comp_y = comp_z = 0.0
        if acc_ok:
            fxlp += a_v * (ax - fxlp)
            if rear_slip != 0.0 or lin_on:
                fylp += a_v * (ay - fylp)
        slipping = False
        limited = False
        a_fwd = 0.0
        vu = v  # the speed of r_v used: the input's, or carried on through a wheel's slip
        if v_ok:
            if vok_prev != 0.0:
                dvdt += a_v * ((v - vprev) * fs - dvdt)
            vprev = v
            # a wheel that does not roll on the road: its v̇ is not what the accelerometer feels
            if abs(dvdt - fxlp) > slip_a:
                slip_t = slip_hold
                slipping = True
            elif slip_t > 0.0:
                slip_t -= h
                slipping = slip_t > 0.0
            if slipping:
                # the vehicle's speed carried on by the IMU's forward acceleration f_x − g R̂ᵀe_z·e_x
                a_fwd = ax - g * 2.0 * (lx * lz - lw * ly) if acc_ok else 0.0
                vheld += h * a_fwd
                vu = vheld
                flags |= fl.ACCEL_GATED
            else:
                vheld = v
            # beyond the tyres' linear range (the horizontal specific force is the tyres' force per
            # mass): the sideslip and the odometry are not the model's; the tilt is the gyro's
            if lin_on:
                if fxlp * fxlp + fylp * fylp > lin2:
                    lim_t = lin_hold
                    limited = True
                elif lim_t > 0.0:
                    lim_t -= h
                    limited = lim_t > 0.0
            # IMU velocity u = (v, v_y, 0) + ω × d, d = −r_v; acceleration u̇ + ω × u
            ux, uy, uz = vu + wy * dz - wz * dy, wz * dx - wx * dz, wx * dy - wy * dx
            if rear_slip != 0.0:
                # the axle's sideslip: slip angle D_r f_y (single-track model), outward of the bend
                vy = -rear_slip * abs(vu) * fylp
                if vok_prev != 0.0:
                    dvydt += a_v * ((vy - vyprev) * fs - dvydt)
                vyprev = vy
                uy += vy
            if slipping:  # the estimate's own gravity along x: no say in the tilt
                comp_x = a_fwd
            else:
                comp_x = dvdt + (wdy * dz - wdz * dy) + (wy * uz - wz * uy)
            comp_y = (wdz * dx - wdx * dz) + (wz * ux - wx * uz)
            if rear_slip != 0.0:
                comp_y += dvydt
            comp_z = (wdx * dy - wdy * dx) + (wx * uy - wy * ux)
            flags |= fl.ACCEL_COMPENSATED
        vok_prev = 1.0 if v_ok else 0.0

        # ---- rest detection (steady gyro and accelerometer; with speed: standing still)
        wl0 = wl0 + ar * (gx - wl0)
        wl1 = wl1 + ar * (gy - wl1)
        wl2 = wl2 + ar * (gz - wl2)
        rest = False
        if acc_ok:
            al0 = al0 + ar * (ax - al0)
            al1 = al1 + ar * (ay - al1)
            al2 = al2 + ar * (az - al2)
            dw2 = (gx - wl0) ** 2 + (gy - wl1) ** 2 + (gz - wl2) ** 2
            da2 = (ax - al0) ** 2 + (ay - al1) ** 2 + (az - al2) ** 2
            still = dw2 < thw2 and da2 < tha2
            if still:
                # not turning either: the bias-corrected rate within the threshold plus 3σ of the bias
                thr = thw + 3.0 * math.sqrt(max(p00, p11, p22))
                rw2 = (wl0 - bx) ** 2 + (wl1 - by) ** 2 + (wl2 - bz) ** 2
                still = rw2 < thr * thr
            if v_ok:
                still = still and abs(vu) < rest_v
            rest_t = rest_t + h if still else 0.0
            rest = rest_t >= rest_n
        if rest:
            flags |= fl.REST

        # ---- tilt error: low-pass of the (compensated) specific force in I, gated
        ex = ey = ez = 0.0  # rotation-vector error of the estimate, world frame
        mag_w = 1.0  # weight of the heading correction (1: k_h as it is)
        if acc_ok:
            if v_ok:
                fx, fy, fz = ax - comp_x, ay - comp_y, az - comp_z
                fnorm = math.sqrt(fx * fx + fy * fy + fz * fz)
            else:  # (f − 0 = f, and |f|² is the input check's)
                fx, fy, fz, fnorm = ax, ay, az, math.sqrt(f2)
            d = abs(fnorm - g) * (inv_gate_g if v_ok else inv_gate_free)
            weight = 1.0 / (1.0 + d * d)
            if limited:
                weight = 0.0
            if weight < 0.5:
                flags |= fl.ACCEL_GATED
            alpha = a_accv if v_ok else a_acc
            start = h > alpha * (t + h)
            if start:  # start: a running mean (as VQF), α = max(α, h/(t + h))
                alpha = h / (t + h)
            fix, fiy, fiz = _qrot(qiw, qix, qiy, qiz, fx, fy, fz)
            if bw_on and not (v_ok or start):
                # second order (without a speed input, after the start), transposed direct form II
                # (bs0..2 and bs3..5: its two delays per axis), entered from the first-order
                # output it continues at that output's steady state
                if bw_ok == 0.0:
                    bw_ok = 1.0
                    bs0, bs1, bs2 = (1.0 - bw_b0) * flp0, (1.0 - bw_b0) * flp1, (1.0 - bw_b0) * flp2
                    bs3, bs4, bs5 = (bw_b2 - bw_a2) * flp0, (bw_b2 - bw_a2) * flp1, (bw_b2 - bw_a2) * flp2
                if weight < 1.0:  # gated: the input moved toward the output by the weight
                    fix = flp0 + weight * (fix - flp0)
                    fiy = flp1 + weight * (fiy - flp1)
                    fiz = flp2 + weight * (fiz - flp2)
                flp0 = bw_b0 * fix + bs0
                flp1 = bw_b0 * fiy + bs1
                flp2 = bw_b0 * fiz + bs2
                bs0 = bw_b1 * fix - bw_a1 * flp0 + bs3
                bs1 = bw_b1 * fiy - bw_a1 * flp1 + bs4
                bs2 = bw_b1 * fiz - bw_a1 * flp2 + bs5
                bs3 = bw_b2 * fix - bw_a2 * flp0
                bs4 = bw_b2 * fiy - bw_a2 * flp1
                bs5 = bw_b2 * fiz - bw_a2 * flp2
            else:
                bw_ok = 0.0
                alpha *= weight
                flp0 = flp0 + alpha * (fix - flp0)
                flp1 = flp1 + alpha * (fiy - flp1)
                flp2 = flp2 + alpha * (fiz - flp2)
            nx, ny, nz = _qrot(qcw, qcx, qcy, qcz, flp0, flp1, flp2)
            ang = _angle_over_sine(nx * nx + ny * ny, nz)
            ex, ey = ny * ang, -nx * ang  # rotate about n × up by the angle between n and up

        # ---- heading error from the magnetometer (offset removed), disturbance detection
        if mag_ok:
            # the offset is learned once the gyro bias is known (an unknown bias turns the I frame
            # and would pass for an offset); its own innovation gate rejects magnets, so the
            # norm/dip test below (which a wrong offset upsets) does not gate it
            if offset_on and max(p00, p11, p22) < off_bias2:
                off_k += 1.0
                if off_k >= off_n:
                    off_k = 0.0
                    st[_S_QI], st[_S_QI + 1], st[_S_QI + 2], st[_S_QI + 3] = qiw, qix, qiy, qiz
                    _offset_update(c, st, mx, my, mz)
                    ox, oy, oz = st[_S_OFF], st[_S_OFF + 1], st[_S_OFF + 2]
            if inv_otest != 0.0 and offset_on and not v_ok:
                # the offset's norm test (without a speed input): the variances of |m − o| and |m|
                # about their means, low-passed over the last Θ_o of rotation (α = |ω| h/Θ_o), and
                # o used only while it makes the norm steadier
                a_ot = min(1.0, math.sqrt(wx * wx + wy * wy + wz * wz) * h * inv_otest)
                n0 = math.sqrt(mx * mx + my * my + mz * mz)
                dmx, dmy, dmz = mx - ox, my - oy, mz - oz
                n1 = math.sqrt(dmx * dmx + dmy * dmy + dmz * dmz)
                j = _S_OTEST
                if st[j] == 0.0:  # the first field: both means from it
                    st[j], st[j + 2] = n1, n0
                st[j] += a_ot * (n1 - st[j])
                d1 = n1 - st[j]
                st[j + 1] += a_ot * (d1 * d1 - st[j + 1])
                st[j + 2] += a_ot * (n0 - st[j + 2])
                d0 = n0 - st[j + 2]
                st[j + 3] += a_ot * (d0 * d0 - st[j + 3])
                if st[j + 1] < st[j + 3]:
                    if off_shrink2 > 0.0:  # shrunk toward 0 by |o|²/(|o|² + σ_s²)
                        o2 = ox * ox + oy * oy + oz * oz
                        sh = o2 / (o2 + off_shrink2)
                        dmx, dmy, dmz = mx - sh * ox, my - sh * oy, mz - sh * oz
                    mwx, mwy, mwz = _qrot(lw, lx, ly, lz, dmx, dmy, dmz)
                else:
                    mwx, mwy, mwz = _qrot(lw, lx, ly, lz, mx, my, mz)
            else:
                mwx, mwy, mwz = _qrot(lw, lx, ly, lz, mx - ox, my - oy, mz - oz)
            mh = math.sqrt(mwx * mwx + mwy * mwy)
            norm = math.sqrt(mh * mh + mwz * mwz)
            if field_ok == 2.0 and tcx * tcx + tcy * tcy > dtol2:
                # provisional, and the tilt corrected by more than θ_δ since (the start's tilt was
                # off by that: the dip and the heading measured with it too): learn both again
                field_ok = 0.0
                head_t = t
                tcx = tcy = 0.0
            if field_ok == 0.0:
                bnorm = norm if learn_norm else c_bnorm
                if learn_dip:
                    dip = math.atan2(-mwz, mh)
                    dipc, dips = (mh / norm, -mwz / norm) if norm > 0.0 else (1.0, 0.0)
                else:
                    dip, dipc, dips = c_dip, c_dipc, c_dips
                # learned before the tilt has settled (the start): provisional (2), since its dip
                # was measured with that tilt
                field_ok = 1.0 if t >= t0 else 2.0
            # the dip δ_m = atan2(−m_U, m_H) against the expected δ: norm·(cos, sin)(δ_m − δ) from
            # (cos δ, sin δ) in the state, without an arctangent of the large dip angle
            c0, s0 = dipc, dips
            dcos = mh * c0 - mwz * s0
            dsin = -mwz * c0 - mh * s0
            if not v_ok:
                # the heading's variance: σ_h² + κ D, D = LP[(|m − o| − |B|)²] (a magnet changes the
                # norm), + (|B| |ω| τ_m)² (the field's time skew under rotation); its weight σ_h²/…
                dn = norm - bnorm
                mdist += a_dist * (dn * dn - mdist)
                mag_w = r_head / (r_head + kappa * mdist + bnorm * bnorm * (wx * wx + wy * wy + wz * wz) * tau_m2)
            if abs(norm - bnorm) > btol * bnorm or dcos < cos_dtol * norm:
                flags |= fl.MAG_DISTURBED
                rej_t += h
                # disturbed for too long, or a provisional field (the dip of an accelerated start's
                # tilt, not of the field): take the present field as the new one
                if rej_t > rej_n or field_ok == 2.0:
                    if field_ok == 2.0:  # and the heading of the start with it: its start again
                        head_t = t
                        tcx = tcy = 0.0
                    field_ok = 0.0
                    rej_t = 0.0
            else:
                rej_t = 0.0
                if field_ok == 2.0 and t >= t0:  # passed with the settled tilt: confirmed
                    field_ok = 1.0
                if learn_norm:
                    bnorm += af * (norm - bnorm)
                if learn_dip:  # δ += α(δ_m − δ), and (cos δ, sin δ) turned with it
                    e = af * _atan2(dsin, dcos)
                    dip += e
                    ce, se = 1.0 - 0.5 * e * e, e * (1.0 - e * e * (1.0 / 6.0))
                    dipc, dips = c0 * ce - s0 * se, s0 * ce + c0 * se
                if mh > 0.0:
                    # the field's azimuth (clockwise from north) minus D, from the horizontal field
                    # turned by −D; turning the estimate about Up by it brings the field to D
                    ez = _atan2(mwx * cd - mwy * sd, mwy * cd + mwx * sd)

        # ---- the correction ω_c = K ε + k_p n × ε as a rotation of q_c (world frame)
        kh = kh0
        # start: heading follows the settling tilt, k_h = max(k_h, 1/(t − t_h + t_w)): from t_h = 0
        # the first attitude counts as t_w = t0 of measurements (as in the tilt); from a t_h > 0,
        # when a provisional field was replaced, the heading held was measured with a wrong tilt
        # and counts as one sample (t_w = h): a running mean of the heading from t_h
        tw = t0 if head_t == 0.0 else h
        head_start = kh * ((t - head_t) + tw) < 1.0
        if head_start:
            kh = 1.0 / ((t - head_t) + tw)
        if mag_w != 1.0:
            kh *= mag_w
        if kp == 0.0:  # the default: the cross-link terms are ±0 and change no sum
            ux, uy, uz = kt * ex, kt * ey, kh * ez
        else:
            ux = kt * ex + kp * (ez - ey)
            uy = kt * ey + kp * (ex - ez)
            uz = kh * ez + kp * (ey - ex)
        if field_ok == 2.0:  # the tilt correction since the provisional field was learned (world x, y)
            tcx += ux * h
            tcy += uy * h
        if ux != 0.0 or uy != 0.0 or uz != 0.0:
            dq0, dq1, dq2, dq3 = _qexp_fast(ux * h, uy * h, uz * h)
            qcw, qcx, qcy, qcz = _unit(qcw, qcx, qcy, qcz)  # (as for q_I: off the chain)
            qcw, qcx, qcy, qcz = _qmul(dq0, dq1, dq2, dq3, qcw, qcx, qcy, qcz)
            lw, lx, ly, lz = _qmul(qcw, qcx, qcy, qcz, qiw, qix, qiy, qiz)

        # ---- gyro bias: Kalman filter (VQF): the correction rate seen through the tilt low-pass
        if p00 < bp0:
            p00 += bv
        if p11 < bp0:
            p11 += bv
        if p22 < bp0:
            p22 += bv
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = _mat_from_q(lw, lx, ly, lz)  # body → world
        alpha = a_accv if v_ok else a_acc
        rlp0 = rlp0 + alpha * (r0 - rlp0)
        rlp1 = rlp1 + alpha * (r1 - rlp1)
        rlp2 = rlp2 + alpha * (r2 - rlp2)
        rlp3 = rlp3 + alpha * (r3 - rlp3)
        rlp4 = rlp4 + alpha * (r4 - rlp4)
        rlp5 = rlp5 + alpha * (r5 - rlp5)
        rlp6 = rlp6 + alpha * (r6 - rlp6)
        rlp7 = rlp7 + alpha * (r7 - rlp7)
        rlp8 = rlp8 + alpha * (r8 - rlp8)
        rblp0 = rblp0 + alpha * ((r0 * bx + r1 * by + r2 * bz) - rblp0)
        rblp1 = rblp1 + alpha * ((r3 * bx + r4 * by + r5 * bz) - rblp1)
        rblp2 = rblp2 + alpha * ((r6 * bx + r7 * by + r8 * bz) - rblp2)
        updated = False
        if rest:
            updated, bx, by, bz, p00, p01, p02, p11, p12, p22 = _bias_update(
                bx, by, bz, p00, p01, p02, p11, p12, p22, (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
                wl0 - bx, wl1 - by, wl2 - bz, bwr, bwr, bwr, blim)
        elif acc_ok and t > t0:  # not during the start, while the low-pass settles
            e0 = rblp0 - (rlp0 * bx + rlp1 * by + rlp2 * bz) - ux
            e1 = rblp1 - (rlp3 * bx + rlp4 * by + rlp5 * bz) - uy
            e2 = rblp2 - (rlp6 * bx + rlp7 * by + rlp8 * bz) - uz
            if v_ok:
                wv = bwv if ez != 0.0 else bwv * 1e6
            else:  # the heading's variance (1/mag_w), and not its start's convergence
                wv = bwvf / mag_w if ez != 0.0 and not head_start else bwvf * 1e6
            updated, bx, by, bz, p00, p01, p02, p11, p12, p22 = _bias_update(
                bx, by, bz, p00, p01, p02, p11, p12, p22, (rlp0, rlp1, rlp2, rlp3, rlp4, rlp5, rlp6, rlp7, rlp8),
                e0, e1, e2, bwm, bwm, wv, blim)
        if updated:
            p10, p20, p21 = p01, p02, p12

        lw, lx, ly, lz = _unit(lw, lx, ly, lz)
        flags_out[i] = flags
        q_out[i, 0], q_out[i, 1], q_out[i, 2], q_out[i, 3] = lw, lx, ly, lz
        bias_out[i, 0], bias_out[i, 1], bias_out[i, 2] = bx, by, bz

    # ---- locals back into the state
    st[_S_LAM], st[_S_LAM + 1], st[_S_LAM + 2], st[_S_LAM + 3] = lw, lx, ly, lz
    st[_S_QI], st[_S_QI + 1], st[_S_QI + 2], st[_S_QI + 3] = qiw, qix, qiy, qiz
    st[_S_QC], st[_S_QC + 1], st[_S_QC + 2], st[_S_QC + 3] = qcw, qcx, qcy, qcz
    st[_S_BIAS], st[_S_BIAS + 1], st[_S_BIAS + 2] = bx, by, bz
    j = _S_BP
    st[j], st[j + 1], st[j + 2], st[j + 3], st[j + 4] = p00, p01, p02, p10, p11
    st[j + 5], st[j + 6], st[j + 7], st[j + 8] = p12, p20, p21, p22
    st[_S_FLP], st[_S_FLP + 1], st[_S_FLP + 2] = flp0, flp1, flp2
    j = _S_RLP
    st[j], st[j + 1], st[j + 2], st[j + 3], st[j + 4] = rlp0, rlp1, rlp2, rlp3, rlp4
    st[j + 5], st[j + 6], st[j + 7], st[j + 8] = rlp5, rlp6, rlp7, rlp8
    st[_S_RBLP], st[_S_RBLP + 1], st[_S_RBLP + 2] = rblp0, rblp1, rblp2
    st[_S_GYRO], st[_S_GYRO + 1], st[_S_GYRO + 2] = hgx, hgy, hgz
    st[_S_WLP], st[_S_WLP + 1], st[_S_WLP + 2] = wl0, wl1, wl2
    st[_S_ALP], st[_S_ALP + 1], st[_S_ALP + 2] = al0, al1, al2
    st[_S_REST_T], st[_S_VPREV], st[_S_DVDT], st[_S_VOK] = rest_t, vprev, dvdt, vok_prev
    st[_S_WPREV], st[_S_WPREV + 1], st[_S_WPREV + 2] = wpx, wpy, wpz
    st[_S_WDOT], st[_S_WDOT + 1], st[_S_WDOT + 2] = wdx, wdy, wdz
    st[_S_OFF_K], st[_S_BNORM], st[_S_DIP], st[_S_FIELD_OK], st[_S_REJ_T] = off_k, bnorm, dip, field_ok, rej_t
    st[_S_DIP_CS], st[_S_DIP_CS + 1] = dipc, dips
    st[_S_TIME] = t
    j = _S_BW
    st[j], st[j + 1], st[j + 2], st[j + 3], st[j + 4], st[j + 5] = bs0, bs1, bs2, bs3, bs4, bs5
    st[_S_BW_OK], st[_S_MDIST], st[_S_HEAD_T] = bw_ok, mdist, head_t
    st[_S_TILT_CORR], st[_S_TILT_CORR + 1] = tcx, tcy
    st[_S_SLIP_T], st[_S_VHELD], st[_S_FXLP], st[_S_FYLP] = slip_t, vheld, fxlp, fylp
    st[_S_VYPREV], st[_S_DVYDT] = vyprev, dvydt
    st[_S_LIM_T] = lim_t


@jit
def _biso_plus_loop(arrays, samples):
    """biso_plus on a period's samples (``biso_cosim.loop``): ``update`` with the wheel
    odometry as ``speed_mps`` and the sensor's flags as ``imu_flags``."""
    k = samples.gyro_b.shape[0]
    _biso_plus_batch(arrays.coef, arrays.state, samples.gyro_b, samples.accel_b, samples.mag_b, samples.speed_mps,
                     samples.imu_flags, arrays.q_wb[:k], arrays.flags[:k], arrays.gyro_bias_b[:k])


class BisoPlusEstimator(Estimator):
    """biso_plus (see the module docstring). Optional per-sample input: ``speed_mps`` (k,),
    the vehicle's forward speed at ``speed_point_b_m`` (wheel odometry or GNSS); NaN = unknown."""

    method = "biso_plus"
    Params = BisoPlusParams
    state_layout = STATE_LAYOUT
    inputs = ("speed_mps", "imu_flags")
    vehicle_params = ("speed_point_b_m", "rear_slip_gradient_rad_per_g", "linear_accel_mps2")
    estimates_bias = True
    loop_kernel = _biso_plus_loop
    retune_kernel = biso_plus_derive
    retune_index = _V_INDEX

    def retune_values(self, params: BisoPlusParams) -> np.ndarray:
        return biso_plus_values(params, self.fs_hz)

    def _coefficients(self, params: BisoPlusParams, fs_hz: float) -> np.ndarray:
        return biso_plus_coefficients(params, fs_hz)

    def _initial_state(self, q0: np.ndarray | None) -> np.ndarray:
        return biso_plus_initial_state(q0, self._params)

    def _run(self, coef, state, gyro, accel, mag, extra, q_out, flags, bias) -> None:
        _biso_plus_batch(coef, state, gyro, accel, mag, extra["speed_mps"], extra["imu_flags"], q_out, flags, bias)
