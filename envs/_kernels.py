"""Jitted kernels of the environments' own per-step work (arrays in, arrays out, no user
errors: the environments validate first). Each has a plain NumPy twin in the tests; the period
hooks at the end, the environments' plain path (the work after the period kernel)."""

from __future__ import annotations

import math

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.estimators.biso import _cutoff_gains
from biso_cosim.estimators._kernels import MAG_PARALLEL_SIN, _accel_ok, _mag_ok
from biso_cosim.estimators.reference import _ref_triad
from biso_cosim.frames import _qexp_rotvec, _qlog_rotvec, _qmul, _qnormalize
from biso_cosim.routes._kernels import LOCATE_AHEAD, LOCATE_BACK, _locate
from biso_cosim.vehicle._kernels import S_CROSS, S_S, TRUTH_LAYOUT, _apply_controls, _brake_command

__all__ = ["_scale_observation", "_inside", "_drive_action", "_tune_closed", "_push_window", "_angle", "_angles_to", "_mean_angle",
           "_mean_angles_to", "_dead_reckon", "_route_ahead", "_navigate_period", "_driving_view", "_attitude_period",
           "_tuning_period", "_driving_period", "_window_work", "_attitude_work", "_tuning_work", "_driving_work",
           "_corrected", "_log_gains", "_innovation", "_correction_work", "_mean_error_work",
           "_innovation_statistics"]

_Q0, _Q1 = TRUTH_LAYOUT.q_wb, TRUTH_LAYOUT.q_wb + 4  # a packed truth row's q_wb


@jit
def _push_window(values, gyro, accel, mag, fresh):
    """Shift the (n, 11) IMU window up by the k new samples (or as many as fit) and write
    them last: gyro, accel, mag (a non-finite row reads 0 and is not fresh), mag_fresh, new=1.
    Rows kept from before get new = 0."""
    n = values.shape[0]
    k = gyro.shape[0]
    take = min(k, n)
    keep = n - take
    for i in range(keep):  # ascending: row i + take is read before it is overwritten
        for j in range(11):
            values[i, j] = values[i + take, j]
        values[i, 10] = 0.0
    for r in range(take):
        i, src = keep + r, k - take + r
        finite = True
        for j in range(3):
            values[i, j] = gyro[src, j]
            values[i, 3 + j] = accel[src, j]
            if not math.isfinite(mag[src, j]):
                finite = False
        for j in range(3):
            values[i, 6 + j] = mag[src, j] if finite else 0.0
        values[i, 9] = 1.0 if (fresh[src] and finite) else 0.0
        values[i, 10] = 1.0


@jit
def _scale_observation(raw, index, inverse_scale, low, high):
    """The public observation of a raw (physical, float64) one: out[j] = raw[index[j]] ·
    inverse_scale[j], clipped to [low[j], high[j]], as a new float32 array."""
    out = np.empty(index.shape[0], dtype=np.float32)
    for j in range(index.shape[0]):
        out[j] = min(max(raw[index[j]] * inverse_scale[j], low[j]), high[j])
    return out


@jit
def _inside(a, low, high):
    """Whether low[i] <= a[i] <= high[i] for every i (False for NaN)."""
    for i in range(a.shape[0]):
        if not (low[i] <= a[i] <= high[i]):
            return False
    return True


@jit
def _drive_action(a, low, high, max_steer_rad, max_steer_step_rad, brake_kv, max_brake_nm, ctrl, actuators, wheel_rates,
                  drivetrain, driver_state):
    """Driving-v0's action (throttle, steering) into MuJoCo's ``ctrl`` when it is inside
    [low, high] (``_inside``): the controls of its DriverCommand, steer = the steering
    command moved towards steering · max_steer_rad by at most ``max_steer_step_rad`` (the
    steering system's rate limit over one step; the previous command is the one in ``ctrl``),
    drive = max(throttle, 0), and for a throttle below 0 the brake command
    that asks that fraction of each wheel's largest brake torque ``max_brake_nm`` at the
    wheels' mean spin rate (``_brake_command``, as the scripted driver asks a torque; the
    brakes are dampers of gain ``brake_kv``, so the command itself is not a torque share), by
    ``_apply_controls`` (``VehicleSim.apply``'s: the drive through the drivetrain). Returns
    the driver's progress along the route before the step (m), or NaN, with nothing written,
    when the action is not inside."""
    if not _inside(a, low, high):
        return math.nan
    throttle, steering = a[0], a[1]
    brake = 0.0
    if throttle < 0.0:
        rate = 0.0
        for j in range(wheel_rates.shape[0]):
            rate += wheel_rates[j]
        brake = min(_brake_command(-throttle * max_brake_nm, brake_kv, rate / wheel_rates.shape[0]), 1.0)
    steer, steer_before = steering * max_steer_rad, ctrl[actuators[0]]
    if steer > steer_before + max_steer_step_rad:  # (within reach: the target itself, bit for bit)
        steer = steer_before + max_steer_step_rad
    elif steer < steer_before - max_steer_step_rad:
        steer = steer_before - max_steer_step_rad
    _apply_controls(ctrl, actuators, steer, max(throttle, 0.0), brake, wheel_rates, drivetrain)
    return driver_state[S_S]


@jit
def _tune_closed(a, low, high, gains, scales, cutoff_index, ratio_index, reading_l, values, alpha):
    """GainTuning-v0's action for BISO tuned by f_c and r alone, in its closed form, when
    it is inside [low, high] (``_inside``): the ``gains`` in force move by the fraction
    ``alpha`` towards it (g + alpha · (a − g); 1: to a), and when that changes them, the
    values they stand for into values[:m] (``params_from_action``: scales' rows are low,
    high / low, high − low and 1 for a log scale), k and k_p into values[m], values[m + 1]
    (``gains_from_cutoff`` of f_c, k_p times r; for ``BisoEstimator.retune``) and the new
    gains into ``gains``. Returns 1 then, 0 when the gains stay, and -1, with nothing
    written, when a is not inside."""
    if not _inside(a, low, high):
        return -1
    m = a.shape[0]
    same = True
    for i in range(m):
        g = gains[i] + alpha * (a[i] - gains[i])
        same = same and g == gains[i]
        values[i] = g  # (the new gains for now)
    if same:
        return 0
    for i in range(m):
        gains[i] = values[i]
        u = 0.5 * (values[i] + 1.0)
        values[i] = scales[0, i] * scales[1, i] ** u if scales[3, i] else scales[0, i] + u * scales[2, i]
    k, kp = _cutoff_gains(values[cutoff_index], reading_l)
    kp *= values[ratio_index]
    values[m], values[m + 1] = k, kp
    return 1


@jit
def _angle(p, q):
    """Rotation angle (rad, [0, π]) between the attitudes of quaternions p and q of any
    non-zero length (the expression of ``frames.quat_angle_between``, bit for bit)."""
    pw, px, py, pz = _qnormalize(p[0], p[1], p[2], p[3])
    qw, qx, qy, qz = _qnormalize(q[0], q[1], q[2], q[3])
    d = _qmul(pw, -px, -py, -pz, qw, qx, qy, qz)
    return 2.0 * math.atan2(math.sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3]), abs(d[0]))


@jit
def _angles_to(p1, p2, q):
    """(_angle(p1, q), _angle(p2, q)) in one call."""
    return _angle(p1, q), _angle(p2, q)


@jit
def _mean_angle(p, q):
    """Mean over the rows of the angle between p[i] and q[i] ((k, 4) each, k > 0)."""
    total = 0.0
    for i in range(p.shape[0]):
        total += _angle(p[i], q[i])
    return total / p.shape[0]


@jit
def _mean_angles_to(p1, p2, q, last1, last2):
    """(_mean_angle(p1, q), _mean_angle(p2, q)) in one call, with the last rows of p1 and p2
    copied into last1, last2 (k > 0 rows each)."""
    k = p1.shape[0]
    for j in range(4):
        last1[j] = p1[k - 1, j]
        last2[j] = p2[k - 1, j]
    return _mean_angle(p1, q), _mean_angle(p2, q)


@jit
def _dead_reckon(q, wheel_rates, speed_scale, dt, pose):
    """Advance the 2-D pose (x, y, yaw) over k samples: each moves it by dt·v·(horizontal
    forward axis of q_wb), v = speed_scale·(front-left + front-right wheel rate); the yaw
    becomes that of the last sample's forward axis."""
    fx = 1.0
    fy = 0.0
    for i in range(q.shape[0]):
        w, x, y, z = q[i, 0], q[i, 1], q[i, 2], q[i, 3]
        fx = 1.0 - 2.0 * (y * y + z * z)
        fy = 2.0 * (x * y + w * z)
        v = speed_scale * (wheel_rates[i, 0] + wheel_rates[i, 1])
        pose[0] += dt * v * fx
        pose[1] += dt * v * fy
    if q.shape[0]:
        pose[2] = math.atan2(fy, fx)


@jit
def _navigate_period(q, packed, sensordata, steer_index, half_radius_m, dt, pose, q_est):
    """Driving-v0's navigation over one period's k samples (k > 0): ``_dead_reckon`` with the
    rear axle's speed half_radius·cos(steering)·(fl + fr wheel rate) (the packed truth's
    wheel rates; steering read from MuJoCo's sensordata), and the newest estimate copied
    into q_est."""
    speed_scale = half_radius_m * math.cos(sensordata[steer_index])
    wheels = TRUTH_LAYOUT.wheel_rates
    _dead_reckon(q, packed[:, wheels:wheels + 4], speed_scale, dt, pose)
    for j in range(4):
        q_est[j] = q[q.shape[0] - 1, j]


@jit
def _attitude_period(window, gyro, accel, mag, fresh, baseline, baseline_q):
    """AttitudeEstimation-v0's work after a period of k samples: ``_push_window``, and the
    newest reference estimate (the last row of ``baseline``) copied into baseline_q (k > 0)."""
    _push_window(window, gyro, accel, mag, fresh)
    k = baseline.shape[0]
    if k:
        for j in range(4):
            baseline_q[j] = baseline[k - 1, j]


@jit
def _corrected(prior, a, innovation, gain_max, out):
    """AttitudeEstimation-v0's correction action: out = prior ∘ exp(g ⊙ innovation), the
    gains g_i = max(a_i, 0) · gain_max (0: the prior; 1 with gain_max 1: the
    accelerometer+magnetometer attitude), normalised, w >= 0."""
    g0, g1, g2 = max(a[0], 0.0) * gain_max, max(a[1], 0.0) * gain_max, max(a[2], 0.0) * gain_max
    cw, cx, cy, cz = _qexp_rotvec(g0 * innovation[0], g1 * innovation[1], g2 * innovation[2])
    w, x, y, z = _qmul(prior[0], prior[1], prior[2], prior[3], cw, cx, cy, cz)
    w, x, y, z = _qnormalize(w, x, y, z)
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    out[0], out[1], out[2], out[3] = w, x, y, z


@jit
def _log_gains(a, dt, tau, log_ratio, out):
    """AttitudeEstimation-v0's correction gains on the logarithmic scale: out_i = 1 − exp(−dt/τ_i),
    τ_i = tau · exp((1 − a_i)/2 · log_ratio) (a_i = 1: tau; a_i = −1: tau times the ratio)."""
    for i in range(a.shape[0]):
        out[i] = -math.expm1(-dt / (tau * math.exp(0.5 * (1.0 - a[i]) * log_ratio)))


@jit
def _innovation(prior, f, m, cdh, sdh, out):
    """The rotation vector (body axes, rad) from ``prior`` (unit) to the accelerometer+magnetometer
    attitude of the specific force f and field m (TRIAD, declination D: cdh, sdh = cos(D/2),
    sin(D/2); ``reference_attitude``'s expressions; without a usable field the heading is the
    prior's): prior ∘ exp(out) is that attitude. Zeros without a usable specific force."""
    fx, fy, fz = f[0], f[1], f[2]
    ok, f2 = _accel_ok(fx, fy, fz)
    if not ok:
        out[0] = out[1] = out[2] = 0.0
        return
    mx, my, mz = m[0], m[1], m[2]
    ex, ey, ez = my * fz - mz * fy, mz * fx - mx * fz, mx * fy - my * fx
    e2 = ex * ex + ey * ey + ez * ez
    mag_ok, m2 = _mag_ok(mx, my, mz)
    mag_ok = mag_ok and e2 > (MAG_PARALLEL_SIN * MAG_PARALLEL_SIN) * m2 * f2
    pw, px, py, pz = prior[0], prior[1], prior[2], prior[3]
    q = _ref_triad(fx, fy, fz, f2, ex, ey, ez, e2, mag_ok, pw, px, py, pz, cdh, sdh)
    d = _qmul(pw, -px, -py, -pz, q[0], q[1], q[2], q[3])
    out[0], out[1], out[2] = _qlog_rotvec(d[0], d[1], d[2], d[3])


@jit
def _correction_period(window, gyro, accel, mag, fresh, baseline, baseline_q, estimate, dt, cdh, sdh, prior,
                       innovation):
    """AttitudeEstimation-v0's work after a period of k samples with correction actions:
    ``_attitude_period``, and (k > 0) the prior, the agent's ``estimate`` rotated by
    exp(ω_i dt) for each sample i in turn (normalised, w >= 0), and the ``_innovation`` of the
    newest sample from it."""
    _attitude_period(window, gyro, accel, mag, fresh, baseline, baseline_q)
    k = gyro.shape[0]
    if k == 0:
        return
    w, x, y, z = estimate[0], estimate[1], estimate[2], estimate[3]
    for i in range(k):
        cw, cx, cy, cz = _qexp_rotvec(gyro[i, 0] * dt, gyro[i, 1] * dt, gyro[i, 2] * dt)
        w, x, y, z = _qmul(w, x, y, z, cw, cx, cy, cz)
    w, x, y, z = _qnormalize(w, x, y, z)
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    prior[0], prior[1], prior[2], prior[3] = w, x, y, z
    _innovation(prior, accel[k - 1], mag[k - 1], cdh, sdh, innovation)


@jit
def _tuning_period(window, gyro, accel, mag, fresh, tuned, baseline, q_true, tuned_q, baseline_q, errors):
    """GainTuning-v0's work after a period of k samples: ``_push_window``, and (k > 0)
    ``_mean_angles_to(tuned, baseline, q_true, tuned_q, baseline_q)`` into errors (2,)."""
    _push_window(window, gyro, accel, mag, fresh)
    if tuned.shape[0]:
        errors[0], errors[1] = _mean_angles_to(tuned, baseline, q_true, tuned_q, baseline_q)


@jit
def _driving_period(window, gyro, accel, mag, fresh, q, packed, sensordata, steer_index, half_radius_m, dt, pose,
                    q_est):
    """Driving-v0's work after a period of k samples: ``_push_window``, and (k > 0)
    ``_navigate_period``."""
    _push_window(window, gyro, accel, mag, fresh)
    if q.shape[0]:
        _navigate_period(q, packed, sensordata, steer_index, half_radius_m, dt, pose, q_est)


@jit
def _driving_view(obs, window, gnss, q_est, newest, sensordata, axle_x, steer_index, wheel_radius_m, nav_pose,
                  use_truth, path_x, path_y, path_s, nav_hint, offsets, driver_state, values):
    """Driving-v0's observation and the true state of its ``info``, from the newest truth row
    ``newest`` (packed, 23 columns), MuJoCo's sensordata (rear axle x, y; steering) and the
    driver's state array (progress, cross-track error).

    values (9,) = tilt of the body's up axis (rad), true rear-axle x, y (m) and yaw (rad),
    angle between q_est and the true attitude (rad), forward speed (m/s), the driver's
    progress and cross-track error (m), the path's length (m). obs = window (ravelled),
    gnss, q_est, wheel speeds (rate × radius), steering, the pose the route ahead is placed
    from (nav_pose, or the true pose with use_truth) relative to the route (signed offset
    from the centre line, m, left +; heading relative to the route's, rad), the route ahead of it
    (``_route_ahead`` from the nearest point found by ``_locate`` in Path.locate's window
    around nav_hint). Returns the index of that nearest point (the next call's hint)."""
    w, x, y, z = newest[7], newest[8], newest[9], newest[10]
    values[0] = math.acos(min(max(1.0 - 2.0 * (x * x + y * y), -1.0), 1.0))
    values[1] = sensordata[axle_x]
    values[2] = sensordata[axle_x + 1]
    values[3] = math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))
    values[4] = _angle(q_est, newest[7:11])
    values[5] = newest[17]
    values[6] = driver_state[S_S]
    values[7] = driver_state[S_CROSS]
    values[8] = path_s[path_s.shape[0] - 1]
    pose = values[1:4] if use_truth else nav_pose
    i = 0
    for v in window.ravel():
        obs[i] = v
        i += 1
    for j in range(gnss.shape[0]):
        obs[i + j] = gnss[j]
    i += gnss.shape[0]
    for j in range(4):
        obs[i + j] = q_est[j]
        obs[i + 4 + j] = newest[18 + j] * wheel_radius_m
    obs[i + 8] = sensordata[steer_index]
    lo = max(nav_hint - LOCATE_BACK, 0)
    hi = min(nav_hint + LOCATE_AHEAD, path_s.shape[0] - 1)
    nearest, s, offset = _locate(path_x, path_y, path_s, pose[0], pose[1], lo, hi)
    # the pose relative to the route: signed offset from the centre line (left +) and heading
    # relative to the direction of travel of the nearest segment
    heading = math.atan2(path_y[nearest + 1] - path_y[nearest], path_x[nearest + 1] - path_x[nearest])
    obs[i + 9] = offset
    obs[i + 10] = (pose[2] - heading + math.pi) % (2.0 * math.pi) - math.pi
    i += 11
    _route_ahead(path_x, path_y, path_s, s, offsets, pose[0], pose[1], pose[2], obs[i:].reshape((offsets.shape[0], 2)))
    return nearest


@jit
def _route_ahead(path_x, path_y, path_s, s, offsets, x, y, yaw, out):
    """Points of the path at arc lengths s + offsets (the last sample at or before each;
    beyond the path's end, on the straight line its last segment continues on: the road
    goes on past the finish line, so the preview does not shrink to a point there),
    relative to (x, y), in the frame turned by yaw: out (P, 2)."""
    c, sn = math.cos(yaw), math.sin(yaw)
    n = path_s.shape[0]
    end_s = path_s[n - 1]
    tx, ty = path_x[n - 1] - path_x[n - 2], path_y[n - 1] - path_y[n - 2]
    norm = math.hypot(tx, ty)
    j = max(np.searchsorted(path_s, s + offsets[0], side="right") - 1, 0)
    for i in range(offsets.shape[0]):  # offsets ascending: walk on from there
        target = s + offsets[i]
        while j + 1 < n and path_s[j + 1] <= target:
            j += 1
        beyond = (target - end_s) / norm if target > end_s else 0.0
        dx, dy = path_x[j] + beyond * tx - x, path_y[j] + beyond * ty - y
        out[i, 0] = c * dx + sn * dy
        out[i, 1] = -sn * dx + c * dy


# --------------------------------------------------------------------------- per-period work
# Each environment's work after a period (``biso_cosim.loop.PeriodWork``, attached to the
# co-simulation): ``kernel(samples, q, arrays)`` on the period's ``PeriodSamples`` (k rows),
# ``q`` the q_wb outputs of the estimators the environment named (their first k rows are
# the period's), ``arrays`` the environment's own; the same call on both of the loop's paths.


@jit
def _window_work(samples, q, arrays):
    """The IMU window alone (arrays: (window,))."""
    _push_window(arrays[0], samples.gyro_b, samples.accel_b, samples.mag_b, samples.mag_fresh)


@jit
def _attitude_work(samples, q, arrays):
    """``_attitude_period`` (q: the baseline's; arrays: window, baseline_q)."""
    k = samples.gyro_b.shape[0]
    _attitude_period(arrays[0], samples.gyro_b, samples.accel_b, samples.mag_b, samples.mag_fresh, q[0][:k],
                     arrays[1])


@jit
def _tuning_work(samples, q, arrays):
    """``_tuning_period`` (q: the tuned copy's, the baseline's; arrays: window, tuned_q,
    baseline_q, errors (2,), samples (1,) int64: the period's number of samples)."""
    k = samples.gyro_b.shape[0]
    arrays[4][0] = k
    _tuning_period(arrays[0], samples.gyro_b, samples.accel_b, samples.mag_b, samples.mag_fresh, q[0][:k], q[1][:k],
                   samples.truth[:, _Q0:_Q1], arrays[1], arrays[2], arrays[3])


@jit
def _driving_work(samples, q, arrays):
    """``_driving_period`` (q: the estimator's; arrays: window, sensordata, steer_index,
    half_radius_m, dt, pose, q_est)."""
    k = samples.gyro_b.shape[0]
    _driving_period(arrays[0], samples.gyro_b, samples.accel_b, samples.mag_b, samples.mag_fresh, q[0][:k],
                    samples.truth, arrays[1], arrays[2], arrays[3], arrays[4], arrays[5], arrays[6])


@jit
def _correction_work(samples, q, arrays):
    """``_correction_period`` (q: the baseline's; arrays: window, baseline_q, estimate,
    constants (dt, cos(D/2), sin(D/2)), prior, innovation)."""
    k = samples.gyro_b.shape[0]
    c = arrays[3]
    _correction_period(arrays[0], samples.gyro_b, samples.accel_b, samples.mag_b, samples.mag_fresh, q[0][:k],
                       arrays[1], arrays[2], c[0], c[1], c[2], arrays[4], arrays[5])


@jit
def _mean_error_work(samples, q, arrays):
    """One estimator's angle to the truth over the period's samples (q: its; arrays: (errors
    (2,),)): the mean into errors[0] and the newest sample's into errors[1], when the period has
    samples (GainTuning-v0's reference copy)."""
    k = samples.gyro_b.shape[0]
    if k:
        arrays[0][0] = _mean_angle(q[0][:k], samples.truth[:, _Q0:_Q1])
        arrays[0][1] = _angle(q[0][k - 1], samples.truth[k - 1, _Q0:_Q1])


@jit
def _innovation_statistics(q_tuned, q_baseline, weight, state, out):
    """GainTuning-v0's innovation statistics after a step: the rotation vector d (rad, the tuned
    estimate's body axes) from the tuned copy's attitude ``q_tuned`` to the baseline copy's
    ``q_baseline`` (q_tuned ∘ exp(d) = q_baseline; any non-zero length), and exponential moving
    averages of d and of |d|² with this ``weight`` (1 at the episode's first step: they start there):
    state[:3] += weight·(d − state[:3]), state[3] += weight·(|d|² − state[3]);
    out[:3] = state[:3], out[3] = √state[3]."""
    pw, px, py, pz = _qnormalize(q_tuned[0], q_tuned[1], q_tuned[2], q_tuned[3])
    qw, qx, qy, qz = _qnormalize(q_baseline[0], q_baseline[1], q_baseline[2], q_baseline[3])
    d = _qmul(pw, -px, -py, -pz, qw, qx, qy, qz)
    dx, dy, dz = _qlog_rotvec(d[0], d[1], d[2], d[3])
    d2 = dx * dx + dy * dy + dz * dz
    if weight >= 1.0:  # (the first step: the averages start at its values, whatever was there)
        state[0], state[1], state[2], state[3] = dx, dy, dz, d2
    else:
        state[0] += weight * (dx - state[0])
        state[1] += weight * (dy - state[1])
        state[2] += weight * (dz - state[2])
        state[3] += weight * (d2 - state[3])
    out[0], out[1], out[2] = state[0], state[1], state[2]
    out[3] = math.sqrt(max(state[3], 0.0))
