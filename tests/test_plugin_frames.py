"""The plug-in's frame adapters against each other: one motion written in each supported
convention (ENU/NED world, FLU/FRD body, scalar-first/last quaternions), mapped here with
scipy's rotations (an independent implementation), gives the same readings and estimates."""

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from biso_cosim.motions import make_motion
from biso_cosim.plugin import HostFrames, ImuPlugin, Mounting
from biso_cosim.sensors import Dipole, EarthField, MagneticEnvironment

_W = {"ENU": np.eye(3), "NED": np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])}  # host ← ENU
_B = {"FLU": np.eye(3), "FRD": np.diag([1.0, -1.0, -1.0])}  # host body ← FLU
CONVENTIONS = list(itertools.product(("ENU", "NED"), ("FLU", "FRD"), ("wxyz", "xyzw")))


def _quat_out(rot: Rotation, order: str) -> np.ndarray:
    q = rot.as_quat()  # scipy: scalar last
    return q if order == "xyzw" else q[..., [3, 0, 1, 2]]


def _to_host(world, body, order, q_wb, vectors_b, vectors_w, q_body_chip, r_b):
    """The package-frame motion in a host's conventions (matrices: host ← package)."""
    W, B = _W[world], _B[body]
    r_pkg = Rotation.from_quat(q_wb[:, [1, 2, 3, 0]])
    q_host = _quat_out(Rotation.from_matrix(W @ r_pkg.as_matrix() @ B.T), order)
    chip = Rotation.from_quat(np.asarray(q_body_chip)[[1, 2, 3, 0]])
    q_chip_host = _quat_out(Rotation.from_matrix(B @ chip.as_matrix()), order)
    return (q_host, {k: v @ B.T for k, v in vectors_b.items()}, {k: v @ W.T for k, v in vectors_w.items()},
            q_chip_host, B @ r_b)


def _to_package(world, body, order, q_host):
    W, B = _W[world], _B[body]
    q = q_host if order == "xyzw" else q_host[:, [1, 2, 3, 0]]
    return Rotation.from_matrix(W.T @ Rotation.from_quat(q).as_matrix() @ B).as_quat()[:, [3, 0, 1, 2]]


def test_the_same_motion_in_every_convention_gives_the_same_readings():
    h = 0.001
    motion = make_motion("tumble", duration_s=1.0, fs_hz=1.0 / h, seed=4)
    n = len(motion)
    g_enu = np.array([0.0, 0.0, -9.80665])
    accel_w = np.einsum("nij,nj->ni", Rotation.from_quat(motion.q_wb[:, [1, 2, 3, 0]]).as_matrix(),
                        motion.specific_force_b) + g_enu
    v_w = np.cumsum(accel_w, axis=0) * h
    p_w = np.cumsum(v_w, axis=0) * h
    q_chip = Rotation.from_euler("zyx", [30.0, -10.0, 170.0], degrees=True).as_quat()[[3, 0, 1, 2]]
    r_b = np.array([0.4, -0.25, 0.1])
    site = MagneticEnvironment(EarthField(), [Dipole((1.0, 0.5, 0.2), (0.0, 0.0, 300.0))])  # position matters
    runs = {}
    for world, body, order in CONVENTIONS:
        q_host, vb, vw, q_chip_host, r_host = _to_host(world, body, order, motion.q_wb, {"omega": motion.omega_b},
                                                       {"a": accel_w, "v": v_w, "p": p_w}, q_chip, r_b)
        plugin = ImuPlugin(tick_s=h, frames=HostFrames(world, body, order), profile="mpu9250", seed=9, site=site,
                           mounting=Mounting(tuple(r_host), tuple(q_chip_host)), speed_from_velocity=True,
                           estimators=["biso_plus", "biso"])
        out = plugin.step(motion.t_s, q_host, vb["omega"], accel_w=vw["a"], v_w=vw["v"], p_w=vw["p"])
        runs[world, body, order] = (out, plugin.frames)
    base, _ = runs["ENU", "FLU", "wxyz"]
    assert len(base) == 200
    for (world, body, order), (out, frames) in runs.items():
        # raw registers are chip axes: the same chip on the same motion reads the same
        assert np.array_equal(out.raw.words, base.raw.words), (world, body, order)
        assert np.array_equal(out.raw.status, base.raw.status)
        for name in ("gyro_b", "accel_b", "mag_b"):
            host = getattr(out, name)
            np.testing.assert_allclose(host @ _B[body], getattr(base.samples, name), rtol=0.0, atol=1e-12)
        for label in ("biso_plus", "biso"):
            q_est = _to_package(world, body, order, out.estimates[label].q_wb)
            q_ref = base.estimates[label].estimate.q_wb
            dot = np.abs(np.sum(q_est * q_ref, axis=1))
            assert np.all(dot > 1.0 - 1e-12), (label, world, body, order)
            for angle, err in out.estimates[label].errors_deg.items():
                np.testing.assert_allclose(err, base.estimates[label].errors_deg[angle], atol=1e-7)
        q_true = _to_package(world, body, order, out.q_true)
        assert np.all(np.abs(np.sum(q_true * base.q_true_wb, axis=1)) > 1.0 - 1e-12)


@pytest.mark.parametrize("world, body, order", CONVENTIONS)
def test_adapter_maps_agree_with_scipy(world, body, order):
    frames = HostFrames(world, body, order)
    rng = np.random.default_rng(1)
    q = Rotation.random(20, random_state=2).as_quat()[:, [3, 0, 1, 2]]
    v = rng.normal(size=(20, 3))
    q_host, vb, vw, _, _ = _to_host(world, body, order, q, {"v": v}, {"v": v}, (1.0, 0, 0, 0), np.zeros(3))
    back = frames.attitude_to_package(q_host)
    assert np.all(np.abs(np.sum(back * q, axis=1)) > 1.0 - 1e-14)
    again = frames.attitude_from_package(back)
    assert np.all(np.abs(np.sum(again * q_host, axis=1)) > 1.0 - 1e-14)
    assert np.array_equal(frames.body_to_flu(vb["v"]), v) and np.array_equal(frames.world_to_enu(vw["v"]), v)
    np.testing.assert_allclose(frames.world_to_enu(frames.standard_gravity_w()), [0.0, 0.0, -9.80665])


def test_frame_names_and_aliases():
    assert HostFrames("ned", "frd", "scalar_last") == HostFrames("NED", "FRD", "xyzw")
    assert HostFrames.coerce(None).is_package and HostFrames.coerce({"world": "NED"}).world == "NED"
    for kwargs, name in (({"world": "ECEF"}, "world"), ({"body": "FLD"}, "body"), ({"quaternion": "wzyx"}, "quaternion"),
                         ({"world": 3}, "world")):
        with pytest.raises(ValueError, match=f"^{name} must be one of"):
            HostFrames(**kwargs)
    with pytest.raises(ValueError, match="frames: unknown field"):
        HostFrames.coerce({"up": "z"})


@pytest.mark.parametrize("world, body, order", CONVENTIONS)
def test_body_rate_from_consecutive_attitudes(world, body, order):
    """A constant body rate recovered from two attitudes h apart, in the host's body axes."""
    motion = make_motion("rotation", duration_s=0.01, fs_hz=1000.0)
    q_host, vb, _, _, _ = _to_host(world, body, order, motion.q_wb, {"w": motion.omega_b}, {}, (1.0, 0, 0, 0),
                                   np.zeros(3))
    rate = HostFrames(world, body, order).body_rate(q_host[3], q_host[4], 0.001)
    np.testing.assert_allclose(rate, vb["w"][4], atol=1e-9)
    with pytest.raises(ValueError, match="dt_s must be positive"):
        HostFrames().body_rate(q_host[3], q_host[4], 0.0)
