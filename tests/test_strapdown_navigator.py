"""The strapdown navigator: streaming = batch, state, reference twin, exact position (5.2),
drift on the coning and sculling motions end to end, gravity and bad input."""

import copy
import math
import pickle

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from biso_cosim import frames
from biso_cosim import strapdown as sd
from biso_cosim.strapdown.motions import ConingMotion, HarmonicSignal, ScullingMotion
from biso_cosim.units import G0


def _random_increments(rng, n, m, T, multiple):
    """Plausible increments: rates ~1 rad/s, specific force ~10 m/s²."""
    scale = T ** np.arange(1, m + 1) / np.array([math.factorial(r) for r in range(1, m + 1)]) if multiple \
        else np.full(m, T / m)
    th = rng.normal(size=(n, m, 3)) * scale[:, None]
    dv = (rng.normal(size=(n, m, 3)) * 3.0 + [0, 0, G0]) * scale[:, None]
    return th, dv


def _scipy(q):
    return Rotation.from_quat(np.roll(q, -1))


def reference_navigate(params, dtheta, dv, q0, v0, p0):
    """Plain Python/NumPy/scipy twin of the navigator, one interval at a time."""
    T, g = params.interval_s, np.array(params.gravity_w)
    multiple = sd.StrapdownNavigator(params).input_form == "multiple"
    rot, v, p = _scipy(np.asarray(q0, float)), np.array(v0, float), np.array(p0, float)
    qs, vs, ps = [], [], []
    for th, a in zip(dtheta, dv):
        tot_th = th[0] if multiple else th.sum(axis=0)
        tot_v = a[0] if multiple else a.sum(axis=0)
        con_in = tot_th[None] if params.coning == "one_sample" else th
        s_th, s_v = (tot_th[None], tot_v[None]) if params.sculling == "traditional1" else (th, a)
        v_new = v + rot.apply(tot_v + sd.sculling_correction(params.sculling, s_th, s_v, T)) + g * T
        if params.position == "rectangle":
            p = p + v * T
        elif params.position == "trapezoid":
            p = p + 0.5 * (v + v_new) * T
        else:
            ds = a[1] + sd.position_correction(params.sculling, s_th, s_v, T)
            p = p + v * T + rot.apply(ds) + 0.5 * g * T * T
        v = v_new
        rot = rot * Rotation.from_rotvec(tot_th + sd.coning_correction(params.coning, con_in, T))
        q = np.roll(rot.as_quat(), 1)
        qs.append(q * np.sign(q[0]))
        vs.append(v)
        ps.append(p)
    return np.array(qs), np.array(vs), np.array(ps)


CASES = [
    # (coning, sculling, position, form, m)
    ("invariant", "invariant_rate1", "exact", "multiple", 4),
    ("smoothing", "smoothing", "exact", "multiple", 4),
    ("one_sample", "invariant_accel1", "exact", "multiple", 4),
    ("invariant", "traditional1", "trapezoid", "multiple", 4),
    ("traditional3", "traditional1", "rectangle", "sub", 3),
    ("two_sample", "traditional2", "trapezoid", "sub", 2),
    ("one_sample", "traditional1", "rectangle", "sub", 5),
]


@pytest.mark.parametrize("coning, sculling, position, form, m", CASES)
def test_navigator_matches_plain_reference(coning, sculling, position, form, m):
    rng = np.random.default_rng(11)
    T = 0.01
    params = sd.NavigatorParams(T, coning=coning, sculling=sculling, position=position)
    assert sd.StrapdownNavigator(params).input_form == form
    th, dv = _random_increments(rng, 300, m, T, form == "multiple")
    q0 = frames.quat_normalize(rng.normal(size=4))
    v0, p0 = rng.normal(size=3) * 5, rng.normal(size=3) * 100
    out = sd.navigate(params, th, dv, q_wb=q0, v_w=v0, p_w=p0, t_s=2.0)
    q_ref, v_ref, p_ref = reference_navigate(params, th, dv, q0, v0, p0)
    np.testing.assert_allclose(out.q_wb * np.sign(out.q_wb[:, :1]), q_ref, atol=1e-12)
    np.testing.assert_allclose(out.v_w, v_ref, atol=1e-11)
    np.testing.assert_allclose(out.p_w, p_ref, atol=1e-10)
    np.testing.assert_allclose(out.t_s, 2.0 + T * np.arange(1, 301), rtol=1e-15)


def test_streaming_equals_batch_bit_for_bit_and_state_round_trip():
    rng = np.random.default_rng(4)
    T = 0.005
    params = sd.NavigatorParams(T)
    th, dv = _random_increments(rng, 400, 4, T, True)
    q0 = frames.quat_normalize(rng.normal(size=4))
    batch = sd.navigate(params, th, dv, q_wb=q0, t_s=1.0)
    nav = sd.StrapdownNavigator(params, q_wb=q0, t_s=1.0)
    parts = [nav.update(th[a:b], dv[a:b]) for a, b in ((0, 0), (0, 1), (1, 18), (18, 18), (18, 250), (250, 400))]
    for field in ("t_s", "q_wb", "v_w", "p_w"):
        np.testing.assert_array_equal(np.concatenate([getattr(o, field) for o in parts]), getattr(batch, field))
    assert nav.t_s == batch.t_s[-1]

    # get_state / set_state, also through pickle and deepcopy
    nav2 = sd.StrapdownNavigator(params, q_wb=q0, t_s=1.0)
    nav2.update(th[:200], dv[:200])
    state = nav2.get_state()
    first = nav2.update(th[200:], dv[200:])
    for restored in (state, pickle.loads(pickle.dumps(state)), copy.deepcopy(state)):
        nav2.set_state(restored)
        again = nav2.update(th[200:], dv[200:])
        np.testing.assert_array_equal(again.q_wb, first.q_wb)
        np.testing.assert_array_equal(again.p_w, batch.p_w[200:])
    assert nav2.get_state() == nav.get_state()


def test_refused_update_keeps_the_state():
    rng = np.random.default_rng(8)
    T = 0.01
    params = sd.NavigatorParams(T)
    th, dv = _random_increments(rng, 50, 4, T, True)
    nav = sd.StrapdownNavigator(params)
    nav.update(th[:20], dv[:20])
    before = nav.get_state()
    bad = th[20:].copy()
    bad[7, 2, 1] = np.inf
    with pytest.raises(ValueError, match=r"dtheta contains non-finite values \(first in interval 7\)"):
        nav.update(bad, dv[20:])
    with pytest.raises(ValueError, match=r"dtheta must hold the multiple integrals ΔΘ¹..ΔΘ\^4 \(m >= 4\) per interval "
                                         r"for coning='invariant'.*got m = 3"):
        nav.update(th[20:, :3], dv[20:])
    with pytest.raises(ValueError, match="same intervals"):
        nav.update(th[20:], dv[21:])
    with pytest.raises(ValueError, match=r"shape \(k, m, 3\)"):
        nav.update(th[20], dv[20])
    assert nav.get_state() == before
    ref = sd.StrapdownNavigator(params)
    ref.update(th[:20], dv[:20])
    np.testing.assert_array_equal(nav.update(th[20:], dv[20:]).p_w, ref.update(th[20:], dv[20:]).p_w)


def test_params_and_state_validation():
    with pytest.raises(ValueError, match="unknown coning algorithm 'bogus'; known:"):
        sd.NavigatorParams(0.01, coning="bogus")
    with pytest.raises(ValueError, match="unknown position method 'simpson'"):
        sd.NavigatorParams(0.01, position="simpson")
    with pytest.raises(ValueError, match="'traditional3' takes sub-interval increments"):
        sd.NavigatorParams(0.01, coning="traditional3", sculling="smoothing")
    with pytest.raises(ValueError, match="position='exact' .* needs ΔV²"):
        sd.NavigatorParams(0.01, coning="traditional3", sculling="traditional1", position="exact", input_form="sub")
    with pytest.raises(ValueError, match=r"different numbers of sub-interval increments \(\[2, 3\]\)"):
        sd.NavigatorParams(0.01, coning="traditional3", sculling="traditional2", position="rectangle")
    with pytest.raises(ValueError, match="interval_s must be finite and > 0"):
        sd.NavigatorParams(0.0)
    with pytest.raises(ValueError, match="gravity_w must be 3 finite numbers"):
        sd.NavigatorParams(0.01, gravity_w=(0.0, np.nan, -9.8))
    with pytest.raises(ValueError, match="input_form must be"):
        sd.NavigatorParams(0.01, input_form="increments")
    with pytest.raises(TypeError, match="params must be a NavigatorParams"):
        sd.StrapdownNavigator({"interval_s": 0.01})
    with pytest.raises(ValueError, match="q_wb must be non-zero"):
        sd.StrapdownNavigator(sd.NavigatorParams(0.01), q_wb=(0, 0, 0, 0))
    with pytest.raises(ValueError, match=r"v_w must have shape \(3,\)"):
        sd.StrapdownNavigator(sd.NavigatorParams(0.01), v_w=(0, 0))
    nav = sd.StrapdownNavigator(sd.NavigatorParams(0.01))
    with pytest.raises(ValueError, match="steps must be an integer >= 0"):
        nav.set_state(sd.NavigatorState(np.array([1.0, 0, 0, 0]), np.zeros(3), np.zeros(3), 0.0, -1))
    # sub form with one-sample algorithms: any m, summed
    nav = sd.StrapdownNavigator(sd.NavigatorParams(0.01, coning="one_sample", sculling="traditional1",
                                                   position="rectangle"))
    assert nav.input_form == "sub"
    with pytest.raises(ValueError, match="exactly m = 3 sub-interval increments"):
        sd.StrapdownNavigator(sd.NavigatorParams(0.01, coning="traditional3", sculling="traditional1",
                                                 position="rectangle")).update(np.zeros((2, 2, 3)), np.zeros((2, 3, 3)))


@pytest.mark.parametrize("position", ["rectangle", "trapezoid", "exact"])
def test_at_rest_stays_at_rest(position):
    """An accelerometer at rest reads +g up in body axes; gravity (0, 0, −g) ENU cancels it."""
    rng = np.random.default_rng(1)
    q0 = frames.quat_normalize(rng.normal(size=4))
    T = 0.02
    f_b = frames.quat_rotate(frames.quat_conjugate(q0), [0.0, 0.0, G0])
    dv = np.zeros((100, 4, 3))
    dv[:, :, :] = f_b * (T ** np.arange(1, 5) / [1, 2, 6, 24])[:, None]
    params = sd.NavigatorParams(T, coning="one_sample", sculling="traditional1", position=position,
                                input_form="multiple")
    out = sd.navigate(params, np.zeros_like(dv), dv, q_wb=q0, p_w=(1.0, 2.0, 3.0))
    np.testing.assert_allclose(out.v_w, 0.0, atol=1e-13)
    np.testing.assert_allclose(out.p_w, [[1.0, 2.0, 3.0]] * 100, atol=1e-12)
    np.testing.assert_array_equal(out.q_wb, np.broadcast_to(out.q_wb[0], out.q_wb.shape))


def test_exact_position_is_exact_at_any_interval():
    """(5.2) with V(k) (printed: V̇(k)) integrates position without error at fixed attitude,
    whatever T: here T = 0.5 s against 3-7 Hz vibration; (5.1) and the trapezoid do not."""
    rng = np.random.default_rng(9)
    R = Rotation.from_rotvec(rng.normal(size=3))
    q0 = np.roll(R.as_quat(), 1)
    a_w = HarmonicSignal.of((0.1, -0.2, 0.05), [((2.0, 1j, -0.5), 2 * np.pi * 3.1), ((0.3j, 0.4, 1.0), 2 * np.pi * 7.3)])
    g = np.array([0.0, 0.0, -G0])
    mat = R.as_matrix()
    f_b = HarmonicSignal(mat.T @ (a_w.mean - g), a_w.amplitudes @ mat, a_w.rates_rad_s)  # f_b = Rᵀ(a_w − g)
    T, n = 0.5, 40
    t0 = np.arange(n) * T
    dv = f_b.multiple_integrals(t0, T, 2)
    v0, p0 = np.array([3.0, -1.0, 0.2]), np.array([10.0, 20.0, 5.0])
    t_end = t0 + T
    v_true = v0 + np.array([a_w.multiple_integrals([0.0], t, 1)[0, 0] for t in t_end])
    p_true = p0 + np.outer(t_end, v0) + np.array([a_w.multiple_integrals([0.0], t, 2)[0, 1] for t in t_end])
    errors = {}
    for position in ("exact", "rectangle", "trapezoid"):
        params = sd.NavigatorParams(T, coning="one_sample", sculling="traditional1", position=position,
                                    input_form="multiple")
        out = sd.navigate(params, np.zeros_like(dv), dv, q_wb=q0, v_w=v0, p_w=p0)
        np.testing.assert_allclose(out.v_w, v_true, atol=1e-12)
        errors[position] = np.abs(out.p_w - p_true).max()
    assert errors["exact"] < 1e-11
    assert errors["rectangle"] > 1.0 and errors["trapezoid"] > 0.01


@pytest.mark.parametrize("name, order, coef", [
    ("two_sample", 4, -1 / 480), ("traditional3", 4, 1 / 3240), ("traditional3_miller", 6, -1 / 102060),
    ("smoothing", 6, -1 / 50400), ("invariant", 6, -1 / 100800),
])
def test_coning_drift_end_to_end(name, order, coef):
    """Attitude drift about the cone axis through the quaternion chain, small cone angle."""
    motion = ConingMotion(half_angle_rad=0.01, rate_rad_s=2 * np.pi * 10)
    x = 0.3
    T = x / motion.rate_rad_s
    n = 1500
    info = sd.get_algorithm("coning", name)
    t0 = np.arange(n) * T
    if info.form == "sub":
        inc = motion.omega_b.sub_increments(t0, T, info.m_dtheta)
    else:
        inc = motion.omega_b.multiple_integrals(t0, T, 4)
    params = sd.NavigatorParams(T, coning=name, sculling="traditional1", position="rectangle",
                                input_form=info.form)
    out = sd.navigate(params, inc, np.zeros_like(inc), q_wb=motion.q_wb(0.0)[0])
    err = frames.quat_multiply(frames.quat_conjugate(motion.q_wb(out.t_s[-1])[0]), out.q_wb[-1])
    drift = frames.quat_to_rotvec(err)[2] / out.t_s[-1]
    expect = motion.error_scale * coef * x**order
    assert drift / expect == pytest.approx(1.0, abs=0.02)


@pytest.mark.parametrize("name, order, coef", [
    ("traditional1", 2, -1 / 6), ("traditional2", 4, -3 / 1440), ("smoothing", 4, -4 / 1440),
    ("invariant_accel1", 4, -1 / 720), ("invariant_rate1", 4, -1 / 720),
    ("invariant_accel0", 2, -1 / 12), ("invariant_rate0", 2, -1 / 12),
])
def test_sculling_error_end_to_end(name, order, coef):
    """Velocity drift along z of the navigator on the sculling motion against the exact velocity."""
    motion = ScullingMotion(angle_amplitude_rad=1e-3, accel_amplitude_mps2=5.0, rate_rad_s=2 * np.pi * 10)
    x = 0.4
    T = x / motion.rate_rad_s
    n = 3000
    info = sd.get_algorithm("sculling", name)
    t0 = np.arange(n) * T
    if info.form == "sub":
        th = motion.omega_b.sub_increments(t0, T, info.m_dtheta)
        dv = motion.specific_force_b.sub_increments(t0, T, info.m_dv)
        coning = {1: "one_sample", 2: "two_sample"}[info.m_dtheta]
    else:
        th = motion.omega_b.multiple_integrals(t0, T, 4)
        dv = motion.specific_force_b.multiple_integrals(t0, T, 4)
        coning = "invariant"
    params = sd.NavigatorParams(T, coning=coning, sculling=name, position="rectangle", gravity_w=(0, 0, 0),
                                input_form=info.form)
    out = sd.navigate(params, th, dv)
    err_rate = (out.v_w[-1, 2] - motion.v_w(out.t_s[-1])[0, 2]) / out.t_s[-1]
    expect = motion.error_scale * coef * x**order
    assert err_rate / expect == pytest.approx(1.0, abs=0.02)
