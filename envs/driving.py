"""``biso_cosim/Driving-v0``: the agent drives from what the car itself measures."""

from __future__ import annotations

import bisect
import math
from typing import Any, Mapping

import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle

from biso_cosim.cosim import CONTROLS_APPLIED, DEFAULT_SENSOR_PROFILE, EstimatorSpec
from biso_cosim.loop import PeriodWork
from biso_cosim.envs._common import COMMON_ARGUMENTS, CosimEnv, Scale, _check_choice, _check_number
from biso_cosim.envs._docs import finish_docstring
from biso_cosim.envs._kernels import _drive_action, _driving_view, _driving_work
from biso_cosim.routes import Route
from biso_cosim.routes.path import curvature_speed_limit
from biso_cosim.vehicle.driver import DriverCommand, DriverParams

__all__ = ["DrivingEnv"]

_POSE_SOURCES = ("estimate", "truth")
# Within this distance of the end of the route (m) the route counts as driven.
_END_TOLERANCE_M = 1.0
# Progress along the route (m) that restarts the stall clock (``stall_s``).
_STALL_PROGRESS_M = 1.0
# The first control period after reset holds the car (the agent's first action follows it).
_HOLD = DriverCommand(steer_rad=0.0, drive=0.0, brake=1.0)
_NO_GNSS = np.empty(0)


class DrivingEnv(CosimEnv, EzPickle):
    r"""
    ## Description
    The agent drives the car (throttle, brake, steering) along a route, observing only what
    a car has on board: the virtual MPU-9250's samples, the attitude of the estimator in
    the loop (`biso_plus` by default, which takes the co-simulation's wheel odometry; the
    faithful BISO of Aleshkin et al. 2024 with `estimator="biso"`), wheel speeds, the
    steering angle, and the route ahead as a navigation system would place it from its own
    pose. That pose is dead-reckoned from the estimator's heading and the front-wheel speed,
    starting at the known start of the route, so the estimator's errors steer the car: this
    is estimation in the control loop (with the faithful BISO's errors of tens of degrees the
    car leaves the road within tens of metres; with `biso_plus` a pure-pursuit policy that
    keeps the driven wheels from spinning drives `figure8` to its end, 0.6 m off). With `pose_source="truth"` the route ahead is placed
    from the true pose instead (the same task without the estimation errors). With
    `gnss_rate_hz` the newest GNSS fix joins the observation: the agent may use it to correct
    the navigation pose (the environment does not fuse it).

    ## Action Space
    A `Box(-1, 1, (2,), float32)`:

    | Num | Action | Min | Max | Unit |
    |---|---|---|---|---|
    | 0 | throttle: > 0 drive torque at the rear wheels (fraction of 2400 N·m at the axle), < 0 brakes (fraction of each wheel's largest brake torque, all four wheels) | -1 | 1 | - |
    | 1 | steering: road-wheel angle as a fraction of the largest (0.6 rad), positive left, that the steering turns towards at up to `steer_rate_rad_s` | -1 | 1 | - |

    The steering system turns the road wheels at most `steer_rate_rad_s` (0.6 rad/s by
    default, about 500 °/s at the steering wheel with a 15:1 ratio: a brisk driver's rate,
    the scripted driver's `DriverParams.steer_rate_rad_s`), so an action that jumps from lock
    to lock between steps moves the wheels by 0.012 rad a step at 50 Hz, as a real car's
    steering would, instead of swinging them 1.2 rad in a few milliseconds.

    NaN/inf or a wrong shape raise `ValueError`; out-of-bounds values are clipped (or
    refused with `action_bounds="raise"`), as MuJoCo would clamp the controls.

    ## Observation Space
    A bounded `Box(low, high, (9·n + 11 + 2·P,), float32)` (`+9` with GNSS), scaled as in
    `AttitudeEstimation-v0` (`observation_fields`, `observation_scale`, `split_observation`),
    in this order (`env.unwrapped.observation_structure`):

    - *imu (n × 9):* the newest `n = ceil(ODR / control rate)` IMU samples as in
      `AttitudeEstimation-v0`;
    - *gnss (9), only with `gnss_rate_hz`:* the newest GNSS fix as in `AttitudeEstimation-v0`;
    - *q_wb (4):* the estimator's attitude at the newest sample;
    - *wheel_speed_mps (4):* wheel spin rate × tyre radius, fl, fr, rl, rr (ideal sensors),
      in units of 10 m/s (bounds ±100 m/s);
    - *steering_rad (1):* the measured road-wheel angle, in units of the largest (0.6 rad);
    - *route_pose (2):* the pose the route ahead is placed from (dead-reckoned, or true with
      `pose_source="truth"`) relative to the route: `offset`, the signed distance from the
      centre line (left +) in units of `max_cross_track_m` (±1 is the edge of the road), and
      `heading`, the heading relative to the route's direction of travel, in units of π rad;
    - *route_ahead (P × 2):* the route's centre line at `preview_spacing_m`, 2·`preview_spacing_m`,
      … ahead of the nearest point to the pose, in the pose's frame (x forward, y left), in
      units of the preview's reach P·`preview_spacing_m` (bounds ±2). Past the route's end
      the points go on along its last direction, as the road does past a finish line (the
      preview shrinking to the end point would read as a wall: the policies of `docs/envs.md`
      "Driving at 10 Hz" stopped short of it).

    ## Rewards
    The total reward is: ***reward*** *=* *reward_progress + reward_cross_track +
    reward_rollover + reward_off_route*, each from the true state at the end of the step.
    Every term is bounded by the step's progress or is a one-off at the end, so that no
    penalty accumulates while the car stands or crawls:

    - *reward_progress:* `progress_weight` × Δs', the credited progress Δs' = min(Δs, L) −
      `overspeed_weight` × max(Δs − L, 0), Δs the distance gained along the route in the step
      (m; negative when driving back), L = v_lim·dt the distance the road's speed limit v_lim
      at the car's position allows in a step: about 0.14 a step at 7 m/s, and the route's
      length over an episode that drives it within the limit (387 for `figure8`). The limit
      is `speed_limit_mps`, lowered in turns to √(a/|κ|) (κ the route's curvature, a =
      `speed_limit_accel_mps2`) and before them so that braking at a reaches the turn's limit
      (`speed_limits_mps`). Each metre beyond the limit's takes `overspeed_weight` metres off
      (default 1: a step at 1.5·v_lim earns what one at 0.5·v_lim does, at 2·v_lim nothing),
      so the reward peaks at the limit and its slope tells the agent which way to go (with
      0, speed above the limit is merely worth nothing, and a policy may drive the turns at
      any speed it survives). |Δs'| ≤ |Δs|. With `speed_limit_mps=None` every metre counts;
    - *reward_cross_track:* −`progress_weight` × `cross_track_weight` × max(Δs', 0) ×
      min(|e| / `max_cross_track_m`, 1), Δs' the credited progress, e the cross-track error:
      the fraction of the step's forward progress lost for driving off the centre line, all of
      it (with the default weight 1) at the edge of the road. It is zero when the car does not
      progress and never larger than the progress term: the one-off penalties aside, a step
      earns w·Δs' when Δs' ≤ 0 and between 0 and w·Δs' otherwise (w = `progress_weight`), so
      standing still earns exactly 0, dawdling little, driving along the centre line the most;
    - *reward_rollover:* −`rollover_penalty` when the car tilts past `rollover_tilt_rad`;
    - *reward_off_route:* −`off_route_penalty` when |e| exceeds `max_cross_track_m`.

    Leaving the road or rolling over ends the episode (terminated) with a penalty of 5 by
    default, the worth of 5 m of road: less than what is lost with the episode (about 14
    discounted with γ = 0.99 at 7 m/s, the rest of the route undiscounted), so that the loss of
    the progress not made dominates it and driving on is worth more than its risk. An episode
    in which the car gains less than 1 m along the route in `stall_s` seconds is truncated
    (`info["stalled"]`): a stalled car earns nothing, and the rest of such an episode would
    only waste samples. The scripted pure-pursuit driver of `biso_cosim.envs.baselines` earns
    342.5 on `figure8` with the dead-reckoned pose (mean over the evaluation seeds 1000–1004;
    353.6 on the procedural routes of those seeds; 343.3 and 359.1 at 10 Hz decisions) and
    completes every one of them (tested).

    `info` carries each term (they sum to the reward exactly) and `distance_m`,
    `speed_limit_mps` (v_lim at the car's position),
    `cross_track_m`, `speed_mps`, `tilt_rad`, `attitude_error_rad` (estimator vs truth),
    `nav_pose` and `true_pose` (rear axle x, y in m and yaw in rad, ENU), `pose_error_m` and
    `heading_error_rad` (navigation pose vs truth), `rolled_over`, `off_route`, `finished`,
    `stalled`.

    ## Starting State
    The car stands at the start of the route, settled, brakes on. `reset` holds it there for
    `alignment_s` (at least one control period): the estimator initialises and aligns at
    rest, as a car's navigation does before driving off; the first observation follows.

    ## Episode End
    ### Termination
    The car rolls over, leaves the route by more than `max_cross_track_m`, or reaches the end
    of the route (`info["finished"]`).

    ### Truncation
    After `episode_duration_s` simulated seconds (default: 1.5 times the route's nominal
    duration plus 10 s), or when the car has gained less than 1 m along the route in the last
    `stall_s` seconds (`info["stalled"]`).

    ## Arguments
    {arguments}

    ## Version History
    * v0: Initial version; the speed limit of the progress reward (`speed_limit_mps`,
      `speed_limit_accel_mps2`) added (2026-12-07); the steering system's rate limit
      (`steer_rate_rad_s`) and the loss of progress beyond the limit (`overspeed_weight`)
      added (2026-12-07, `docs/envs.md` "Driving: the steering's rate and the overspeed");
      the route ahead continued past the route's end (2026-12-07, "Driving at 10 Hz").
    """

    ARGUMENTS = {
        "estimator": "estimator in the loop (`biso_cosim.estimators.estimator_names()`)",
        "estimator_params": "its parameters; the declination of the route's site is set unless given",
        "pose_source": '`"estimate"`: route ahead placed from the dead-reckoned pose; `"truth"`: from the true pose',
        "alignment_s": "time the car stands braked at the start before the first observation (the "
                       "estimator's alignment at rest), s",
        "preview_points": "number P of route points ahead in the observation",
        "preview_spacing_m": "distance between them along the route, m",
        "progress_weight": "weight of the progress term, per m",
        "cross_track_weight": "fraction of a step's forward progress lost at the edge of the road (linear in "
                              "the cross-track error), 0 to 1",
        "rollover_penalty": "penalty of a roll-over (ends the episode), in units of the progress term (m of road)",
        "off_route_penalty": "penalty of leaving the route (ends the episode), in units of the progress term (m of road)",
        "speed_limit_mps": "speed up to which progress is credited, m/s (None: all progress); lowered in turns "
                           "and before them by `speed_limit_accel_mps2`",
        "overspeed_weight": "metres of credited progress taken off for each metre driven beyond the speed "
                            "limit's, 0 to 1",
        "speed_limit_accel_mps2": "lateral acceleration the speed limit allows in turns, and its deceleration "
                                  "before them, m/s²",
        "stall_s": "the episode is truncated when the car gains less than 1 m along the route in this time, s "
                   "(None: never)",
        "steer_rate_rad_s": "largest rate of the road-wheel angle the steering system turns at, rad/s (None: "
                            "no limit)",
        "max_cross_track_m": "cross-track error that counts as leaving the route, m",
        "rollover_tilt_rad": "tilt of the body's up axis from the vertical that counts as a roll-over, rad (60°)",
    }
    ACTION_NAMES = ("throttle", "steering")
    REWARD_TERMS = ("reward_progress", "reward_cross_track", "reward_rollover", "reward_off_route")

    def __init__(self, *, route: str | Route = "figure8", estimator: str = "biso_plus",
                 estimator_params: Mapping[str, Any] | None = None, pose_source: str = "estimate",
                 alignment_s: float = 2.0,
                 preview_points: int = 10, preview_spacing_m: float = 2.0, progress_weight: float = 1.0,
                 cross_track_weight: float = 1.0, rollover_penalty: float = 5.0, off_route_penalty: float = 5.0,
                 steer_rate_rad_s: float | None = DriverParams.steer_rate_rad_s,
                 max_cross_track_m: float = 5.0, rollover_tilt_rad: float = math.radians(60.0),
                 speed_limit_mps: float | None = 10.0, speed_limit_accel_mps2: float = 3.0,
                 overspeed_weight: float = 1.0,
                 stall_s: float | None = 10.0,
                 random_route_options: Mapping[str, Any] | None = None, episode_duration_s: float | None = None,
                 sensor_profile: str = DEFAULT_SENSOR_PROFILE, sensor_noise: bool = True,
                 sensor_seed: int | None = None, registers: Mapping[str, int] | None = None,
                 gnss_rate_hz: float | None = None,
                 gnss_profile: str = "consumer", control_rate_hz: float = 50.0,
                 physics_rate_hz: float = 1000.0, gyro_calibration_s: float = 0.0, action_bounds: str = "clip",
                 render_mode: str | None = None, render_width: int = 480, render_height: int = 270):
        arguments = {k: v for k, v in locals().items() if k not in ("self", "__class__")}
        EzPickle.__init__(self, **arguments)
        self.pose_source = _check_choice("pose_source", pose_source, _POSE_SOURCES)
        self.alignment_s = _check_number("alignment_s", alignment_s, low=0.0, high=60.0)
        self._alignment_periods = int(round(self.alignment_s * _check_number("control_rate_hz", control_rate_hz,
                                                                             low=0.0, low_open=True)))
        if isinstance(preview_points, bool) or not isinstance(preview_points, (int, np.integer)) or preview_points < 1:
            raise ValueError(f"preview_points must be an int >= 1, got {preview_points!r}")
        self.preview_points = int(preview_points)
        self.preview_spacing_m = _check_number("preview_spacing_m", preview_spacing_m, low=0.0, low_open=True)
        self.weights = {
            "progress": _check_number("progress_weight", progress_weight, low=0.0),
            "cross_track": _check_number("cross_track_weight", cross_track_weight, low=0.0, high=1.0),
            "rollover": _check_number("rollover_penalty", rollover_penalty, low=0.0),
            "off_route": _check_number("off_route_penalty", off_route_penalty, low=0.0),
            "overspeed": _check_number("overspeed_weight", overspeed_weight, low=0.0, high=1.0),
        }
        self.max_cross_track_m = _check_number("max_cross_track_m", max_cross_track_m, low=0.0, low_open=True)
        self.speed_limit_mps = None if speed_limit_mps is None else _check_number(
            "speed_limit_mps", speed_limit_mps, low=0.0, low_open=True)
        self.speed_limit_accel_mps2 = _check_number("speed_limit_accel_mps2", speed_limit_accel_mps2, low=0.0,
                                                    low_open=True)
        self.steer_rate_rad_s = None if steer_rate_rad_s is None else _check_number(
            "steer_rate_rad_s", steer_rate_rad_s, low=0.0, low_open=True)
        self.stall_s = None if stall_s is None else _check_number("stall_s", stall_s, low=0.0, low_open=True)
        self.rollover_tilt_rad = _check_number("rollover_tilt_rad", rollover_tilt_rad, low=0.0, high=math.pi,
                                               low_open=True)
        spec = EstimatorSpec(estimator, dict(estimator_params or {}), label="estimator")
        super().__init__(**{k: arguments[k] for k in COMMON_ARGUMENTS}, estimators=(spec,))
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self._raw_structure.update(q_wb=(4,), wheel_speed_mps=(4,), steering_rad=(1,), route_pose=(2,),
                                   route_ahead=(self.preview_points, 2))
        max_steer = self._sim.vehicle.parameters["max_steer_rad"]
        reach = self.preview_spacing_m * self.preview_points  # the farthest preview point, m
        self._raw_scales.update(
            q_wb={c: Scale(1.0, -1.0, 1.0, "-") for c in "wxyz"},
            wheel_speed_mps={w: Scale(10.0, -10.0, 10.0, "m/s") for w in ("fl", "fr", "rl", "rr")},
            steering_rad={"angle": Scale(max_steer, -1.0, 1.0, "rad")},
            route_pose={"offset": Scale(self.max_cross_track_m, -2.0, 2.0, "m"),
                        "heading": Scale(math.pi, -1.0, 1.0, "rad")},
            route_ahead={"x": Scale(reach, -2.0, 2.0, "m"), "y": Scale(reach, -2.0, 2.0, "m")})
        self._set_observation_space()
        self._preview_offsets = self.preview_spacing_m * np.arange(1, self.preview_points + 1)
        self._q_est = np.array([1.0, 0.0, 0.0, 0.0])
        self._pose = np.zeros(3)  # navigation pose: rear-axle x, y (m), yaw (rad)
        self._nav_index = 0  # the path sample nearest to the pose the route ahead is placed from
        self._stall_mark_m = 0.0  # progress along the route when the stall clock last restarted, m
        self._stall_steps = 0  # steps since then
        # v_lim at each sample of the route's path (m/s) and the samples' distances along it (m), set
        # at reset as lists: the step looks the limit up with bisect (a NumPy call costs µs there)
        self._speed_limits: list[float] = [math.inf]
        self._path_s: list[float] = [0.0]

    def _check_route(self, route: Route) -> None:
        if any(w.reverse for w in route.waypoints):
            raise ValueError(f"route {route.name!r} has legs driven in reverse; Driving-v0 drives forwards only")

    def _reset_time_s(self) -> float:
        return max(self._alignment_periods, 1) / self._sim_options["control_rate_hz"]

    def _default_duration_s(self, route: Route) -> float:
        return math.ceil(1.5 * route.nominal_duration_s + 10.0)

    # ------------------------------------------------------------------ API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        info = self._begin_episode(seed, options)
        self._speed_limits = self.speed_limits_mps().tolist()
        self._path_s = self._sim.route.path.s_m.tolist()
        vehicle = self._sim.vehicle
        x, y = self._rear_axle_xy()
        self._pose[:] = (x, y, vehicle.route.start_xy_yaw[2])
        self._nav_index = 0
        self._q_est[:] = (1.0, 0.0, 0.0, 0.0)
        self._first_period(_HOLD)
        for _ in range(self._alignment_periods - 1):  # the rest of the alignment
            self._advance(_HOLD)
        state_info, observation = self._view()
        info.update(state_info)
        self._stall_mark_m, self._stall_steps = state_info["distance_m"], 0
        return observation, info

    def step(self, action: Any):
        self._require_running()
        before = self._apply_action(action)
        self._advance(CONTROLS_APPLIED)  # (the driver's progress and cross-track error: at the end of the step)
        info, observation = self._view()
        w = self.weights
        limit = self._speed_limits[max(bisect.bisect_right(self._path_s, info["distance_m"]) - 1, 0)]
        info["speed_limit_mps"] = limit
        moved_m, allowed_m = info["distance_m"] - before, limit * self.dt
        gained_m = min(moved_m, allowed_m) - w["overspeed"] * max(moved_m - allowed_m, 0.0)  # (the progress credited)
        edge = min(abs(info["cross_track_m"]) / self.max_cross_track_m, 1.0)
        terms = {
            "reward_progress": w["progress"] * gained_m,
            "reward_cross_track": -w["progress"] * w["cross_track"] * max(gained_m, 0.0) * edge,
            "reward_rollover": -w["rollover"] if info["rolled_over"] else 0.0,
            "reward_off_route": -w["off_route"] if info["off_route"] else 0.0,
        }
        reward = (terms["reward_progress"] + terms["reward_cross_track"] + terms["reward_rollover"]
                  + terms["reward_off_route"])
        info.update(terms)
        if info["distance_m"] >= self._stall_mark_m + _STALL_PROGRESS_M:
            self._stall_mark_m, self._stall_steps = info["distance_m"], 0
        else:
            self._stall_steps += 1
        info["stalled"] = self.stall_s is not None and self._stall_steps * self.dt >= self.stall_s
        terminated = info["rolled_over"] or info["off_route"] or info["finished"]
        truncated = (self._truncated or info["stalled"]) and not terminated
        self._end_if(terminated, truncated)
        return observation, reward, terminated, truncated, info

    def speed_limits_mps(self) -> np.ndarray:
        """The speed limit v_lim of the progress reward at each sample of the route's path, m/s:
        `speed_limit_mps`, at most √(a/|κ|) in turns (``curvature_speed_limit``), and lowered
        before them so that braking at a = `speed_limit_accel_mps2` reaches each turn's limit
        (v_i² ≤ v_{i+1}² + 2·a·Δs). All inf with ``speed_limit_mps=None``."""
        path = self._sim.route.path
        if self.speed_limit_mps is None:
            return np.full(len(path), np.inf)
        a = self.speed_limit_accel_mps2
        v = np.minimum(curvature_speed_limit(path, a), self.speed_limit_mps)
        ds = np.diff(path.s_m)
        for i in range(len(v) - 2, -1, -1):  # (once per episode: a few ms)
            v[i] = min(v[i], math.sqrt(v[i + 1] * v[i + 1] + 2.0 * a * ds[i]))
        return v

    def _apply_action(self, action: Any) -> float:
        """Check the action (``_check_action``'s errors and clipping) and write the controls
        of its DriverCommand (see the action space; the steering rate-limited) into MuJoCo's ctrl: for an action inside
        the bounds in one kernel call (``_drive_action``). Returns the driver's progress
        along the route before the step (m)."""
        a = self._action_array(action)
        vehicle = self._sim.vehicle
        space = self.action_space
        car = vehicle.parameters
        max_step = math.inf if self.steer_rate_rad_s is None else self.steer_rate_rad_s * self.dt
        apply = (space.low, space.high, car["max_steer_rad"], max_step, car["brake_kv_nms_per_rad"],
                 car["max_brake_torque_per_wheel_nm"], *vehicle.control_arrays, vehicle.driver.state.array)
        before = _drive_action(a, *apply)
        if before != before:  # NaN: not inside the bounds; refused (ValueError), or clipped and applied
            before = _drive_action(self._bounded_action(a), *apply)
        return before

    # ------------------------------------------------------------------ navigation
    def _rear_axle_xy(self) -> tuple[float, float]:
        v = self._sim.vehicle
        p = v.data.sensordata[v.index.rear_axle_pos]
        return float(p[0]), float(p[1])

    def _period_work(self) -> PeriodWork:
        """The IMU window, and the rear axle dead-reckoned over the step's samples: the
        estimator's forward axis, projected on the horizontal, times the rear axle's speed
        (no sideslip there; ``_driving_period``).

        The speed comes from the undriven front wheels, as a car's odometry does (the driven
        rear wheels slip under torque): in the bicycle model the rear axle moves at the front
        wheels' speed times cos(steering angle)."""
        vehicle = self._sim.vehicle
        return PeriodWork(_driving_work, (self._window.values, vehicle.sensordata, vehicle.index.steering_angle.start,
                                          0.5 * vehicle.index.wheel_radius_m, 1.0 / self.imu_rate_hz, self._pose,
                                          self._q_est), ("estimator",))

    # ------------------------------------------------------------------ parts
    def _view(self) -> tuple[dict[str, Any], np.ndarray]:
        """The true state's part of ``info``, and the observation: one kernel call
        (``_driving_view``) for both, from the newest truth row and MuJoCo's sensordata."""
        vehicle = self._sim.vehicle
        path = self._sim.route.path
        observation = self._observation_buffer  # (the window and GNSS parts are already in it)
        values = np.empty(9)
        gnss = self._gnss.values if self._gnss is not None else _NO_GNSS
        self._nav_index = _driving_view(
            observation, self._window.values, gnss, self._q_est, self._newest_row, vehicle.sensordata,
            vehicle.index.rear_axle_pos.start, vehicle.index.steering_angle.start, vehicle.index.wheel_radius_m,
            self._pose, self.pose_source == "truth", path.x_m, path.y_m, path.s_m, self._nav_index,
            self._preview_offsets, vehicle.driver.state.array, values)
        observation = self._public(observation)
        tilt, x, y, yaw, attitude_error, speed_mps, s_m, cross_track_m, length_m = values.tolist()
        pose = self._pose
        nav_x, nav_y, nav_yaw = pose.tolist()
        info = {
            "distance_m": s_m,
            "cross_track_m": cross_track_m,
            "speed_mps": speed_mps,
            "tilt_rad": tilt,
            "attitude_error_rad": attitude_error,
            "nav_pose": pose.copy(),
            "true_pose": values[1:4].copy(),
            "pose_error_m": math.hypot(nav_x - x, nav_y - y),
            "heading_error_rad": math.remainder(nav_yaw - yaw, 2.0 * math.pi),
            "rolled_over": tilt > self.rollover_tilt_rad,
            "off_route": abs(cross_track_m) > self.max_cross_track_m,
            "finished": s_m >= length_m - _END_TOLERANCE_M,
        }
        return info, observation


finish_docstring(DrivingEnv)
