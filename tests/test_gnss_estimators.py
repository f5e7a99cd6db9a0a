"""GNSS-aided estimators (Ibrahim & Lukyanov 2020): the paper's equations against numerical
derivatives, the discretisation against Van Loan, the kernels against a slow twin, the
decided open points (heading sign, gravity, A_GNSS from velocity, coupling), convergence,
sustained turns, latency, drift estimation, filter consistency, streaming and bad input."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.linalg import expm

from _gnss_reference import from_gost, gost_angles, n_matrix, reference_run
from biso_cosim import frames as fr
from biso_cosim import motions as mo
from biso_cosim.estimators import _gnss_kernels as K
from biso_cosim.estimators import flags as fl
from biso_cosim.estimators.gnss_aided import (
    GNSS_REJECTED,
    GNSS_UNAIDED,
    GNSS_UPDATE,
    UPDATE_KINDS,
    GnssComplementaryEstimator,
    GnssKalmanEstimator,
    GnssKalmanParams,
    error_matrix,
    euler_rates,
    gnss_coefficients,
    magnetic_heading,
)
from biso_cosim.sensors.gnss import IDEAL, GnssFixes, GnssReceiver
from biso_cosim.units import DEG, G0

CLASSES = (GnssComplementaryEstimator, GnssKalmanEstimator)
FIELD_W = np.array(mo.EARTH_FIELD_W)


def _make(cls, fs, **params):
    return cls(fs, cls.Params(**params))


def _drive(seconds, fs, seed=0):
    """Analytic vehicle-like motion: attitude from a Z-Y-X chain of smooth angles, position a sum
    of sines (independent of the attitude), exact rates, specific force, field and velocity."""
    t = np.arange(int(round(seconds * fs))) / fs
    rng = np.random.default_rng(seed)
    ph = rng.uniform(0, 2 * np.pi, 6)
    yaw = (lambda tt: 0.3 * tt + 0.8 * np.sin(0.05 * tt + ph[0]), lambda tt: 0.3 + 0.04 * np.cos(0.05 * tt + ph[0]))
    pitch = (lambda tt: 0.06 * np.sin(0.21 * tt + ph[1]), lambda tt: 0.0126 * np.cos(0.21 * tt + ph[1]))
    roll = (lambda tt: 0.08 * np.sin(0.17 * tt + ph[2]), lambda tt: 0.0136 * np.cos(0.17 * tt + ph[2]))
    q, om = mo._euler_chain(t, yaw, pitch, roll)
    w = np.array([0.3, 0.11, 0.05])
    amp = np.array([[30.0, 20.0, 1.0], [8.0, 14.0, 0.5], [2.0, 3.0, 0.2]])
    vel = np.zeros((t.size, 3))
    acc = np.zeros((t.size, 3))
    for j in range(3):
        arg = w[j] * t[:, None] + ph[3 + j]
        vel += amp[j] * w[j] * np.cos(arg)
        acc -= amp[j] * w[j] ** 2 * np.sin(arg)
    qc = fr.quat_conjugate(q)
    f_b = fr.quat_rotate(qc, acc + [0.0, 0.0, G0])
    return t, q, om, f_b, fr.quat_rotate(qc, np.tile(FIELD_W, (t.size, 1))), vel


def _fixes(t, vel, rate=5.0, latency=0.0, fs=None):
    """Ideal fixes at the epochs j/rate (on the sample grid), arriving ``latency`` later."""
    step = int(round((fs or 1.0 / (t[1] - t[0])) / rate))
    idx = np.arange(0, t.size, step)
    return GnssFixes.from_arrays(t[idx], vel[idx], t_arrival_s=t[idx] + latency)


def _same(a, b):
    """Bit for bit (NaN included), for the structured updates records."""
    assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _tilt_err_deg(q_est, q_true):
    """Largest of |roll error|, |pitch error| per sample, degrees."""
    a = fr.euler_from_quat(q_est) - fr.euler_from_quat(q_true)
    return np.degrees(np.abs(fr.wrap_angle(a[:, :2]))).max(axis=1)


# --------------------------------------------------------------------------------------
# the paper's equations
# --------------------------------------------------------------------------------------


def test_eq4_is_the_quaternion_kinematics_in_euler_angles():
    rng = np.random.default_rng(1)
    for _ in range(20):
        psi, th, ga = rng.uniform(-3, 3), rng.uniform(-1.2, 1.2), rng.uniform(-3, 3)
        w_ours = rng.normal(size=3)
        q = fr.quat_from_gost_angles(psi, th, ga)
        d = 1e-6
        ang = [fr.gost_angles_from_quat(fr.quat_multiply(q, fr.quat_from_rotvec(w_ours * s))) for s in (-d, d)]
        num = (ang[1] - ang[0]) / (2 * d)  # (ψ̇, ϑ̇, γ̇)
        num[0] = fr.wrap_angle(ang[1][0] - ang[0][0]) / (2 * d)
        g_dot, th_dot, psi_dot = euler_rates(th, ga, [w_ours[0], w_ours[2], -w_ours[1]])
        np.testing.assert_allclose([psi_dot, th_dot, g_dot], num, rtol=1e-6, atol=1e-8)


def test_error_matrix_is_the_jacobian_of_eq4_and_the_kernel_uses_it():
    rng = np.random.default_rng(2)
    for _ in range(20):
        th, ga = rng.uniform(-1.0, 1.0), rng.uniform(-3, 3)
        w = rng.normal(size=3)
        f = error_matrix(th, ga, w, 300.0)

        def rates(x):  # (ϑ̇, γ̇) as functions of (ϑ, γ, ω)
            g_dot, th_dot, _ = euler_rates(x[0], x[1], x[2:])
            return np.array([th_dot, g_dot])

        x0 = np.array([th, ga, *w])
        jac = np.array([(rates(x0 + e) - rates(x0 - e)) / 2e-6 for e in np.eye(5) * 1e-6]).T
        np.testing.assert_allclose(f[:2], jac, rtol=1e-6, atol=1e-7)
        np.testing.assert_allclose(np.diag(f)[2:], -1 / 300.0)
        coef = K._error_model(math.sin(ga), math.cos(ga), math.tan(th), math.cos(th), *w)
        np.testing.assert_allclose(coef, [f[0, 1], f[0, 3], f[0, 4], f[1, 0], f[1, 1], f[1, 3], f[1, 4]], rtol=1e-12)
        r = fr.quat_to_matrix(fr.quat_from_gost_angles(0.3, th, ga)).ravel()
        terms = K._tilt_terms(r[6], r[7], r[8], 0.0)
        np.testing.assert_allclose(terms, [math.sin(ga), math.cos(ga), math.tan(th), math.cos(th)], rtol=1e-9,
                                   atol=1e-12)


def test_n_is_the_derivative_of_the_rotated_specific_force():
    rng = np.random.default_rng(3)
    for _ in range(20):
        psi, th, ga = rng.uniform(-3, 3), rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8)
        f_b = rng.normal(size=3) * 3 + [0, 0, G0]
        q = fr.quat_from_gost_angles(psi, th, ga)
        d = 1e-6
        num = [(fr.quat_rotate(fr.quat_from_gost_angles(psi, th + e[0], ga + e[1]), f_b)
                - fr.quat_rotate(fr.quat_from_gost_angles(psi, th - e[0], ga - e[1]), f_b)) / (2 * d)
               for e in ((d, 0.0), (0.0, d))]
        r = fr.quat_to_matrix(q)
        f_w = r @ f_b
        n = K._n_columns(r[0, 0], r[1, 0], r[2, 0], *f_w)
        np.testing.assert_allclose(n[:3], num[0], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(n[3:], num[1], rtol=1e-6, atol=1e-6)
        # the GOST matrices of the slow twin agree (N-U-E is a cyclic permutation of E-N-U)
        from scipy.spatial.transform import Rotation

        np.testing.assert_allclose(n_matrix(Rotation.from_quat(np.roll(q, -1)), f_b), np.array(num).T, atol=1e-6)
        # heading: N0 = e_Up × f
        dpsi = (fr.quat_rotate(fr.quat_from_gost_angles(psi + d, th, ga), f_b)
                - fr.quat_rotate(fr.quat_from_gost_angles(psi - d, th, ga), f_b)) / (2 * d)
        np.testing.assert_allclose(dpsi, np.cross([0, 0, 1], f_w), atol=1e-6)


def test_covariance_step_agrees_with_van_loan():
    """Φ = I + Fh + ½F²h², Q_d = Qh + ½(FQ + QFᵀ)h² against the exact Van Loan step (scipy's
    expm): the error is below (‖F‖h)³ of P and falls as h³."""
    params = GnssKalmanParams(gyro_noise_density=0.05 * DEG, drift_sigma_rad_s=0.1 * DEG, drift_tau_s=50.0)
    rng = np.random.default_rng(4)
    a = rng.normal(size=(5, 5))
    p0 = a @ a.T * 1e-4
    for _ in range(5):
        th, ga, w = rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.normal(size=3) * 0.5
        f = error_matrix(th, ga, w, 50.0)
        coef = (f[0, 1], f[0, 3], f[0, 4], f[1, 0], f[1, 1], f[1, 3], f[1, 4])
        errors = []
        for fs in (100.0, 200.0):
            c = gnss_coefficients(params, fs)
            p = p0.copy()
            K._propagate_covariance(c, p, np.zeros((4, 3, 5)), *coef)
            g = np.zeros((5, 6))
            g[0, 1:3], g[1, 0], g[1, 1:3], g[2:, 3:] = f[0, 3:5], 1.0, f[1, 3:5], np.eye(3)
            qc = np.diag([c[K.C_QG]] * 3 + [c[K.C_QD]] * 3)
            h = 1.0 / fs
            vl = expm(np.block([[-f, g @ qc @ g.T], [np.zeros((5, 5)), f.T]]) * h)
            phi = vl[5:, 5:].T
            exact = phi @ p0 @ phi.T + phi @ vl[:5, 5:]
            errors.append(np.abs(p - exact).max() / np.abs(exact).max())
            assert errors[-1] < (np.abs(f).sum(axis=1).max() * h) ** 3
        assert 6.0 < errors[0] / errors[1] < 10.0


def test_heading_coupling_is_the_tilt_sensitivity_of_the_magnetic_heading():
    rng = np.random.default_rng(5)
    for _ in range(10):
        roll, pitch, yaw = rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), rng.uniform(-3, 3)
        q = fr.quat_from_euler(roll, pitch, yaw)
        m_b = fr.quat_rotate(fr.quat_conjugate(q), FIELD_W)
        d = 1e-6

        def yaw_m(droll, dpitch):  # the magnetic heading (as a yaw) with the estimate's tilt off
            return math.pi / 2 - magnetic_heading(m_b, roll + droll, pitch + dpitch)[0]

        # ϑ = −pitch, γ = roll; the heading error Δψ = Δyaw
        p1 = -(yaw_m(0, d) - yaw_m(0, -d)) / (2 * d)
        p2 = (yaw_m(d, 0) - yaw_m(-d, 0)) / (2 * d)
        r = fr.quat_to_matrix(q)
        np.testing.assert_allclose(K._heading_coupling(r[0, 0], r[1, 0], r[2, 0], *FIELD_W), [p1, p2],
                                   rtol=1e-5, atol=1e-6)


# --------------------------------------------------------------------------------------
# open point 1: heading sign; eq. (5) with hard and soft iron
# --------------------------------------------------------------------------------------


def test_magnetic_heading_sign_declination_and_iron():
    decl = 7.0 * DEG
    h, z = 18.0, 46.0
    field = np.array([h * math.sin(decl), h * math.cos(decl), -z])  # ENU, east of true north by D
    q_east = fr.quat_from_euler(0.0, 0.0, 0.0)  # level, heading East: yaw 0, compass 90°
    m_b = fr.quat_rotate(fr.quat_conjugate(q_east), field)
    assert magnetic_heading(m_b, 0.0, 0.0, declination_rad=decl)[0] == pytest.approx(math.pi / 2, abs=1e-12)
    # the paper's ψ (positive toward West) is −(compass heading): −90° for East
    assert fr.gost_angles_from_quat(q_east)[0] == pytest.approx(-math.pi / 2)
    rng = np.random.default_rng(6)
    q = fr.quat_from_euler(rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.5, 0.5, 50), rng.uniform(-3, 3, 50))
    e = fr.euler_from_quat(q)
    b_b = fr.quat_rotate(fr.quat_conjugate(q), field)
    soft = np.array([[1.1, 0.05, -0.02], [0.03, 0.92, 0.04], [-0.01, 0.06, 1.05]])
    hard = np.array([12.0, -7.0, 20.0])
    seen = b_b @ soft.T + hard  # T_c = (E + M) T + P
    got = magnetic_heading(seen, e[:, 0], e[:, 1], hard_iron_ut=hard, soft_iron=soft, declination_rad=decl)
    np.testing.assert_allclose(fr.wrap_angle(got - fr.heading_from_quat(q)), 0.0, atol=1e-10)
    raw = magnetic_heading(seen, e[:, 0], e[:, 1], declination_rad=decl)
    assert np.abs(fr.wrap_angle(raw - fr.heading_from_quat(q))).max() > 10 * DEG


@pytest.mark.parametrize("cls", CLASSES)
def test_kernel_heading_is_eq5_and_t2_blends(cls):
    q = fr.quat_from_euler(0.1, -0.15, 2.0)
    soft = np.array([[1.1, 0.05, -0.02], [0.03, 0.92, 0.04], [-0.01, 0.06, 1.05]])
    hard = np.array([5.0, -3.0, 8.0])
    n = 200
    f_b = np.tile(fr.quat_rotate(fr.quat_conjugate(q), [0, 0, G0]), (n, 1))
    m_b = np.tile(fr.quat_rotate(fr.quat_conjugate(q), FIELD_W) @ soft.T + hard, (n, 1))
    wrong = fr.quat_multiply(fr.quat_from_rotvec([0, 0, 0.3]), q)  # heading off by 0.3 rad
    est = _make(cls, 100.0, t2_s=1e-9, unaided="gyro", mag_hard_iron_ut=tuple(hard), mag_soft_iron=soft)
    est.reset(q0=wrong)
    out = est.update(np.zeros((n, 3)), f_b, m_b)
    assert fr.quat_angle_between(out.q_wb[-1], q) < 1e-9
    # T2: the heading error decays as e^{−t/T2}
    est = _make(cls, 100.0, t2_s=0.5, unaided="gyro", mag_hard_iron_ut=tuple(hard), mag_soft_iron=soft)
    est.reset(q0=wrong)
    err = fr.quat_angle_between(est.update(np.zeros((n, 3)), f_b, m_b).q_wb, q)
    i = np.arange(0, 101, 20)
    np.testing.assert_allclose(err[i], 0.3 * np.exp(-i / 100.0 / 0.5), rtol=1e-9)


@pytest.mark.parametrize("cls", CLASSES)
def test_singular_soft_iron_is_refused(cls):
    singular = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]
    with pytest.raises(ValueError, match="mag_soft_iron is singular"):
        _make(cls, 100.0, mag_soft_iron=singular)
    est = _make(cls, 100.0)
    before = est.coefficients
    with pytest.raises(ValueError, match="singular"):
        est.set_params(mag_soft_iron=singular)
    np.testing.assert_array_equal(est.coefficients, before)
    with pytest.raises(ValueError, match="mag_hard_iron_ut"):
        est.set_params(mag_hard_iron_ut=(1.0, 2.0))


# --------------------------------------------------------------------------------------
# open points 2 and 3: gravity and A_GNSS from velocity; convergence and turns
# --------------------------------------------------------------------------------------


def test_complementary_tilt_error_decays_with_t1():
    fs, n = 100.0, 2001
    q = fr.quat_from_euler(0.0, 0.0, 0.4)
    f_b = np.tile(fr.quat_rotate(fr.quat_conjugate(q), [0, 0, G0]), (n, 1))
    m_b = np.tile(fr.quat_rotate(fr.quat_conjugate(q), FIELD_W), (n, 1))
    t = np.arange(n) / fs
    fixes = _fixes(t, np.zeros((n, 3)), rate=5.0)
    est = _make(GnssComplementaryEstimator, fs, t1_s=3.0, t2_s=math.inf)
    est.reset(q0=fr.quat_multiply(q, fr.quat_from_euler(2.0 * DEG, -1.0 * DEG, 0.0)))
    out = est.update(np.zeros((n, 3)), f_b, m_b, gnss=fixes)
    roll = np.degrees(fr.euler_from_quat(out.q_wb)[:, 0])
    # one correction per 1 s window (the first fix only anchors), each by 1 − e^{−1/3}
    k = np.arange(1, 20)
    np.testing.assert_allclose(roll[k * 100 + 1] / 2.0, np.exp(-k / 3.0), rtol=2e-3)
    np.testing.assert_allclose(roll[k * 100 - 1] / 2.0, np.exp(-(k - 1) / 3.0), rtol=2e-3)
    assert np.count_nonzero(out.flags & GNSS_UPDATE) == 20


@pytest.mark.parametrize("cls", CLASSES)
def test_sustained_turn_gnss_keeps_the_tilt_while_gravity_leans_into_it(cls):
    fs = 100.0
    m = mo.make_motion("circle", 40.0, fs, speed_mps=15.0, radius_m=60.0)
    w = 15.0 / 60.0
    vel = 15.0 * np.stack([np.cos(w * m.t_s), np.sin(w * m.t_s), 0 * m.t_s], axis=1)
    est = _make(cls, fs)
    est.reset(q0=m.q_wb[0])
    out = est.update(m.omega_b, m.specific_force_b, m.mag_b, gnss=_fixes(m.t_s, vel))
    err = _tilt_err_deg(out.q_wb, m.q_wb)
    assert err.max() < 0.01
    assert not (out.flags[200:] & (GNSS_UNAIDED | GNSS_REJECTED)).any()
    # Without GNSS the gravity reference takes the specific force (0, a, g) in body axes for gravity:
    # it leans by atan(a/g) into the turn. Tilt errors stay put in the world frame under the gyro
    # while the turn turns the target, so a loop of gain k per window T_w settles at
    # k / |1 − (1 − k) e^{iωT_w}| of it. A gentle turn: 10 m/s on 100 m.
    m = mo.make_motion("circle", 60.0, fs, speed_mps=10.0, radius_m=100.0)
    lean = math.atan(1.0 / G0)
    fast = {"t1_unaided_s": 1.0} if cls is GnssComplementaryEstimator else {"unaided_accel_sigma_mps2": 0.05}
    est = _make(cls, fs, unaided="gravity", t2_s=math.inf, **fast)
    est.reset(q0=m.q_wb[0])
    out = est.update(m.omega_b, m.specific_force_b, m.mag_b)
    tilt = fr.quat_angle_between(out.q_wb[-1], m.q_wb[-1])
    if cls is GnssComplementaryEstimator:
        k = 1.0 - math.exp(-1.0)
        assert tilt == pytest.approx(lean * k / abs(1.0 - (1.0 - k) * np.exp(0.1j)), rel=0.05)
    else:
        assert 0.95 * lean < tilt < 1.01 * lean
    assert (out.flags & GNSS_UNAIDED).all()


@pytest.mark.parametrize("cls", CLASSES)
def test_latency_is_compensated_by_the_time_of_validity(cls):
    fs = 100.0
    t, q, om, f_b, m_b, vel = _drive(120.0, fs)
    errs = []
    for stamp in ("validity", "arrival"):
        fixes = _fixes(t, vel, latency=0.3)
        if stamp == "arrival":  # a receiver log stamped on arrival: the acceleration is 0.3 s late
            fixes = GnssFixes.from_arrays(fixes.t_arrival_s, fixes.vel_w, t_arrival_s=fixes.t_arrival_s)
        est = _make(cls, fs, t2_s=math.inf)
        est.reset(q0=q[0])
        out = est.update(om, f_b, m_b, gnss=fixes)
        errs.append(_tilt_err_deg(out.q_wb, q)[1000:].max())
    assert errs[0] < 0.01 < 0.1 < errs[1]


def test_gnss_acceleration_window_uses_velocity_differences_exactly():
    """At constant acceleration the innovation is zero whatever the window (velocity, not position)."""
    fs, n = 100.0, 1500
    a = np.array([1.5, -0.8, 0.0])
    t = np.arange(n) / fs
    q = fr.quat_from_euler(0.05, -0.03, 0.7)
    f_b = np.tile(fr.quat_rotate(fr.quat_conjugate(q), a + [0, 0, G0]), (n, 1))
    m_b = np.tile(fr.quat_rotate(fr.quat_conjugate(q), FIELD_W), (n, 1))
    vel = t[:, None] * a
    for window in (0.2, 1.0, 2.6):
        est = _make(GnssKalmanEstimator, fs, window_s=window)
        est.reset(q0=q)
        out = est.update(np.zeros((n, 3)), f_b, m_b, gnss=_fixes(t, vel))
        used = out.updates[out.updates["kind"] == UPDATE_KINDS.index("gnss")]
        assert len(used) >= 4
        np.testing.assert_allclose(used["interval_s"], math.ceil(window * 5 - 1e-9) / 5)
        np.testing.assert_allclose(used["innovation_w"], 0.0, atol=1e-9)
        assert fr.quat_angle_between(out.q_wb[-1], q) < 1e-10


# --------------------------------------------------------------------------------------
# the Kalman filter: drift, consistency, the slow twin
# --------------------------------------------------------------------------------------


def _noisy(seconds, fs, seed, bias_deg_s=(0.0, 0.0, 0.0), gyro_nd=0.01 * DEG, accel_nd=300e-6 * G0):
    t, q, om, f_b, m_b, vel = _drive(seconds, fs, seed)
    rng = np.random.default_rng(seed + 100)
    gyro = om + np.radians(bias_deg_s) + gyro_nd * math.sqrt(fs) * rng.normal(size=om.shape)
    accel = f_b + accel_nd * math.sqrt(fs) * rng.normal(size=f_b.shape)
    return t, q, gyro, accel, m_b, vel


def test_kalman_estimates_the_observable_drifts():
    fs = 100.0
    bias = (0.06, -0.04, 0.0)  # (a vertical drift turns the heading, which N0 = e_Up × f couples into tilt)
    t, q, gyro, accel, m_b, vel = _noisy(400.0, fs, 7, bias)
    est = _make(GnssKalmanEstimator, fs, drift_tau_s=1e4)
    est.reset(q0=q[0])
    out = est.update(gyro, accel, m_b, gnss=_fixes(t, vel))
    got = np.degrees(out.gyro_bias_b[-1])
    np.testing.assert_allclose(got[:2], bias[:2], atol=0.006)  # roll and pitch axes
    # what is left is the filter's own noise floor (gyro random walk over its memory): its σ says so
    err = np.radians(_tilt_err_deg(out.q_wb, q)[-10000:])
    assert np.sqrt(np.mean(err ** 2)) < 1.2 * out.tilt_sigma_rad[-10000:].mean()


def test_kalman_is_consistent_when_its_noise_model_is_right():
    """White GNSS velocity and IMU noise, R and Q matched: the NIS averages its 3 degrees of
    freedom (within the sampling error and the neglected correlation of adjacent windows) and
    the filter's σ matches the actual tilt error."""
    fs = 50.0
    sv = 0.05
    nis, ratio = [], []
    for seed in range(3):
        t, q, gyro, accel, m_b, vel = _noisy(600.0, fs, seed, bias_deg_s=(0.02, -0.02, 0.0))
        rx = GnssReceiver(dataclasses.replace(IDEAL, vel_white_mps=(sv, sv)), seed=seed, rate_hz=5.0,
                          input_rate_hz=fs)
        fixes = rx.simulate(np.zeros_like(vel), vel)
        est = _make(GnssKalmanEstimator, fs, gnss_vel_sigma_mps=(sv, sv), accel_sigma_mps2=0.0,
                    heading_sigma_rad=0.0, drift_sigma_rad_s=0.03 * DEG, drift_tau_s=1e4, t2_s=math.inf)
        est.reset(q0=q[0])
        out = est.update(gyro, accel, m_b, gnss=fixes)
        u = out.updates[out.updates["kind"] == 0]
        nis.append(u["nis"][50:])
        e = fr.euler_from_quat(out.q_wb) - fr.euler_from_quat(q)
        late = t > 100
        ratio.append(np.sqrt(np.mean(e[late, :2] ** 2, axis=0)) / np.sqrt(np.mean(out.tilt_sigma_rad[late] ** 2, axis=0)))
    nis = np.concatenate(nis)
    assert 2.7 < nis.mean() < 3.3
    assert np.mean(nis > 11.34) < 0.03  # χ²₃ 99 % point
    # the filter's σ bounds the actual error: windows that share a fix are negatively
    # correlated, which it ignores (their noise telescopes), so it is pessimistic, not blind
    assert np.all((np.array(ratio) > 0.4) & (np.array(ratio) < 1.1))


@pytest.mark.parametrize("cls", CLASSES)
def test_kernel_agrees_with_the_slow_twin(cls):
    fs = 50.0
    t, q, gyro, accel, m_b, vel = _noisy(24.0, fs, 3, bias_deg_s=(0.3, -0.2, 0.1))
    soft = ((1.02, 0.01, 0.0), (0.0, 0.98, 0.02), (0.01, 0.0, 1.01))
    m_seen = m_b @ np.array(soft).T + [1.0, -2.0, 0.5]
    fixes = _fixes(t, vel, latency=0.1)
    keep = (fixes.t_s < 8.0) | (fixes.t_s > 14.0)  # an outage: unaided updates after 3 s, coasting off
    fixes = fixes[keep]
    params = cls.Params(window_s=0.4, t2_s=2.0, mag_soft_iron=soft, mag_hard_iron_ut=(1.0, -2.0, 0.5),
                        declination_rad=0.1, unaided="gravity", t0_s=0.0)
    q0 = fr.quat_multiply(q[0], fr.quat_from_euler(1.0 * DEG, -0.5 * DEG, 2.0 * DEG))
    est = cls(fs, params)
    est.reset(q0=q0)
    out = est.update(gyro, accel, m_seen, gnss=fixes)
    rows = np.column_stack([fixes.t_s, fixes.t_arrival_s, fixes.vel_w])
    ref = reference_run(params, fs, q0, gyro, accel, m_seen, rows, exact=False)
    assert fr.quat_angle_between(out.q_wb, ref).max() < 1e-10
    if cls is GnssKalmanEstimator:  # and with the exact covariance step (the discretisation error)
        ref = reference_run(params, fs, q0, gyro[:400], accel[:400], m_seen[:400], rows, exact=True)
        assert fr.quat_angle_between(out.q_wb[:400], ref).max() < 1e-4 * DEG
    kinds = out.updates["kind"]
    assert (kinds == UPDATE_KINDS.index("unaided")).any() and (kinds == UPDATE_KINDS.index("gnss")).sum() > 20


def test_slow_twin_matches_its_own_frames():
    """The twin's GOST angles are the package's (so the comparison above is like for like)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(8)
    for _ in range(10):
        a = rng.uniform([-3, -1, -3], [3, 1, 3])
        r = from_gost(*a)
        np.testing.assert_allclose(fr.wrap_angle(np.array(gost_angles(r)) - a), 0.0, atol=1e-12)
        np.testing.assert_allclose(fr.quat_angle_between(np.roll(r.as_quat(), 1), fr.quat_from_gost_angles(*a)), 0,
                                   atol=1e-7)
        assert isinstance(r, Rotation)


# --------------------------------------------------------------------------------------
# time, streaming, state, fall-backs and bad input
# --------------------------------------------------------------------------------------


def _scenario(n=3000, fs=100.0, seed=0):
    t, q, gyro, accel, m_b, vel = _noisy(n / fs, fs, seed, bias_deg_s=(0.05, 0.0, -0.05))
    rx = GnssReceiver("consumer", seed=seed, rate_hz=5.0, input_rate_hz=fs)
    fixes = rx.simulate(np.cumsum(vel, axis=0) / fs, vel)
    return t, q, gyro, accel, m_b, fixes


@pytest.mark.parametrize("cls", CLASSES)
def test_any_chunking_of_imu_and_fixes_is_bit_identical(cls):
    t, q, gyro, accel, m_b, fixes = _scenario()
    whole = cls(100.0).update(gyro, accel, m_b, gnss=fixes)
    est = cls(100.0)
    rng = np.random.default_rng(1)
    parts, i, j = [], 0, 0
    while i < len(t):
        n = int(rng.integers(0, 40))
        end = t[min(i + n, len(t)) - 1] if n else -1.0
        # the fixes that arrive by the chunk's last sample, sometimes a few early (they wait)
        k = j + int(np.count_nonzero(fixes.t_arrival_s[j:] <= end + 1e-9)) + int(rng.integers(0, 3))
        k = min(k, len(fixes))
        parts.append(est.update(gyro[i:i + n], accel[i:i + n], m_b[i:i + n], gnss=fixes[j:k] if k > j else None))
        i, j = i + n, k
    for name in ("q_wb", "flags", "gyro_bias_b", "tilt_sigma_rad"):
        if getattr(whole, name) is None:
            assert all(getattr(p, name) is None for p in parts)
            continue
        np.testing.assert_array_equal(np.concatenate([getattr(p, name) for p in parts]), getattr(whole, name))
    _same(np.concatenate([p.updates for p in parts]), whole.updates)


@pytest.mark.parametrize("cls", CLASSES)
def test_state_round_trip_keeps_waiting_fixes(cls):
    import pickle

    t, q, gyro, accel, m_b, fixes = _scenario(1500)
    est = cls(100.0)
    cut = 700
    first = fixes[fixes.t_s < 7.5]  # some arrive after sample 699 (t = 6.99 s): they wait
    est.update(gyro[:cut], accel[:cut], m_b[:cut], gnss=first)
    assert est.get_state()["pending_count"][0] > 0
    snap = pickle.loads(pickle.dumps(est.get_state()))
    rest = est.update(gyro[cut:], accel[cut:], m_b[cut:], gnss=fixes[fixes.t_s >= 7.5])
    other = cls(100.0)
    other.set_state(snap)
    again = other.update(gyro[cut:], accel[cut:], m_b[cut:], gnss=fixes[fixes.t_s >= 7.5])
    np.testing.assert_array_equal(again.q_wb, rest.q_wb)
    _same(again.updates, rest.updates)


@pytest.mark.parametrize("cls", CLASSES)
def test_missing_stream_and_outage_fall_back_and_flag(cls):
    t, q, gyro, accel, m_b, fixes = _scenario(6000)
    out = cls(100.0).update(gyro, accel, m_b)
    assert (out.flags & GNSS_UNAIDED).all() and not (out.flags & GNSS_UPDATE).any()
    assert (out.updates["kind"] == UPDATE_KINDS.index("unaided")).sum() >= 55  # never aided: gravity at once
    # an outage of 20 s: coasting on the gyro for coast_s = 10 s, then the gravity reference
    hole = (fixes.t_s >= 20.0) & (fixes.t_s < 40.0)
    gap = dataclasses.replace(fixes, valid=fixes.valid & ~hole)
    out = _make(cls, 100.0, coast_s=10.0).update(gyro, accel, m_b, gnss=gap)
    unaided = (out.flags & GNSS_UNAIDED) != 0
    last = fixes.t_arrival_s[fixes.t_s < 20.0][-1]
    back = fixes.t_arrival_s[fixes.t_s >= 40.0][0]
    expect = (t > last + 3.0) & (t < back)
    clear = (t > 1.0) & (np.abs(t - last - 3.0) > 1e-6) & (np.abs(t - back) > 1e-6)
    np.testing.assert_array_equal(unaided[clear], expect[clear])
    u = out.updates[out.updates["kind"] == UPDATE_KINDS.index("unaided")]
    assert u["t_s"].min() >= last + 10.0 + 1.0 - 1e-9  # the first gravity window closes after coasting
    # the first fix after the outage only anchors
    after = out.updates[(out.updates["t_s"] >= 40.0) & (out.updates["kind"] != UPDATE_KINDS.index("unaided"))]
    assert after["kind"][0] == UPDATE_KINDS.index("anchor")


def test_gyro_policy_without_heading_is_plain_integration():
    t, q, gyro, accel, m_b, fixes = _scenario(800)
    est = _make(GnssKalmanEstimator, 100.0, unaided="gyro", t2_s=math.inf, drift_tau_s=1e12)
    est.reset(q0=q[0])
    out = est.update(gyro, accel, m_b)
    ref = [q[0]]
    for w in gyro[1:]:
        ref.append(fr.quat_normalize(fr.quat_multiply(ref[-1], fr.quat_from_rotvec(w / 100.0))))
    assert fr.quat_angle_between(out.q_wb, np.array(ref)).max() < 1e-10
    assert not out.updates.size


@pytest.mark.parametrize("cls", CLASSES)
def test_nonfinite_velocity_is_refused_and_flagged(cls):
    t, q, gyro, accel, m_b, fixes = _scenario(1500)
    bad = dataclasses.replace(fixes, vel_w=fixes.vel_w.copy())
    bad.vel_w[30, 1] = np.nan
    out = cls(100.0).update(gyro, accel, m_b, gnss=bad)
    same = cls(100.0).update(gyro, accel, m_b, gnss=dataclasses.replace(fixes, valid=np.arange(len(fixes)) != 30))
    np.testing.assert_array_equal(out.q_wb, same.q_wb)
    i = int(np.searchsorted(t, fixes.t_arrival_s[30] - 1e-9))
    assert out.flags[i] & GNSS_REJECTED and not same.flags[i] & GNSS_REJECTED
    row = out.updates[out.updates["t_s"] == fixes.t_s[30]]
    assert UPDATE_KINDS[row["kind"][0]] == "rejected_nonfinite"


@pytest.mark.parametrize("cls", CLASSES)
def test_bad_gnss_input_is_refused_and_loses_nothing(cls):
    t, q, gyro, accel, m_b, fixes = _scenario(600)
    est, ref = cls(100.0), cls(100.0)
    for e in (est, ref):
        e.update(gyro[:300], accel[:300], m_b[:300], gnss=fixes[fixes.t_arrival_s <= t[299]])
    later = fixes[fixes.t_arrival_s > t[299]]
    shuffled = later[np.r_[1, 0, 2:len(later)]]
    nan_t = dataclasses.replace(later, t_s=later.t_s.copy())
    nan_t.t_s[2] = np.nan
    early = dataclasses.replace(later, t_arrival_s=later.t_s - 0.01)
    cases = [
        (shuffled, ValueError, "gnss.t_s must increase"),
        (nan_t, ValueError, "gnss.t_s must be finite"),
        (fixes[:3], ValueError, "continue the stream"),
        (early, ValueError, "must not precede"),
        (dataclasses.replace(later, vel_w=later.vel_w[:, :2]), ValueError, "vel_w must have shape"),
        ({"t_s": later.t_s}, TypeError, "GnssFixes"),
    ]
    for gnss, exc, match in cases:
        with pytest.raises(exc, match=match):
            est.update(gyro[300:], accel[300:], m_b[300:], gnss=gnss)
    future = GnssFixes.from_arrays(10.0 + 0.2 * np.arange(20), np.zeros((20, 3)))
    with pytest.raises(ValueError, match="at most 16 may wait"):
        est.update(gyro[300:301], accel[300:301], m_b[300:301], gnss=future)
    with pytest.raises(ValueError, match="at most 16 may wait"):  # no samples: every fix waits
        est.update(gyro[:0], accel[:0], m_b[:0], gnss=future)
    with pytest.raises(TypeError, match="speed_mps"):
        est.update(gyro[300:], accel[300:], m_b[300:], gnss=later, speed_mps=np.zeros(300))
    a = est.update(gyro[300:], accel[300:], m_b[300:], gnss=later)
    b = ref.update(gyro[300:], accel[300:], m_b[300:], gnss=later)
    np.testing.assert_array_equal(a.q_wb, b.q_wb)
    _same(a.updates, b.updates)


@pytest.mark.parametrize("cls", CLASSES)
def test_invalid_imu_samples_follow_the_policy(cls):
    t, q, gyro, accel, m_b, fixes = _scenario(400)
    gyro, accel, m_b = gyro.copy(), accel.copy(), m_b.copy()
    accel[:3] = np.nan  # uninitialised until sample 3
    gyro[50] = np.inf
    accel[60] = 0.0
    m_b[70] = np.nan
    out = cls(100.0).update(gyro, accel, m_b, gnss=fixes)
    assert np.isfinite(out.q_wb).all()
    assert (out.flags[:3] & fl.UNINITIALIZED).all() and not out.flags[3] & fl.UNINITIALIZED
    np.testing.assert_array_equal(out.q_wb[:3], np.tile([1.0, 0, 0, 0], (3, 1)))
    assert out.flags[50] & fl.GYRO_INVALID and out.flags[60] & fl.ACCEL_INVALID and out.flags[70] & fl.MAG_INVALID
    # the fix of t = 0 arrived before the start (no attitude yet): refused as too old
    assert UPDATE_KINDS[out.updates["kind"][0]] == "rejected_too_old"


def test_parameters_are_documented_and_checked():
    from biso_cosim.estimators._base import param_table

    for cls in CLASSES:
        rows = param_table(cls.Params)
        assert all(r["doc"] and r["unit"] is not None for r in rows)
    for bad, match in (({"window_s": 5.0}, "max_interval_s"), ({"unaided": "pray"}, "unaided"),
                       ({"heading_coupling": "both"}, "heading_coupling"), ({"t2_s": 0.0}, "t2_s"),
                       ({"max_pitch_rad": 2.0}, "max_pitch_rad")):
        with pytest.raises(ValueError, match=match):
            _make(GnssKalmanEstimator, 100.0, **bad)
    with pytest.raises(ValueError, match="t1_s"):
        _make(GnssComplementaryEstimator, 100.0, t1_s=-1.0)
    with pytest.raises(ValueError, match="gnss_vel_sigma_mps"):
        _make(GnssKalmanEstimator, 100.0, gnss_vel_sigma_mps=(0.1,))
