"""The host simulator's frame conventions, mapped onto the package's.

The package works in ENU world axes (x East, y North, z Up), FLU vehicle body axes (x
forward, y left, z up) and Hamilton quaternions stored scalar first, ``q_wb`` mapping body
vectors to world vectors (``biso_cosim.frames``). A host simulator states its own:

=============  ==================================================  ===========================
argument       values                                              map to the package's
=============  ==================================================  ===========================
``world``      ``"ENU"``; ``"NED"`` (x North, y East, z Down)       ``v_enu = (v_e, v_n, −v_d)``
``body``       ``"FLU"``; ``"FRD"`` (x forward, y right, z down)    ``v_flu = (v_f, −v_r, −v_d)``
``quaternion`` ``"wxyz"`` (scalar first); ``"xyzw"`` (scalar last)  reordered to ``(w, x, y, z)``
=============  ==================================================  ===========================

(``"scalar_first"`` and ``"scalar_last"`` are accepted for the two orders.) The host's
quaternion is its ``q_world_body`` (Hamilton, body vectors to world vectors, as in ROS,
Gazebo, pybullet and Eigen); in the package's frames it is

    q_enu_flu = q_enu_hostworld ∘ q_hostworld_hostbody ∘ q_hostbody_flu,

with ``q_enu_ned = (0, √½, √½, 0)`` (180° about the bisector of North and East) and
``q_frd_flu = (0, 1, 0, 0)`` (180° about the forward axis). Each map is a proper rotation, so
the same motion written in any of these conventions is the same motion: every reading and
estimate of the plug-in is the same. Left-handed hosts (CARLA's Unreal axes) must flip an
axis first: see docs/plugin.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from biso_cosim.frames import quat_conjugate, quat_multiply, quat_to_rotvec
from biso_cosim.units import G0

__all__ = ["HostFrames", "WORLDS", "BODIES", "QUATERNION_ORDERS"]

WORLDS = ("ENU", "NED")
BODIES = ("FLU", "FRD")
QUATERNION_ORDERS = ("wxyz", "xyzw")
_ORDER_ALIASES = {"wxyz": "wxyz", "scalar_first": "wxyz", "xyzw": "xyzw", "scalar_last": "xyzw"}

_S = math.sqrt(0.5)
Q_ENU_NED = np.array([0.0, _S, _S, 0.0])
"""Maps NED components to ENU components (a rotation by 180° about (1, 1, 0)/√2)."""
Q_FRD_FLU = np.array([0.0, 1.0, 0.0, 0.0])
"""Maps FLU components to FRD components, and back (180° about the forward axis)."""
_CONJ = np.array([1.0, -1.0, -1.0, -1.0])


def _choice(name: str, value: Any, known: tuple[str, ...], aliases: dict[str, str] | None = None) -> str:
    key = value.strip() if isinstance(value, str) else value
    if isinstance(key, str) and aliases is not None:
        key = aliases.get(key.lower(), key)
    elif isinstance(key, str):
        key = key.upper()
    if key not in known:
        extra = f" (or {', '.join(a for a in aliases if a not in known)})" if aliases else ""
        raise ValueError(f"{name} must be one of {', '.join(known)}{extra}, got {value!r}")
    return key


@dataclass(frozen=True)
class HostFrames:
    """The frame conventions of a host simulator's truth (see the module docstring).

    Args:
        world: ``"ENU"`` or ``"NED"``: the axes of positions, velocities, accelerations,
            gravity and the attitude's world side.
        body: ``"FLU"`` or ``"FRD"``: the axes of angular rate, angular acceleration,
            specific force, the mounting and the readings returned.
        quaternion: ``"wxyz"`` (scalar first) or ``"xyzw"`` (scalar last): the order of the
            components of every quaternion given to or returned by the plug-in.
    """

    world: str = "ENU"
    body: str = "FLU"
    quaternion: str = "wxyz"

    def __post_init__(self) -> None:
        object.__setattr__(self, "world", _choice("world", self.world, WORLDS))
        object.__setattr__(self, "body", _choice("body", self.body, BODIES))
        object.__setattr__(self, "quaternion", _choice("quaternion", self.quaternion, QUATERNION_ORDERS,
                                                       _ORDER_ALIASES))

    @classmethod
    def coerce(cls, value: "HostFrames | dict | tuple | None") -> "HostFrames":
        """A HostFrames from itself, a dict of its fields, a (world, body, quaternion) tuple or None."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            unknown = sorted(set(value) - {"world", "body", "quaternion"})
            if unknown:
                raise ValueError(f"frames: unknown field(s) {unknown}; known: world, body, quaternion")
            return cls(**value)
        if isinstance(value, (tuple, list)) and len(value) == 3:
            return cls(*value)
        raise TypeError(f"frames must be a HostFrames, a dict, a (world, body, quaternion) tuple or None, "
                        f"got {value!r}")

    # -- what the kernels need ----------------------------------------------------------

    @property
    def is_package(self) -> bool:
        """Whether these are the package's own conventions (ENU, FLU, scalar first)."""
        return (self.world, self.body, self.quaternion) == ("ENU", "FLU", "wxyz")

    @property
    def codes(self) -> np.ndarray:
        """(ned, frd, scalar_last) as 0/1 integers, for the plug-in's kernels."""
        return np.array([self.world == "NED", self.body == "FRD", self.quaternion == "xyzw"], dtype=np.int64)

    def standard_gravity_w(self) -> np.ndarray:
        """Standard gravity (9.80665 m/s² down) in the host's world axes."""
        return np.array([0.0, 0.0, G0 if self.world == "NED" else -G0])

    # -- conversions (arrays (3,) / (n, 3) and (4,) / (n, 4)) ----------------------------

    def world_to_enu(self, v_w: Any) -> np.ndarray:
        """Host world vectors in ENU components."""
        v = np.asarray(v_w, dtype=np.float64)
        return v.copy() if self.world == "ENU" else np.stack([v[..., 1], v[..., 0], -v[..., 2]], axis=-1)

    enu_to_world = world_to_enu  # each map is its own inverse

    def body_to_flu(self, v_b: Any) -> np.ndarray:
        """Host body vectors in FLU components."""
        v = np.asarray(v_b, dtype=np.float64)
        return v.copy() if self.body == "FLU" else v * np.array([1.0, -1.0, -1.0])

    flu_to_body = body_to_flu

    def _wxyz(self, q: Any) -> np.ndarray:
        q = np.asarray(q, dtype=np.float64)
        return q.copy() if self.quaternion == "wxyz" else q[..., [3, 0, 1, 2]]

    def _order(self, q: np.ndarray) -> np.ndarray:
        return q if self.quaternion == "wxyz" else q[..., [1, 2, 3, 0]]

    def attitude_to_package(self, q_wb: Any) -> np.ndarray:
        """The host's attitude quaternion(s) as the package's ``q_wb`` (ENU ← FLU, scalar first)."""
        q = self._wxyz(q_wb)
        if self.world == "NED":
            q = quat_multiply(Q_ENU_NED, q) if q.ndim == 1 else quat_multiply(np.broadcast_to(Q_ENU_NED, q.shape), q)
        if self.body == "FRD":
            q = quat_multiply(q, Q_FRD_FLU) if q.ndim == 1 else quat_multiply(q, np.broadcast_to(Q_FRD_FLU, q.shape))
        return q

    def attitude_from_package(self, q_wb: Any) -> np.ndarray:
        """The package's ``q_wb`` (ENU ← FLU, scalar first) in the host's conventions."""
        q = np.asarray(q_wb, dtype=np.float64)
        if self.world == "NED":
            c = Q_ENU_NED * _CONJ
            q = quat_multiply(c, q) if q.ndim == 1 else quat_multiply(np.broadcast_to(c, q.shape), q)
        if self.body == "FRD":
            c = Q_FRD_FLU * _CONJ
            q = quat_multiply(q, c) if q.ndim == 1 else quat_multiply(q, np.broadcast_to(c, q.shape))
        return self._order(q.copy() if q is q_wb else q)

    def mounting_to_package(self, q_body_chip: Any) -> np.ndarray:
        """A rotation chip → host body (host quaternion order) as chip → FLU, scalar first."""
        q = self._wxyz(q_body_chip)
        return quat_multiply(Q_FRD_FLU, q) if self.body == "FRD" else q

    def body_rate(self, q_prev_wb: Any, q_wb: Any, dt_s: float) -> np.ndarray:
        """The mean body rate (rad/s, host body axes) that turns attitude ``q_prev_wb`` into
        ``q_wb`` (host conventions) in ``dt_s``: rotvec(q_prev* ∘ q) / dt, for hosts whose
        angular velocity is missing or in awkward axes (CARLA, BeamNG)."""
        if not (np.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt_s must be positive and finite, got {dt_s!r}")
        a, b = self._wxyz(q_prev_wb), self._wxyz(q_wb)
        return quat_to_rotvec(quat_multiply(quat_conjugate(a), b)) / dt_s
