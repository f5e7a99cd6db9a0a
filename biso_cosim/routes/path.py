"""Dense paths from waypoints, and the speed profile a driver follows along them.

A route's waypoints are the corners of a polyline; a corner with ``radius_m > 0`` is
rounded by a circular fillet tangent to both legs (the legs are shortened by the tangent
length ``r·tan(Δ/2)`` for a turn of Δ). The result is sampled every ``spacing_m`` along its
arc length ``s``, with heading and curvature at each sample.

The free-flow speed profile ``v(s)`` is the lowest of the leg's target speed and the
curvature limit ``sqrt(a_lat/|κ|)``, then made feasible by a forward pass (acceleration
limit, ``v² ≤ v₀² + 2·a·Δs``) and a backward pass (deceleration limit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from biso_cosim.routes._kernels import LOCATE_AHEAD, LOCATE_BACK, _feasible_speeds, _locate

__all__ = ["Path", "densify", "speed_profile", "curvature_speed_limit"]


@dataclass(frozen=True)
class Path:
    """A path sampled along its arc length (ENU metres, heading CCW from East)."""

    x_m: np.ndarray
    y_m: np.ndarray
    s_m: np.ndarray
    heading_rad: np.ndarray
    curvature_per_m: np.ndarray
    leg: np.ndarray  # index of the waypoint whose leg each sample belongs to
    closed: bool

    @property
    def length_m(self) -> float:
        return float(self.s_m[-1])

    def __len__(self) -> int:
        return self.x_m.shape[0]

    def locate(self, x: float, y: float, hint: int, back: int = LOCATE_BACK, ahead: int = LOCATE_AHEAD,
               floor: int = 0) -> tuple[int, float, float]:
        """Nearest point of the path to (x, y), searched in a window around index ``hint``
        and never before index ``floor``.

        Returns (index of the segment start, arc length s, signed cross-track error, positive
        when the point is left of the path). The window (2 m back, 20 m ahead at the default
        spacing) keeps self-crossing routes (a figure eight) on the branch being driven.
        """
        lo = max(hint - back, floor, 0)
        hi = min(hint + ahead, len(self) - 1)
        i, s, cross = _locate(self.x_m, self.y_m, self.s_m, float(x), float(y), lo, hi)
        return int(i), float(s), float(cross)

    def index_at(self, s: float) -> int:
        """Index of the last sample with arc length ≤ s (clamped to the path)."""
        i = int(np.searchsorted(self.s_m, s, side="right")) - 1
        return min(max(i, 0), len(self) - 1)


def _corner(prev_xy, corner_xy, next_xy):
    """Turn angle Δ (signed, left positive) and unit directions of the two legs at a corner."""
    a = np.subtract(corner_xy, prev_xy)
    b = np.subtract(next_xy, corner_xy)
    ua = a / np.linalg.norm(a)
    ub = b / np.linalg.norm(b)
    turn = math.atan2(ua[0] * ub[1] - ua[1] * ub[0], float(ua @ ub))
    return turn, ua, ub


def densify(xy: np.ndarray, radius_m: np.ndarray, closed: bool, spacing_m: float = 0.25,
            names: list[str] | None = None) -> Path:
    """Sample the rounded polyline through ``xy`` (n, 2) with corner fillets ``radius_m`` (n,).

    For a closed route the last leg returns to the first waypoint, which must not be
    rounded (the route starts and ends there). Raises ValueError naming the waypoint when
    two fillets overlap on a leg or a leg has zero length.
    """
    n = xy.shape[0]
    label = names or [f"waypoint[{i}]" for i in range(n)]
    nodes = np.vstack([xy, xy[:1]]) if closed else xy
    nlegs = nodes.shape[0] - 1
    lengths = np.linalg.norm(np.diff(nodes, axis=0), axis=1)
    for i, length in enumerate(lengths):
        if length == 0.0:
            raise ValueError(f"{label[i]} and the next waypoint coincide: a leg must have a length")
    # tangent length of each interior corner (corner i joins leg i-1 and leg i)
    tangent = np.zeros(nodes.shape[0])
    turns = np.zeros(nodes.shape[0])
    for i in range(1, nlegs):
        if radius_m[i] > 0.0:
            turn, _, _ = _corner(nodes[i - 1], nodes[i], nodes[i + 1])
            if abs(turn) > math.radians(179.0):
                raise ValueError(f"{label[i]}: a corner that turns back on itself cannot be rounded")
            turns[i] = turn
            tangent[i] = radius_m[i] * math.tan(0.5 * abs(turn))
    for i in range(nlegs):
        # 1 mm of slack for coordinates written to the millimetre (meeting fillets)
        if tangent[i] + tangent[i + 1] > lengths[i] + 1e-3:
            raise ValueError(
                f"{label[i % n]}: the corner fillets at both ends of its leg need "
                f"{tangent[i] + tangent[i + 1]:.1f} m but the leg is {lengths[i]:.1f} m long; "
                "reduce radius_m or move the waypoints apart"
            )
    # straight pieces of all legs at once: from the end of one fillet to the start of the next
    u = np.diff(nodes, axis=0) / lengths[:, None]
    a = nodes[:-1] + tangent[:-1, None] * u
    b = nodes[1:] - tangent[1:, None] * u
    straight = np.array([float((q - p) @ w) for p, q, w in zip(a, b, u)])  # as a 2-vector product, to the bit
    count = np.where(straight < 1e-6, 0, np.maximum(np.ceil(straight / spacing_m), 1)).astype(np.int64)
    first = np.concatenate([[0], np.cumsum(count)])
    which = np.repeat(np.arange(nlegs), count)
    t = (np.arange(first[-1]) - first[which]) / count[which]
    line_x = a[which, 0] + t * (b[which, 0] - a[which, 0])
    line_y = a[which, 1] + t * (b[which, 1] - a[which, 1])
    heading = [math.atan2(q[1] - p[1], q[0] - p[0]) for p, q in zip(a, b)]
    xs, ys, hs, ks, legs = [], [], [], [], []

    def emit_arc(start, heading0, radius, turn, leg):
        arc = radius * abs(turn)
        m = max(int(math.ceil(arc / spacing_m)), 1)
        sign = 1.0 if turn > 0 else -1.0
        # centre to the left (turn > 0) or right of the heading
        cx = start[0] - sign * radius * math.sin(heading0)
        cy = start[1] + sign * radius * math.cos(heading0)
        phi = heading0 + turn * np.arange(m) / m
        xs.append(cx + sign * radius * np.sin(phi))
        ys.append(cy - sign * radius * np.cos(phi))
        hs.append(phi)
        ks.append(np.full(m, sign / radius))
        legs.append(np.full(m, leg))

    for i in range(nlegs):
        if count[i]:
            lo, hi = first[i], first[i + 1]
            xs.append(line_x[lo:hi])
            ys.append(line_y[lo:hi])
            hs.append(np.full(count[i], heading[i]))
            ks.append(np.zeros(count[i]))
            legs.append(np.full(count[i], i % n))
        if tangent[i + 1] > 0.0:
            emit_arc(b[i], math.atan2(u[i, 1], u[i, 0]), radius_m[i + 1], turns[i + 1], (i + 1) % n)
    end = nodes[-1]
    xs.append(np.array([end[0]]))
    ys.append(np.array([end[1]]))
    hs.append(np.array([hs[-1][-1]]))
    ks.append(np.array([0.0]))
    legs.append(np.array([legs[-1][-1]]))
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    return Path(x_m=x, y_m=y, s_m=s, heading_rad=np.unwrap(np.concatenate(hs)),
                curvature_per_m=np.concatenate(ks), leg=np.concatenate(legs).astype(np.int64), closed=closed)


def polyline_curvature(path_x: np.ndarray, path_y: np.ndarray, window_m: float, spacing_m: float) -> np.ndarray:
    """Curvature of a sampled polyline from the rate of change of heading, smoothed over a window.

    Used for routes given as dense points (imported tracks, sharp corners) where the curvature
    is not known in closed form.
    """
    heading = np.unwrap(np.arctan2(np.gradient(path_y), np.gradient(path_x)))
    ds = np.hypot(np.gradient(path_x), np.gradient(path_y))
    kappa = np.gradient(heading) / np.maximum(ds, 1e-9)
    width = max(int(round(window_m / spacing_m)), 1)
    kernel = np.ones(width) / width
    return np.convolve(kappa, kernel, mode="same")


def curvature_speed_limit(path: Path, max_lateral_accel_mps2: float, cusps: tuple[int, ...] = ()) -> np.ndarray:
    """The curvature limit ``sqrt(a_lat/|κ|)`` at each path sample (inf on straights), κ the
    larger of the closed-form curvature and the sampled one, taken piece by piece between
    ``cusps`` (where the direction of travel flips)."""
    spacing = float(np.median(np.diff(path.s_m)))
    sampled = np.zeros(len(path))
    bounds = [0, *sorted(cusps), len(path)]
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        if hi - lo >= 3:
            sampled[lo:hi] = polyline_curvature(path.x_m[lo:hi], path.y_m[lo:hi], window_m=4.0, spacing_m=spacing)
    kappa = np.maximum(np.abs(path.curvature_per_m), np.abs(sampled))
    with np.errstate(divide="ignore"):
        return np.sqrt(max_lateral_accel_mps2 / np.maximum(kappa, 1e-12))


def speed_profile(path: Path, leg_speed_mps: np.ndarray, *, max_lateral_accel_mps2: float,
                  accel_mps2: float, decel_mps2: float, zero_at: tuple[int, ...] = (),
                  cusps: tuple[int, ...] = ()) -> np.ndarray:
    """Target speed at each path sample, at rest at the sample indices ``zero_at`` (stops,
    the start, the end) and feasible for the acceleration limits in between; in curves at
    most ``curvature_speed_limit``."""
    v = np.asarray(leg_speed_mps, dtype=np.float64)[path.leg].copy()
    v = np.minimum(v, curvature_speed_limit(path, max_lateral_accel_mps2, cusps))
    v[list(zero_at)] = 0.0
    _feasible_speeds(v, np.diff(path.s_m), float(accel_mps2), float(decel_mps2), 2.0)
    return v
