"""Procedurally generated routes: a new closed drive for every episode seed.

``random_route(seed)`` draws a closed loop around a star-shaped polygon (its corners at
increasing bearings from a centre, so the loop never crosses itself; corners that lie
inward of their neighbours make right turns among the left ones), rounds its corners,
rotates it to a uniformly random start heading and mirrors it with probability ½ (so
clockwise and counter-clockwise loops are equally likely). Leg speeds, stops and optional
hills are drawn too. The route starts and ends at rest in the middle of a straight leg.

The same seed gives the same route on every machine (NumPy's PCG64 through
``np.random.default_rng(seed)``). Every range below is ``(low, high)``, drawn uniformly.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from biso_cosim.routes import Route, parse_route

__all__ = ["random_route", "RANDOM_ROUTE_DEFAULTS"]

RANDOM_ROUTE_DEFAULTS: dict[str, Any] = {
    "corners": (5, 8),
    "size_m": (60.0, 120.0),
    "speed_mps": (6.0, 14.0),
    "fillet_m": (8.0, 30.0),
    "stops": 1,
    "stop_s": (2.0, 5.0),
    "hills": 0,
    "hill_radius_m": (25.0, 50.0),
    "hill_height_m": (1.0, 4.0),
    "start_wait_s": 2.0,
    "max_lateral_accel_mps2": 2.5,
}
"""Options of :func:`random_route` and their defaults:

* ``corners``: number of polygon corners (ints, both ends included);
* ``size_m``: mean distance of the corners from the centre; each corner lies at 0.45–1.0 of it;
* ``speed_mps``: target speed of each leg;
* ``fillet_m``: corner radius (reduced where the legs are too short for it);
* ``stops``: number of corners where the car stops (a traffic light), ``stop_s`` how long;
* ``hills``: number of round hills beside the legs (0 keeps the ground flat: a flat route
  compiles in a fraction of the time), ``hill_radius_m`` and ``hill_height_m`` their size;
* ``start_wait_s``: standing still before driving off (the estimators' alignment);
* ``max_lateral_accel_mps2``: corner speed limit of the driver's speed profile.
"""

# Largest share of a leg that one corner's fillet may take (two corners share a leg).
_FILLET_SHARE = 0.45
# Nearest a corner may lie to the centre, as a share of the size (lower: more right turns).
_INNER_RADIUS = 0.45
# Bearing jitter of a corner, as a share of its sector (< 0.5 keeps the bearings in order).
_BEARING_JITTER = 0.3


def _range(options: Mapping[str, Any], key: str, *, integer: bool = False, minimum: float = 0.0) -> tuple:
    value = options[key]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = (value, value)
    try:
        low, high = value
    except (TypeError, ValueError):
        raise ValueError(f"random_route: {key} must be a number or a (low, high) pair, got {value!r}") from None
    for v in (low, high):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < minimum:
            raise ValueError(f"random_route: {key} must hold finite numbers >= {minimum}, got {value!r}")
        if integer and int(v) != v:
            raise ValueError(f"random_route: {key} must hold integers, got {value!r}")
    if low > high:
        raise ValueError(f"random_route: {key} must be (low, high) with low <= high, got {value!r}")
    return (int(low), int(high)) if integer else (float(low), float(high))


def _options(options: Mapping[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(options) - set(RANDOM_ROUTE_DEFAULTS))
    if unknown:
        raise ValueError(f"random_route: unknown option(s) {unknown}; known: {sorted(RANDOM_ROUTE_DEFAULTS)}")
    merged = {**RANDOM_ROUTE_DEFAULTS, **options}
    out = {
        "corners": _range(merged, "corners", integer=True, minimum=4),
        "size_m": _range(merged, "size_m", minimum=10.0),
        "speed_mps": _range(merged, "speed_mps", minimum=0.5),
        "fillet_m": _range(merged, "fillet_m"),
        "stop_s": _range(merged, "stop_s", minimum=0.1),
        "hill_radius_m": _range(merged, "hill_radius_m", minimum=1.0),
        "hill_height_m": _range(merged, "hill_height_m", minimum=0.01),
    }
    for key in ("stops", "hills"):
        value = merged[key]
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"random_route: {key} must be an integer >= 0, got {value!r}")
        out[key] = int(value)
    for key in ("start_wait_s", "max_lateral_accel_mps2"):
        value = merged[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0.0:
            raise ValueError(f"random_route: {key} must be a finite number >= 0, got {value!r}")
        out[key] = float(value)
    if out["max_lateral_accel_mps2"] == 0.0:
        raise ValueError("random_route: max_lateral_accel_mps2 must be > 0")
    if out["stops"] > out["corners"][0]:
        raise ValueError(f"random_route: stops ({out['stops']}) must not exceed the fewest corners "
                         f"({out['corners'][0]})")
    return out


def _turn(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Signed turn angle at b of the polyline a → b → c (left positive)."""
    u, v = b - a, c - b
    return math.atan2(u[0] * v[1] - u[1] * v[0], float(u @ v))


def random_route(seed: int | np.random.SeedSequence, **options: Any) -> Route:
    """A closed route drawn from ``seed`` (see the module docstring and ``RANDOM_ROUTE_DEFAULTS``).

    >>> route = random_route(7, hills=2)        # the same route for the same seed and options
    >>> route.path.length_m, route.nominal_duration_s
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer, np.random.SeedSequence)):
        raise TypeError(f"seed must be an int >= 0 or a numpy SeedSequence, got {seed!r}")
    if not isinstance(seed, np.random.SeedSequence) and seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    opt = _options(options)
    rng = np.random.default_rng(seed)

    n = int(rng.integers(opt["corners"][0], opt["corners"][1] + 1))
    size = rng.uniform(*opt["size_m"])
    sector = 2.0 * math.pi / n
    bearing = sector * (np.arange(n) + rng.uniform(-_BEARING_JITTER, _BEARING_JITTER, n))
    radius = size * rng.uniform(_INNER_RADIUS, 1.0, n)
    corners = np.column_stack([radius * np.cos(bearing), radius * np.sin(bearing)])
    if rng.random() < 0.5:  # clockwise loop
        corners[:, 1] = -corners[:, 1]
    rotation = rng.uniform(0.0, 2.0 * math.pi)
    c, s = math.cos(rotation), math.sin(rotation)
    corners = corners @ np.array([[c, s], [-s, c]])
    # start in the middle of the leg from the last corner to the first, at the origin
    start = 0.5 * (corners[-1] + corners[0])
    points = np.vstack([start, corners]) - start

    # fillets: each corner takes at most a share of its two legs
    m = points.shape[0]
    legs = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)  # leg i: point i -> i+1
    fillet = np.zeros(m)
    for i in range(1, m):
        turn = abs(_turn(points[i - 1], points[i], points[(i + 1) % m]))
        wanted = rng.uniform(*opt["fillet_m"])
        room = _FILLET_SHARE * min(legs[i - 1], legs[i]) / max(math.tan(0.5 * turn), 1e-9)
        fillet[i] = min(wanted, room)
    speeds = rng.uniform(*opt["speed_mps"], m)
    stop_at = set((1 + rng.choice(n, size=opt["stops"], replace=False)).tolist()) if opt["stops"] else set()
    stop_s = rng.uniform(*opt["stop_s"], m)

    waypoints = []
    for i in range(m):
        wp = {"x_m": float(points[i, 0]), "y_m": float(points[i, 1]), "speed_mps": float(speeds[i])}
        if fillet[i] > 0.0:
            wp["radius_m"] = float(fillet[i])
        if i in stop_at:
            wp["stop_s"] = float(stop_s[i])
        waypoints.append(wp)

    features = []
    for _ in range(opt["hills"]):
        leg = int(rng.integers(m))
        a, b = points[leg], points[(leg + 1) % m]
        along = a + rng.uniform(0.2, 0.8) * (b - a)
        hill_radius = rng.uniform(*opt["hill_radius_m"])
        normal = np.array([a[1] - b[1], b[0] - a[0]]) / max(float(np.linalg.norm(b - a)), 1e-9)
        centre = along + normal * rng.uniform(-0.5, 0.5) * hill_radius
        features.append({"type": "hill", "x_m": float(centre[0]), "y_m": float(centre[1]),
                         "radius_m": float(hill_radius), "height_m": float(rng.uniform(*opt["hill_height_m"]))})

    label = seed if not isinstance(seed, np.random.SeedSequence) else seed.entropy
    data = {
        "name": f"random-{label}",
        "description": f"procedurally generated closed route (seed {label}, {n} corners)",
        "excites": "turns both ways, acceleration and braking" + (", stops" if stop_at else "")
                   + (", grades" if features else ""),
        "closed": True,
        "driving": {"default_speed_mps": float(np.mean(speeds)), "start_wait_s": opt["start_wait_s"],
                    "max_lateral_accel_mps2": opt["max_lateral_accel_mps2"]},
        "waypoint": waypoints,
    }
    if features:
        data["terrain"] = {"feature": features}
    return parse_route(data, source=f"random_route({label})")
