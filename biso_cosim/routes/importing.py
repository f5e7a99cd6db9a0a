"""Real routes: a recorded GPX or CSV track becomes a route the car can drive.

The steps, each with its reason:

1. Read and check every point (:mod:`biso_cosim.routes.tracks`): the errors name the point.
2. Convert to the local ENU frame of the first point (WGS-84, pymap3d); heights are the
   ellipsoidal heights themselves (ENU "up" drops with the Earth's curvature, 7.8 m over
   10 km, which is no grade of the road). A fix implying more than ``MAX_TRACK_SPEED_MPS``
   from the one before (with times; without, a jump of more than ``MAX_JUMP_M``) is refused
   naming it (a bad fix, or two recordings in one file), and so is a track longer than
   ``max_length_km``.
3. Drop repeated fixes (a time stamp seen before), find the stops from the time stamps
   (:mod:`biso_cosim.routes.stops`: an 8 s wait at a light becomes a waypoint with
   ``stop_s = 8``), stand each stop's fixes in for one point, and drop the standing at the
   start and the end of the recording and points that repeat the one before.
4. Smooth the positions along the arc length with a smoother that keeps the ends
   (:mod:`biso_cosim.routes.smoothing`, cutoff ``smoothing_m``), twice, the second time along
   the arc length of the first result (jitter lengthens the raw track). Where the smoothed
   path still turns tighter than the car can (``TURN_MARGIN`` × its turning radius), smooth
   further (up to ``MAX_EXTRA_SMOOTHING`` × as much) with a :class:`RouteWarning`, else refuse
   naming the point.
5. Heights the same way with ``height_smoothing_m`` (GNSS heights scatter by metres: 2 m of
   noise 10 m apart reads as a 28 % grade), checked against the steepest grade the car can
   climb (:func:`biso_cosim.routes.limits.car_limits`).
6. Waypoints along the smoothed path at most ``spacing_m`` apart, closer in curves (the chord
   of a curve departs from it by at most ``SAGITTA_M``), and at every stop.
7. Leg speeds from the time stamps (or a ``speed_mps`` column), smoothed over
   ``speed_smoothing_m``, capped at the car's top speed (with a warning); else ``speed_mps``.
   Either way the driver slows for curvature (``max_lateral_accel_mps2``), and a leg that
   curves all along gets the speed its curvature allows (a recording often corners harder
   than the 2.5 m/s² default): capped here, with one warning for the import, so that loading
   the route does not warn of speeds it never reaches (the driven profile is the same).

The route's site (latitude, longitude and height of its ground plane; date from the track's
first time stamp, else the default) sets the Earth's magnetic field and the GNSS location.
Heights become a ``road`` terrain feature along the waypoints, relative to the lowest point.
A track that ends within ``close_within_m`` of its start becomes a closed route, smoothed
round the loop. The route's length (its description, its summary) is that of its waypoints.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from biso_cosim.output import atomic_output
from biso_cosim.routes.limits import car_limits
from biso_cosim.routes.route import Route, RouteWarning, Waypoint, parse_route
from biso_cosim.routes.smoothing import bin_along, smooth_along, whittaker, whittaker_lambda
from biso_cosim.routes.stops import find_stops
from biso_cosim.routes.tracks import MAX_FILE_MB, Track, read_track

__all__ = ["Track", "ImportedTrack", "read_track", "convert_track", "track_to_route_data", "import_track",
           "write_route_file", "MAX_TRACK_SPEED_MPS", "MAX_JUMP_M", "TURN_MARGIN", "MAX_EXTRA_SMOOTHING",
           "SAGITTA_M"]

MAX_TRACK_SPEED_MPS = 100.0
"""A fix further from the one before than this speed allows is a bad fix (360 km/h)."""

MAX_JUMP_M = 5000.0
"""Without time stamps, the largest step between two points of a track."""

TURN_MARGIN = 1.25
"""The imported path may turn no tighter than this many times the car's turning radius (the
driver needs some steering left to correct)."""

MAX_EXTRA_SMOOTHING = 4.0
"""Positions and heights are smoothed up to this many times longer than asked before the
import is refused."""

SAGITTA_M = 0.05
"""Largest gap between a curve and the chord between two waypoints on it."""

MIN_SPACING_M = 1.0
"""Closest spacing of waypoints (in the tightest curves)."""

GRID_M = 1.0
"""Spacing of the smoothing grid along the track."""

ROAD_SHOULDER_M = 3.0
"""Width over which an imported road's surface falls to the ground beside it."""

BRIDGE_M = 10.0
"""Where the road passes over itself with heights further apart than this (more than GNSS
height noise usually explains), the import warns that it may be a bridge."""

Progress = Callable[[float, str], None]
"""Called with the fraction of the import done and what it is doing."""


@dataclass(frozen=True)
class ImportedTrack:
    """A track turned into route-file data, with what the import did to it."""

    data: dict
    """The route file's content (the TOML schema of :mod:`biso_cosim.routes.route`)."""
    length_m: float
    points_read: int
    points_used: int
    repeated_dropped: int
    """Fixes with a time stamp already seen."""
    standing_dropped: int
    """Fixes of the stops (each stop stands for them as one point), of the standing at the start
    and the end, and points that repeat the one before."""
    stops: tuple[tuple[float, float], ...]
    """(arc length m, dwell s) of each stop."""
    smoothing_m: float
    """The positions' smoothing used (more than asked when the track turned too tightly)."""
    height_smoothing_m: float | None
    notes: tuple[str, ...] = field(default_factory=tuple)
    curve_capped: int = 0
    """Waypoints whose recorded speed their leg's curvature does not allow anywhere
    (``max_lateral_accel_mps2``): capped to the fastest it allows."""


def _positive(label: str, value: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{label} must be a positive number, got {value!r}")
    return float(value)


def _local_xy(track: Track) -> tuple[np.ndarray, np.ndarray]:
    """ENU east/north of every point in the tangent plane of the first (at its height, so that
    height noise does not move points sideways)."""
    import pymap3d

    h0 = float(track.alt_m[0]) if track.alt_m is not None else 0.0
    e, n, _ = pymap3d.geodetic2enu(track.lat_deg, track.lon_deg, np.full(len(track), h0),
                                   track.lat_deg[0], track.lon_deg[0], h0)
    return np.asarray(e, dtype=np.float64), np.asarray(n, dtype=np.float64)


def _check_steps(track: Track, x: np.ndarray, y: np.ndarray, max_length_km: float) -> None:
    step = np.hypot(np.diff(x), np.diff(y))
    if track.t_s is not None:
        dt = np.diff(track.t_s)
        with np.errstate(divide="ignore", invalid="ignore"):
            speed = np.where(dt > 0.0, step / dt, 0.0)
        bad = np.flatnonzero(speed > MAX_TRACK_SPEED_MPS)
        if bad.size:
            i = int(bad[0]) + 1
            raise ValueError(f"{track.where(i)} is {_distance(step[i - 1])} from the point before, {dt[i - 1]:g} s "
                             f"later ({speed[i - 1]:.0f} m/s; a car's track stays below {MAX_TRACK_SPEED_MPS:g} m/s): "
                             "a bad fix, or two recordings in one file")
    else:
        bad = np.flatnonzero(step > MAX_JUMP_M)
        if bad.size:
            i = int(bad[0]) + 1
            raise ValueError(f"{track.where(i)} is {_distance(step[i - 1])} from the point before (more than "
                             f"{MAX_JUMP_M / 1000:g} km): a bad point, or two tracks in one file")
    length = float(step.sum())
    if length > max_length_km * 1000.0:
        raise ValueError(f"{track.source}: the track is {_distance(length)} long, more than the {max_length_km:g} km "
                         "a route may be (max_length_km)")


def _distance(m: float) -> str:
    return f"{m / 1000:.1f} km" if m >= 1000.0 else f"{m:.1f} m"


@dataclass
class _Points:
    """The track's points being cleaned: positions, times, and the file index of each."""

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray | None
    t: np.ndarray | None
    v: np.ndarray | None
    index: np.ndarray  # into the track, for messages
    dwell: np.ndarray  # stop duration at each point (0: none)

    def keep(self, mask: np.ndarray) -> "_Points":
        pick = lambda a: None if a is None else a[mask]  # noqa: E731
        return _Points(self.x[mask], self.y[mask], pick(self.z), pick(self.t), pick(self.v), self.index[mask],
                       self.dwell[mask])


def _stand_for_stops(p: _Points, min_stop_s: float) -> tuple[_Points, int]:
    """One point (the median position, at the arrival time) for each stop's fixes, with the
    stop's dwell; the standing at both ends left out. Later times are moved back by the
    dwell, so that times count driving only."""
    runs = find_stops(p.t, p.x, p.y, min_stop_s=min_stop_s)
    keep = np.ones(p.x.shape[0], dtype=bool)
    t = p.t.copy()
    last = p.x.shape[0] - 1
    for first, final, dwell in runs:
        if first == 0:  # standing before driving off: the route's start_wait_s
            keep[:final] = False
            continue
        if final == last:  # standing at the end: the route ends at rest anyway
            keep[first + 1:] = False
            continue
        keep[first + 1:final + 1] = False
        p.x[first] = np.median(p.x[first:final + 1])
        p.y[first] = np.median(p.y[first:final + 1])
        if p.v is not None:
            p.v[first] = 0.0
        p.dwell[first] = dwell
        t[final + 1:] -= float(p.t[final] - p.t[first])
    p.t = t
    return p.keep(keep), int((~keep).sum())


@dataclass(frozen=True)
class _Curve:
    """The smoothed path on a grid: node positions and arc lengths, curvature, and each
    point's arc length on it."""

    xy: np.ndarray
    s_nodes: np.ndarray
    length_m: float
    kappa: np.ndarray
    s_points: np.ndarray


def _arc(xy: np.ndarray, closed: bool) -> tuple[np.ndarray, float]:
    ends = np.vstack([xy, xy[:1]]) if closed else xy
    seg = np.hypot(np.diff(ends[:, 0]), np.diff(ends[:, 1]))
    s = np.concatenate([[0.0], np.cumsum(seg)])
    return s[:xy.shape[0]], float(s[-1])


def _smooth_path(s: np.ndarray, xy: np.ndarray, cutoff_m: float, closed: bool, period: float | None) -> _Curve:
    """Smooth along s, then again along the arc length of that first result."""
    for _ in range(2):
        grid, nodes = smooth_along(s, xy, cutoff_m, grid_m=GRID_M, period_m=period)
        s_nodes, length = _arc(nodes, closed)
        if closed:
            s = np.interp(s, np.append(grid, period), np.append(s_nodes, length))
            period = length
        else:
            s = np.interp(s, grid, s_nodes)
    h = grid[1] - grid[0]
    if closed:
        d1 = (np.roll(nodes, -1, axis=0) - np.roll(nodes, 1, axis=0)) / (2 * h)
        d2 = (np.roll(nodes, -1, axis=0) - 2 * nodes + np.roll(nodes, 1, axis=0)) / (h * h)
    else:
        d1 = np.gradient(nodes, h, axis=0)
        d2 = np.gradient(d1, h, axis=0)
    kappa = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]) / np.maximum(np.hypot(d1[:, 0], d1[:, 1]), 1e-9) ** 3
    return _Curve(nodes, s_nodes, length, kappa, s)


def _self_crossings(grid: np.ndarray, x: np.ndarray, y: np.ndarray, reach_m: float,
                    period_m: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of grid nodes within ``reach_m`` of each other that are not neighbours along the
    road (more than 2·reach apart along it): where the road passes over or beside itself."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(np.column_stack([x, y])).query_pairs(reach_m, output_type="ndarray")
    if pairs.shape[0] == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    along = np.abs(grid[pairs[:, 1]] - grid[pairs[:, 0]])
    if period_m is not None:
        along = np.minimum(along, period_m - along)
    far = along > 2.0 * reach_m
    return pairs[far, 0].astype(np.int64), pairs[far, 1].astype(np.int64)


def _nearest_point(s_points: np.ndarray, s: float) -> int:
    return int(np.argmin(np.abs(s_points - s)))


def _smoothed_until(check: Callable[[float], tuple[object, float, float]], asked_m: float, limit: float,
                    what: str, refuse: Callable[[object, float, float], str], warn: Callable[[str], None]):
    """Smooth with the asked cutoff, then longer (×2 each time, up to MAX_EXTRA_SMOOTHING) while
    ``check(cutoff)`` returns a worst value over ``limit``; refuse with ``refuse(...)``."""
    cutoff = asked_m
    while True:
        result, worst, at = check(cutoff)
        if worst <= limit:
            if cutoff > asked_m:
                warn(f"{what}; smoothed over {cutoff:g} m instead of {asked_m:g} m")
            return result, cutoff
        if cutoff * 2.0 > asked_m * MAX_EXTRA_SMOOTHING + 1e-9:
            raise ValueError(refuse(result, worst, cutoff))
        cutoff *= 2.0


def _waypoint_s(curve: _Curve, closed: bool, spacing_m: float, stops_s: list[float]) -> np.ndarray:
    """Arc lengths of the waypoints: at most spacing_m apart, closer in curves (sagitta), with
    one at every stop."""
    step = np.clip(np.sqrt(8.0 * SAGITTA_M / np.maximum(np.abs(curve.kappa), 1e-12)), MIN_SPACING_M, spacing_m)
    s_nodes = np.append(curve.s_nodes, curve.length_m) if closed else curve.s_nodes
    density = 1.0 / (np.append(step, step[:1]) if closed else step)
    count = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(s_nodes))])
    bounds = [0.0, *stops_s, curve.length_m]
    out = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        na, nb = np.interp([a, b], s_nodes, count)
        n = max(int(math.ceil(nb - na - 1e-9)), 1)
        out.append(np.interp(na + (nb - na) * np.arange(n) / n, count, s_nodes))
    if not closed:
        out.append(np.array([curve.length_m]))
    return np.concatenate(out)


def _leg_speeds(s_points: np.ndarray, t: np.ndarray | None, v_points: np.ndarray | None, s_way: np.ndarray,
                end_m: float, smoothing_m: float) -> np.ndarray:
    """Mean recorded speed on each waypoint's leg (to the next waypoint; the last leg ends at
    end_m), from a speed column or else from the time stamps."""
    grid = np.arange(0.0, end_m + GRID_M, GRID_M)
    inside = (grid >= s_points[0]) & (grid <= s_points[-1])
    if v_points is not None:
        v_nodes = np.interp(grid, s_points, v_points)
        weights = inside.astype(np.float64)
    else:
        t_nodes = np.interp(grid, s_points, t)
        dt = np.diff(t_nodes)
        valid = inside[1:] & inside[:-1] & (dt > 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            v_cells = np.where(valid, np.diff(grid) / dt, 0.0)
        # speeds of the cells, at the nodes between them
        v_nodes = np.concatenate([v_cells[:1], 0.5 * (v_cells[1:] + v_cells[:-1]), v_cells[-1:]])
        weights = np.concatenate([valid[:1], valid[1:] | valid[:-1], valid[-1:]]).astype(np.float64)
    if not weights.any():
        weights[:] = 1.0
    smooth = whittaker(np.where(weights > 0.0, v_nodes, 0.0), weights, whittaker_lambda(smoothing_m, GRID_M))
    ends = np.append(s_way[1:], end_m)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (smooth[1:] + smooth[:-1]) * np.diff(grid))])
    a, b = np.interp(s_way, grid, cum), np.interp(ends, grid, cum)
    v = (b - a) / np.maximum(ends - s_way, 1e-9)
    if s_way.shape[0] > 1 and ends[-1] - s_way[-1] < 1e-9:  # an open route's last waypoint has no leg
        v[-1] = v[-2]
    return v


def convert_track(track: Track, *, name: str | None = None, description: str | None = None,
                  speed_mps: float = 10.0, max_lateral_accel_mps2: float = 2.5, spacing_m: float = 5.0,
                  smoothing_m: float = 15.0, height_smoothing_m: float = 200.0, speed_smoothing_m: float = 50.0,
                  close_within_m: float = 15.0, road_half_width_m: float = 4.0, min_stop_s: float = 2.0,
                  max_length_km: float = 200.0, progress: Progress | None = None) -> ImportedTrack:
    """The route-file data for a track, and what the import did (see the module docstring).

    Warnings (a :class:`RouteWarning` each): smoothing longer than asked, speeds capped at the
    car's top speed, gaps in the fixes.
    """
    for label, value in (("speed_mps", speed_mps), ("max_lateral_accel_mps2", max_lateral_accel_mps2),
                         ("spacing_m", spacing_m), ("smoothing_m", smoothing_m),
                         ("height_smoothing_m", height_smoothing_m), ("speed_smoothing_m", speed_smoothing_m),
                         ("close_within_m", close_within_m), ("road_half_width_m", road_half_width_m),
                         ("min_stop_s", min_stop_s), ("max_length_km", max_length_km)):
        _positive(label, value)
    if spacing_m < MIN_SPACING_M:
        raise ValueError(f"spacing_m must be at least {MIN_SPACING_M:g} m, got {spacing_m!r}")
    report = progress or (lambda fraction, stage: None)
    notes: list[str] = []

    def warn(message: str) -> None:
        notes.append(message)
        warnings.warn(f"{track.source}: {message}", RouteWarning, stacklevel=3)

    car = car_limits()
    report(0.0, "checking points")
    x, y = _local_xy(track)
    _check_steps(track, x, y, max_length_km)
    n_read = len(track)
    h0 = float(track.alt_m[0]) if track.alt_m is not None else 0.0
    p = _Points(x, y, None if track.alt_m is None else track.alt_m - h0,
                None if track.t_s is None else track.t_s.astype(np.float64),
                None if track.speed_mps is None else track.speed_mps.astype(np.float64),
                np.arange(n_read), np.zeros(n_read))
    repeated = 0
    if p.t is not None:
        fresh = np.concatenate([[True], np.diff(p.t) > 0.0])
        repeated = int((~fresh).sum())
        p = p.keep(fresh)
        gaps = np.diff(p.t)
        typical = float(np.median(gaps)) if gaps.size else 0.0
        long = np.flatnonzero(gaps > max(5.0, 5.0 * typical))
        if long.size:
            k = int(long[np.argmax(gaps[long])])
            warn(f"{long.size} gap(s) in the fixes, the longest {gaps[k]:.0f} s "
                 f"({_distance(math.hypot(p.x[k + 1] - p.x[k], p.y[k + 1] - p.y[k]))}) after "
                 f"{track.where(int(p.index[k])).split(': ', 1)[1]}: bridged by the smoothed path")
    report(0.1, "finding stops")
    standing = 0
    if p.t is not None and p.x.shape[0] > 2:
        p, standing = _stand_for_stops(p, min_stop_s)
    step = np.hypot(np.diff(p.x), np.diff(p.y))
    moved = np.concatenate([[True], step > 1e-3])  # a point on the one before: nothing to smooth
    # a stop's dwell stays with the point that stands for it
    for i in np.flatnonzero(~moved):
        p.dwell[i - 1] = max(p.dwell[i - 1], p.dwell[i])
    standing += int((~moved).sum())
    p = p.keep(moved)
    if p.x.shape[0] < 2:
        raise ValueError(f"{track.source}: the track does not move (all its points are in one place)")
    step = np.hypot(np.diff(p.x), np.diff(p.y))
    s_raw = np.concatenate([[0.0], np.cumsum(step)])
    if s_raw[-1] < 2.0 * spacing_m:
        raise ValueError(f"{track.source}: the track is only {s_raw[-1]:.1f} m long; a route needs at least "
                         f"{2 * spacing_m:g} m (twice spacing_m)")
    gap_home = math.hypot(p.x[-1] - p.x[0], p.y[-1] - p.y[0])
    closed = gap_home <= close_within_m and s_raw[-1] > 4.0 * close_within_m
    if closed:  # a logger often repeats the start at the end: leave those points out
        home = np.hypot(p.x - p.x[0], p.y - p.y[0]) < 0.5 * spacing_m
        home[0] = False
        tail = p.x.shape[0]
        while tail > 2 and home[tail - 1]:
            tail -= 1
        p = p.keep(np.arange(p.x.shape[0]) < tail)
        s_raw = s_raw[:tail]
        gap_home = math.hypot(p.x[-1] - p.x[0], p.y[-1] - p.y[0])
    period = s_raw[-1] + gap_home if closed else None

    report(0.3, "smoothing positions")
    kappa_limit = 1.0 / (TURN_MARGIN * car.turning_radius_m)
    xy = np.column_stack([p.x, p.y])

    def path_check(cutoff):
        curve = _smooth_path(s_raw, xy, cutoff, closed, period)
        k = int(np.argmax(np.abs(curve.kappa)))
        return curve, float(abs(curve.kappa[k])), float(curve.s_nodes[k])

    def path_refusal(curve, worst, cutoff):
        at = _nearest_point(curve.s_points, curve.s_nodes[int(np.argmax(np.abs(curve.kappa)))])
        return (f"{track.where(int(p.index[at]))}: the track turns on a radius of {1 / worst:.1f} m there even "
                f"smoothed over {cutoff:g} m; the car needs at least {1 / kappa_limit:.1f} m "
                f"({TURN_MARGIN:g} × its turning radius of {car.turning_radius_m:.2f} m)")

    curve, used_smoothing = _smoothed_until(
        path_check, smoothing_m, kappa_limit,
        f"the track turns tighter than the car can (radius under {1 / kappa_limit:.1f} m)",
        path_refusal, warn)
    length = curve.length_m
    s_pts = curve.s_points

    # stops on the smoothed path; too near an end (or another stop) they are dropped
    stops = []
    for i in np.flatnonzero(p.dwell > 0.0):
        s = float(s_pts[i])
        if s < 2 * MIN_SPACING_M or s > length - 2 * MIN_SPACING_M:
            continue
        if stops and s - stops[-1][0] < 2 * MIN_SPACING_M:
            stops[-1] = (stops[-1][0], stops[-1][1] + float(p.dwell[i]))
            continue
        stops.append((s, round(float(p.dwell[i]), 1)))
    s_way = _waypoint_s(curve, closed, spacing_m, [s for s, _ in stops])
    s_nodes_ext = np.append(curve.s_nodes, length) if closed else curve.s_nodes
    xy_ext = np.vstack([curve.xy, curve.xy[:1]]) if closed else curve.xy
    # to the millimetre, as written
    wx = np.round(np.interp(s_way, s_nodes_ext, xy_ext[:, 0]), 3)
    wy = np.round(np.interp(s_way, s_nodes_ext, xy_ext[:, 1]), 3)
    # the route's own length: its waypoints' polyline (and the closing leg)
    _, route_length = _arc(np.column_stack([wx, wy]), closed)

    report(0.6, "smoothing heights")
    zw, used_height = None, None
    if p.z is not None:
        period_z = length if closed else None
        grid, means, weights = bin_along(s_pts, p.z, grid_m=GRID_M, period_m=period_z)
        h = grid[1] - grid[0]
        reach = road_half_width_m + ROAD_SHOULDER_M
        ties = _self_crossings(grid, np.interp(grid, s_nodes_ext, xy_ext[:, 0]),
                               np.interp(grid, s_nodes_ext, xy_ext[:, 1]), reach, period_z)
        if ties[0].size:
            apart = whittaker(means, weights, whittaker_lambda(height_smoothing_m, h), closed)
            gap = np.abs(apart[ties[0]] - apart[ties[1]])
            k = int(np.argmax(gap))
            if gap[k] > BRIDGE_M:
                at = _nearest_point(s_pts, grid[ties[1][k]])
                warn(f"the track passes within {reach:g} m of itself at {track.where(int(p.index[at])).split(': ', 1)[1]} "
                     f"with heights {gap[k]:.1f} m apart (a bridge, or GNSS height noise?); the ground has one height "
                     "per place, so they are made equal")

        def height_check(cutoff):
            z = whittaker(means, weights, whittaker_lambda(cutoff, h), closed, ties)
            grade = (np.roll(z, -1) - np.roll(z, 1)) / (2 * h) if closed else np.gradient(z, h)
            k = int(np.argmax(np.abs(grade)))
            return (z, grade), float(abs(grade[k])), float(grid[k])

        def height_refusal(result, worst, cutoff):
            _, grade = result
            at = _nearest_point(s_pts, grid[int(np.argmax(np.abs(grade)))])
            return (f"{track.where(int(p.index[at]))}: the road's grade is {worst:.0%} there even with the heights "
                    f"smoothed over {cutoff:g} m; the car climbs at most {car.grade:.0%}")

        (z, _), used_height = _smoothed_until(
            height_check, height_smoothing_m, car.grade,
            f"the heights give grades steeper than the car can climb ({car.grade:.0%})", height_refusal, warn)
        zw = np.interp(s_way, np.append(grid, length) if closed else grid, np.append(z, z[:1]) if closed else z)

    report(0.8, "speeds")
    if p.v is not None or p.t is not None:
        ends = length if closed else s_way[-1]
        v = _leg_speeds(s_pts, p.t, p.v, s_way, ends, speed_smoothing_m)
        fast = v > car.top_speed_mps
        if fast.any():
            warn(f"{int(fast.sum())} waypoint(s) recorded faster than the car's top speed "
                 f"({car.top_speed_mps:.1f} m/s, up to {v.max():.1f} m/s): capped to it")
        v = np.clip(v, 1.0, car.top_speed_mps)
    else:
        v = None

    stop_at = {round(s, 6): dwell for s, dwell in stops}
    speeds = np.round(v, 2).tolist() if v is not None else [float(speed_mps)] * s_way.shape[0]
    waypoints = [{"x_m": a, "y_m": b, "speed_mps": c} for a, b, c in zip(wx.tolist(), wy.tolist(), speeds)]
    for i, s in enumerate(s_way.tolist()):
        dwell = stop_at.get(round(s, 6))
        if dwell:
            waypoints[i]["stop_s"] = dwell
    stem = Path(track.source).stem
    site = {"lat_deg": float(track.lat_deg[0]), "lon_deg": float(track.lon_deg[0]), "alt_m": round(h0, 2)}
    if track.start is not None:
        site["date"] = track.start.date()
    data = {
        "format": 1,
        "name": name or stem,
        "description": description or f"imported from {Path(track.source).name}: {route_length / 1000:.2f} km",
        "excites": "a real road's turns and grades",
        "closed": bool(closed),
        "driving": {"default_speed_mps": float(speed_mps), "max_lateral_accel_mps2": float(max_lateral_accel_mps2)},
        "site": site,
        "waypoint": waypoints,
    }
    if zw is not None:
        zmin = float(zw.min())
        site["alt_m"] = round(h0 + zmin, 2)  # the ground plane (z = 0) lies at the lowest point
        zrel = zw - zmin
        if np.ptp(zrel) > 0.05:
            points = np.round(np.column_stack([wx, wy, zrel]), 3).tolist()
            if closed:
                points.append(points[0])
            data["terrain"] = {"feature": [{"type": "road", "points": points, "half_width_m": road_half_width_m,
                                            "shoulder_m": ROAD_SHOULDER_M}]}
    report(0.85, "speeds in curves")
    capped, recorded_lateral, a_lat = _cap_in_curves(data)
    if capped:
        k, recorded, allowed = capped[0]
        more = f" (and {len(capped) - 1} more waypoint(s))" if len(capped) > 1 else ""
        source = (("as recorded", f"the recording corners at up to {recorded_lateral:.1f} m/s², which a larger "
                   "max_lateral_accel_mps2 drives as recorded") if v is not None
                  else ("(speed_mps: the track has no times)", ""))
        warn(f"waypoint[{k}].speed_mps = {recorded:g} m/s {source[0]}{more} is never reached: its leg curves all "
             f"along (radius {allowed ** 2 / a_lat:.1f} m at the widest), which allows at most {allowed:.2f} m/s at "
             f"max_lateral_accel_mps2 = {a_lat:g}; capped to that in the route (the car drives it so anyway"
             + (f"; {source[1]})" if source[1] else ")"))
    report(0.9, "checking the route")
    return ImportedTrack(data=data, length_m=route_length, points_read=n_read, points_used=int(p.x.shape[0]),
                         repeated_dropped=repeated, standing_dropped=standing, stops=tuple(stops),
                         smoothing_m=used_smoothing, height_smoothing_m=used_height, notes=tuple(notes),
                         curve_capped=len(capped))


def _cap_in_curves(data: dict) -> tuple[list[tuple[int, float, float]], float, float]:
    """Cap each waypoint's speed at the fastest its leg may be driven anywhere by the
    curvature limit ``sqrt(max_lateral_accel_mps2/|κ|)`` of the route's own path (the
    bound by which loading a route warns of a speed that is never reached), rounded down to
    the centimetre per second; the speed profile the driver follows stays as it was (it
    drives such a leg at the curvature limit either way). Returns (index, recorded speed,
    the leg's limit) of each waypoint capped, the largest lateral acceleration their
    recorded speeds implied and the lateral limit (m/s²)."""
    from biso_cosim.routes.path import curvature_speed_limit

    # the route's path depends on the waypoints' places alone (the whole route, parsed, is
    # checked when it is loaded); an imported track never reverses, so it has no cusps
    n = len(data["waypoint"])
    path = Route(name=data["name"], description="", closed=data["closed"],
                 waypoints=tuple(Waypoint(w["x_m"], w["y_m"]) for w in data["waypoint"])).path
    a_lat = min(data["driving"]["max_lateral_accel_mps2"], car_limits().lateral_accel_mps2)  # as the route caps it
    allowed = np.full(n, -np.inf)
    np.maximum.at(allowed, path.leg % n, curvature_speed_limit(path, a_lat))
    capped, worst = [], 0.0
    for k, (wp, fastest) in enumerate(zip(data["waypoint"], allowed.tolist())):
        speed = wp["speed_mps"]
        if math.isfinite(fastest) and fastest < speed * (1.0 - 1e-9):
            wp["speed_mps"] = math.floor(fastest * 100.0) / 100.0
            capped.append((k, speed, fastest))
            worst = max(worst, a_lat * (speed / fastest) ** 2)  # v²/R, R = fastest²/a_lat
    return capped, worst, a_lat


def track_to_route_data(track: Track, **options) -> dict:
    """The route-file data (a dict in the TOML schema) for a track (options: ``convert_track``)."""
    return convert_track(track, **options).data


def import_track(path: str | Path, *, max_file_mb: float = MAX_FILE_MB, **options) -> Route:
    """A route from a GPX or CSV track (options: see ``convert_track``)."""
    track = read_track(path, max_file_mb=max_file_mb)
    return parse_route(convert_track(track, **options).data, source=str(path))


def write_route_file(data: dict, path: str | Path) -> Path:
    """Write route-file data as TOML (readable by ``load_route``), atomically (whole or not at all)."""
    import tomli_w

    path = Path(path)
    text = tomli_w.dumps(data)
    with atomic_output(path) as temporary:
        temporary.write_text(text, encoding="utf-8")
    return path
