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
  profile's acceleration limits, speeding up at most at the car's full-throttle
  acceleration ``a(v) = P/(m·max(v, 1 m/s)) − k·v² − g·c_rr`` (engine power at the wheels,
  drag, rolling resistance: the drivetrain's figures); a PI controller
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
from biso_cosim.vehicle import _kernels as K

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


class DriverState:
    """Everything the driver remembers between calls, in one array (copyable, picklable):
    ``index``, ``s_m`` (progress along the path), ``cross_track_m`` (positive left of the
    path), ``speed_cmd_mps``, ``speed_integral_m``, ``steer_rad``, ``next_stop``,
    ``floor_index`` (progress never goes back before it), ``dwell_s``, ``hold`` (brake
    command), ``time_s``, ``finished``."""

    __slots__ = ("array",)

    def __init__(self, array: np.ndarray | None = None):
        self.array = np.zeros(K.STATE_SIZE) if array is None else array

    def __repr__(self) -> str:
        return "DriverState(" + ", ".join(f"{name}={getattr(self, name)!r}" for name in _STATE_FIELDS) + ")"


def _state_field(slot: int, kind: type) -> property:
    return property(lambda self: kind(self.array[slot]))


_STATE_FIELDS = {"index": (K.S_INDEX, int), "s_m": (K.S_S, float), "cross_track_m": (K.S_CROSS, float),
                 "speed_cmd_mps": (K.S_VCMD, float), "speed_integral_m": (K.S_INTEGRAL, float),
                 "steer_rad": (K.S_STEER, float), "next_stop": (K.S_NEXT, int), "floor_index": (K.S_FLOOR, int),
                 "dwell_s": (K.S_DWELL, float), "hold": (K.S_HOLD, float), "time_s": (K.S_TIME, float),
                 "finished": (K.S_FINISHED, bool)}
for _name, (_slot, _kind) in _STATE_FIELDS.items():
    setattr(DriverState, _name, _state_field(_slot, _kind))


class RouteDriver:
    """Drives a car along ``route``; ``command()`` once per control period of ``dt_s``.

    ``power_w_per_kg``, ``drag_per_m`` and ``rolling_mps2`` (P/m, ½ρc_wA/m, g·c_rr; none by
    default) bound the speed command's ramp by the car's full-throttle acceleration, and the
    speed integral stops (anti-windup) where the drive torque asked exceeds what the power
    gives at the speed, m·r·P/(m·max(v, 1 m/s)), as it does beyond the peak torque.

    The work of a period is one numba kernel (``biso_cosim.vehicle._kernels._driver_command``);
    ``tests/_driver_reference.py`` is the same method written plainly, and the tests compare
    them command by command.
    """

    def __init__(self, route: Route, *, wheelbase_m: float, wheel_radius_m: float, mass_kg: float,
                 max_drive_torque_nm: float, brake_kv: float, max_brake_torque_nm: float,
                 max_steer_rad: float, dt_s: float, params: DriverParams | None = None,
                 power_w_per_kg: float = math.inf, drag_per_m: float = 0.0, rolling_mps2: float = 0.0):
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
        self.power_w_per_kg, self.drag_per_m, self.rolling_mps2 = power_w_per_kg, drag_per_m, rolling_mps2
        p, d = self.params, route.driving
        c = np.zeros(K.PARAMS_SIZE)
        c[K.P_LMIN], c[K.P_TLA], c[K.P_LMAX] = p.lookahead_min_m, p.lookahead_time_s, p.lookahead_max_m
        c[K.P_STEER_RATE], c[K.P_KP], c[K.P_KI] = p.steer_rate_rad_s, p.speed_kp_per_s, p.speed_ki_per_s2
        c[K.P_STOP_DIST], c[K.P_STOP_SPEED] = p.stop_distance_m, p.stop_speed_mps
        c[K.P_CREEP], c[K.P_HOLD_RAMP] = p.stop_creep_s, p.hold_ramp_s
        c[K.P_WHEELBASE], c[K.P_MAX_STEER], c[K.P_MASS], c[K.P_RADIUS] = wheelbase_m, max_steer_rad, mass_kg, wheel_radius_m
        c[K.P_MAX_DRIVE], c[K.P_BRAKE_KV], c[K.P_MAX_BRAKE] = max_drive_torque_nm, brake_kv, max_brake_torque_nm
        c[K.P_DT], c[K.P_DECEL], c[K.P_ACCEL], c[K.P_WAIT] = dt_s, d.decel_mps2, d.accel_mps2, d.start_wait_s
        c[K.P_LENGTH] = self.path.length_m
        c[K.P_POWER], c[K.P_DRAG_K], c[K.P_ROLL_A] = power_w_per_kg, drag_per_m, rolling_mps2
        self._params = c
        path, stops = self.path, route.stops
        self._arrays = (path.x_m, path.y_m, path.s_m, path.heading_rad, route.speed_free_mps,
                        route.direction.astype(np.int64),
                        np.array([st.s_m for st in stops]), np.array([st.index for st in stops], dtype=np.int64),
                        np.array([st.dwell_s for st in stops]), np.array([st.cusp for st in stops]))
        self._out = np.zeros(3)
        self.state = DriverState()

    def reset(self) -> None:
        self.state = DriverState()

    @property
    def finished(self) -> bool:
        """The car has reached the end of the route and holds there."""
        return self.state.finished

    def track(self, rear_axle_xy) -> None:
        """Update progress along the path and the cross-track error from the rear-axle position
        (without driving: when an agent drives). Progress never goes back past a stop already
        left behind: where a route reverses along its own track, the nearest point could
        otherwise lie on the leg before the cusp."""
        a = self._arrays
        K._track(a[0], a[1], a[2], self.state.array, float(rear_axle_xy[0]), float(rear_axle_xy[1]))

    def command(self, rear_axle_xy, yaw_rad: float, speed_mps: float, wheel_speed_rad_s: float) -> DriverCommand:
        """The command for the next period from the rear-axle position (x, y in ENU, m), the
        yaw (rad, CCW from East), the forward speed (m/s, negative when reversing) and the mean
        wheel spin rate (rad/s)."""
        out = self._out
        K._driver_command(*self._arrays, self._params, self.state.array, float(rear_axle_xy[0]),
                          float(rear_axle_xy[1]), float(yaw_rad), float(speed_mps), float(wheel_speed_rad_s), out)
        return DriverCommand(steer_rad=float(out[0]), drive=float(out[1]), brake=float(out[2]))
