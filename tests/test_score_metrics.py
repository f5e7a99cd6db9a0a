"""BROAD's error measures (biso_cosim.score.metrics): analytic cases, a hand-computed
quaternion, and a literal transcription of the published definitions as the slow twin."""

import math

import numpy as np
import pytest

from biso_cosim.frames import quat_from_rotvec, quat_multiply
from biso_cosim.score.metrics import broad_errors_rad, error_quat_earth, rmse_deg, trial_rmse_deg
from biso_cosim.score.run import group_means


def _random_attitudes(n, seed=0):
    q = np.random.default_rng(seed).normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _about(axis, angle_rad, n):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.tile(quat_from_rotvec(axis * angle_rad), (n, 1))


def _broad_literal(q_est, q_ref):
    """Laidig et al. (2021) §4 / broad_utils.py as printed: e = q_est ∘ q_ref⁻¹,
    total 2·acos|e_w|, heading 2·atan|e_z/e_w|, inclination 2·acos√(e_w² + e_z²)."""
    out = {"total": [], "heading": [], "inclination": []}
    for p, q in zip(q_est, q_ref):
        p = p / np.linalg.norm(p)
        q = q / np.linalg.norm(q)
        qi = np.array([q[0], -q[1], -q[2], -q[3]])
        w = p[0] * qi[0] - p[1] * qi[1] - p[2] * qi[2] - p[3] * qi[3]
        z = p[0] * qi[3] + p[1] * qi[2] - p[2] * qi[1] + p[3] * qi[0]
        out["total"].append(2 * math.acos(min(abs(w), 1.0)))
        out["heading"].append(2 * math.atan(abs(z / w)))
        out["inclination"].append(2 * math.acos(min(math.sqrt(w * w + z * z), 1.0)))
    return {k: np.array(v) for k, v in out.items()}


def test_a_constant_heading_error_is_exactly_that_heading_error_on_any_attitude():
    q_ref = _random_attitudes(500)
    delta = math.radians(7.5)
    q_est = quat_multiply(_about((0, 0, 1), delta, 500), q_ref)  # turned about Up, Earth frame
    e = broad_errors_rad(q_est, q_ref)
    np.testing.assert_allclose(e["heading"], delta, rtol=0, atol=1e-12)
    np.testing.assert_allclose(e["total"], delta, rtol=0, atol=1e-7)  # acos near 1 loses digits
    np.testing.assert_allclose(e["inclination"], 0.0, rtol=0, atol=5e-8)  # 2·acos(1 − ulp) = 3e-8


def test_a_constant_tilt_error_is_exactly_that_inclination_error_on_any_attitude():
    q_ref = _random_attitudes(500, seed=1)
    eps = math.radians(4.0)
    for axis in ((1, 0, 0), (0, 1, 0), (1, -2, 0)):  # any horizontal Earth axis
        q_est = quat_multiply(_about(axis, eps, 500), q_ref)
        e = broad_errors_rad(q_est, q_ref)
        np.testing.assert_allclose(e["inclination"], eps, rtol=0, atol=1e-7)
        np.testing.assert_allclose(e["heading"], 0.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("order", ["heading_first", "tilt_first"])
def test_heading_and_tilt_together_split_exactly_in_either_order(order):
    q_ref = _random_attitudes(200, seed=2)
    delta, eps = math.radians(20.0), math.radians(6.0)
    qz, qh = _about((0, 0, 1), delta, 200), _about((0.6, 0.8, 0), eps, 200)
    e_w = qz if order == "heading_first" else qh
    e_w = quat_multiply(e_w, qh if order == "heading_first" else qz)
    e = broad_errors_rad(quat_multiply(e_w, q_ref), q_ref)
    np.testing.assert_allclose(e["heading"], delta, atol=1e-12)
    np.testing.assert_allclose(e["inclination"], eps, atol=1e-9)
    total = 2 * math.acos(math.cos(delta / 2) * math.cos(eps / 2))
    np.testing.assert_allclose(e["total"], total, atol=1e-9)


def test_a_hand_computed_error_quaternion():
    # q_ref = identity, q_est = (0.9, 0.1, 0.2, 0.3)/√0.95, so e = q_est. By hand:
    # heading 2·atan(0.3/0.9) = atan(2·(1/3)/(1 − 1/9)) = atan(3/4) = 36.869898°;
    # inclination 2·acos(√((0.81 + 0.09)/0.95)) = 2·acos(0.973329) = 26.525352°;
    # total 2·acos(0.9/√0.95) = 2·acos(0.923381) = 45.149192°, and cos(total/2) =
    # cos(heading/2)·cos(inclination/2) = (0.9/√0.9)·√(0.9/0.95) checks the split.
    q_est = np.array([[0.9, 0.1, 0.2, 0.3]])
    e = broad_errors_rad(q_est, np.array([[1.0, 0.0, 0.0, 0.0]]))
    assert math.degrees(e["heading"][0]) == pytest.approx(math.degrees(math.atan(0.75)), abs=1e-12)
    assert math.degrees(e["heading"][0]) == pytest.approx(36.869897645844, abs=1e-9)
    assert math.degrees(e["total"][0]) == pytest.approx(2 * math.degrees(math.acos(0.9 / math.sqrt(0.95))), abs=1e-12)
    assert math.degrees(e["inclination"][0]) == pytest.approx(2 * math.degrees(math.acos(math.sqrt(0.9 / 0.95))),
                                                              abs=1e-12)
    assert math.degrees(e["inclination"][0]) == pytest.approx(26.525352, abs=1e-6)
    assert math.degrees(e["total"][0]) == pytest.approx(45.149192, abs=1e-6)
    c = math.cos(e["heading"][0] / 2) * math.cos(e["inclination"][0] / 2)
    assert c == pytest.approx(math.cos(e["total"][0] / 2), abs=1e-15)


def test_the_error_is_taken_in_the_earth_frame_not_the_body_frame():
    # reference rolled 90° about x; the estimate is off by 10° about the *body* z axis, which
    # then lies along −y of the Earth: BROAD calls that an inclination error, not heading.
    q_ref = _about((1, 0, 0), math.pi / 2, 1)
    q_est = quat_multiply(q_ref, _about((0, 0, 1), math.radians(10.0), 1))
    e_earth = error_quat_earth(q_est, q_ref)[0]
    np.testing.assert_allclose(e_earth, quat_from_rotvec(np.array([0.0, -math.radians(10.0), 0.0])), atol=1e-15)
    e = broad_errors_rad(q_est, q_ref)
    assert math.degrees(e["inclination"][0]) == pytest.approx(10.0, abs=1e-6)
    assert math.degrees(e["heading"][0]) == pytest.approx(0.0, abs=1e-12)


def test_equal_to_the_literal_published_definitions_and_sign_blind():
    q_ref, q_est = _random_attitudes(1000, seed=3), _random_attitudes(1000, seed=4)
    ours = broad_errors_rad(q_est, q_ref)
    theirs = _broad_literal(q_est, q_ref)
    for k in ours:
        np.testing.assert_allclose(ours[k], theirs[k], rtol=0, atol=1e-12)
    flipped = broad_errors_rad(-q_est, 3.0 * q_ref)  # q and −q are one attitude; scale is normalised away
    for k in ours:
        np.testing.assert_allclose(flipped[k], ours[k], rtol=0, atol=1e-12)


def test_rmse_over_movement_skips_reference_dropouts():
    n = 100
    q_ref = _random_attitudes(n, seed=5)
    angles = np.where(np.arange(n) < 50, 2.0, 4.0)  # heading error 2° then 4°
    q_est = np.array([quat_multiply(quat_from_rotvec(np.array([0, 0, math.radians(a)])), q) for a, q in zip(angles, q_ref)])
    q_ref_nan = q_ref.copy()
    q_ref_nan[40:60] = np.nan  # an optical dropout
    movement = np.arange(n) >= 10
    r = trial_rmse_deg(q_est, q_ref_nan, movement)
    expected = math.sqrt((30 * 2.0**2 + 40 * 4.0**2) / 70)  # samples 10–39 and 60–99
    assert r["heading"] == pytest.approx(expected, abs=1e-9)
    assert r["total"] == pytest.approx(expected, abs=1e-5)
    assert math.isnan(rmse_deg(np.full(5, np.nan)))
    with pytest.raises(ValueError, match="movement must have shape"):
        trial_rmse_deg(q_est, q_ref, movement[:-1])
    with pytest.raises(ValueError, match=r"q_est must have shape \(N, 4\)"):
        broad_errors_rad(q_est[:, :3], q_ref)


def test_a_group_scores_the_mean_of_its_trials_rmse():
    trials = {
        "a": {"groups": ["all_trials", "x"], "methods": {"m": {"total_rmse_deg": 1.0, "heading_rmse_deg": 0.5,
                                                               "inclination_rmse_deg": 0.2}}},
        "b": {"groups": ["all_trials"], "methods": {"m": {"total_rmse_deg": 3.0, "heading_rmse_deg": 1.5,
                                                          "inclination_rmse_deg": 0.4}}},
    }
    g = group_means(trials, ["m"])
    assert g["all_trials"]["methods"]["m"] == {"total_rmse_deg": 2.0, "heading_rmse_deg": 1.0,
                                               "inclination_rmse_deg": pytest.approx(0.3)}
    assert g["x"]["trials"] == ["a"] and g["x"]["methods"]["m"]["total_rmse_deg"] == 1.0
