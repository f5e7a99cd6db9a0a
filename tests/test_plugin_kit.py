"""The route-test kit on drives of another simulator: recorded truth in, assertions out
(biso_cosim.testing.replay / ExternalDrive)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from biso_cosim.motions import make_motion
from biso_cosim.plugin import HostFrames, ImuPlugin, PluginOutput
from biso_cosim.testing import AttitudeErrorExceeded, ExternalDrive, replay


def _recording(motion, frames: HostFrames):
    """A circle as another simulator would record it: NED/FRD, scalar last, positions."""
    ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    frd = np.diag([1.0, -1.0, -1.0])
    rot = Rotation.from_quat(motion.q_wb[:, [1, 2, 3, 0]])
    q = Rotation.from_matrix(ned @ rot.as_matrix() @ frd).as_quat()
    t = motion.t_s
    v_enu = rot.apply(np.column_stack([motion.info["speed_mps"], np.zeros((len(t), 2))]))  # along body x
    return {"t_s": t + 3.0, "q_wb": q if frames.quaternion == "xyzw" else q[:, [3, 0, 1, 2]],
            "omega_b": motion.omega_b @ frd.T, "accel_w": motion.accel_w @ ned.T,
            "p_w": np.cumsum(v_enu, axis=0) @ ned.T / motion.fs_hz, "v_w": v_enu @ ned.T}


def test_replay_of_a_recorded_drive_gives_the_kits_assertions(tmp_path):
    frames = HostFrames("NED", "FRD", "xyzw")
    motion = make_motion("circle", duration_s=8.0, fs_hz=1000.0, speed_mps=8.0, radius_m=25.0)
    recording = _recording(motion, frames)
    path = tmp_path / "drive.npz"
    np.savez(path, **recording)
    run = replay(path, estimator="biso_plus", seed=0, frames=frames, speed_from_velocity=True, name="my sim's circle")
    run.assert_max_error(roll=1.0, pitch=1.0, after_s=4.0)
    run.assert_rms_error(roll=0.5, pitch=0.5)
    # the same numbers as the plug-in in the host's loop, tick by tick
    live = ImuPlugin(tick_s=0.001, frames=frames, seed=0, estimators=["biso_plus"], speed_from_velocity=True)
    outs = [live.step(recording["t_s"][i], recording["q_wb"][i], recording["omega_b"][i],
                      accel_w=recording["accel_w"][i], p_w=recording["p_w"][i], v_w=recording["v_w"][i])
            for i in range(len(motion))]
    again = ExternalDrive.from_output(PluginOutput.concatenate(outs), truth_t_s=recording["t_s"], p_w=recording["p_w"])
    for angle in ("roll", "pitch", "heading", "total"):
        assert np.array_equal(again.errors[angle], run.errors[angle])
    # a failure says which angle, when it first went over, the largest error and where
    uncompensated = replay(recording, estimator="biso", seed=0, frames=frames, name="my sim's circle")
    with pytest.raises(AttitudeErrorExceeded) as info:
        uncompensated.assert_max_error(roll=1.0)
    message = str(info.value)
    assert message.startswith("my sim's circle (seed 0) with biso:")
    assert "roll error over 1°" in message and "m along the drive" in message and "largest" in message
    with pytest.raises(AttitudeErrorExceeded, match=r"roll RMS error [0-9.]+° is over 0.5°"):
        uncompensated.assert_rms_error(roll=0.5)


def test_closure_needs_rest_windows_and_checks_the_start_to_end_change():
    motion = make_motion("static", duration_s=6.0, fs_hz=1000.0)
    truth = {"t_s": motion.t_s, "q_wb": motion.q_wb, "omega_b": motion.omega_b,
             "specific_force_b": motion.specific_force_b}
    windows = ((0.5, 1.5), (5.0, 6.0))
    good = replay(truth, estimator="biso_plus", start_end_windows=windows)
    good.assert_closure(roll=0.2, pitch=0.2, heading=1.5)
    # the raw part's gyro bias (±5 °/s) integrated without correction tilts the estimate
    drifting = replay(truth, estimator="poisson", profile="mpu9250", seed=1, start_end_windows=windows)
    with pytest.raises(AttitudeErrorExceeded, match=r"roll start-to-end error \+5.35[0-9]°.*\n.*pitch"):
        drifting.assert_closure(roll=1.0, pitch=1.0)
    with pytest.raises(AssertionError, match="no start-to-end figures"):
        replay(truth, estimator="biso_plus").assert_closure(heading=1.0)


def test_recordings_that_cannot_make_a_run_are_refused_by_name():
    motion = make_motion("static", duration_s=0.5, fs_hz=1000.0)
    truth = {"t_s": motion.t_s, "q_wb": motion.q_wb, "omega_b": motion.omega_b,
             "specific_force_b": motion.specific_force_b}
    with pytest.raises(ValueError, match="truth needs the column 'omega_b'"):
        replay({k: v for k, v in truth.items() if k != "omega_b"})
    with pytest.raises(ValueError, match=r"unknown column\(s\) \['speed'\]"):
        replay({**truth, "speed": motion.t_s})
    with pytest.raises(ValueError, match="at least two ticks"):
        replay({k: v[:1] for k, v in truth.items()})
    gap = {k: np.delete(v, 200, axis=0) for k, v in truth.items()}
    with pytest.raises(ValueError, match=r"t_s \(row 200\) = 0.201 s is not the next tick"):
        replay(gap)
    bad = {**truth, "q_wb": truth["q_wb"] * 1.1}
    with pytest.raises(ValueError, match="q_wb .* must be a unit quaternion"):
        replay(bad)
    with pytest.raises(AssertionError, match="an external drive has none"):
        replay(truth).assert_completed()
