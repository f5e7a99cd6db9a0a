"""A third-party vehicle simulator in the loop: pybullet's racecar (pybullet_data's
racecar.urdf) driving a steady circle with the plug-in fed from its base state every
physics tick (biso_cosim.plugin.pybullet_racecar)."""

import numpy as np
import pytest

pytest.importorskip("pybullet")

from biso_cosim.plugin import Mounting, PluginOutput  # noqa: E402
from biso_cosim.plugin.pybullet_racecar import FRAMES, RacecarBridge  # noqa: E402
from biso_cosim.sensors import Profile  # noqa: E402

G = 9.80665
PROFILE = "mpu9250_calibrated"
REGISTERS = {"accel_fs_sel": 2}  # ±8 g: the 1:10 car's contact vibration reaches several g
REST_S, CIRCLE_S, STEADY_FROM_S = 1.5, 6.0, 4.5  # steady circle from 3 s after the turn-in
SPEED_MPS, STEER_RAD = 1.5, 0.3
# documented in docs/plugin.md ("pybullet's racecar"): biso_plus on the steady circle
BOUNDS_DEG = {"roll": 0.5, "pitch": 0.5, "heading": 3.0}


def _budget(sensor: str, truth: np.ndarray, window_s: float) -> np.ndarray:
    """Worst-case error of the mean reading of each axis given the profile's tolerances: turn-on
    bias, scale factor, cross-axis and nonlinearity on the true vector, the gyro's
    g-sensitivity to a specific force of 1.2 g, bias instability, and 4σ of the white noise
    averaged over the window."""
    prof = Profile.load(PROFILE)
    x = np.abs(truth)
    budget = (prof.axes(f"{sensor}.bias_initial") + prof.axes(f"{sensor}.scale_factor") * x
              + float(prof.si(f"{sensor}.cross_axis")) * (x.sum() - x) + prof.axes(f"{sensor}.nonlinearity") * x
              + prof.axes(f"{sensor}.bias_instability") + 4.0 * prof.axes(f"{sensor}.noise_density") / np.sqrt(window_s))
    if sensor == "gyro":
        budget = budget + prof.axes("gyro.g_sensitivity") * 1.2 * G
    return budget


def _circle_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    a = np.column_stack([2.0 * x, 2.0 * y, np.ones_like(x)])
    cx, cy, k = np.linalg.lstsq(a, x * x + y * y, rcond=None)[0]
    return cx, cy, float(np.sqrt(k + cx * cx + cy * cy))


@pytest.fixture(scope="module")
def drive():
    with RacecarBridge(seed=0, profile=PROFILE, registers=REGISTERS, speed_from_velocity=True) as bridge:
        rest = bridge.drive(REST_S)
        bridge.command(SPEED_MPS, STEER_RAD)
        circle = bridge.drive(CIRCLE_S)
    return rest, circle


def test_at_rest_the_accelerometer_reads_g_up_and_the_gyro_zero(drive):
    rest, _ = drive
    out = rest.output
    window = out.t_s >= 0.5  # after the car settled on its wheels
    accel, gyro = out.accel_b[window].mean(axis=0), out.gyro_b[window].mean(axis=0)
    truth = np.array([0.0, 0.0, G])
    assert np.all(np.abs(accel - truth) <= _budget("accel", truth, 1.0)), accel
    assert np.all(np.abs(gyro) <= _budget("gyro", np.zeros(3), 1.0)), gyro
    assert np.max(np.linalg.norm(rest.v_w[rest.t_s >= 0.5], axis=1)) < 1e-3  # the host is at rest


def test_on_a_steady_circle_the_gyro_reads_the_yaw_rate_and_the_accelerometer_v2_over_r(drive):
    _, circle = drive
    out = circle.output
    ticks, window = circle.t_s >= STEADY_FROM_S, out.t_s >= STEADY_FROM_S
    span = REST_S + CIRCLE_S - STEADY_FROM_S
    speed = float(np.mean(np.linalg.norm(circle.v_w[ticks, :2], axis=1)))
    _, _, radius = _circle_fit(circle.p_w[ticks, 0], circle.p_w[ticks, 1])
    yaw_rate = float(np.mean(circle.omega_b[ticks, 2]))
    assert 0.8 < radius < 2.0 and 1.0 < speed < 1.6  # a steady left turn of the 1:10 car
    assert abs(yaw_rate - speed / radius) < 0.02 * yaw_rate  # the host's kinematics agree
    gyro, accel = out.gyro_b[window].mean(axis=0), out.accel_b[window].mean(axis=0)
    gyro_truth = np.array([0.0, 0.0, yaw_rate])
    accel_truth = np.array([0.0, speed ** 2 / radius, G])  # centripetal toward the centre (left), +g up
    assert np.all(np.abs(gyro - gyro_truth) <= _budget("gyro", gyro_truth, span)), (gyro, gyro_truth)
    assert np.all(np.abs(accel - accel_truth) <= _budget("accel", accel_truth, span)), (accel, accel_truth)
    assert np.count_nonzero(out.flags[window]) == 0  # no saturation in the steady turn


def test_the_estimator_error_stays_within_the_documented_bounds(drive):
    _, circle = drive
    est = circle.output.estimates["biso_plus"]
    window = circle.output.t_s >= STEADY_FROM_S
    for angle, bound in BOUNDS_DEG.items():
        rms = float(np.sqrt(np.mean(est.errors_deg[angle][window] ** 2)))
        assert rms <= bound, (angle, rms)
    assert np.all(np.isfinite(est.q_wb)) and est.q_wb.shape[1] == 4


def test_the_run_repeats_under_a_seed_and_blocks_of_ticks_change_nothing():
    def run(seed, block_ticks=1):
        with RacecarBridge(seed=seed, block_ticks=block_ticks, mounting=Mounting((0.1, 0.05, 0.05))) as bridge:
            bridge.command(1.0, -0.2)
            return bridge.drive(1.0)

    a, b, c, d = run(3), run(3), run(3, block_ticks=20), run(4)
    for other in (b, c):
        assert np.array_equal(a.q_wb, other.q_wb) and np.array_equal(a.v_w, other.v_w)
        _same_output(a.output, other.output)
    assert np.array_equal(a.q_wb, d.q_wb)  # the same drive, another chip
    assert not np.array_equal(a.output.gyro_b, d.output.gyro_b)


def _same_output(a: PluginOutput, b: PluginOutput) -> None:
    assert np.array_equal(a.t_s, b.t_s)
    assert np.array_equal(a.raw.words, b.raw.words) and np.array_equal(a.samples.gyro_b, b.samples.gyro_b)
    assert np.array_equal(a.estimates["biso_plus"].estimate.q_wb, b.estimates["biso_plus"].estimate.q_wb)


def test_bridge_refuses_a_plugin_of_other_frames_or_tick():
    from biso_cosim.plugin import ImuPlugin

    with pytest.raises(ValueError, match="plugin.frames must be"):
        RacecarBridge(ImuPlugin(tick_s=0.001))
    with pytest.raises(ValueError, match="must equal the bridge's tick_s"):
        RacecarBridge(ImuPlugin(tick_s=0.002, frames=FRAMES))
    with pytest.raises(ValueError, match="block_ticks"):
        RacecarBridge(block_ticks=0)
