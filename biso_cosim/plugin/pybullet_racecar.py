"""A real third-party vehicle simulator in the loop: pybullet's racecar with the plug-in fed
from its vehicle state every physics tick (the ``pybullet`` extra: ``pip install
biso_cosim[pybullet]``).

The car is ``racecar/racecar.urdf`` of ``pybullet_data`` (MIT RACECAR, a 1:10 model car, as
the package ships it) on ``plane.urdf``, in a DIRECT (headless) client of its own, stepped at
``tick_s``. pybullet's frames: world z up, taken as ENU (x East); the car's base link x
forward, y left, z up (FLU); quaternions scalar last: ``HostFrames("ENU", "FLU", "xyzw")``.
The reference point is the base link's origin (its centre of mass, which pybullet reports).
After every ``stepSimulation`` the bridge reads ``getBasePositionAndOrientation`` and
``getBaseVelocity`` (both velocities in world axes) and gives the plug-in

* ``q_wb`` as pybullet reports it, ``omega_b`` = R_wbᵀ·ω_w,
* ``accel_w`` = (v_k − v_{k−1})/tick_s, the backward difference of the base's velocity over
  the step (pybullet reports no acceleration; zero at the first tick) with pybullet's
  gravity as ``gravity_w``,
* ``p_w`` and ``v_w``.

``block_ticks`` > 1 keeps the truth rows of that many ticks and gives them to the plug-in
in one call (the same outputs bit for bit; one call per control period costs less than one
per tick, see benchmarks/plugin.py).

The driver is open loop: the rear wheels' velocity motors hold a speed, the steering hinges'
position motors a steering angle (``command``), as pybullet's own racecar examples drive it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from biso_cosim.plugin.adapter import HostFrames
from biso_cosim.plugin.imu_plugin import ImuPlugin
from biso_cosim.plugin.output import PluginOutput

__all__ = ["RacecarBridge", "RacecarRun", "HostTick", "FRAMES", "WHEEL_RADIUS_M", "WHEEL_CONTACT"]

FRAMES = HostFrames("ENU", "FLU", "xyzw")
"""pybullet's conventions for the racecar."""

WHEEL_RADIUS_M = 0.05
"""The racecar's wheel radius (racecar.urdf: cylinders of radius 0.05 m)."""

WHEEL_CONTACT = {"contactStiffness": 1e4, "contactDamping": 300.0}
"""Wheel-ground contact (pybullet ``changeDynamics``): stiffness N/m and damping N·s/m, a
rubber tyre's compliance. With pybullet's rigid default the 1 ms contact makes the chassis
ring with tens of g (over the accelerometer's ±16 g); ``{}`` keeps pybullet's default."""

_WHEELS = (2, 3, 5, 7)   # left/right rear, left/right front wheel joints of racecar.urdf
_STEERING = (4, 6)       # left/right steering hinges
_MOTOR_FORCE_N = 10.0    # wheel motor torque limit (N·m), as pybullet's racecar example
_GRAVITY_W = (0.0, 0.0, -9.80665)


def _pybullet():
    try:
        import pybullet
        import pybullet_data
    except ImportError:  # pragma: no cover - the extra is not installed
        raise ImportError("the pybullet bridge needs pybullet: pip install 'biso_cosim[pybullet]'") from None
    return pybullet, pybullet_data


class HostTick(NamedTuple):
    """The racecar's truth after one physics step, pybullet's frames (see the module docstring)."""

    t_s: float
    q_wb: np.ndarray
    p_w: np.ndarray
    v_w: np.ndarray
    omega_w: np.ndarray
    omega_b: np.ndarray
    accel_w: np.ndarray


@dataclass(frozen=True, eq=False)
class RacecarRun:
    """A drive: the host's truth at every tick (pybullet's frames) and the plug-in's outputs.

    ``t_s`` (n,), ``p_w``, ``v_w``, ``omega_w``, ``omega_b``, ``accel_w`` (n, 3) and ``q_wb``
    (n, 4, scalar last), one row per physics tick; ``output``: the plug-in's outputs of the
    whole drive (``PluginOutput.concatenate``).
    """

    t_s: np.ndarray
    q_wb: np.ndarray
    p_w: np.ndarray
    v_w: np.ndarray
    omega_w: np.ndarray
    omega_b: np.ndarray
    accel_w: np.ndarray
    output: PluginOutput


class RacecarBridge:
    """pybullet's racecar on a plane with an ``ImuPlugin`` fed every physics tick.

    Args:
        plugin: the plug-in, built with ``tick_s`` and ``frames=FRAMES`` (the bridge checks
            both); None: ``ImuPlugin(tick_s=tick_s, frames=FRAMES, gravity_w=(0, 0, −g),
            **plugin_options)``.
        tick_s: pybullet's time step (1 ms by default; pybullet's own 1/240 s cannot drive
            the chip's 1 kHz internal sampling).
        block_ticks: ticks of truth per plug-in call (1: every tick).
        start_xy_m, start_yaw_rad: where the car starts (it settles on its wheels first
            during the drive's first ticks).
    """

    def __init__(self, plugin: ImuPlugin | None = None, *, tick_s: float = 0.001, block_ticks: int = 1,
                 start_xy_m: tuple[float, float] = (0.0, 0.0), start_yaw_rad: float = 0.0,
                 wheel_contact: dict[str, float] | None = None, **plugin_options: Any) -> None:
        if isinstance(block_ticks, bool) or not isinstance(block_ticks, int) or block_ticks < 1:
            raise ValueError(f"block_ticks must be a positive int, got {block_ticks!r}")
        if plugin is None:
            plugin = ImuPlugin(tick_s=tick_s, frames=FRAMES, gravity_w=_GRAVITY_W, **plugin_options)
        elif plugin_options:
            raise TypeError(f"give either plugin or plugin options, not both ({sorted(plugin_options)})")
        if plugin.frames != FRAMES:
            raise ValueError(f"plugin.frames must be {FRAMES} (pybullet's), got {plugin.frames}")
        if not math.isclose(plugin.tick_s, tick_s, rel_tol=1e-12):
            raise ValueError(f"plugin.tick_s = {plugin.tick_s!r} s must equal the bridge's tick_s = {tick_s!r} s")
        self.plugin, self.tick_s, self.block_ticks = plugin, float(tick_s), block_ticks
        pb, data = _pybullet()
        self._pb = pb
        self.client = pb.connect(pb.DIRECT)
        pb.setAdditionalSearchPath(data.getDataPath(), physicsClientId=self.client)
        pb.setGravity(*_GRAVITY_W, physicsClientId=self.client)
        pb.setTimeStep(self.tick_s, physicsClientId=self.client)
        self.plane = pb.loadURDF("plane.urdf", physicsClientId=self.client)
        orn = pb.getQuaternionFromEuler((0.0, 0.0, float(start_yaw_rad)))
        self.car = pb.loadURDF("racecar/racecar.urdf", [float(start_xy_m[0]), float(start_xy_m[1]), 0.05], orn,
                               physicsClientId=self.client)
        for joint in range(pb.getNumJoints(self.car, physicsClientId=self.client)):
            pb.setJointMotorControl2(self.car, joint, pb.VELOCITY_CONTROL, targetVelocity=0.0, force=0.0,
                                     physicsClientId=self.client)
        for wheel in _WHEELS:
            pb.changeDynamics(self.car, wheel, **(WHEEL_CONTACT if wheel_contact is None else wheel_contact),
                              physicsClientId=self.client)
        self.command(0.0, 0.0)
        self._ticks = 0
        self._v_prev: np.ndarray | None = None

    def command(self, speed_mps: float, steer_rad: float) -> None:
        """Hold a wheel speed (m/s at the tread; the driven wheels' velocity motors) and a
        steering angle (rad, left positive)."""
        pb, c = self._pb, self.client
        if not (math.isfinite(speed_mps) and math.isfinite(steer_rad)):
            raise ValueError(f"speed_mps and steer_rad must be finite, got {speed_mps!r}, {steer_rad!r}")
        for wheel in _WHEELS:
            pb.setJointMotorControl2(self.car, wheel, pb.VELOCITY_CONTROL, targetVelocity=speed_mps / WHEEL_RADIUS_M,
                                     force=_MOTOR_FORCE_N, physicsClientId=c)
        for hinge in _STEERING:
            pb.setJointMotorControl2(self.car, hinge, pb.POSITION_CONTROL, targetPosition=steer_rad, physicsClientId=c)

    def step_host(self) -> HostTick:
        """One physics step of pybullet alone and the truth it gives the plug-in (for a loop
        of your own: ``plugin.step(tick.t_s, tick.q_wb, tick.omega_b, accel_w=tick.accel_w,
        p_w=tick.p_w, v_w=tick.v_w)``)."""
        pb, c = self._pb, self.client
        pb.stepSimulation(physicsClientId=c)
        pos, orn = pb.getBasePositionAndOrientation(self.car, physicsClientId=c)
        lin, ang = pb.getBaseVelocity(self.car, physicsClientId=c)
        q, p, v, w = np.array(orn), np.array(pos), np.array(lin), np.array(ang)
        r_wb = np.array(pb.getMatrixFromQuaternion(orn)).reshape(3, 3)
        accel = np.zeros(3) if self._v_prev is None else (v - self._v_prev) / self.tick_s
        self._v_prev = v
        t = self._ticks * self.tick_s
        self._ticks += 1
        return HostTick(t, q, p, v, w, r_wb.T @ w, accel)

    def drive(self, duration_s: float) -> RacecarRun:
        """Step the simulation for ``duration_s`` with the commands in force, the plug-in fed
        every tick (in blocks of ``block_ticks``); the truth and the plug-in's outputs."""
        n = int(round(duration_s / self.tick_s))
        if n < 1:
            raise ValueError(f"duration_s must hold at least one tick of {self.tick_s} s, got {duration_s!r}")
        rows, outputs, block = [], [], []
        for i in range(n):
            row = self.step_host()
            rows.append(row)
            block.append(row)
            if len(block) < self.block_ticks and i < n - 1:
                continue
            if self.block_ticks == 1:
                t, q, p, v, _, w_b, a = row
            else:
                t, q, p, v, _, w_b, a = (np.array([r[j] for r in block]) for j in range(7))
            out = self.plugin.step(t, q, w_b, accel_w=a, p_w=p, v_w=v)
            outputs.append(out.copy() if self.plugin.reuse_outputs else out)  # (the drive keeps every output)
            block = []
        t, q, p, v, w, w_b, a = (np.array([r[i] for r in rows]) for i in range(7))
        return RacecarRun(t, q, p, v, w, w_b, a, PluginOutput.concatenate(outputs))

    def close(self) -> None:
        """Disconnect the pybullet client."""
        if self.client is not None:
            self._pb.disconnect(physicsClientId=self.client)
            self.client = None

    def __enter__(self) -> "RacecarBridge":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
