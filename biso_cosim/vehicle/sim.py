"""The car on a route's terrain: placement, control inputs and chunked stepping with truth.

``VehicleSim.step(n)`` advances the physics by n steps and returns the truth of those steps
as a :class:`Truth` record at the physics rate. MuJoCo's sensor values read after
``mj_step`` belong to the state at the start of that step (DESIGN.md §3), so the k-th row of
a chunk is the truth at ``t0 + k·dt``, where ``t0`` was the simulation time before the call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from biso_cosim.frames import _q_from_euler
from biso_cosim.routes import Route
from biso_cosim.vehicle.driver import DriverCommand, DriverParams, RouteDriver
from biso_cosim.vehicle.model import CarIndex, build_model, vehicle_parameters

__all__ = ["Truth", "VehicleSim"]

# Before time zero the car settles on its suspension with the brakes on for this long, so
# that the first samples show a car at rest rather than contacts finding their depth.
_SETTLE_S = 3.0


@dataclass(frozen=True)
class Truth:
    """True motion at the IMU site, one row per physics step (frame names as in frames.py)."""

    t_s: np.ndarray          # (n,)
    omega_b: np.ndarray      # (n, 3) rad/s, angular rate in body axes
    specific_force_b: np.ndarray  # (n, 3) m/s², +g up at rest
    q_wb: np.ndarray         # (n, 4) attitude of the body (IMU site) in ENU
    pos_w: np.ndarray        # (n, 3) m, IMU site position
    vel_w: np.ndarray        # (n, 3) m/s, IMU site velocity
    speed_mps: np.ndarray    # (n,) forward speed of the rear axle, body x
    wheel_rates: np.ndarray  # (n, 4) rad/s, wheel spin rates fl, fr, rl, rr

    def __len__(self) -> int:
        return self.t_s.shape[0]

    @staticmethod
    def concatenate(parts: list["Truth"]) -> "Truth":
        return Truth(**{name: np.concatenate([getattr(p, name) for p in parts])
                        for name in Truth.__dataclass_fields__})


class VehicleSim:
    """The reference car on ``route``'s terrain, driven by the scripted driver."""

    def __init__(self, route: Route, *, physics_rate_hz: float = 1000.0, control_rate_hz: float = 50.0,
                 driver_params: DriverParams | None = None):
        if not physics_rate_hz > 0.0:
            raise ValueError(f"physics_rate_hz must be > 0, got {physics_rate_hz}")
        if not control_rate_hz > 0.0:
            raise ValueError(f"control_rate_hz must be > 0, got {control_rate_hz}")
        ratio = physics_rate_hz / control_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(f"physics_rate_hz ({physics_rate_hz}) must be a whole multiple of "
                             f"control_rate_hz ({control_rate_hz})")
        self.route = route
        self.physics_rate_hz = float(physics_rate_hz)
        self.control_rate_hz = float(control_rate_hz)
        self.steps_per_control = int(round(ratio))
        self.model, self.patches = build_model(route.terrain, timestep_s=1.0 / physics_rate_hz)
        self.data = mujoco.MjData(self.model)
        self.index = CarIndex.of(self.model)
        params = vehicle_parameters(self.model)
        self.parameters = params
        self.driver = RouteDriver(
            route, wheelbase_m=self.index.wheelbase_m, wheel_radius_m=self.index.wheel_radius_m,
            mass_kg=params["total_mass_kg"], max_drive_torque_nm=params["max_drive_torque_nm"],
            brake_kv=params["brake_kv_nms_per_rad"],
            max_brake_torque_nm=params["max_brake_torque_per_wheel_nm"],
            max_steer_rad=params["max_steer_rad"], dt_s=1.0 / control_rate_hz, params=driver_params)
        self._buffer = np.empty((self.steps_per_control, self.model.nsensordata))
        self.reset()

    # ------------------------------------------------------------------ placement
    def reset(self) -> None:
        """Put the car at the start of the route, at rest and settled; time zero."""
        m, d, ix = self.model, self.data, self.index
        mujoco.mj_resetData(m, d)
        x0, y0, yaw = self.route.start_xy_yaw
        # the route starts at the rear axle; the free joint sits at the centre of mass
        c, s = math.cos(yaw), math.sin(yaw)
        back = -ix.rear_axle_b[0]
        cx, cy = x0 + c * back, y0 + s * back
        ground = float(self.route.terrain.height(cx, cy))
        d.qpos[0:3] = (cx, cy, ground + float(m.body("chassis").pos[2]))
        d.qpos[3:7] = _q_from_euler(0.0, 0.0, yaw)
        d.ctrl[:] = 0.0
        d.ctrl[ix.brakes] = 1.0
        mujoco.mj_forward(m, d)
        for _ in range(int(round(_SETTLE_S * self.physics_rate_hz))):
            mujoco.mj_step(m, d)
        d.time = 0.0
        self.steps_done = 0
        self.driver.reset()

    # ------------------------------------------------------------------ stepping
    def apply(self, command: DriverCommand) -> None:
        d, ix = self.data, self.index
        d.ctrl[ix.steer] = command.steer_rad
        d.ctrl[ix.drive] = command.drive
        d.ctrl[ix.brakes] = command.brake

    def drive(self) -> DriverCommand:
        """Ask the driver for the next control period's command from the current state."""
        sd, ix = self.data.sensordata, self.index
        q = sd[ix.quat]
        yaw = math.atan2(2.0 * (q[1] * q[2] + q[0] * q[3]), 1.0 - 2.0 * (q[2] * q[2] + q[3] * q[3]))
        wheels = sd[ix.wheel_rates]
        command = self.driver.command(sd[ix.rear_axle_pos], yaw, float(sd[ix.rear_axle_vel_b][0]),
                                      float(np.mean(wheels)))
        self.apply(command)
        return command

    def step(self, n: int | None = None) -> Truth:
        """Advance ``n`` physics steps (default: one control period); truth of those steps."""
        m, d = self.model, self.data
        n = self.steps_per_control if n is None else n
        buf = self._buffer if n == self._buffer.shape[0] else np.empty((n, m.nsensordata))
        for k in range(n):
            mujoco.mj_step(m, d)
            buf[k] = d.sensordata
        first = self.steps_done
        self.steps_done += n
        return self._truth(buf, first)

    def current_truth(self) -> Truth:
        """The truth of the current state as one row (at the time of the last step's start)."""
        return self._truth(self.data.sensordata[None, :].copy(), max(self.steps_done - 1, 0))

    def _truth(self, buf: np.ndarray, first_step: int) -> Truth:
        ix = self.index
        n = buf.shape[0]
        return Truth(
            t_s=(first_step + np.arange(n)) / self.physics_rate_hz,
            omega_b=buf[:, ix.gyro].copy(),
            specific_force_b=buf[:, ix.accel].copy(),
            q_wb=buf[:, ix.quat].copy(),
            pos_w=buf[:, ix.pos].copy(),
            vel_w=buf[:, ix.vel_w].copy(),
            speed_mps=buf[:, ix.rear_axle_vel_b][:, 0].copy(),
            wheel_rates=buf[:, ix.wheel_rates].copy(),
        )
