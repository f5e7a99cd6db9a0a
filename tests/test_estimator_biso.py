"""Faithful BISO (Aleshkin et al. 2024, reading D): exact discretisation against a slow
scipy reference, poles, the paper's tuning, streaming, state, and the input policy."""

import math
import pickle

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from biso_cosim import frames as fr
from biso_cosim import motions as mo
from biso_cosim.estimators import (
    BisoParams,
    estimate_attitude,
    estimator_names,
    flags as fl,
    make_estimator,
    reference_attitude,
)
from biso_cosim.estimators.biso import EARTH_RATE, gains_from_cutoff, geographic_rate, stability

FIELD = np.array(mo.EARTH_FIELD_W)


# --------------------------------------------------------------------------------------
# slow plain reference (matrices and scipy; no code shared with the kernels)
# --------------------------------------------------------------------------------------


def L(a):
    w, x, y, z = a
    return np.array([[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]], float)


def R(b):
    w, x, y, z = b
    return np.array([[w, -x, -y, -z], [x, w, z, -y], [y, -z, w, x], [z, y, -x, w]], float)


P12 = np.array([[0, 1, 1, 1], [-1, 0, 1, -1], [-1, -1, 0, 1], [-1, 1, -1, 0]], float)
P13 = np.array([[0, 1, 1, -1], [-1, 0, -1, -1], [-1, 1, 0, -1], [1, 1, -1, 0]], float)


def g_matrix_q(k, kp, pattern=12):
    """G of eq. (8) on λ = q_gb, moved to q_wb components: λ = Q_NUE_ENU ∘ q ∘ Q_FLU_FUR."""
    pat = P12 if pattern == 12 else P13
    g = -np.diag(np.broadcast_to(k, 4)) - pat * np.broadcast_to(kp, 4)[None, :]
    t = L(fr.Q_NUE_ENU) @ R(fr.Q_FLU_FUR)
    return t.T @ g @ t


def ref_lambda_k(f, m, decl):
    """TRIAD with scipy: rows E, N, U in body axes; magnetic → true by −D about Up."""
    up = f / np.linalg.norm(f)
    east = np.cross(m, up)
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    r = Rotation.from_euler("z", -decl) * Rotation.from_matrix(np.array([east, north, up]))
    return np.roll(r.as_quat(), 1)


def ref_omega_g(latitude, vel, altitude=0.0):
    """Earth rate + transport rate in ENU, WGS-84 radii of curvature (written out here)."""
    a, e2 = 6378137.0, 6.69437999014e-3
    s2 = math.sin(latitude) ** 2
    rm = a * (1 - e2) / (1 - e2 * s2) ** 1.5 + altitude
    rn = a / math.sqrt(1 - e2 * s2) + altitude
    ve, vn = vel[0], vel[1]
    return (7.292115e-5 * np.array([0, math.cos(latitude), math.sin(latitude)])
            + np.array([-vn / rm, ve / rn, ve * math.tan(latitude) / rn]))


def ref_biso(gyro, accel, mag, fs, *, k=44.4, kp=25.64, pattern=12, norm_gain=1.0, renormalize=False,
             decl=0.0, latitude=None, vel=None, q0=None):
    h = 1.0 / fs
    g = g_matrix_q(k, kp, pattern)
    lam = None if q0 is None else np.asarray(q0, float)
    out = []
    for i in range(gyro.shape[0]):
        wg = np.zeros(3) if latitude is None else ref_omega_g(latitude, np.zeros(3) if vel is None else vel[i])
        lwg = L((0, *(-0.5 * wg)))
        qk = ref_lambda_k(accel[i], mag[i], decl)
        if lam is None:
            lam = qk
        elif i > 0 or q0 is None:
            if qk @ lam < 0:
                qk = -qk
            rb = R((0, *(0.5 * gyro[i])))
            # λ_k carried back to t_{i−1} along the uncorrected eq. (1)
            back = expm(-(lwg + rb) * h) @ qk
            lam = qk + expm((g + lwg + rb) * h) @ (lam - back)
            n2 = lam @ lam
            if renormalize:
                lam = lam / math.sqrt(n2)
            elif norm_gain:
                e = math.exp(2 * norm_gain * h)
                lam = lam * math.sqrt(e / (1 + n2 * (e - 1)))
        out.append(lam / np.linalg.norm(lam))
    return np.array(out)


def noisy(motion, rng, sg=0.02, sa=0.2, sm=1.0, bias=(0.01, -0.02, 0.015)):
    n = len(motion)
    return (motion.omega_b + np.asarray(bias) + sg * rng.normal(size=(n, 3)),
            motion.specific_force_b + sa * rng.normal(size=(n, 3)),
            motion.mag_b + sm * rng.normal(size=(n, 3)))


# --------------------------------------------------------------------------------------
# the kernel against the slow reference
# --------------------------------------------------------------------------------------


# a vehicle's velocity, fast enough that the transport rate is not lost in rounding
VELOCITY = "velocity"


@pytest.mark.parametrize("fs", [100.0, 1000.0])
@pytest.mark.parametrize("opts", [
    {},
    {"renormalize": True},
    {"norm_gain": 0.0, "latitude": 0.9, "decl": 0.2},
    {"latitude": -0.6, "vel": VELOCITY},
    {"pattern": 13},
    {"pattern": 13, "latitude": 1.2, "vel": VELOCITY},
    {"k": (30.0, 44.0, 50.0, 40.0), "kp": (20.0, 25.0, 22.0, 27.0)},
])
def test_kernel_matches_slow_reference(fs, opts):
    m = mo.make_motion("tumble", 2.0 if fs == 100.0 else 0.3, fs)
    gyro, accel, mag = noisy(m, np.random.default_rng(3))
    opts = dict(opts)
    inputs = {}
    if opts.get("vel") is VELOCITY:
        t = np.arange(len(m)) / fs
        opts["vel"] = np.stack([300.0 * np.cos(t), -250.0 * np.sin(0.7 * t), np.zeros_like(t)], axis=1)
        inputs["velocity_enu_mps"] = opts["vel"]
    ref = ref_biso(gyro, accel, mag, fs, **opts)
    names = {"kp": "k_p", "decl": "declination_rad", "latitude": "latitude_rad"}
    params = {names.get(key, key): v for key, v in opts.items() if key != "vel"}
    q = estimate_attitude(gyro, accel, mag, fs, "biso", **params, **inputs)
    assert np.max(fr.quat_angle_between(q, ref)) < 1e-10


def test_geographic_rate_and_the_transport_rate():
    """ω_g against the formula written out in the test, and its physics: an estimator that
    knows ω_g keeps a level vehicle level and on its heading while the geographic frame turns
    under it; without ω_g, the gyro alone drifts at |ω_g|."""
    lat, vel = 0.8, np.array([30.0, -20.0, 1.0])
    np.testing.assert_allclose(geographic_rate(lat, vel), ref_omega_g(lat, vel), rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(geographic_rate(lat), EARTH_RATE * np.array([0, math.cos(lat), math.sin(lat)]))
    # east at 300 m/s at the equator: transport rate v/R about north
    np.testing.assert_allclose(geographic_rate(0.0, [300.0, 0, 0])[1] - EARTH_RATE, 300.0 / 6378137.0, rtol=1e-12)
    # a vehicle holding its attitude in the geographic frame: the gyro measures ω_g in body axes
    fs, n = 100.0, 6000
    q = fr.quat_from_euler(0.02, -0.01, 1.0)
    v = np.tile([200.0, 150.0, 0.0], (n, 1))
    gyro = np.tile(fr.quat_rotate(fr.quat_conjugate(q), geographic_rate(lat, v[0])), (n, 1))
    f = np.tile(fr.quat_rotate(fr.quat_conjugate(q), np.array([0, 0, 9.8])), (n, 1))
    b = np.tile(fr.quat_rotate(fr.quat_conjugate(q), FIELD), (n, 1))
    held = estimate_attitude(gyro, f, b, fs, "poisson", latitude_rad=lat, q0=q, velocity_enu_mps=v)
    assert np.max(fr.quat_angle_between(held, q)) < 1e-12
    drift = estimate_attitude(gyro, f, b, fs, "poisson", q0=q)
    assert fr.quat_angle_between(drift[-1], q) == pytest.approx(np.linalg.norm(geographic_rate(lat, v[0])) * (n - 1) / fs,
                                                                 rel=1e-6)
    with pytest.raises(ValueError, match="latitude_rad"):
        make_estimator("biso", fs).update(gyro[:3], f[:3], b[:3], velocity_enu_mps=v[:3])
    with pytest.raises(ValueError, match="velocity_enu_mps"):
        make_estimator("biso", fs, latitude_rad=lat).update(gyro[:3], f[:3], b[:3], velocity_enu_mps=v[:2])
    with pytest.raises(ValueError, match="latitude_rad"):
        make_estimator("biso", fs, latitude_rad=1.5705)


def test_norm_flow_far_from_unit_norm_is_the_exact_logistic_flow():
    """λ with |λ|² = 1.44 (the series is not used there) and with |λ|² − 1 = 1e-6 (it is):
    one step of poisson with the norm term against the exact flow |λ|² E/(1 + |λ|²(E − 1))."""
    fs, gn = 50.0, 3.0
    e = math.exp(2 * gn / fs)
    for n2 in (1.44, 1.0 + 1e-6, 1.0 - 1e-6):
        est = make_estimator("poisson", fs, norm_gain=gn)
        est.update(np.zeros((1, 3)), np.array([[0, 0, 9.8]]), FIELD[None])
        st = est.get_state()
        v = st.values.copy()
        v[1:5] = math.sqrt(n2) * np.array([0.5, 0.5, -0.5, 0.5])
        est.set_state(type(st)(st.method, v, st.layout))
        est.update(np.zeros((1, 3)), np.array([[0, 0, 9.8]]), FIELD[None])
        lam = est.get_state()["lam"]
        assert lam @ lam == pytest.approx(n2 * e / (1 + n2 * (e - 1)), rel=1e-15)


def test_error_dynamics_are_exact_at_100_hz():
    """Perfect sensors: e_i = e^{ah} ∘ e_{i−1} ∘ e^{bh} exactly; |e| decays as e^{−kt}."""
    fs, k, kp = 100.0, 44.4, 25.64
    h = 1.0 / fs
    m = mo.make_motion("rotation", 1.0, fs, omega_b=(3.0, -5.0, 7.0))
    # consistent truth for held rates: q_i = q_{i−1} ∘ exp(ω h)
    q_true = np.empty_like(m.q_wb)
    q_true[0] = m.q_wb[0]
    step = fr.quat_from_rotvec(m.omega_b[0] * h)
    for i in range(1, len(m)):
        q_true[i] = fr.quat_multiply(q_true[i - 1], step)
    f = fr.quat_rotate(fr.quat_conjugate(q_true), np.array([0, 0, 9.81]))
    b = fr.quat_rotate(fr.quat_conjugate(q_true), FIELD)
    est = make_estimator("biso", fs, norm_gain=0.0)
    est.update(m.omega_b[:1], f[:1], b[:1])
    state = est.get_state()
    lam0 = q_true[0] + np.array([0.05, -0.03, 0.02, 0.04])  # an unnormalised start error
    values = state.values.copy()
    values[1:5] = lam0
    est.set_state(type(state)(state.method, values, state.layout))
    errs = [lam0 - q_true[0]]
    for i in range(1, len(m)):
        est.update(m.omega_b[i:i + 1], f[i:i + 1], b[i:i + 1])
        errs.append(est.get_state()["lam"] - q_true[i])
    a = np.array([-k, kp, kp, kp])
    phi = expm(L(a) * h) @ expm(R((0, *(0.5 * m.omega_b[0]))) * h)
    for i in range(1, len(errs)):
        np.testing.assert_allclose(errs[i], phi @ errs[i - 1], atol=1e-14)
        if np.linalg.norm(errs[i]) > 1e-9:  # above the rounding of the simulated truth
            assert np.linalg.norm(errs[i]) == pytest.approx(math.exp(-k * h) * np.linalg.norm(errs[i - 1]), rel=1e-9)


def test_discrete_poles_are_exp_of_continuous_poles():
    """Transition of the error over one step: eigenvalues e^{ph}, p = −k ± i(√3k_p ± |ω|/2)."""
    fs, k, kp = 100.0, 44.4, 25.64
    w = np.array([1.0, 2.0, -2.0])  # |ω| = 3
    q_k = fr.quat_from_euler(0.1, 0.2, 0.3)
    f = fr.quat_rotate(fr.quat_conjugate(q_k), np.array([0, 0, 9.81]))[None]
    b = fr.quat_rotate(fr.quat_conjugate(q_k), FIELD)[None]
    # λ_k held moving with the gyro: at t_{i−1} it is q_k ∘ e^{−bh}
    q_prev = fr.quat_multiply(q_k, fr.quat_from_rotvec(-w / fs))
    cols = []
    for j in range(4):
        est = make_estimator("biso", fs, norm_gain=0.0)
        est.update(np.zeros((1, 3)), f, b)
        st = est.get_state()
        v = st.values.copy()
        v[1:5] = q_prev + 1e-3 * np.eye(4)[j]
        est.set_state(type(st)(st.method, v, st.layout))
        est.update(w[None], f, b)
        cols.append((est.get_state()["lam"] - q_k) / 1e-3)
    eig = np.sort_complex(np.linalg.eigvals(np.array(cols).T))
    p = np.array([-k + 1j * s1 * (math.sqrt(3) * kp + s2 * 1.5) for s1 in (1, -1) for s2 in (1, -1)])
    np.testing.assert_allclose(eig, np.sort_complex(np.exp(p / fs)), atol=1e-9)


def test_paper_tuning_and_readings():
    k, kp = gains_from_cutoff(10.0)
    assert k == pytest.approx(44.4, rel=2e-3) and kp == pytest.approx(25.64, rel=2e-3)
    poles = stability(BisoParams())["poles_at_rest"]
    np.testing.assert_allclose(np.sort(poles.imag), [-44.4098, -44.4098, 44.4098, 44.4098], atol=1e-3)
    np.testing.assert_allclose(poles.real, -44.4)
    # reading L: the same gains give poles at half the frequency (the 5 Hz of docs/design.md §5)
    lit = stability(BisoParams(reading="L"))["poles_at_rest"]
    np.testing.assert_allclose(np.abs(lit), 0.5 * np.abs(poles))
    # pattern (13): −k ± i k_p and −k ± i√3 k_p
    p13 = stability(BisoParams(pattern=13))["poles_at_rest"]
    np.testing.assert_allclose(np.sort(np.abs(p13.imag)), [25.64, 25.64, 44.4098, 44.4098], atol=1e-3)
    # cutoff_hz with reading L keeps the poles where the cutoff says
    cl = stability(BisoParams(cutoff_hz=10.0, reading="L"))["poles_at_rest"]
    np.testing.assert_allclose(np.abs(cl), 2 * math.pi * 10.0)


def test_equal_gains_are_stable_at_any_rate_and_contractive():
    st = stability(BisoParams(), rates_rad_s=np.array([[50.0, -30.0, 80.0], [5.0, 5.0, 5.0]]))
    assert st["contractive"]
    assert st["max_real_rotating"] == pytest.approx(-44.4)


def test_unstable_gains_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="at the body rate"):
        make_estimator("biso", 200.0, k=(1.0, 1.0, 1.0, 1.0), k_p=(30.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="poles at rest"):
        make_estimator("biso", 200.0, pattern=13, k=(39.03, 27.6, 2.77, 13.78), k_p=(13.37, 4.94, 44.35, 31.07))
    with pytest.raises(ValueError, match="not asymptotically stable"):
        make_estimator("biso", 200.0, k=0.0, k_p=10.0)
    with pytest.raises(ValueError, match="k_p"):
        make_estimator("biso", 200.0, k_p=-1.0)
    with pytest.raises(ValueError, match="cutoff_hz or k"):
        make_estimator("biso", 200.0, cutoff_hz=5.0, k=10.0)


# --------------------------------------------------------------------------------------
# behaviour
# --------------------------------------------------------------------------------------


def test_poisson_integrates_exactly_and_ignores_the_correction():
    fs = 200.0
    m = mo.make_motion("rotation", 2.0, fs, omega_b=(0.5, -2.0, 1.0))
    f = m.specific_force_b + 3.0  # a wrong accelerometer must not matter after the first sample
    q = estimate_attitude(m.omega_b, f, m.mag_b, fs, "poisson", q0=m.q_wb[0])
    assert np.max(fr.quat_angle_between(q, m.q_wb)) < 1e-12


def test_converges_from_a_wrong_start_and_tracks_fast_rotation_at_100_hz():
    fs = 100.0
    m = mo.make_motion("tumble", 20.0, fs)
    q = estimate_attitude(m.omega_b, m.specific_force_b, m.mag_b, fs, "biso", q0=fr.quat_from_euler(2.0, -1.0, 3.0))
    err = fr.quat_angle_between(q, m.q_wb)
    assert err[0] > 1.0
    # truth is smooth (not held), so a small commutation error remains; it is tiny
    assert np.max(err[int(fs):]) < 2e-3


def test_first_sample_initialises_from_accel_and_mag():
    m = mo.make_motion("static", 0.1, 200.0)
    q = estimate_attitude(m.omega_b, m.specific_force_b, m.mag_b, 200.0, "biso")
    assert np.max(fr.quat_angle_between(q, m.q_wb)) < 1e-12
    q = estimate_attitude(m.omega_b, m.specific_force_b, m.mag_b, 200.0, "biso", q0=[0, 1, 0, 0])
    np.testing.assert_array_equal(q[0], [0.0, 1.0, 0.0, 0.0])


def test_reference_constructions_agree_and_apply_declination():
    rng = np.random.default_rng(5)
    q = rng.normal(size=(500, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    pitch = fr.euler_from_quat(q)[:, 1]
    q = q[np.abs(pitch) < np.radians(85)]
    decl = 0.3
    # the field's north is D east of true north
    field = np.array([FIELD[1] * math.sin(decl), FIELD[1] * math.cos(decl), FIELD[2]])
    f = fr.quat_rotate(fr.quat_conjugate(q), np.array([0, 0, 9.8]))
    b = fr.quat_rotate(fr.quat_conjugate(q), field)
    for method in ("vector", "euler"):
        qk = np.array([reference_attitude(f[i:i + 1], b[i:i + 1], declination_rad=decl, method=method)[0]
                       for i in range(len(q))])
        assert np.max(fr.quat_angle_between(qk, q)) < 1e-9
    # vector has no singularity: straight up
    q_up = fr.quat_from_euler(0.3, -math.pi / 2, 1.0)
    f = fr.quat_rotate(fr.quat_conjugate(q_up), np.array([0, 0, 9.8]))[None]
    b = fr.quat_rotate(fr.quat_conjugate(q_up), FIELD)[None]
    assert fr.quat_angle_between(reference_attitude(f, b)[0], q_up) < 1e-9


# --------------------------------------------------------------------------------------
# streaming, state, parameters
# --------------------------------------------------------------------------------------


def _bad_samples(n, rng):
    m = mo.make_motion("shake", n / 200.0, 200.0)
    gyro, accel, mag = noisy(m, rng)
    gyro[7] = np.nan
    accel[11] = [np.inf, 0, 0]
    accel[12] = 0.0
    mag[20] = np.nan
    return gyro, accel, mag


@pytest.mark.parametrize("name", ["biso", "poisson", "positional"])
def test_any_chunking_is_bit_identical_to_one_call(name):
    rng = np.random.default_rng(7)
    gyro, accel, mag = _bad_samples(400, rng)
    whole = make_estimator(name, 200.0).update(gyro, accel, mag)
    est = make_estimator(name, 200.0)
    parts, i = [], 0
    while i < 400:
        n = int(rng.integers(0, 9))
        parts.append(est.update(gyro[i:i + n], accel[i:i + n], mag[i:i + n]))
        i += n
    np.testing.assert_array_equal(np.concatenate([p.q_wb for p in parts]), whole.q_wb)
    np.testing.assert_array_equal(np.concatenate([p.flags for p in parts]), whole.flags)


def test_state_round_trip_and_pickle():
    rng = np.random.default_rng(8)
    gyro, accel, mag = _bad_samples(300, rng)
    est = make_estimator("biso", 200.0, pattern=13)
    est.update(gyro[:150], accel[:150], mag[:150])
    snap = pickle.loads(pickle.dumps(est.get_state()))
    rest = est.update(gyro[150:], accel[150:], mag[150:])
    other = make_estimator("biso", 200.0, pattern=13)
    other.set_state(snap)
    assert other.get_state() == snap and other.get_state() is not snap
    np.testing.assert_array_equal(other.update(gyro[150:], accel[150:], mag[150:]).q_wb, rest.q_wb)
    assert other.get_state() != snap
    assert snap.q_wb.shape == (4,)
    with pytest.raises(ValueError, match="method"):
        make_estimator("poisson", 200.0).set_state(snap)
    with pytest.raises(TypeError):
        est.set_state(snap.values)


def test_set_params_retunes_without_a_jump():
    m = mo.make_motion("static", 2.0, 200.0)
    gyro, accel, mag = noisy(m, np.random.default_rng(9))
    est = make_estimator("biso", 200.0)
    a = est.update(gyro[:200], accel[:200], mag[:200]).q_wb
    est.set_params(cutoff_hz=1.0, k=None, k_p=None)
    b = est.update(gyro[200:], accel[200:], mag[200:]).q_wb
    assert fr.quat_angle_between(a[-1], b[0]) < 0.01
    assert est.params.cutoff_hz == 1.0
    with pytest.raises(ValueError):
        est.set_params(k=(1.0, 1.0, 1.0, 1.0), k_p=(30.0, 0.0, 0.0, 0.0), cutoff_hz=None)
    assert est.params.cutoff_hz == 1.0  # refused change leaves everything as it was
    with pytest.raises(TypeError, match="no parameter"):
        est.set_params(gain=3)


# --------------------------------------------------------------------------------------
# bad input
# --------------------------------------------------------------------------------------


def test_registry_errors():
    assert {"biso", "poisson", "positional"} <= set(estimator_names())
    with pytest.raises(ValueError, match="biso.*poisson"):
        make_estimator("madgwick", 200.0)
    with pytest.raises(TypeError, match="no parameter"):
        make_estimator("biso", 200.0, gain=1.0)
    with pytest.raises(TypeError, match="fixes"):
        make_estimator("poisson", 200.0, k=3.0)
    for fs in (0.0, -5.0, float("nan")):
        with pytest.raises(ValueError, match="fs_hz"):
            make_estimator("biso", fs)


def test_wrong_shapes_are_refused_and_lose_nothing():
    rng = np.random.default_rng(10)
    gyro, accel, mag = _bad_samples(60, rng)
    est, ref = make_estimator("biso", 200.0), make_estimator("biso", 200.0)
    first = est.update(gyro[:30], accel[:30], mag[:30])
    ref.update(gyro[:30], accel[:30], mag[:30])
    with pytest.raises(ValueError, match="mag_b"):
        est.update(gyro[30:], accel[30:], mag[30:40])
    with pytest.raises(ValueError, match=r"gyro_b must have shape \(k, 3\)"):
        est.update(gyro[30:, :2], accel[30:], mag[30:])
    with pytest.raises(TypeError, match="accel_b"):
        est.update(gyro[30:], "abc", mag[30:])
    with pytest.raises(TypeError, match="does not take"):
        est.update(gyro[30:], accel[30:], mag[30:], speed_mps=np.zeros(30))
    with pytest.raises(ValueError, match="q0"):
        est.reset(q0=[0, 0, 0, 0])
    np.testing.assert_array_equal(est.update(gyro[30:], accel[30:], mag[30:]).q_wb,
                                  ref.update(gyro[30:], accel[30:], mag[30:]).q_wb)
    assert first.q_wb.shape == (30, 4)
    empty = est.update(np.empty((0, 3)), np.empty((0, 3)), np.empty((0, 3)))
    assert empty.q_wb.shape == (0, 4) and empty.flags.shape == (0,)


def test_nan_policy():
    m = mo.make_motion("rotation", 1.0, 200.0)
    gyro, accel, mag = m.omega_b.copy(), m.specific_force_b.copy(), m.mag_b.copy()
    gyro[50] = np.nan
    accel[60] = np.nan
    accel[61] = 0.0
    mag[70] = [np.inf, 1, 2]
    mag[71] = accel[71] * 3.0  # parallel to f: no heading
    out = make_estimator("biso", 200.0).update(gyro, accel, mag)
    assert np.all(np.isfinite(out.q_wb))
    assert out.flags[50] == fl.GYRO_INVALID
    assert out.flags[60] == out.flags[61] == fl.ACCEL_INVALID | fl.MAG_INVALID
    assert out.flags[70] == out.flags[71] == fl.MAG_INVALID
    assert np.count_nonzero(out.flags) == 5
    # a NaN gyro sample is the previous valid one held
    held = gyro.copy()
    held[50] = gyro[49]
    ref = make_estimator("biso", 200.0).update(held, accel, mag)
    np.testing.assert_array_equal(ref.q_wb[50:60], out.q_wb[50:60])
    # consistent rotation: skipping corrections or heading keeps the truth
    assert np.max(fr.quat_angle_between(out.q_wb, m.q_wb)) < 1e-3


def test_no_valid_accelerometer_yet_gives_identity_and_flag():
    n = 5
    acc = np.full((n, 3), np.nan)
    acc[3] = [0, 0, 9.8]
    out = make_estimator("biso", 100.0).update(np.zeros((n, 3)), acc, np.tile(FIELD, (n, 1)))
    np.testing.assert_array_equal(out.q_wb[:3], np.tile([1.0, 0, 0, 0], (3, 1)))
    assert np.all(out.flags[:3] & fl.UNINITIALIZED)
    assert out.flags[3] == 0 and out.flags[4] == fl.ACCEL_INVALID | fl.MAG_INVALID


# --------------------------------------------------------------------------------------
# gyro_step: a coning algorithm of Litmanovich (2002) as BISO's attitude propagation
# --------------------------------------------------------------------------------------


def _coning_data(seconds=2.0, fs=200.0, alpha=0.05, f_cone=8.0):
    from biso_cosim.strapdown.motions import ConingMotion

    motion = ConingMotion(alpha, 2.0 * math.pi * f_cone)
    h = 1.0 / fs
    t = np.arange(int(seconds * fs)) * h
    gyro = motion.omega_b(t)  # the rate sampled at each sample's time
    dtheta = motion.omega_b.multiple_integrals(t - h, h, 4)  # sample i covers (t_i − h, t_i]
    f = np.tile([0.0, 0.0, 9.80665], (t.size, 1))
    mag = np.tile([0.0, 20.0, -40.0], (t.size, 1))
    return motion, t, gyro, f, mag, dtheta


def test_gyro_step_is_the_rotation_vector_chain_of_the_strapdown_algorithm():
    """Uncorrected (k = k_p = 0), BISO's step with gyro_step turns λ by exactly Φ = ΔΘ + δΘ_c
    of the chosen coning algorithm (eq. (1.11)): the chain q ∘ exp(Φ), to rounding."""
    from biso_cosim.strapdown import rotation_vector

    motion, t, gyro, f, mag, dtheta = _coning_data()
    h = t[1] - t[0]
    q0 = motion.q_wb(t[:1])[0]
    for step in ("invariant", "smoothing", "one_sample"):
        rows = dtheta[:, :1] if step == "one_sample" else dtheta  # ΔΘ¹ is the interval's increment
        est = make_estimator("poisson", 1.0 / h, gyro_step=step, norm_gain=0.0)
        est.reset(q0=q0)
        q = est.update(gyro, f, mag, dtheta_b=rows).q_wb
        phi = rotation_vector(step, rows[1:], h)
        ref = [q0]
        for p in phi:
            ref.append(fr.quat_multiply(ref[-1], fr.quat_from_rotvec(p)))
        np.testing.assert_allclose(np.abs(np.sum(q * np.array(ref), axis=1)), 1.0, atol=1e-12, err_msg=step)


def test_gyro_step_removes_the_coning_drift_of_the_held_rate():
    """On pure coning a rate held over each interval, or the bare increment (one_sample),
    drifts about the cone axis by the coning integral it misses; the invariant algorithm on the exact multiple integrals
    is left with its fourth-order residual (4.14): orders of magnitude smaller."""
    motion, t, gyro, f, mag, dtheta = _coning_data()
    q0 = motion.q_wb(t[:1])[0]
    truth = motion.q_wb(t)
    err = {}
    for step in ("hold", "one_sample", "invariant"):
        est = make_estimator("poisson", 200.0, gyro_step=step)
        est.reset(q0=q0)
        rows = dtheta[:, :1] if step == "one_sample" else dtheta
        q = est.update(gyro, f, mag, **({} if step == "hold" else {"dtheta_b": rows})).q_wb
        err[step] = float(np.max(fr.quat_angle_between(q, truth)))
    # one_sample misses the exact coning integral of every interval, ½sin²α(ω_cT − sin ω_cT)
    drift = motion.coning_integral_z(t[1] - t[0]) * (t.size - 1)
    assert err["one_sample"] == pytest.approx(drift, rel=0.02)
    assert err["invariant"] < 1e-3 * err["one_sample"]
    assert err["invariant"] < 1e-3 * err["hold"]


def test_gyro_step_input_policy():
    motion, t, gyro, f, mag, dtheta = _coning_data(seconds=0.2)
    with pytest.raises(ValueError, match="gyro_step must be one of hold, one_sample"):
        make_estimator("biso", 200.0, gyro_step="rk4")
    est = make_estimator("biso", 200.0, gyro_step="invariant")
    with pytest.raises(ValueError, match="needs the gyro increments: pass dtheta_b"):
        est.update(gyro, f, mag)
    with pytest.raises(ValueError, match=r"m >= 4\), got m = 2"):
        est.update(gyro, f, mag, dtheta_b=dtheta[:, :2])
    with pytest.raises(ValueError, match=r"dtheta_b must have shape \(40, m, 3\)"):
        est.update(gyro, f, mag, dtheta_b=dtheta[:-1])
    with pytest.raises(ValueError, match="with gyro_step='hold' leave it out"):
        make_estimator("biso", 200.0).update(gyro, f, mag, dtheta_b=dtheta)
    # a sample with non-finite increments falls back to its gyro reading
    bad = dtheta.copy()
    bad[5, 2, 0] = np.nan
    a = make_estimator("biso", 200.0, gyro_step="invariant").update(gyro, f, mag, dtheta_b=bad)
    gyro_eff = gyro.copy()
    from biso_cosim.strapdown import rotation_vector

    ok = np.arange(t.size) != 5
    gyro_eff[ok] = rotation_vector("invariant", dtheta[ok], 1 / 200.0) / (1 / 200.0)
    b = make_estimator("biso", 200.0).update(gyro_eff, f, mag)
    np.testing.assert_array_equal(a.q_wb, b.q_wb)
    assert not np.any(a.flags & fl.GYRO_INVALID)


def test_gyro_step_kernel_is_the_rotation_vector_chain_bit_for_bit():
    """``_rates_from_increments`` (BISO's gyro step in its kernels: ``update`` and the period
    call) against its slow twin ``rates_from_increments`` (the strapdown package's
    ``rotation_vector``, numpy): every coning algorithm, increments over 11 decades, a NaN, an
    inf and a row of −0.0, the multiple integrals with a row more than the algorithm reads,
    and the same rows as a strided view (the period call slices the sensor's increments)."""
    from biso_cosim.estimators.biso import _rates_from_increments, rates_from_increments
    from biso_cosim.strapdown.algorithms import list_algorithms

    rng = np.random.default_rng(1)
    h = 1.0 / 200.0
    for info in list_algorithms("coning"):
        for m in {info.m_dtheta, info.m_dtheta + (info.form == "multiple")}:
            dtheta = rng.normal(size=(300, m, 3)) * 10.0 ** rng.uniform(-10.0, 1.0, size=(300, m, 3))
            dtheta[5, 0, 1], dtheta[7, m - 1, 2], dtheta[9] = np.nan, np.inf, -0.0
            gyro = rng.normal(size=(300, 3))
            want = rates_from_increments(info, dtheta, gyro, h)
            got = np.empty((300, 3))
            _rates_from_increments(info.id, info.form == "sub", dtheta, gyro, h, got)
            assert got.tobytes() == want.tobytes(), (info.name, m)
            wide = np.concatenate([dtheta, rng.normal(size=(300, 2, 3))], axis=1)[:, :m]
            _rates_from_increments(info.id, info.form == "sub", wide, gyro, h, got)
            assert got.tobytes() == want.tobytes(), (info.name, m, "strided")
            assert np.array_equal(got[5], gyro[5]) and np.array_equal(got[7], gyro[7])  # non-finite: the reading


def test_gyro_step_in_the_loop_gets_the_sensor_increments():
    """The co-simulation asks the MPU-9250 model for the increments the algorithm needs and
    passes them in; re-running offline on the logged samples gives the same estimates."""
    from biso_cosim.cosim import CoSimulation, EstimatorSpec

    sim = CoSimulation("figure8", duration_s=2.0, seed=3, estimators=[
        EstimatorSpec("biso", {"gyro_step": "invariant"}, label="inv"),
        EstimatorSpec("biso", {"gyro_step": "traditional3"}, label="t3")], gnss=None)
    r = sim.run()
    assert r.imu.dtheta.shape[1] >= 4 and r.imu.dtheta_sub.shape[1] == 3
    for label, step, dth in (("inv", "invariant", r.imu.dtheta), ("t3", "traditional3", r.imu.dtheta_sub)):
        est = make_estimator("biso", 200.0, gyro_step=step, declination_rad=sim.earth.declination_rad)
        q = est.update(r.imu.gyro_b, r.imu.accel_b, r.imu.mag_b, dtheta_b=dth).q_wb
        np.testing.assert_array_equal(q, r.estimates[label][0])


@pytest.mark.parametrize("reading", ["D", "L"])
@pytest.mark.parametrize("latitude", [None, 0.9])
def test_gain_changes_take_the_short_path_to_the_same_coefficients(reading, latitude):
    """set_params with equal scalar gains (GainTuning's change every step) derives only the
    gain-dependent coefficients: the same array, bit for bit, as the full derivation; other
    changes and invalid gains take the full path (its checks and messages)."""
    from biso_cosim.estimators.biso import biso_coefficients

    rng = np.random.default_rng(4)
    est = make_estimator("biso", 200.0, reading=reading, latitude_rad=latitude)
    for i in range(60):
        if i % 3 == 0:
            changes = {"cutoff_hz": float(rng.uniform(0.01, 20.0)), "k": None, "k_p": None}
        else:
            changes = {"k": float(rng.uniform(0.01, 50.0)), "k_p": float(rng.uniform(0.0, 50.0)), "cutoff_hz": None}
        est.set_params(**changes)
        assert np.array_equal(est.coefficients, biso_coefficients(est.params, 200.0))
        assert all(getattr(est.params, name) == value for name, value in changes.items())
    before = (est.params, est.coefficients)
    for bad, message in (({"k": 0.0}, "not asymptotically stable"), ({"k": float("nan")}, "k"),
                         ({"cutoff_hz": 1.0}, "either cutoff_hz or k")):
        with pytest.raises(ValueError, match=message):
            est.set_params(**bad)
        assert est.params == before[0] and np.array_equal(est.coefficients, before[1])
    est.set_params(k=(1.0, 2.0, 3.0, 4.0), k_p=0.5)  # per-channel gains: the full path
    assert np.array_equal(est.coefficients, biso_coefficients(est.params, 200.0))
