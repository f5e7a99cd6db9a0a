"""Slow references of the route layer's fast code: the dense path built leg by leg in Python
(as before the straight legs were vectorised) and the speed profile's limit passes as Python
loops (as before they became a kernel). Tests hold the fast code to these, bit for bit."""

import math

import numpy as np

from biso_cosim.routes.path import Path


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
    xs, ys, hs, ks, legs = [], [], [], [], []

    def emit_line(p0, p1, leg, u):
        length = float((p1 - p0) @ u)
        if length < 1e-6:  # the fillets take the whole leg (up to rounding)
            return
        m = max(int(math.ceil(length / spacing_m)), 1)
        t = np.arange(m) / m
        heading = math.atan2(p1[1] - p0[1], p1[0] - p0[0])
        xs.append(p0[0] + t * (p1[0] - p0[0]))
        ys.append(p0[1] + t * (p1[1] - p0[1]))
        hs.append(np.full(m, heading))
        ks.append(np.zeros(m))
        legs.append(np.full(m, leg))

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
        p0, p1 = nodes[i], nodes[i + 1]
        u = (p1 - p0) / lengths[i]
        a = p0 + tangent[i] * u
        b = p1 - tangent[i + 1] * u
        emit_line(a, b, i % n, u)
        if tangent[i + 1] > 0.0:
            emit_arc(b, math.atan2(u[1], u[0]), radius_m[i + 1], turns[i + 1], (i + 1) % n)
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


def feasible_speeds(v: np.ndarray, ds: np.ndarray, accel: float, decel: float) -> np.ndarray:
    """The forward (acceleration) and backward (deceleration) passes in plain Python."""
    v = v.copy()
    for i in range(1, v.shape[0]):
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2.0 * accel * ds[i - 1]))
    for i in range(v.shape[0] - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * decel * ds[i]))
    return v
