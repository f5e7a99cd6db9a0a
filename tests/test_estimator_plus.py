"""biso_plus: acceleration compensation, bias, magnetic disturbances and offset, the unbiased
cross-link (against the biased faithful one), and the DCM PI baseline."""

import math

import numpy as np
import pytest

from biso_cosim import frames as fr
from biso_cosim import motions as mo
from biso_cosim.estimators import estimate_attitude, flags as fl, make_estimator
from biso_cosim.metrics import angle_errors_deg


def _tilt_deg(q, q_true):
    e = angle_errors_deg(q, q_true)
    return np.hypot(e["roll"], e["pitch"])


def test_speed_compensation_removes_the_turn_tilt():
    """Circle at 10 m/s, R = 30 m (0.34 g): faithful BISO tilts by about a/g, biso_plus with
    speed does not, and without speed it cannot know (it tilts, less than the faithful one)."""
    m = mo.make_motion("circle", 30.0, 200.0)
    a_over_g = math.degrees(math.atan2(10.0 ** 2 / 30.0, 9.80665))
    late = slice(int(20 * 200), None)
    plus = make_estimator("biso_plus", 200.0).update(m.omega_b, m.specific_force_b, m.mag_b,
                                                     speed_mps=m.info["speed_mps"])
    assert np.all(plus.flags[1:] & fl.ACCEL_COMPENSATED)
    assert np.max(_tilt_deg(plus.q_wb, m.q_wb)[late]) < 0.05
    biso = estimate_attitude(m.omega_b, m.specific_force_b, m.mag_b, 200.0, "biso")
    assert np.mean(_tilt_deg(biso, m.q_wb)[late]) == pytest.approx(a_over_g, rel=0.05)
    blind = estimate_attitude(m.omega_b, m.specific_force_b, m.mag_b, 200.0, "biso_plus")
    assert 0.5 < np.mean(_tilt_deg(blind, m.q_wb)[late]) < a_over_g


def test_lever_arm_of_the_speed_point():
    """Speed measured 2 m behind the IMU (a rear axle without sideslip): the IMU moves sideways
    at ω × d; with speed_point_b_m the compensation is exact again."""
    m = mo.make_motion("circle", 25.0, 200.0, speed_mps=8.0, radius_m=20.0, imu_ahead_m=2.0)
    late = slice(int(15 * 200), None)
    args = (m.omega_b, m.specific_force_b, m.mag_b)
    with_arm = make_estimator("biso_plus", 200.0, speed_point_b_m=m.info["speed_point_b_m"]).update(
        *args, speed_mps=m.info["speed_mps"])
    without = make_estimator("biso_plus", 200.0).update(*args, speed_mps=m.info["speed_mps"])
    assert np.max(_tilt_deg(with_arm.q_wb, m.q_wb)[late]) < 0.05
    assert np.mean(_tilt_deg(without.q_wb, m.q_wb)[late]) > 0.5


def test_gyro_bias_is_learned_at_rest_and_in_motion():
    bias = np.array([0.02, -0.015, 0.01])  # rad/s (about 1 °/s)
    m = mo.make_motion("static", 20.0, 200.0)
    out = make_estimator("biso_plus", 200.0).update(m.omega_b + bias, m.specific_force_b, m.mag_b)
    assert np.any(out.flags & fl.REST)
    np.testing.assert_allclose(out.gyro_bias_b[-1], bias, atol=2e-4)
    m = mo.make_motion("tumble", 60.0, 200.0, rate_scale=0.5)
    out = make_estimator("biso_plus", 200.0).update(m.omega_b + bias, m.specific_force_b, m.mag_b)
    assert not np.any(out.flags & fl.REST)
    # in motion the bias filter is deliberately slow (VQF's tuning): more than half learned;
    # the residual bias turns the heading until the slow magnetometer correction (k_heading =
    # 0.05/s, chosen for vehicles) holds it (2.05° at the end: the exact field's norm is constant,
    # so the 0.24 µT offset the filter took from the residual bias is not used; 1.95° with it)
    assert np.linalg.norm(out.gyro_bias_b[-1] - bias) < 0.5 * np.linalg.norm(bias)
    assert np.degrees(np.max(fr.quat_angle_between(out.q_wb[-2000:], m.q_wb[-2000:]))) < 2.1


def test_magnet_is_detected_and_does_not_turn_the_heading():
    m = mo.make_motion("magnet", 30.0, 200.0)
    plus = make_estimator("biso_plus", 200.0).update(m.omega_b, m.specific_force_b, m.mag_b)
    near = m.info["distance_m"] < 0.15
    assert np.all(plus.flags[near] & fl.MAG_DISTURBED)
    err_plus = np.abs(angle_errors_deg(plus.q_wb, m.q_wb)["heading"])
    biso = estimate_attitude(m.omega_b, m.specific_force_b, m.mag_b, 200.0, "biso")
    err_biso = np.abs(angle_errors_deg(biso, m.q_wb)["heading"])
    assert np.max(err_biso) > 30.0
    assert np.max(err_plus) < 5.0 and np.sqrt(np.mean(err_plus ** 2)) < 1.5


def test_magnetometer_offset_is_estimated():
    """A 6 µT offset turns the heading by ~20° at first; once the offset is learned the heading
    follows the magnetometer back (at k_heading = 0.05/s: within a minute or so, and another
    minute without a speed input, where the norm error of the unlearned offset counts as a
    disturbance D and lowers the heading gain until the offset is learned)."""
    offset = np.array([6.0, -4.0, 3.0])  # µT, body axes
    m = mo.make_motion("tumble", 180.0, 200.0, rate_scale=0.5)
    est = make_estimator("biso_plus", 200.0)
    out = est.update(m.omega_b, m.specific_force_b, m.mag_b + offset)
    np.testing.assert_allclose(est.get_state()["mag_offset_b"], offset, atol=0.3)
    assert np.degrees(np.max(fr.quat_angle_between(out.q_wb[:2000], m.q_wb[:2000]))) > 10.0
    assert np.degrees(np.max(fr.quat_angle_between(out.q_wb[-4000:], m.q_wb[-4000:]))) < 0.6
    off = make_estimator("biso_plus", 200.0, estimate_mag_offset=False).update(m.omega_b, m.specific_force_b,
                                                                               m.mag_b + offset)
    def rms_late(q):
        return np.sqrt(np.mean(np.degrees(fr.quat_angle_between(q[-8000:], m.q_wb[-8000:])) ** 2))

    assert rms_late(off.q_wb) > 3.0 * rms_late(out.q_wb)
    # the offset makes the raw norm change with the attitude: the norm test uses it
    assert make_estimator("biso_plus", 200.0, mag_offset_test_angle_rad=0.0).update(
        m.omega_b, m.specific_force_b, m.mag_b + offset).q_wb[-1] == pytest.approx(out.q_wb[-1], abs=2e-3)
    test = est.get_state()["offset_norm_test"]  # mean and variance of |m − o|, then of |m|
    assert test[1] < 0.05 * test[3]


@pytest.mark.parametrize("theta, used", [(0.0, True), (2.0 * math.pi, False)])
def test_an_offset_the_norm_does_not_show_is_not_used(theta, used):
    """A calibrated magnetometer in a uniform field (|m| the same at every attitude) with a
    wrong learned offset of 3 µT (what a field changing along the path or a lagging field under
    fast rotation can leave in m = R_Ibᵀ B_I + o): |m − o| then changes with the attitude by the
    field's direction · o, more than |m|. With the norm test (Θ_o) the raw field is used and the
    heading is that of the estimator without an offset; without it the heading is off by up to
    atan(3 µT/|B_H|) (less on average: the disturbance measure κ D lowers the heading gain)."""
    m = mo.make_motion("tumble", 90.0, 200.0, rate_scale=0.5)
    wrong = np.array([3.0, -2.0, 1.5])
    # the offset filter never runs (its gyro-bias condition is never met): the offset stays as set
    est = make_estimator("biso_plus", 200.0, mag_offset_bias_sigma_rad_s=1e-9, mag_offset_test_angle_rad=theta)
    st = est.get_state()
    start = dict(zip((name for name, _ in st.layout), np.cumsum([0] + [n for _, n in st.layout])))["mag_offset_b"]
    st.values[start:start + 3] = wrong
    est.set_state(st)
    out = est.update(m.omega_b, m.specific_force_b, m.mag_b)
    np.testing.assert_array_equal(est.get_state()["mag_offset_b"], wrong)
    plain = make_estimator("biso_plus", 200.0, estimate_mag_offset=False).update(m.omega_b, m.specific_force_b,
                                                                                 m.mag_b)
    late = slice(-6000, None)

    def rms(q):
        return np.sqrt(np.mean(np.degrees(fr.quat_angle_between(q[late], m.q_wb[late])) ** 2))

    if used:
        assert rms(out.q_wb) > 4.0 * rms(plain.q_wb)
    else:
        assert rms(out.q_wb) < 1.2 * rms(plain.q_wb) < 0.3
        test = est.get_state()["offset_norm_test"]
        assert test[1] > 2.0 * test[3]  # |m − o| varies more than |m|


def test_the_norm_test_holds_its_decision_without_rotation():
    """The variances are low-passed over the rotation angle (α = |ω| h/Θ_o): at rest the norm
    cannot tell an offset, and nothing changes."""
    m = mo.make_motion("static", 20.0, 200.0)
    est = make_estimator("biso_plus", 200.0)
    est.reset(q0=m.q_wb[0])
    est.update(m.omega_b[:10], m.specific_force_b[:10], m.mag_b[:10] + [1.0, 2.0, 3.0])
    before = est.get_state()["offset_norm_test"].copy()
    est.update(m.omega_b[10:], m.specific_force_b[10:], m.mag_b[10:] + [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(est.get_state()["offset_norm_test"], before)


def _noisy_reference(n, sigma, rng, q_true):
    """Accelerometer and magnetometer samples whose λ_k is q_true turned by isotropic noise."""
    noise = fr.quat_from_rotvec(sigma * rng.normal(size=(n, 3)))
    qk = fr.quat_multiply(noise, np.tile(q_true, (n, 1)))
    qc = fr.quat_conjugate(qk)
    f = fr.quat_rotate(qc, np.array([0.0, 0.0, 9.80665]))
    b = fr.quat_rotate(qc, np.array(mo.EARTH_FIELD_W))
    # μ: length of the mean of λ_k (all in one hemisphere)
    qk = qk * np.sign(qk @ q_true)[:, None]
    return f, b, float(np.linalg.norm(qk.mean(axis=0)))


def _mean_error_rotvec(q, q_true):
    """World-frame rotation vector of the mean attitude (after the transient) against the truth."""
    qm = q[len(q) // 4:].mean(axis=0)
    qm /= np.linalg.norm(qm)
    return fr.quat_to_rotvec(fr.quat_multiply(qm, fr.quat_conjugate(q_true)))


def test_cross_link_bias_renormalised_versus_norm_term_versus_biso_plus():
    """docs/design.md §5: faithful BISO (k = √3 k_p) renormalised every step settles at a rotation
    of 2·(asin(1/(μ√2)) − 45°) about (1, 1, 1) when λ_k is noisy (μ: length of the mean λ_k;
    the formula is the fixed point of the averaged dynamics, met within 20 % at 1 kHz).

    Measured here as well: the paper's own norm term (eq. (2), gain 1/s) keeps the dynamics
    linear in λ and does not bias; biso_plus applies the correction as rotations of the
    rotation error, which removes the renormalisation bias, but any cross-link on rotations
    leaves a second-order "coning" drift (the noisy error spirals about (1, 1, 1)): with the
    paper's k_p it is well below the renormalised bias, and with biso_plus's default k_p = 0
    there is none."""
    rng = np.random.default_rng(0)
    fs, n = 1000.0, 20000
    q_true = fr.quat_from_euler(0.1, -0.2, 0.7)
    f, b, mu = _noisy_reference(n, 0.5, rng, q_true)
    predicted = 2.0 * (math.asin(1.0 / (mu * math.sqrt(2.0))) - math.pi / 4)
    gyro = np.zeros((n, 3))
    err = _mean_error_rotvec(make_estimator("biso", fs, renormalize=True).update(gyro, f, b).q_wb, q_true)
    axis = np.ones(3) / math.sqrt(3.0)
    assert err @ axis == pytest.approx(predicted, rel=0.2)
    assert np.linalg.norm(err - (err @ axis) * axis) < 0.1 * abs(err @ axis)  # about (1, 1, 1)
    err_term = _mean_error_rotvec(make_estimator("biso", fs).update(gyro, f, b).q_wb, q_true)
    assert np.linalg.norm(err_term) < 0.1 * predicted
    plain = dict(k_tilt=44.4, k_heading=44.4, tau_acc_s=0.0, mag_dip_tol_rad=math.pi, mag_norm_tol=10.0,
                 estimate_mag_offset=False, bias_sigma_init_rad_s=1e-9)
    crossed = make_estimator("biso_plus", fs, k_p=25.64, **plain).update(gyro, f, b).q_wb
    assert np.linalg.norm(_mean_error_rotvec(crossed, q_true)) < 0.5 * predicted
    default = make_estimator("biso_plus", fs, **plain).update(gyro, f, b).q_wb
    assert np.linalg.norm(_mean_error_rotvec(default, q_true)) < 0.05 * predicted


def test_biso_plus_parameters_are_checked():
    with pytest.raises(ValueError, match="tau_acc_s"):
        make_estimator("biso_plus", 200.0, tau_acc_s=-1.0)
    with pytest.raises(ValueError, match="speed_point_b_m"):
        make_estimator("biso_plus", 200.0, speed_point_b_m=(1.0, 2.0))
    with pytest.raises(TypeError, match="estimate_mag_offset"):
        make_estimator("biso_plus", 200.0, estimate_mag_offset="yes")
    with pytest.raises(ValueError, match="mag_norm_tol"):
        make_estimator("biso_plus", 200.0, mag_norm_tol=0.0)


def test_saturation_is_flagged_and_not_used_for_tilt():
    m = mo.make_motion("static", 2.0, 200.0)
    accel = m.specific_force_b.copy()
    accel[100:120] = [39.2, 0.0, 0.0]  # clipped at ±4 g on x
    out = make_estimator("biso_plus", 200.0, accel_range_mps2=39.2266).update(m.omega_b, accel, m.mag_b)
    assert np.all(out.flags[100:120] & fl.SATURATED)
    assert np.degrees(np.max(fr.quat_angle_between(out.q_wb, m.q_wb))) < 0.01


def test_dcm_pi_converges_and_estimates_the_bias():
    bias = np.array([0.01, -0.02, 0.015])
    m = mo.make_motion("static", 120.0, 100.0)
    out = make_estimator("dcm_pi", 100.0).update(m.omega_b + bias, m.specific_force_b, m.mag_b)
    np.testing.assert_allclose(out.gyro_bias_b[-1], bias, atol=1e-3)
    assert np.degrees(fr.quat_angle_between(out.q_wb[-1], m.q_wb[-1])) < 0.1


def _handheld(name, seed, fs=200.0, **kwargs):
    """A test motion with white noise and a constant gyro bias (σ 0.3 °/s per axis)."""
    m = mo.make_motion(name, 60.0, fs, seed=seed, **kwargs)
    rng = np.random.default_rng(100 + seed)
    n = len(m)
    gyro = m.omega_b + np.radians(0.3) * rng.normal(size=3) + np.radians(0.01) * np.sqrt(fs) * rng.normal(size=(n, 3))
    accel = m.specific_force_b + 0.003 * np.sqrt(fs) * rng.normal(size=(n, 3))
    mag = m.mag_b + 0.3 * rng.normal(size=(n, 3))
    return m, gyro, accel, mag


def _inclination_rms_deg(q, q_true, skip):
    """BROAD's inclination error (Laidig et al. 2021): 2 acos √(e_w² + e_z²), e = q ∘ q_true⁻¹."""
    e = fr.quat_multiply(q, fr.quat_conjugate(q_true))[skip:]
    inc = 2.0 * np.arccos(np.clip(np.sqrt(e[:, 0] ** 2 + e[:, 3] ** 2), 0.0, 1.0))
    return float(np.degrees(np.sqrt(np.mean(inc ** 2))))


@pytest.mark.parametrize("seed", [0, 1])
def test_fast_translations_need_the_second_order_ungated_tilt_filter(seed):
    """Handheld translations of 1–2.5 Hz, |f| − g ≈ 1 g RMS all the time (BROAD's fast-translation
    trials, where biso_plus with the first-order gated low-pass had up to 6x VQF's inclination
    error). A first order passes the specific force at f into the tilt reference attenuated
    by 1/(2π f τ) only (≈ 0.5 m/s² at 2 Hz and 2 g: ~3° of tilt); the second order by its
    square. The gate, with |f| ≠ g all the time, lengthens the filter's memory so that the
    gyro bias tilts the estimate meanwhile. Without a speed input both are off by default,
    and each alone leaves the error well above the default's, which is within VQF's."""
    m, gyro, accel, mag = _handheld("translation", seed)
    skip = int(5 * m.fs_hz)

    def inclination(**kw):
        est = make_estimator("biso_plus", m.fs_hz, **kw)
        est.reset(q0=m.q_wb[0])
        return _inclination_rms_deg(est.update(gyro, accel, mag).q_wb, m.q_wb, skip)

    new = inclination()
    assert new < 1.2
    assert inclination(tilt_lp_order=1) > 1.7 * new
    assert inclination(accel_gate_free=3.0) > 2.0 * new
    assert inclination(tilt_lp_order=1, accel_gate_free=3.0) > 2.5 * new
    vqf = pytest.importorskip("vqf")
    v = vqf.VQF(1.0 / m.fs_hz).updateBatch(np.ascontiguousarray(gyro), np.ascontiguousarray(accel),
                                            np.ascontiguousarray(mag))
    assert new < 1.1 * _inclination_rms_deg(v["quat9D"], m.q_wb, skip)


def test_speed_input_keeps_the_vehicle_tilt_filter():
    """With a speed input the tilt low-pass stays first order and gated, and the heading gain
    unweighted: the new no-speed parameters change nothing there (bit for bit)."""
    m = mo.make_motion("circle", 20.0, 200.0, speed_mps=10.0, radius_m=30.0)
    speed = np.full(len(m), 10.0)
    a = make_estimator("biso_plus", 200.0).update(m.omega_b, m.specific_force_b, m.mag_b, speed_mps=speed)
    b = make_estimator("biso_plus", 200.0, tilt_lp_order=1, accel_gate_free=3.0, mag_disturbance_gain=0.0,
                       mag_time_skew_s=0.05).update(m.omega_b, m.specific_force_b, m.mag_b, speed_mps=speed)
    np.testing.assert_array_equal(a.q_wb, b.q_wb)


@pytest.mark.parametrize("seed", [0, 1])
def test_vibration_does_not_freeze_the_tilt_correction(seed):
    """A phone vibrating on the sensor (150 Hz, ~2 g, aliased at 200 Hz: BROAD's phone-vibration
    trials, where the gated filter had 2.3x VQF's inclination error): |f| is far from g for the
    20 s of vibration, a gate holds the tilt reference meanwhile, and the gyro bias tilts the
    estimate. Ungated (the default without a speed input) the aliased vibration averages out."""
    m, gyro, accel, mag = _handheld("vibration", seed)
    skip = int(5 * m.fs_hz)

    def inclination(**kw):
        est = make_estimator("biso_plus", m.fs_hz, **kw)
        est.reset(q0=m.q_wb[0])
        return _inclination_rms_deg(est.update(gyro, accel, mag).q_wb, m.q_wb, skip)

    new = inclination()
    assert inclination(accel_gate_free=3.0) > 2.0 * new
    vqf = pytest.importorskip("vqf")
    v = vqf.VQF(1.0 / m.fs_hz).updateBatch(np.ascontiguousarray(gyro), np.ascontiguousarray(accel),
                                            np.ascontiguousarray(mag))
    assert new < 1.25 * _inclination_rms_deg(v["quat9D"], m.q_wb, skip)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_start_in_motion_does_not_reject_the_magnetometer(seed):
    """Started in motion (a hand swinging the sensor, 0.5 g horizontal at t = 0): the first
    attitude is tilted by ~25°, and so is the dip of the expected field learned with it. That
    field is provisional until the tilt has settled: a failing dip test replaces it (instead of
    rejecting the magnetometer for t_B = 60 s), as does a tilt corrected by more than θ_δ since it
    was learned, and the heading's start (its running mean) begins again then. Before, seed 0
    rejected 99 % of the samples and had 51° of total error (VQF 1.5°)."""
    m, gyro, accel, mag = _handheld("moving_start", seed)
    est = make_estimator("biso_plus", m.fs_hz)
    out = est.update(gyro, accel, mag)  # no q0: the first attitude from the first sample
    skip = int(5 * m.fs_hz)
    assert np.mean(out.flags[skip:] & fl.MAG_DISTURBED != 0) < 0.01
    e = fr.quat_multiply(out.q_wb, fr.quat_conjugate(m.q_wb))[skip:]
    total = float(np.degrees(np.sqrt(np.mean((2 * np.arccos(np.clip(np.abs(e[:, 0]), 0, 1))) ** 2))))
    vqf = pytest.importorskip("vqf")
    v = vqf.VQF(1.0 / m.fs_hz).updateBatch(np.ascontiguousarray(gyro), np.ascontiguousarray(accel),
                                            np.ascontiguousarray(mag))
    ev = fr.quat_multiply(v["quat9D"], fr.quat_conjugate(m.q_wb))[skip:]
    total_vqf = float(np.degrees(np.sqrt(np.mean((2 * np.arccos(np.clip(np.abs(ev[:, 0]), 0, 1))) ** 2))))
    assert total < 2.5 * total_vqf  # 2.2x on seed 0 (the random bias left), 1.1x on seed 1


@pytest.mark.parametrize("name", ["translation", "shake"])
def test_vertical_gyro_bias_is_learned_in_motion_without_rest(name):
    """A handheld sensor that never rests, with a 0.3 °/s bias on every axis: the body's vertical
    axis stays near the vertical (±15°), so tilt barely observes its bias, and the heading loop
    alone turns the heading by b/k_h (6° at k_h = 0.05/s). Without a speed input the heading
    correction is a measurement of the vertical bias in the bias filter (f_zf = 0.1 against the
    vehicle's 0.01, its variance raised by the heading's disturbance weight, not during the
    heading's start): after 90 s the heading error is 0.43-0.62x that with f_zf = 0.01 and
    0.35-1.31x VQF's (before: 0.75-2.1x VQF's on translation, 0.99-1.26x on shake)."""
    for seed in (0, 1):
        m = mo.make_motion(name, 180.0, 200.0, seed=seed)
        rng = np.random.default_rng(100 + seed)
        n = len(m)
        gyro = m.omega_b + np.radians(0.3) + np.radians(0.01) * np.sqrt(200.0) * rng.normal(size=(n, 3))
        accel = m.specific_force_b + 0.003 * np.sqrt(200.0) * rng.normal(size=(n, 3))
        mag = m.mag_b + 0.3 * rng.normal(size=(n, 3))
        skip = int(90 * m.fs_hz)

        def heading_rms(q):
            e = fr.quat_multiply(q, fr.quat_conjugate(m.q_wb))[skip:]
            return float(np.degrees(np.sqrt(np.mean((2 * np.arctan(np.abs(e[:, 3] / e[:, 0]))) ** 2))))

        est = make_estimator("biso_plus", 200.0)
        est.reset(q0=m.q_wb[0])
        new = heading_rms(est.update(gyro, accel, mag).q_wb)
        old = make_estimator("biso_plus", 200.0, bias_heading_factor_free=0.01)
        old.reset(q0=m.q_wb[0])
        assert new < 0.7 * heading_rms(old.update(gyro, accel, mag).q_wb)
        vqf = pytest.importorskip("vqf")
        v = vqf.VQF(1.0 / m.fs_hz).updateBatch(np.ascontiguousarray(gyro), np.ascontiguousarray(accel),
                                                np.ascontiguousarray(mag))
        assert new < 1.4 * heading_rms(v["quat9D"])


def _slow_translation_heading_rmse(seed, offset_b, **params):
    """BROAD's slow translation (`slow_translation`, 33 s at rest first) through the lab's
    gradient, with white noise, a 0.3 °/s gyro bias and a magnetometer offset ``offset_b``:
    biso_plus's heading RMSE over the movement (°) and the offset it learned."""
    from biso_cosim.compare import MOTION_SETUP
    from biso_cosim.score.metrics import trial_rmse_deg

    fs = 200.0
    m = mo.make_motion("slow_translation", 120.0, fs, seed=seed, rest_s=33.0,
                       field_gradient_ut_per_m=MOTION_SETUP["slow_translation"]["field_gradient_ut_per_m"])
    rng = np.random.default_rng(100 + seed)
    n = len(m)
    gyro = m.omega_b + np.radians(0.3) * rng.normal(size=3) + np.radians(0.01) * np.sqrt(fs) * rng.normal(size=(n, 3))
    accel = m.specific_force_b + 0.003 * np.sqrt(fs) * rng.normal(size=(n, 3))
    mag = m.mag_b + 0.7 * rng.normal(size=(n, 3)) + offset_b
    est = make_estimator("biso_plus", fs, **params)
    q = est.update(gyro, accel, mag).q_wb
    return trial_rmse_deg(q, m.q_wb, m.info["moving"])["heading"], est.get_state()["mag_offset_b"]


@pytest.mark.parametrize("seed", [0, 1])
def test_an_offset_taken_from_the_gradient_at_a_nearly_fixed_attitude_is_shrunk(seed):
    """A calibrated sensor (no offset) moved by decimetres through a room's gradient with the hand's
    turns in step and hardly another change of attitude (BROAD's trial 11): the offset filter takes
    0.8–1.1 µT of the gradient for an offset, and the norm test cannot tell (at a nearly fixed
    attitude the norm hardly changes either). Shrunk by |o|²/(|o|² + σ_s²) (σ_s = 1 µT), it costs half
    the heading error it cost used whole (BROAD 11: total RMSE 1.43° → 1.19°, VQF 0.90°)."""
    whole, o = _slow_translation_heading_rmse(seed, 0.0, mag_offset_shrink_ut=0.0)
    shrunk, _ = _slow_translation_heading_rmse(seed, 0.0)
    plain, _ = _slow_translation_heading_rmse(seed, 0.0, estimate_mag_offset=False)
    assert np.linalg.norm(o) > 0.7 and whole > 5.0 * plain
    assert shrunk < 0.6 * whole


def test_a_phone_sized_offset_is_used_nearly_whole():
    """The same motion with a phone lying on the sensor (2.4 µT fixed in body axes, BROAD's trial 27):
    where the offset filter learns it, the shrunk offset keeps nearly all of what it gains."""
    whole, o = _slow_translation_heading_rmse(2, np.asarray(mo.PHONE_FIELD_B_UT), mag_offset_shrink_ut=0.0)
    shrunk, _ = _slow_translation_heading_rmse(2, np.asarray(mo.PHONE_FIELD_B_UT))
    plain, _ = _slow_translation_heading_rmse(2, np.asarray(mo.PHONE_FIELD_B_UT), estimate_mag_offset=False)
    assert np.linalg.norm(o) > 2.0 and whole < 0.7 * plain
    assert shrunk - whole < 0.15 * (plain - whole)
