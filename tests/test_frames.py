"""Frames and quaternions against scipy's Rotation (scalar-last!) and at special points."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from biso_cosim import frames as fr

N = 2000


def _scipy(q_wxyz):
    """scipy Rotation of our scalar-first quaternions."""
    return Rotation.from_quat(np.roll(np.atleast_2d(q_wxyz), -1, axis=1))


def _same_rotation(q1, q2, atol=1e-12):
    """q and −q are the same rotation."""
    q1, q2 = np.atleast_2d(q1), np.atleast_2d(q2)
    dots = np.abs(np.sum(q1 * q2, axis=1))
    np.testing.assert_allclose(dots, 1.0, atol=atol)


@pytest.fixture(scope="module")
def quats():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(N, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_product_and_rotation_match_scipy(quats):
    rng = np.random.default_rng(2)
    p = np.roll(quats, 7, axis=0)
    v = rng.normal(size=(N, 3))
    expected = (_scipy(quats) * _scipy(p)).as_quat()
    _same_rotation(fr.quat_multiply(quats, p), np.roll(expected, 1, axis=1))
    np.testing.assert_allclose(fr.quat_rotate(quats, v), _scipy(quats).apply(v), atol=1e-12)
    # the definition: q ∘ (0, v) ∘ q*
    qv = np.hstack([np.zeros((N, 1)), v])
    full = fr.quat_multiply(fr.quat_multiply(quats, qv), fr.quat_conjugate(quats))
    np.testing.assert_allclose(full[:, 1:], fr.quat_rotate(quats, v), atol=1e-12)
    np.testing.assert_allclose(full[:, 0], 0.0, atol=1e-12)


def test_matrix_round_trip_matches_scipy(quats):
    m = fr.quat_to_matrix(quats)
    np.testing.assert_allclose(m, _scipy(quats).as_matrix(), atol=1e-12)
    q = fr.quat_from_matrix(m)
    assert np.all(q[:, 0] >= 0.0)
    _same_rotation(q, quats)
    # the four branches of Shepperd's method: rotations by π about each axis and identity
    for mat in (np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])):
        _same_rotation(fr.quat_from_matrix(mat), np.roll(Rotation.from_matrix(mat).as_quat(), 1))


def test_rotvec_round_trip_matches_scipy(quats):
    rv = fr.quat_to_rotvec(quats)
    np.testing.assert_allclose(rv, _scipy(quats).as_rotvec(), atol=1e-10)
    _same_rotation(fr.quat_from_rotvec(rv), quats)
    tiny = np.array([[1e-9, -2e-9, 3e-10], [0.0, 0.0, 0.0], [1e-5, 0, 0]])
    np.testing.assert_allclose(fr.quat_to_rotvec(fr.quat_from_rotvec(tiny)), tiny, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(fr.quat_from_rotvec(tiny), np.roll(Rotation.from_rotvec(tiny).as_quat(), 1, axis=1), atol=1e-16)


def test_euler_matches_scipy_zyx(quats):
    e = fr.euler_from_quat(quats)
    ypr = _scipy(quats).as_euler("ZYX")
    np.testing.assert_allclose(e[:, ::-1], ypr, atol=1e-10)
    _same_rotation(fr.quat_from_euler(e[:, 0], e[:, 1], e[:, 2]), quats)


def test_euler_signs_follow_iso8855():
    """Positive roll lowers the right side, positive pitch lowers the nose, yaw CCW from East."""
    left_b, fwd_b = np.array([0.0, 1, 0]), np.array([1.0, 0, 0])
    assert fr.quat_rotate(fr.quat_from_euler(0.3, 0, 0), left_b)[2] > 0  # left side up
    assert fr.quat_rotate(fr.quat_from_euler(0, 0.3, 0), fwd_b)[2] < 0  # nose down
    nose = fr.quat_rotate(fr.quat_from_euler(0, 0, 0.3), fwd_b)
    assert nose[1] > 0 and math.isclose(math.atan2(nose[1], nose[0]), 0.3)


@pytest.mark.parametrize("pitch", [math.pi / 2, -math.pi / 2])
def test_euler_at_gimbal_lock_reconstructs_rotation(pitch):
    for roll, yaw in [(0.4, 1.1), (-2.0, 3.0), (0.0, -0.5)]:
        q = fr.quat_from_euler(roll, pitch, yaw)
        e = fr.euler_from_quat(q)
        assert e[0] == 0.0 and math.isclose(e[1], pitch, abs_tol=1e-7)
        _same_rotation(fr.quat_from_euler(*e), q, atol=1e-12)
    # just off the lock: ordinary decomposition, still exact
    q = fr.quat_from_euler(0.4, pitch * (1 - 1e-6), 1.1)
    _same_rotation(fr.quat_from_euler(*fr.euler_from_quat(q)), q, atol=1e-12)


def test_heading_and_wraps():
    yaw = np.array([0.0, math.pi / 2, math.pi, -math.pi, -math.pi / 2, 1e-17, -1e-17])
    expected = np.array([math.pi / 2, 0.0, 3 * math.pi / 2, 3 * math.pi / 2, math.pi, math.pi / 2, math.pi / 2])
    np.testing.assert_allclose(fr.heading_from_yaw(yaw), expected, atol=1e-15)
    h = fr.heading_from_quat(fr.quat_from_euler(np.zeros(7), np.zeros(7), yaw))
    np.testing.assert_allclose(np.unwrap(h), np.unwrap(expected), atol=1e-12)
    assert np.all((h >= 0) & (h < 2 * math.pi))
    # 180° wraps: yaw ±π decompose to ±π (the same angle), wrap_angle maps into (−π, π]
    for yaw180 in (math.pi, -math.pi, math.pi - 1e-15):
        got = fr.euler_from_quat(fr.quat_from_euler(0, 0, yaw180))[2]
        assert abs(fr.wrap_angle(got - yaw180)) < 1e-12 and abs(got) <= math.pi
    np.testing.assert_allclose(fr.wrap_angle([math.pi, -math.pi, 3 * math.pi, 0.1 - 4 * math.pi]), [math.pi, math.pi, math.pi, 0.1], atol=1e-12)


def test_gost_angles_formula_matches_frame_relation(quats):
    """eq. (4)/(7) of Aleshkin et al. in the GOST frames equal (yaw − π/2, −pitch, roll)."""
    g = fr.gost_angles_from_quat(quats)
    e = fr.euler_from_quat(quats)
    np.testing.assert_allclose(fr.wrap_angle(g[:, 0] - (e[:, 2] - math.pi / 2)), 0.0, atol=1e-10)
    np.testing.assert_allclose(g[:, 1], -e[:, 1], atol=1e-10)
    np.testing.assert_allclose(g[:, 2], e[:, 0], atol=1e-10)
    _same_rotation(fr.quat_from_gost_angles(g[:, 0], g[:, 1], g[:, 2]), quats)


def test_gost_lambda_is_the_papers_quaternion():
    """λ = Q_NUE_ENU ∘ q_wb ∘ Q_FLU_FUR maps GOST body vectors to GOST geographic vectors."""
    psi, theta, gamma = 0.7, 0.2, -0.3
    q_wb = fr.quat_from_gost_angles(psi, theta, gamma)
    lam = fr.quat_multiply(fr.quat_multiply(fr.Q_NUE_ENU, q_wb), fr.Q_FLU_FUR)
    # eq. (7) directly
    c, s = np.cos(np.array([psi, theta, gamma]) / 2), np.sin(np.array([psi, theta, gamma]) / 2)
    lam7 = [
        c[0] * c[1] * c[2] - s[0] * s[1] * s[2],
        c[0] * c[1] * s[2] + s[0] * s[1] * c[2],
        s[0] * c[1] * c[2] + c[0] * s[1] * s[2],
        c[0] * s[1] * c[2] - s[0] * c[1] * s[2],
    ]
    _same_rotation(lam, lam7)
    # nose (GOST body x) points North rotated toward West by ψ and up by ϑ
    nose_nue = fr.quat_rotate(lam, [1.0, 0, 0])
    np.testing.assert_allclose(nose_nue, [math.cos(theta) * math.cos(psi), math.sin(theta), -math.cos(theta) * math.sin(psi)], atol=1e-12)
    # the cross-link axis (1, 1, 1) is the same vector in NUE and ENU
    np.testing.assert_allclose(fr.quat_rotate(fr.Q_NUE_ENU, [1.0, 1, 1]), [1.0, 1, 1], atol=1e-15)
    np.testing.assert_allclose(fr.quat_rotate(fr.Q_NUE_ENU, [0.0, 1, 0]), [1.0, 0, 0], atol=1e-15)  # North


def test_gost_gimbal_lock():
    for theta in (math.pi / 2, -math.pi / 2):
        q = fr.quat_from_gost_angles(0.5, theta, 0.2)
        g = fr.gost_angles_from_quat(q)
        assert g[2] == 0.0
        _same_rotation(fr.quat_from_gost_angles(*g), q)


def test_angle_between(quats):
    p = np.roll(quats, 3, axis=0)
    expected = (_scipy(p).inv() * _scipy(quats)).magnitude()
    np.testing.assert_allclose(fr.quat_angle_between(p, quats), expected, atol=1e-10)
    assert fr.quat_angle_between(quats[0], -quats[0]) == pytest.approx(0.0, abs=1e-7)


def test_bad_shapes_name_the_argument():
    with pytest.raises(ValueError, match="q_ab"):
        fr.quat_rotate(np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="p and q"):
        fr.quat_multiply(np.ones((2, 4)), np.ones((3, 4)))
    with pytest.raises(ValueError, match="mat_ab"):
        fr.quat_from_matrix(np.eye(4))
    with pytest.raises(ValueError, match="non-zero"):
        fr.quat_normalize(np.zeros(4))


def test_scalar_kernels_compile_and_agree_with_the_array_functions():
    """Every scalar kernel is usable inside other numba kernels (nopython)."""
    angles = np.array([-7.0, -math.pi, -1e-17, 0.0, 1e-17, 1.0, math.pi, 3 * math.pi, 12.5])
    for a in angles:
        assert fr._wrap(a) == pytest.approx(float(fr.wrap_angle(a)), abs=1e-12)
        assert fr._heading_from_yaw(a) == pytest.approx(float(fr.heading_from_yaw(a)), abs=1e-12)
        assert -math.pi < fr._wrap(a) <= math.pi and 0.0 <= fr._heading_from_yaw(a) < 2 * math.pi
    q = fr.quat_from_euler(0.1, -0.2, 0.3)
    assert fr._euler_from_q(*q) == pytest.approx(tuple(fr.euler_from_quat(q)))
    assert fr._q_from_euler(0.1, -0.2, 0.3) == pytest.approx(tuple(q))
    assert fr._qrot_inv(*q, 1.0, 2.0, 3.0) == pytest.approx(tuple(fr.quat_rotate(fr.quat_conjugate(q), [1.0, 2, 3])))
    lam = fr._gost_lambda_from_angles(0.3, 0.2, 0.1)
    assert fr._gost_angles_from_lambda(*lam) == pytest.approx((0.3, 0.2, 0.1))
    assert fr._q_from_mat(*fr._mat_from_q(*q)) == pytest.approx(tuple(q))
    assert fr._qlog_rotvec(*fr._qexp_rotvec(0.1, 0.2, -0.3)) == pytest.approx((0.1, 0.2, -0.3))
