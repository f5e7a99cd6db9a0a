"""The scripted driver: pure-pursuit steering and PI speed control along a route.

Called once per control period with what a driver-assist controller would measure (rear-
axle position, yaw, speed), it returns the steering, drive and brake commands for the next
period:

* steering: pure pursuit (Coulter 1992) on the rear axle: the goal point lies a look-ahead
  distance ``L_d = clip(L_min + T_la·v, L_min, L_max)`` further along the path, and the
  bicycle steering angle ``δ = atan(2·L·sin α / L_d)`` puts the rear axle on a circle through
  it (α: bearing of the goal point in the body frame, L: wheelbase), rate limited like a
  human driver's hands;
* speed: the target is the route's free-flow profile, capped at distance d before the next
  stop by ``min(sqrt(2·a_dec·d), d/τ_stop)`` (constant deceleration, then an exponential
  creep over the last metres, as a driver eases off the brake) and rate limited by the
  profile's acceleration limits; a PI controller
  on the speed error plus the feed-forward of the target's rate gives an acceleration
  command, turned into drive torque at the rear wheels or brake torque at all four;
* start: the car stands with its brakes on for the route's ``start_wait_s`` (an initial
  alignment period for the estimators), then drives off;
* stops: within ``stop_distance_m`` of a stop and below ``stop_speed_mps`` the brakes close
  over ``hold_ramp_s`` and hold for the stop's dwell time, then the car drives on; at the
  end of the route it holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from biso_cosim.routes import Route

__all__ = ["DriverParams", "DriverCommand", "DriverState", "RouteDriver"]


@dataclass(frozen=True)
class DriverParams:
    lookahead_min_m: float = 4.0
    """L_min: look-ahead at standstill, m."""
    lookahead_time_s: float = 0.7
    """T_la: look-ahead growth with speed, s."""
    lookahead_max_m: float = 20.0
    """L_max: largest look-ahead, m."""
    steer_rate_rad_s: float = 0.6
    """Largest rate of the road-wheel angle (a brisk driver at a 15:1 steering ratio), rad/s."""
    speed_kp_per_s: float = 1.0
    """Proportional gain: m/s² of acceleration command per m/s of speed error."""
    speed_ki_per_s2: float = 0.3
    """Integral gain, m/s² per m of accumulated speed error."""
    stop_distance_m: float = 2.0
    """A stop counts as reached this close to it (m) ..."""
    stop_speed_mps: float = 0.1
    """... once slower than this (m/s)."""
    stop_creep_s: float = 1.0
    """τ_stop: time constant of the final approach to a stop, s."""
    hold_ramp_s: float = 1.0
    """Time over which the brakes close once a stop is reached, s."""

    def check(self) -> None:
        for name, value in vars(self).items():
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"DriverParams.{name} must be a positive number, got {value!r}")
        if self.lookahead_max_m < self.lookahead_min_m:
            raise ValueError("DriverParams.lookahead_max_m must be >= lookahead_min_m")


@dataclass(frozen=True)
class DriverCommand:
    steer_rad: float
    """Bicycle-model road-wheel angle, left positive."""
    drive: float
    """Drive torque as a fraction of the maximum, [-1, 1]."""
    brake: float
    """Brake command of each wheel's damper actuator, [0, 1]."""


@dataclass
class DriverState:
    """Everything the driver remembers between calls (copyable for checkpoints)."""

    index: int = 0
    s_m: float = 0.0
    cross_track_m: float = 0.0
    speed_cmd_mps: float = 0.0
    speed_integral_m: float = 0.0
    steer_rad: float = 0.0
    next_stop: int = 0
    floor_index: int = 0
    dwell_s: float = 0.0
    hold: float = 0.0
    time_s: float = 0.0
    finished: bool = False


class RouteDriver:
    """Drives a car along ``route``; ``command()`` once per control period of ``dt_s``."""

    def __init__(self, route: Route, *, wheelbase_m: float, wheel_radius_m: float, mass_kg: float,
                 max_drive_torque_nm: float, brake_kv: float, max_brake_torque_nm: float,
                 max_steer_rad: float, dt_s: float, params: DriverParams | None = None):
        self.route = route
        self.path = route.path
        self.params = params or DriverParams()
        self.params.check()
        if not dt_s > 0.0:
            raise ValueError(f"dt_s must be > 0, got {dt_s}")
        self.wheelbase_m = wheelbase_m
        self.wheel_radius_m = wheel_radius_m
        self.mass_kg = mass_kg
        self.max_drive_torque_nm = max_drive_torque_nm
        self.brake_kv = brake_kv
        self.max_brake_torque_nm = max_brake_torque_nm
        self.max_steer_rad = max_steer_rad
        self.dt_s = dt_s
        self._v_free = route.speed_free_mps
        self._stops = route.stops
        self.state = DriverState()

    def reset(self) -> None:
        self.state = DriverState()

    @property
    def finished(self) -> bool:
        """The car has reached the end of the route and holds there."""
        return self.state.finished

    def track(self, rear_axle_xy) -> None:
        """Update progress along the path and the cross-track error from the rear-axle position.

        Progress never goes back past a stop already left behind: where a route reverses along
        its own track, the nearest point could otherwise lie on the leg before the cusp.
        """
        st = self.state
        i, s, cross = self.path.locate(float(rear_axle_xy[0]), float(rear_axle_xy[1]), st.index,
                                       floor=st.floor_index)
        st.index, st.s_m, st.cross_track_m = i, s, cross

    def _goal(self, s_goal: float) -> tuple[float, float]:
        """The path point at arc length ``s_goal``, continued straight beyond the next cusp or the
        end, so that the look-ahead never folds back at a change of direction."""
        path = self.path
        stop = self._stops[self.state.next_stop]
        limit = stop.s_m if (stop.cusp or math.isinf(stop.dwell_s)) else path.length_m
        if s_goal <= limit:
            i = path.index_at(s_goal)
            return float(path.x_m[i]), float(path.y_m[i])
        i = path.index_at(limit)
        heading = float(path.heading_rad[max(i - 1, 0)])
        extra = s_goal - limit
        return float(path.x_m[i]) + extra * math.cos(heading), float(path.y_m[i]) + extra * math.sin(heading)

    def command(self, rear_axle_xy, yaw_rad: float, speed_mps: float, wheel_speed_rad_s: float) -> DriverCommand:
        """The command for the next period from the rear-axle position (x, y in ENU, m), the
        yaw (rad, CCW from East), the forward speed (m/s, negative when reversing) and the mean
        wheel spin rate (rad/s)."""
        st, p = self.state, self.params
        dt = self.dt_s
        x, y = float(rear_axle_xy[0]), float(rear_axle_xy[1])
        self.track(rear_axle_xy)
        st.time_s += dt
        if st.time_s <= self.route.driving.start_wait_s:
            return DriverCommand(steer_rad=0.0, drive=0.0, brake=1.0)
        direction = float(self.route.direction[st.index])

        # --- steering: pure pursuit to the goal point L_d ahead along the path, measured from the
        # direction of travel (the nose, or the tail when reversing: then the steer flips)
        lookahead = min(p.lookahead_min_m + p.lookahead_time_s * abs(speed_mps), p.lookahead_max_m)
        gx, gy = self._goal(st.s_m + lookahead)
        dx, dy = gx - x, gy - y
        c, s = math.cos(yaw_rad) * direction, math.sin(yaw_rad) * direction
        ahead, left = c * dx + s * dy, -s * dx + c * dy
        distance = max(math.hypot(ahead, left), 1e-3)
        alpha = math.atan2(left, ahead)
        steer_target = direction * math.atan(2.0 * self.wheelbase_m * math.sin(alpha) / distance)
        steer_target = min(max(steer_target, -self.max_steer_rad), self.max_steer_rad)
        step = p.steer_rate_rad_s * dt
        st.steer_rad += min(max(steer_target - st.steer_rad, -step), step)

        # --- speed: free-flow target, capped before the next stop; signed by the direction
        stop = self._stops[st.next_stop]
        to_stop = stop.s_m - st.s_m
        decel = self.route.driving.decel_mps2
        accel = self.route.driving.accel_mps2
        reached = to_stop < p.stop_distance_m and abs(speed_mps) < p.stop_speed_mps
        if reached:
            st.dwell_s += dt
            st.speed_cmd_mps = 0.0
            st.speed_integral_m = 0.0
            if st.dwell_s >= stop.dwell_s:
                st.next_stop += 1
                st.floor_index = stop.index
                st.dwell_s = 0.0
                st.hold = 0.0
                # the first command after a cusp is for the new direction
                st.index = max(st.index, stop.index)
                direction = float(self.route.direction[st.index])
            else:
                st.finished = math.isinf(stop.dwell_s)
                st.hold = min(st.hold + dt / p.hold_ramp_s, 1.0)
                return DriverCommand(steer_rad=st.steer_rad, drive=0.0, brake=st.hold)
        room = max(to_stop, 0.0)
        target = direction * min(float(self._v_free[st.index]), math.sqrt(2.0 * decel * room), room / p.stop_creep_s)
        previous = st.speed_cmd_mps
        # the rate limits apply to the magnitude: speeding up at accel, slowing at decel
        down, up = (decel, accel) if direction > 0 else (accel, decel)
        st.speed_cmd_mps += min(max(target - previous, -down * dt), up * dt)
        feedforward = (st.speed_cmd_mps - previous) / dt
        error = st.speed_cmd_mps - speed_mps
        accel_cmd = feedforward + p.speed_kp_per_s * error + p.speed_ki_per_s2 * st.speed_integral_m

        # --- actuators: drive torque at the rear axle when pushing along the direction of
        # travel, else brake torque at all four wheels
        torque = self.mass_kg * accel_cmd * self.wheel_radius_m
        if torque * direction >= 0.0:
            drive = torque / self.max_drive_torque_nm
            brake = 0.0
            saturated = abs(drive) > 1.0
            drive = min(max(drive, -1.0), 1.0)
        else:
            drive = 0.0
            per_wheel = abs(torque) / 4.0
            # the brake is a damper (torque = kv·u·ω): choose u for the wanted torque at this speed
            brake = per_wheel / (self.brake_kv * max(abs(wheel_speed_rad_s), 0.5))
            saturated = brake > 1.0 or per_wheel > self.max_brake_torque_nm
            brake = min(brake, 1.0)
        st.hold = brake
        if not saturated:  # no integration while the actuator saturates (anti-windup)
            st.speed_integral_m += error * dt
        return DriverCommand(steer_rad=st.steer_rad, drive=drive, brake=brake)
