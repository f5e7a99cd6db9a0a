"""Each jitted kernel of the environments against a slow plain-Python/NumPy twin."""

import math

import numpy as np
import pytest


from biso_cosim.envs._kernels import (_angle, _angles_to, _attitude_period, _dead_reckon, _drive_action,
                                      _driving_period, _driving_view, _innovation_statistics, _mean_angle, _mean_angles_to, _navigate_period,
                                      _push_window, _route_ahead, _scale_observation, _tune_closed,
                                      _tuning_period)
from biso_cosim.estimators import make_estimator
from biso_cosim.estimators.biso import gains_from_cutoff
from biso_cosim.envs.procedural import random_route
from biso_cosim.frames import quat_angle_between
from biso_cosim.vehicle._kernels import S_CROSS, S_S
from biso_cosim.vehicle.drivetrain import DRIVETRAIN, drivetrain_coefficients
from biso_cosim.vehicle.driver import DriverCommand, DriverState
from biso_cosim.vehicle.sim import ControlArrays, apply_command


def push_reference(values, gyro, accel, mag, fresh):
    """The window in plain NumPy: stack old rows (marked not new) and new rows, keep the last n."""
    n = values.shape[0]
    old = values.copy()
    old[:, 10] = 0.0
    finite = np.isfinite(mag).all(axis=1)
    new = np.column_stack([gyro, accel, np.where(finite[:, None], mag, 0.0), fresh & finite, np.ones(len(gyro))])
    return np.vstack([old, new])[-n:]


@pytest.mark.parametrize("slots", [1, 3, 4])
def test_push_window_matches_its_reference(slots):
    rng = np.random.default_rng(slots)
    values = np.zeros((slots, 11))
    expected = values.copy()
    for _ in range(60):
        k = int(rng.integers(0, slots + 3))
        gyro, accel, mag = rng.normal(size=(3, k, 3))
        mag[rng.random(k) < 0.2, int(rng.integers(3))] = np.nan  # AK8963 powered down
        fresh = rng.random(k) < 0.5
        _push_window(values, gyro, accel, mag, fresh)
        expected = push_reference(expected, gyro, accel, mag, fresh)
        np.testing.assert_array_equal(values, expected)


def test_angle_is_quat_angle_between_bit_for_bit():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(500, 4)) * rng.uniform(0.1, 3.0, (500, 1))  # any non-zero length
    q = rng.normal(size=(500, 4))
    q[:50] = -p[:50]  # the same attitude
    expected = quat_angle_between(p, q)
    got = np.array([_angle(p[i], q[i]) for i in range(len(p))])
    np.testing.assert_array_equal(got, expected)
    assert np.all(got[:50] < 1e-7)
    total = 0.0
    for value in expected[:7]:
        total += value
    assert _mean_angle(p[:7], q[:7]) == total / 7
    assert _angles_to(p[0], p[1], q[2]) == (_angle(p[0], q[2]), _angle(p[1], q[2]))
    last1, last2 = np.empty(4), np.empty(4)
    assert _mean_angles_to(p[:7], q[7:14], q[:7], last1, last2) == (_mean_angle(p[:7], q[:7]),
                                                                    _mean_angle(q[7:14], q[:7]))
    assert last1.tolist() == p[6].tolist() and last2.tolist() == q[13].tolist()


def test_dead_reckon_matches_a_plain_loop():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(9, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    wheels = rng.uniform(0.0, 30.0, (9, 4))
    pose = np.array([1.0, -2.0, 0.3])
    x, y = pose[0], pose[1]
    for i in range(9):
        w, qx, qy, qz = q[i]
        fx, fy = 1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy + w * qz)
        v = 0.158 * (wheels[i, 0] + wheels[i, 1])
        x += 0.005 * v * fx
        y += 0.005 * v * fy
    _dead_reckon(q, wheels, 0.158, 0.005, pose)
    assert pose[0] == x and pose[1] == y and pose[2] == math.atan2(fy, fx)
    _dead_reckon(q[:0], wheels[:0], 0.158, 0.005, pose)  # no samples: nothing moves
    assert pose[0] == x and pose[2] == math.atan2(fy, fx)


def test_navigate_period_is_dead_reckoning_with_the_rear_axle_speed():
    rng = np.random.default_rng(5)
    q = rng.normal(size=(4, 4))
    packed = rng.normal(size=(20, 23))
    sensordata = rng.normal(size=30)
    pose, expected = np.array([3.0, -1.0, 0.2]), np.array([3.0, -1.0, 0.2])
    q_est = np.empty(4)
    _navigate_period(q, packed, sensordata, 29, 0.5 * 0.316, 0.005, pose, q_est)
    _dead_reckon(q, packed[:, 18:22], 0.5 * 0.316 * math.cos(sensordata[29]), 0.005, expected)
    assert pose.tolist() == expected.tolist() and q_est.tolist() == q[-1].tolist()


@pytest.mark.parametrize("k", [0, 3, 6])
def test_period_kernels_are_the_window_and_each_environments_parts(k):
    """Each environment's work after a period in one call: ``_push_window`` and the kernel of
    its own update (nothing but the window when the period has no samples), bit for bit."""
    rng = np.random.default_rng(k)
    gyro, accel, mag = rng.normal(size=(3, k, 3))
    fresh = rng.random(k) < 0.5
    q1, q2, q_true = rng.normal(size=(3, k, 4))

    def windows():
        """A window, and what ``_push_window`` makes of it."""
        window = rng.normal(size=(4, 11))
        want = window.copy()
        _push_window(want, gyro, accel, mag, fresh)
        return window, want

    window, want_window = windows()
    newest, want_newest = np.full(4, 7.0), np.full(4, 7.0)
    _attitude_period(window, gyro, accel, mag, fresh, q1, newest)
    if k:
        want_newest = q1[-1]
    assert window.tolist() == want_window.tolist() and newest.tolist() == want_newest.tolist()

    window, want_window = windows()
    got, want = np.full((2, 4), 7.0), np.full((2, 4), 7.0)
    errors, want_errors = np.full(2, 9.0), [9.0, 9.0]
    _tuning_period(window, gyro, accel, mag, fresh, q1, q2, q_true, got[0], got[1], errors)
    if k:
        want_errors = list(_mean_angles_to(q1, q2, q_true, want[0], want[1]))
    assert window.tolist() == want_window.tolist()
    assert got.tolist() == want.tolist() and errors.tolist() == want_errors

    window, want_window = windows()
    packed, sensordata = rng.normal(size=(20, 23)), rng.normal(size=30)
    pose, want_pose = np.array([3.0, -1.0, 0.2]), np.array([3.0, -1.0, 0.2])
    q_est, want_q_est = np.full(4, 7.0), np.full(4, 7.0)
    _driving_period(window, gyro, accel, mag, fresh, q1, packed, sensordata, 29, 0.158, 0.005, pose, q_est)
    if k:
        _navigate_period(q1, packed, sensordata, 29, 0.158, 0.005, want_pose, want_q_est)
    assert window.tolist() == want_window.tolist()
    assert pose.tolist() == want_pose.tolist() and q_est.tolist() == want_q_est.tolist()


def test_drive_action_writes_the_controls_of_its_driver_command():
    """Driving-v0's action in one kernel: the controls ``VehicleSim.apply`` (``apply_command``) writes for the
    DriverCommand the action stands for, bit for bit (signed zeros too): its brake the command
    that asks the throttle's fraction of each wheel's largest brake torque at the wheels' mean
    spin rate (the damper's kv·u·ω̄ = fraction · T_max, up to full braking); and the driver's
    progress before the step; an action outside the bounds or NaN writes nothing."""
    actuators = np.array([6, 0, 5, 1, 2, 3, 4], dtype=np.int64)  # steering, drive, resistance, four brakes
    low, high, max_steer = np.array([-1.0, -1.0]), np.array([1.0, 1.0]), 0.6
    kv, max_brake = 4000.0, 1500.0
    drivetrain = drivetrain_coefficients(DRIVETRAIN, mass_kg=1300.0, wheel_radius_m=0.316)
    state = DriverState()
    state.array[S_S] = 12.5
    for wheel_rates in (np.array([20.0, 20.5, 21.0, 21.3]), np.array([0.1, 0.0, -0.1, 0.2])):  # fl, fr, rl, rr
        mean_rate = float(np.mean(wheel_rates))
        for throttle, steering in [(0.3, -0.2), (-0.7, 1.0), (0.0, 0.0), (-0.0, -0.0), (1.0, -1.0), (-1.0, 0.5)]:
            brake = min(-throttle * max_brake / (kv * max(abs(mean_rate), 0.5)), 1.0) if throttle < 0.0 else 0.0
            if throttle < 0.0 and abs(mean_rate) > 0.5:
                assert kv * brake * mean_rate == pytest.approx(-throttle * max_brake, rel=1e-12)
            expected = np.full(7, 9.0)
            command = DriverCommand(steer_rad=steering * max_steer, drive=max(throttle, 0.0), brake=brake)
            apply_command(ControlArrays(expected, actuators, wheel_rates, drivetrain), command)
            ctrl = np.full(7, 9.0)
            assert _drive_action(np.array([throttle, steering]), low, high, max_steer, math.inf, kv, max_brake, ctrl,
                                 actuators, wheel_rates, drivetrain, state.array) == 12.5
            assert ctrl.tobytes() == expected.tobytes()
    for action in ([1.5, 0.0], [0.0, -1.01], [0.0, np.nan], [-np.inf, 0.0]):
        ctrl = np.full(7, 9.0)
        assert math.isnan(_drive_action(np.array(action), low, high, max_steer, math.inf, kv, max_brake, ctrl,
                                        actuators, wheel_rates, drivetrain, state.array))
        assert (ctrl == 9.0).all()


def test_drive_action_turns_the_steering_at_most_its_rate():
    """The steering command moves towards the action's angle by at most the step's rate limit
    from the command in ctrl, and reaches it exactly when it is within reach."""
    actuators = np.array([6, 0, 5, 1, 2, 3, 4], dtype=np.int64)
    low, high, max_steer, step = np.array([-1.0, -1.0]), np.array([1.0, 1.0]), 0.6, 0.012
    drivetrain = drivetrain_coefficients(DRIVETRAIN, mass_kg=1300.0, wheel_radius_m=0.316)
    wheel_rates, state = np.full(4, 20.0), DriverState()
    for before, steering, after in [(0.0, 1.0, 0.012), (0.3, -1.0, 0.288), (0.3, 0.51, 0.306), (-0.6, -1.0, -0.6),
                                    (0.1, 0.5, 0.1 + 0.012), (0.1, 0.175, 0.105)]:
        ctrl = np.zeros(7)
        ctrl[6] = before
        _drive_action(np.array([0.2, steering]), low, high, max_steer, step, 4000.0, 1500.0, ctrl, actuators,
                      wheel_rates, drivetrain, state.array)
        assert abs(ctrl[6] - before) <= step * (1 + 1e-12)
        assert ctrl[6] == pytest.approx(after, abs=1e-15)
    ctrl = np.zeros(7)
    ctrl[6] = 0.1
    _drive_action(np.array([0.2, 0.175]), low, high, max_steer, step, 4000.0, 1500.0, ctrl, actuators, wheel_rates,
                  drivetrain, state.array)
    assert ctrl[6] == 0.175 * max_steer  # (within reach: the action's angle itself)


@pytest.mark.parametrize("reading", ["D", "L"])
def test_tune_closed_sets_the_gains_a_new_estimator_has(reading):
    """GainTuning-v0's action for BISO tuned by r and f_c in one kernel: the values of
    ``params_from_action``'s expressions, ``gains_from_cutoff``, and the coefficients of an
    estimator made with those gains, bit for bit; nothing for the gains in force, nothing
    written for an action out of bounds."""
    tuned = make_estimator("biso", 200.0, cutoff_hz=0.1, reading=reading)
    scales = np.array([[0.0, 0.02], [math.nan, 50.0], [2.0, 0.98], [0.0, 1.0]])  # r linear in [0, 2], f_c log
    low, high, gains, values = -np.ones(2), np.ones(2), np.zeros(2), np.empty(4)
    tune = (low, high, gains, scales, 1, 0, reading == "L", values, 1.0)
    a = np.array([0.3, -0.4])
    assert _tune_closed(a, *tune) == 1
    ratio, cutoff = 0.0 + 0.5 * (0.3 + 1.0) * 2.0, 0.02 * 50.0 ** (0.5 * (-0.4 + 1.0))
    k, kp = gains_from_cutoff(cutoff, reading)
    assert values.tolist() == [ratio, cutoff, k, kp * ratio] and gains.tolist() == a.tolist()
    version = tuned.arrays_version
    tuned.retune(k=values[2], k_p=values[3], cutoff_hz=None)  # (the closed form's short path: in place)
    assert tuned.arrays_version == version
    made = make_estimator("biso", 200.0, k=k, k_p=kp * ratio, reading=reading)
    assert tuned.coefficients.tobytes() == made.coefficients.tobytes()
    assert _tune_closed(a.copy(), *tune) == 0
    for outside in ([1.2, 0.0], [0.0, math.nan]):
        assert _tune_closed(np.array(outside), *tune) == -1
        assert tuned.coefficients.tobytes() == made.coefficients.tobytes() and gains.tolist() == a.tolist()
    # with a lag the gains move by the fraction alpha of the way, and the values are theirs
    lagged = (low, high, gains, scales, 1, 0, reading == "L", values, 0.25)
    assert _tune_closed(np.array([-0.5, 0.4]), *lagged) == 1
    g = [0.3 + 0.25 * (-0.5 - 0.3), -0.4 + 0.25 * (0.4 + 0.4)]
    ratio, cutoff = 0.0 + 0.5 * (g[0] + 1.0) * 2.0, 0.02 * 50.0 ** (0.5 * (g[1] + 1.0))
    k, kp = gains_from_cutoff(cutoff, reading)
    assert gains.tolist() == g and values.tolist() == [ratio, cutoff, k, kp * ratio]


@pytest.mark.parametrize("use_truth", [False, True])
def test_driving_view_matches_the_plain_parts(use_truth):
    """Driving-v0's observation and true state in one kernel: the expressions of the plain
    parts (window, GNSS, estimate, wheel speeds, steering, pose, route ahead from
    ``Path.locate``), bit for bit."""
    path = random_route(9).path
    rng = np.random.default_rng(6)
    window, gnss = rng.normal(size=(4, 11)), rng.normal(size=9)
    q_est = rng.normal(size=4)
    newest = rng.normal(size=23)
    newest[7:11] /= np.linalg.norm(newest[7:11])
    i = 140
    sensordata = rng.normal(size=30)
    sensordata[3:5] = path.x_m[i] + 0.7, path.y_m[i] - 0.4  # the rear axle, near the path
    nav_pose = np.array([path.x_m[i] - 0.3, path.y_m[i] + 0.2, 0.4])
    offsets = 2.0 * np.arange(1, 11)
    driver_state = rng.normal(size=12)
    obs, values = np.empty(11 * 4 + 9 + 11 + 20), np.empty(9)
    nearest = _driving_view(obs, window, gnss, q_est, newest, sensordata, 3, 29, 0.316, nav_pose, use_truth,
                            path.x_m, path.y_m, path.s_m, i - 3, offsets, driver_state, values)
    w, x, y, z = newest[7:11]
    true_pose = [sensordata[3], sensordata[4], math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))]
    assert values.tolist() == [math.acos(min(max(1.0 - 2.0 * (x * x + y * y), -1.0), 1.0)), *true_pose,
                               _angle(q_est, newest[7:11]), newest[17], driver_state[S_S], driver_state[S_CROSS],
                               path.length_m]
    pose = true_pose if use_truth else nav_pose.tolist()
    index, s, offset = path.locate(pose[0], pose[1], i - 3)
    # the pose relative to the route: offset from the centre line, heading relative to the segment's
    heading = math.atan2(path.y_m[index + 1] - path.y_m[index], path.x_m[index + 1] - path.x_m[index])
    relative = [offset, (pose[2] - heading + math.pi) % (2.0 * math.pi) - math.pi]
    ahead = np.empty((10, 2))
    _route_ahead(path.x_m, path.y_m, path.s_m, s, offsets, *pose, ahead)
    expected = np.concatenate([window.ravel(), gnss, q_est, newest[18:22] * 0.316, sensordata[29:30], relative,
                               ahead.ravel()])
    assert nearest == index and obs.tolist() == expected.tolist()


def test_scale_observation_is_the_clipped_quotient_in_float32():
    rng = np.random.default_rng(3)
    raw = rng.normal(0.0, 10.0, size=30)
    index = np.array([0, 3, 4, 29, 7], dtype=np.int64)
    scale = rng.uniform(0.5, 5.0, size=5)
    low, high = -np.ones(5), np.ones(5)
    out = _scale_observation(raw, index, 1.0 / scale, low, high)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, np.clip(raw[index] * (1.0 / scale), low, high).astype(np.float32))


def test_route_ahead_matches_index_at():
    path = random_route(4).path
    offsets = 2.5 * np.arange(1, 13)
    rng = np.random.default_rng(2)
    for s in list(rng.uniform(0.0, path.length_m, 20)) + [0.0, path.length_m - 3.0, path.length_m + 5.0]:
        x, y, yaw = rng.normal(0.0, 30.0), rng.normal(0.0, 30.0), rng.uniform(-math.pi, math.pi)
        out = np.empty((len(offsets), 2))
        _route_ahead(path.x_m, path.y_m, path.s_m, s, offsets, x, y, yaw, out)
        for i, d in enumerate(offsets):
            j = path.index_at(s + d)
            # beyond the end: on along the last segment's direction
            beyond = max(s + d - path.length_m, 0.0)
            tx, ty = path.x_m[-1] - path.x_m[-2], path.y_m[-1] - path.y_m[-2]
            px = path.x_m[j] + beyond / math.hypot(tx, ty) * tx
            py = path.y_m[j] + beyond / math.hypot(tx, ty) * ty
            dx, dy = px - x, py - y
            expected = (math.cos(yaw) * dx + math.sin(yaw) * dy, -math.sin(yaw) * dx + math.cos(yaw) * dy)
            assert tuple(out[i]) == expected


def test_innovation_statistics_are_moving_averages_of_the_relative_rotation():
    """``_innovation_statistics`` against scipy: d = (R_tuned⁻¹ R_baseline).as_rotvec() (so that
    q_tuned ∘ exp(d) = q_baseline), then the exponential moving averages of d and |d|² in plain
    NumPy, the first with weight 1; quaternions of any non-zero length."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(4)
    state, out = np.full(4, np.nan), np.empty(4)  # (weight 1 overwrites whatever was there)
    mean, square = np.zeros(3), 0.0
    for i in range(40):
        q_tuned = rng.normal(size=4) * rng.uniform(0.5, 2.0)
        q_baseline = q_tuned + rng.normal(scale=0.2, size=4)  # (near, as the two copies are)
        weight = 1.0 if i == 0 else float(rng.uniform(0.01, 0.5))
        _innovation_statistics(q_tuned, q_baseline, weight, state, out)
        d = (Rotation.from_quat(np.roll(q_tuned, -1)).inv() * Rotation.from_quat(np.roll(q_baseline, -1))).as_rotvec()
        mean += weight * (d - mean)
        square += weight * (d @ d - square)
        np.testing.assert_allclose(out[:3], mean, rtol=1e-9, atol=1e-12)
        assert out[3] == pytest.approx(math.sqrt(square), rel=1e-9)
        assert state.tolist()[:3] == out.tolist()[:3]
