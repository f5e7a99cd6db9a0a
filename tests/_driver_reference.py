"""The scripted driver written plainly in Python: the slow reference of the jitted kernel
``biso_cosim.vehicle._kernels._driver_command`` (tests/test_driver.py compares them)."""

import math

from biso_cosim.vehicle.driver import DriverCommand


class ReferenceDriver:
    """Same constructor as RouteDriver; state in plain attributes."""

    def __init__(self, driver):
        self.route = driver.route
        self.path = driver.path
        self.params = driver.params
        for name in ("wheelbase_m", "wheel_radius_m", "mass_kg", "max_drive_torque_nm", "brake_kv",
                     "max_brake_torque_nm", "max_steer_rad", "dt_s", "power_w_per_kg", "drag_per_m", "rolling_mps2"):
            setattr(self, name, getattr(driver, name))
        self._v_free = self.route.speed_free_mps
        self._stops = self.route.stops
        self.state = type("State", (), {})()
        for name, value in (("index", 0), ("s_m", 0.0), ("cross_track_m", 0.0), ("speed_cmd_mps", 0.0),
                            ("speed_integral_m", 0.0), ("steer_rad", 0.0), ("next_stop", 0), ("floor_index", 0),
                            ("dwell_s", 0.0), ("hold", 0.0), ("time_s", 0.0), ("finished", False)):
            setattr(self.state, name, value)

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
        # ... speeding up at most at the car's full-throttle acceleration at the command's speed
        v = abs(previous)
        faster = min(accel, max(self.power_w_per_kg / max(v, 1.0) - self.drag_per_m * v * v - self.rolling_mps2, 0.0))
        down, up = (decel, faster) if direction > 0 else (faster, decel)
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
            # saturated beyond the peak torque or beyond the engine's power at this speed
            saturated = abs(drive) > 1.0 or abs(torque) > (self.mass_kg * self.wheel_radius_m * self.power_w_per_kg
                                                           / max(abs(speed_mps), 1.0))
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
