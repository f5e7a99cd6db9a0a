"""Routes: waypoints, a speed profile, the terrain and the site, read from a TOML file.

Route file format (version 1; every length in metres in the route's local ENU frame,
whose origin is the site's latitude and longitude; unknown keys are errors)::

    format = 1                       # optional
    name = "figure8"                 # required
    description = "one line"         # required: what the route is
    excites = "one line"             # optional: what it excites (turns, grades, bank...)
    closed = true                    # required: the route ends where it starts
    laps = 1                         # optional, closed routes only: drive the loop N times
    tyres = "magic_formula"          # optional: the car's tyre model, "magic_formula"
                                     # (slip-based, biso_cosim.vehicle.tyres; the default)
                                     # or "coulomb" (MuJoCo's friction on sphere wheels)
    surface = "dry"                  # optional, magic_formula tyres only: the road's friction,
                                     # "dry", "wet", "gravel", "snow", "ice" or a scale in
                                     # (0, 1.5] of dry asphalt's (vehicle.tyres.SURFACES)

    [driving]                        # optional; the defaults are shown
    default_speed_mps = 10.0         # leg speed where a waypoint gives none
    max_lateral_accel_mps2 = 2.5     # corner speed limit sqrt(a/|curvature|)
    accel_mps2 = 1.2                 # acceleration limit of the speed profile
    decel_mps2 = 2.0                 # deceleration limit
    start_wait_s = 5.0               # standing still before driving off (initial alignment)

    [site]                           # optional; the defaults are shown (Saratov, the
    lat_deg = 51.53                  # Aleshkin et al. car test)
    lon_deg = 46.03
    alt_m = 50.0
    date = 2024-05-01                # TOML date, for the Earth's magnetic field

    [[waypoint]]                     # two or more
    x_m = 0.0                        # required
    y_m = 0.0                        # required
    speed_mps = 12.0                 # optional: target on the leg from here to the next waypoint
    radius_m = 0.0                   # optional: fillet radius of the corner at this waypoint
    stop_s = 0.0                     # optional: stop here for this long (traffic light)
    reverse = false                  # optional: drive the leg from here to the next backwards

    [terrain]                        # optional: flat ground if absent
    resolution_m = 0.5               # optional: grid of the height-field patches
    [[terrain.feature]]              # see biso_cosim.vehicle.terrain for the types
    type = "hill"
    x_m = 100.0
    y_m = 20.0
    radius_m = 60.0
    height_m = 3.0
    # [[terrain.surface]]            # optional, tyres = "magic_formula" only: a stretch of road
    # x0_m = 300.0                   # with its own surface, from (x0_m, y0_m) to (x1_m, y1_m),
    # y0_m = 0.0                     # width_m wide (default 8 m); surface: a name of
    # x1_m = 340.0                   # vehicle.tyres.SURFACES or a friction scale in (0, 1.5];
    # y1_m = 0.0                     # a later patch lies over an earlier one
    # surface = "snow"

    [[gnss_outage]]                  # optional: where a GNSS receiver has no fix (a tunnel,
    x0_m = 200.0                     # the road under a bridge): within half_width_m of the
    y0_m = 0.0                       # segment from (x0_m, y0_m) to (x1_m, y1_m)
    x1_m = 260.0
    y1_m = 0.0
    half_width_m = 10.0
    label = "underpass"              # optional

The first waypoint of a closed route must not be rounded: the route starts there at rest
and ends there at rest, heading along the first leg (or against it, if that leg is driven in
reverse). Where the direction of travel changes (a cusp: the leg before a waypoint and the
leg after it differ in ``reverse``), the car stops for ``max(stop_s, 1 s)``; a cusp must not
be rounded.

What the car can drive (:func:`biso_cosim.routes.limits.car_limits`) bounds a route: a
fillet tighter than the car's turning radius, or a corner without a fillet that turns by more
than 90° (a closed route of two waypoints turns back by 180°), is refused naming the
waypoint; a target speed above the car's top speed, or ``accel_mps2``, ``decel_mps2`` or
``max_lateral_accel_mps2`` above what the tyres and the drive allow, is capped to the car's
limit with a :class:`RouteWarning` naming the field. In curves the speed profile itself keeps
the target within ``sqrt(max_lateral_accel_mps2/|curvature|)``.
"""

from __future__ import annotations

import datetime
import math
import tomllib
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path as FilePath

import numpy as np

from biso_cosim.routes.limits import MAX_UNROUNDED_TURN_RAD, car_limits
from biso_cosim.routes.path import Path, densify, speed_profile
from biso_cosim.vehicle.terrain import Terrain
from biso_cosim.vehicle.tyres import DEFAULT_TYRE_MODEL

__all__ = ["Route", "Waypoint", "DrivingLimits", "Site", "Stop", "GnssOutageZone", "RouteWarning", "parse_route",
           "read_route_file"]


class RouteWarning(UserWarning):
    """A route (or an imported track) was changed to be drivable: a value capped to the car's
    limit, a track smoothed further than asked."""

SPACING_M = 0.25
"""Spacing of the dense path samples."""

CUSP_DWELL_S = 1.0
"""Shortest halt where the direction of travel changes (selecting the other gear)."""

# A closed route must end within this distance of its start (the closing leg is implicit,
# so only an explicit duplicate of the first waypoint at the end can break this).
_CLOSURE_TOLERANCE_M = 1.0


@dataclass(frozen=True)
class Waypoint:
    x_m: float
    y_m: float
    speed_mps: float | None = None
    radius_m: float = 0.0
    stop_s: float = 0.0
    reverse: bool = False


@dataclass(frozen=True)
class DrivingLimits:
    default_speed_mps: float = 10.0
    max_lateral_accel_mps2: float = 2.5
    accel_mps2: float = 1.2
    decel_mps2: float = 2.0
    start_wait_s: float = 5.0


@dataclass(frozen=True)
class Site:
    """Where the route's local ENU origin lies on Earth (for the magnetic field and GNSS)."""

    lat_deg: float = 51.53
    lon_deg: float = 46.03
    alt_m: float = 50.0
    date: datetime.date = datetime.date(2024, 5, 1)


@dataclass(frozen=True)
class Stop:
    """A halt at arc length ``s_m`` of the path (sample ``index``) for ``dwell_s`` seconds;
    ``cusp`` when the direction of travel changes there."""

    index: int
    s_m: float
    dwell_s: float
    cusp: bool = False


@dataclass(frozen=True)
class GnssOutageZone:
    """Where a GNSS receiver on the route has no fix: within ``half_width_m`` of the segment
    from (x0_m, y0_m) to (x1_m, y1_m) (a tunnel, the road under a bridge)."""

    x0_m: float
    y0_m: float
    x1_m: float
    y1_m: float
    half_width_m: float
    label: str = ""


@dataclass(frozen=True)
class Route:
    name: str
    description: str
    closed: bool
    waypoints: tuple[Waypoint, ...]
    excites: str = ""
    laps: int = 1
    driving: DrivingLimits = field(default_factory=DrivingLimits)
    site: Site = field(default_factory=Site)
    terrain: Terrain = field(default_factory=Terrain)
    gnss_outages: tuple[GnssOutageZone, ...] = ()
    source: str = ""
    tyres: str = DEFAULT_TYRE_MODEL
    """The tyre model the car drives this route with (``vehicle.tyres.TYRE_MODELS``)."""
    surface: str | float = "dry"
    """The road surface (a name of ``vehicle.tyres.SURFACES`` or a friction scale); anything but
    "dry" needs ``tyres = "magic_formula"``."""

    @cached_property
    def path(self) -> Path:
        """The dense path (all laps)."""
        xy = np.array([[w.x_m, w.y_m] for w in self.waypoints])
        radius = np.array([w.radius_m for w in self.waypoints])
        names = [f"waypoint[{i}]" for i in range(len(self.waypoints))]
        if self.laps > 1:
            n = len(self.waypoints)
            xy = np.tile(xy, (self.laps, 1))
            radius = np.tile(radius, self.laps)
            # the start waypoint is passed straight through between laps
            names = [names[i % n] for i in range(xy.shape[0])]
        return densify(xy, radius, self.closed, SPACING_M, names)

    @cached_property
    def _leg_speed(self) -> np.ndarray:
        default = self.driving.default_speed_mps
        speeds = np.array([default if w.speed_mps is None else w.speed_mps for w in self.waypoints])
        return np.tile(speeds, self.laps)

    @cached_property
    def direction(self) -> np.ndarray:
        """+1 where the path is driven forwards, −1 where in reverse, per path sample."""
        backwards = np.array([w.reverse for w in self.waypoints] * self.laps)
        return np.where(backwards[self.path.leg], -1, 1).astype(np.int8)

    def _is_cusp(self, leg_index: int) -> bool:
        n = len(self.waypoints)
        return leg_index > 0 and self.waypoints[leg_index % n].reverse != self.waypoints[(leg_index - 1) % n].reverse

    @cached_property
    def stops(self) -> tuple[Stop, ...]:
        """Intermediate stops (traffic lights, cusps) in driving order, then the final stop
        (dwell ∞) at the end."""
        path = self.path
        n = len(self.waypoints)
        out = []
        for leg_index in range(1, n * self.laps):
            wp = self.waypoints[leg_index % n]
            dwell = max(wp.stop_s, CUSP_DWELL_S) if self._is_cusp(leg_index) else wp.stop_s
            if dwell > 0.0:
                # the leg of waypoint k starts at waypoint k: its first sample
                index = int(np.flatnonzero(path.leg == leg_index)[0])
                out.append(Stop(index=index, s_m=float(path.s_m[index]), dwell_s=dwell,
                                cusp=self._is_cusp(leg_index)))
        last = len(path) - 1
        out.append(Stop(index=last, s_m=float(path.s_m[last]), dwell_s=math.inf))
        return tuple(out)

    @cached_property
    def speed_free_mps(self) -> np.ndarray:
        """Target speed along the path ignoring stops: the driver adds the stops (the end of the
        route is one) and the ramp from rest."""
        d = self.driving
        return speed_profile(self.path, self._leg_speed, max_lateral_accel_mps2=d.max_lateral_accel_mps2,
                             accel_mps2=d.accel_mps2, decel_mps2=d.decel_mps2, cusps=self._cusp_indices)

    @cached_property
    def speed_with_stops_mps(self) -> np.ndarray:
        """Target speed along the path, at rest at every stop."""
        d = self.driving
        return speed_profile(self.path, self._leg_speed, max_lateral_accel_mps2=d.max_lateral_accel_mps2,
                             accel_mps2=d.accel_mps2, decel_mps2=d.decel_mps2,
                             zero_at=(0, *(s.index for s in self.stops)), cusps=self._cusp_indices)

    @property
    def _cusp_indices(self) -> tuple[int, ...]:
        return tuple(s.index for s in self.stops if s.cusp)

    @cached_property
    def nominal_duration_s(self) -> float:
        """Time to drive the route along its speed profile, stops included."""
        v = self.speed_with_stops_mps
        ds = np.diff(self.path.s_m)
        mean = 0.5 * (v[:-1] + v[1:])
        drive = float(np.sum(ds / np.maximum(mean, 1e-3)))
        return self.driving.start_wait_s + drive + sum(s.dwell_s for s in self.stops[:-1])

    @property
    def start_xy_yaw(self) -> tuple[float, float, float]:
        """Start position (m) and yaw (rad, CCW from East) of the car (its rear axle)."""
        p = self.path
        yaw = float(p.heading_rad[0]) + (math.pi if self.direction[0] < 0 else 0.0)
        return float(p.x_m[0]), float(p.y_m[0]), yaw

    def summary(self) -> dict:
        return {
            "name": self.name,
            "description": self.description,
            "excites": self.excites,
            "closed": self.closed,
            "laps": self.laps,
            "length_m": round(self.path.length_m, 1),
            "nominal_duration_s": round(self.nominal_duration_s, 1),
            "stops": len(self.stops) - 1,
            "reversing": bool((self.direction < 0).any()),
            "terrain_features": len(self.terrain.features),
            "gnss_outages": len(self.gnss_outages),
            "tyres": self.tyres,
            "surface": self.surface,
        }


# --------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------

_TOP_KEYS = {"format", "name", "description", "excites", "closed", "laps", "tyres", "surface", "driving", "site",
             "waypoint", "terrain", "gnss_outage"}


def _number(value, where: str, *, minimum: float | None = None, strict: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{where} must be a finite number, got {value!r}")
    if minimum is not None and (value < minimum or (strict and value == minimum)):
        relation = ">" if strict else ">="
        raise ValueError(f"{where} must be {relation} {minimum}, got {value!r}")
    return float(value)


def _table(data: dict, key: str, cls, where: str, checks: dict) -> object:
    table = data.get(key, {})
    if not isinstance(table, dict):
        raise ValueError(f"{where}: [{key}] must be a table")
    known = set(cls.__dataclass_fields__)
    unknown = set(table) - known
    if unknown:
        raise ValueError(f"{where}: unknown key(s) in [{key}]: {sorted(unknown)}; expected {sorted(known)}")
    values = {}
    for name, value in table.items():
        check = checks.get(name)
        values[name] = check(value, f"{where}: {key}.{name}") if check else value
    return cls(**values)


def _date(value, where: str) -> datetime.date:
    if isinstance(value, datetime.datetime):
        return value.date()
    if isinstance(value, datetime.date):
        return value
    raise ValueError(f"{where} must be a TOML date like 2024-05-01, got {value!r}")


def parse_route(data: dict, source: str = "<route>") -> Route:
    """Build a Route from the parsed TOML ``data``; errors name the file and the field."""
    where = source
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {sorted(unknown)}; expected {sorted(_TOP_KEYS)}")
    if data.get("format", 1) != 1:
        raise ValueError(f"{where}: format must be 1, got {data.get('format')!r}")
    for key in ("name", "description", "closed"):
        if key not in data:
            raise ValueError(f"{where}: missing required key {key!r}")
    for key in ("name", "description", "excites"):
        if key in data and not isinstance(data[key], str):
            raise ValueError(f"{where}: {key} must be a string, got {data[key]!r}")
    if not isinstance(data["closed"], bool):
        raise ValueError(f"{where}: closed must be true or false, got {data['closed']!r}")
    closed = data["closed"]
    laps = data.get("laps", 1)
    if isinstance(laps, bool) or not isinstance(laps, int) or laps < 1:
        raise ValueError(f"{where}: laps must be an integer >= 1, got {laps!r}")
    if laps > 1 and not closed:
        raise ValueError(f"{where}: laps > 1 needs a closed route")

    tyres, surface = _tyres_and_surface(data, where)

    positive = lambda v, w: _number(v, w, minimum=0.0, strict=True)  # noqa: E731
    driving = _table(data, "driving", DrivingLimits, where, {
        "default_speed_mps": positive, "max_lateral_accel_mps2": positive,
        "accel_mps2": positive, "decel_mps2": positive,
        "start_wait_s": lambda v, w: _number(v, w, minimum=0.0),
    })
    site = _table(data, "site", Site, where, {
        "lat_deg": lambda v, w: _latitude(v, w), "lon_deg": lambda v, w: _longitude(v, w),
        "alt_m": lambda v, w: _number(v, w), "date": _date,
    })

    raw_waypoints = data.get("waypoint")
    if not isinstance(raw_waypoints, list) or len(raw_waypoints) < 2:
        raise ValueError(f"{where}: a route needs at least two [[waypoint]] tables")
    waypoints = []
    known = set(Waypoint.__dataclass_fields__)
    for i, wp in enumerate(raw_waypoints):
        label = f"{where}: waypoint[{i}]"
        if not isinstance(wp, dict):
            raise ValueError(f"{label} must be a table ([[waypoint]] with x_m, y_m, ...), got {wp!r}")
        unknown = set(wp) - known
        if unknown:
            raise ValueError(f"{label}: unknown key(s) {sorted(unknown)}; expected {sorted(known)}")
        for key in ("x_m", "y_m"):
            if key not in wp:
                raise ValueError(f"{label}: missing {key}")
        waypoints.append(Waypoint(
            x_m=_number(wp["x_m"], f"{label}.x_m"),
            y_m=_number(wp["y_m"], f"{label}.y_m"),
            speed_mps=None if "speed_mps" not in wp else _number(wp["speed_mps"], f"{label}.speed_mps", minimum=0.0, strict=True),
            radius_m=_number(wp.get("radius_m", 0.0), f"{label}.radius_m", minimum=0.0),
            stop_s=_number(wp.get("stop_s", 0.0), f"{label}.stop_s", minimum=0.0),
            reverse=_boolean(wp.get("reverse", False), f"{label}.reverse"),
        ))
    for i in range(1, len(waypoints)):
        if waypoints[i].reverse != waypoints[i - 1].reverse and waypoints[i].radius_m > 0.0:
            raise ValueError(f"{where}: waypoint[{i}] changes the direction of travel (reverse), "
                             "so it must not be rounded: set radius_m = 0")
    if closed:
        if waypoints[0].radius_m > 0.0:
            raise ValueError(f"{where}: waypoint[0].radius_m must be 0 on a closed route (it starts and ends there)")
        first, last = waypoints[0], waypoints[-1]
        if math.hypot(first.x_m - last.x_m, first.y_m - last.y_m) < _CLOSURE_TOLERANCE_M:
            raise ValueError(f"{where}: a closed route returns to waypoint[0] by itself; "
                             f"remove the last waypoint, which repeats the first")
    else:
        last = len(waypoints) - 1
        for end in (0, last):
            if waypoints[end].radius_m > 0.0:
                raise ValueError(f"{where}: waypoint[{end}].radius_m must be 0 at the ends of an open route")
        if waypoints[last].stop_s > 0.0:
            raise ValueError(f"{where}: waypoint[{last}].stop_s: an open route ends at its last waypoint, where "
                             "the car stops for good; a stop there has no meaning")
        if waypoints[last].reverse != waypoints[last - 1].reverse:
            raise ValueError(f"{where}: waypoint[{last}].reverse: the last waypoint of an open route has no leg "
                             "of its own, so it cannot change the direction of travel")

    terrain_data = data.get("terrain", {})
    if not isinstance(terrain_data, dict):
        raise ValueError(f"{where}: [terrain] must be a table")
    unknown = set(terrain_data) - {"resolution_m", "feature", "surface"}
    if unknown:
        raise ValueError(f"{where}: unknown key(s) in [terrain]: {sorted(unknown)}; expected ['feature', "
                         "'resolution_m', 'surface']")
    resolution = _number(terrain_data.get("resolution_m", 0.5), f"{where}: terrain.resolution_m", minimum=0.0, strict=True)
    terrain = Terrain.from_dict(terrain_data.get("feature", []), resolution_m=resolution, where=f"{where}: terrain.feature")
    surfaces = Terrain.surfaces_from_dict(terrain_data.get("surface", []), where=f"{where}: terrain.surface")
    if surfaces and tyres == "coulomb":
        raise ValueError(f"{where}: terrain.surface needs tyres = \"magic_formula\" (the coulomb tyres have one "
                         "friction everywhere)")
    terrain = replace(terrain, surfaces=surfaces)

    outages = []
    raw_outages = data.get("gnss_outage", [])
    if not isinstance(raw_outages, list):
        raise ValueError(f"{where}: gnss_outage must be an array of tables ([[gnss_outage]])")
    known = set(GnssOutageZone.__dataclass_fields__)
    for i, zone in enumerate(raw_outages):
        label = f"{where}: gnss_outage[{i}]"
        if not isinstance(zone, dict):
            raise ValueError(f"{label} must be a table")
        unknown = set(zone) - known
        missing = known - set(zone) - {"label"}
        if unknown or missing:
            raise ValueError(f"{label}: unknown key(s) {sorted(unknown)}, missing {sorted(missing)}; "
                             f"expected {sorted(known)}")
        outages.append(GnssOutageZone(
            **{k: _number(zone[k], f"{label}.{k}") for k in ("x0_m", "y0_m", "x1_m", "y1_m")},
            half_width_m=_number(zone["half_width_m"], f"{label}.half_width_m", minimum=0.0, strict=True),
            label=str(zone.get("label", ""))))

    driving, waypoints = _within_car_limits(driving, waypoints, closed, laps, where)
    route = Route(name=data["name"], description=data["description"], excites=data.get("excites", ""),
                  closed=closed, laps=laps, waypoints=tuple(waypoints), driving=driving, site=site,
                  terrain=terrain, gnss_outages=tuple(outages), source=source, tyres=tyres, surface=surface)
    route.path  # noqa: B018 -- build now so that geometry errors surface at load time
    _warn_curvature_caps(route, where)
    return route


def _warn_curvature_caps(route: "Route", where: str) -> None:
    """A RouteWarning naming each waypoint whose own ``speed_mps`` the curvature of its leg
    caps everywhere on the leg (the speed profile drives curves at
    ``sqrt(max_lateral_accel_mps2/|κ|)``), so that the speed asked for is never driven; with
    the speed the leg allows. One warning for a route, the first waypoint named and the
    others counted. A leg that slows only in the curve at its end, and legs at the default
    speed, are capped silently: that is what the profile is for."""
    from biso_cosim.routes.path import curvature_speed_limit

    path = route.path
    n = len(route.waypoints)
    limit = curvature_speed_limit(path, route.driving.max_lateral_accel_mps2, route._cusp_indices)
    # the fastest each leg may be driven anywhere on it (-inf: no path point on the leg)
    leg_fastest = np.full(n, -np.inf)
    np.maximum.at(leg_fastest, path.leg % n, limit)
    capped = []
    for k, wp in enumerate(route.waypoints):
        allowed = float(leg_fastest[k])
        if wp.speed_mps is not None and np.isfinite(allowed) and allowed < wp.speed_mps * (1.0 - 1e-9):
            capped.append((k, wp.speed_mps, allowed))
    if capped:
        k, speed, allowed = capped[0]
        more = f" (and {len(capped) - 1} more waypoint(s))" if len(capped) > 1 else ""
        radius = allowed ** 2 / route.driving.max_lateral_accel_mps2
        warnings.warn(f"{where}: waypoint[{k}].speed_mps = {speed:g} m/s{more} is never reached: its leg curves "
                      f"all along (radius {radius:.1f} m at the widest), which allows at most {allowed:.1f} m/s at "
                      f"max_lateral_accel_mps2 = {route.driving.max_lateral_accel_mps2:g}; capped to that",
                      RouteWarning, stacklevel=3)


def _within_car_limits(driving: DrivingLimits, waypoints: list[Waypoint], closed: bool, laps: int,
                       where: str) -> tuple[DrivingLimits, list[Waypoint]]:
    """The driving limits and waypoints capped to what the car can do (with a RouteWarning per
    field); ValueError naming the waypoint for a corner the car cannot take."""
    car = car_limits()
    n = len(waypoints)
    for i, wp in enumerate(waypoints):
        if 0.0 < wp.radius_m < car.turning_radius_m:
            raise ValueError(f"{where}: waypoint[{i}].radius_m = {wp.radius_m:g} m is tighter than the car's "
                             f"turning radius of {car.turning_radius_m:.2f} m")
    # unrounded corners that are not cusps; a closed route's start corner only if the car
    # drives through it (laps > 1)
    xy = np.array([[w.x_m, w.y_m] for w in waypoints])
    into = xy - np.roll(xy, 1, axis=0)  # the leg arriving at each waypoint
    out = np.roll(xy, -1, axis=0) - xy  # the leg leaving it
    turn = np.abs(np.arctan2(into[:, 0] * out[:, 1] - into[:, 1] * out[:, 0], np.einsum("ij,ij->i", into, out)))
    reverse = np.array([w.reverse for w in waypoints])
    candidate = ((np.array([w.radius_m for w in waypoints]) == 0.0) & (reverse == np.roll(reverse, 1))
                 & (np.hypot(*into.T) > 0.0) & (np.hypot(*out.T) > 0.0) & (turn > MAX_UNROUNDED_TURN_RAD + 1e-9))
    if not closed:
        candidate[[0, n - 1]] = False
    elif laps == 1:
        candidate[0] = False
    if candidate.any():
        i = int(np.flatnonzero(candidate)[0])
        raise ValueError(f"{where}: waypoint[{i}] turns by {math.degrees(turn[i]):.0f}° without a fillet; the car "
                         f"takes at most {math.degrees(MAX_UNROUNDED_TURN_RAD):.0f}° that way: give it a "
                         f"radius_m of at least {car.turning_radius_m:.1f} m, add waypoints, or make the car "
                         "stop and reverse there")
    capped = {}
    for name, limit, what in (("default_speed_mps", car.top_speed_mps, "top speed"),
                              ("accel_mps2", car.accel_mps2, "largest acceleration"),
                              ("decel_mps2", car.decel_mps2, "largest braking deceleration"),
                              ("max_lateral_accel_mps2", car.lateral_accel_mps2, "largest lateral acceleration")):
        value = getattr(driving, name)
        if value > limit:
            warnings.warn(f"{where}: driving.{name} = {value:g} is beyond the car's {what} ({limit:.2f}); "
                          f"capped to it", RouteWarning, stacklevel=3)
            capped[name] = limit
    if capped:
        driving = replace(driving, **capped)
    fast = [i for i, wp in enumerate(waypoints) if wp.speed_mps is not None and wp.speed_mps > car.top_speed_mps]
    if fast:
        i = fast[0]
        more = f" (and {len(fast) - 1} more waypoint(s))" if len(fast) > 1 else ""
        warnings.warn(f"{where}: waypoint[{i}].speed_mps = {waypoints[i].speed_mps:g} m/s{more} is beyond the car's "
                      f"top speed ({car.top_speed_mps:.1f} m/s); capped to it", RouteWarning, stacklevel=3)
        waypoints = [replace(wp, speed_mps=car.top_speed_mps) if k in fast else wp for k, wp in enumerate(waypoints)]
    # reverse legs: the reverse gear's top speed
    leg = [driving.default_speed_mps if wp.speed_mps is None else wp.speed_mps for wp in waypoints]
    backwards = [i for i, wp in enumerate(waypoints) if wp.reverse and leg[i] > car.reverse_top_speed_mps]
    if backwards:
        i = backwards[0]
        more = f" (and {len(backwards) - 1} more waypoint(s))" if len(backwards) > 1 else ""
        warnings.warn(f"{where}: waypoint[{i}] reverses at {leg[i]:g} m/s{more}, beyond the car's top speed in "
                      f"reverse ({car.reverse_top_speed_mps:.1f} m/s, the reverse gear at the rev limit); capped to it",
                      RouteWarning, stacklevel=3)
        waypoints = [replace(wp, speed_mps=car.reverse_top_speed_mps) if k in backwards else wp
                     for k, wp in enumerate(waypoints)]
        leg = [car.reverse_top_speed_mps if k in backwards else v for k, v in enumerate(leg)]
    # the route's acceleration near each leg's speed: more than the engine's power gives there
    # and the car reaches the speed later than the profile (the driver's speed command ramps
    # at what the car can do, see vehicle.driver)
    slow = [i for i, wp in enumerate(waypoints)
            if not wp.reverse and driving.accel_mps2 > car.full_throttle_accel_mps2(leg[i])]
    if slow:
        i = slow[0]
        more = f" (and {len(slow) - 1} more waypoint(s))" if len(slow) > 1 else ""
        warnings.warn(f"{where}: waypoint[{i}]: at its speed of {leg[i]:g} m/s{more} the car accelerates at most "
                      f"{car.full_throttle_accel_mps2(leg[i]):.2f} m/s² at full throttle, less than driving.accel_mps2 = "
                      f"{driving.accel_mps2:g}: it reaches the speed later than the profile says", RouteWarning,
                      stacklevel=3)
    return driving, waypoints


def _tyres_and_surface(data: dict, where: str) -> tuple[str, str | float]:
    """The route's ``tyres`` and ``surface``, checked: one line naming the field and what it
    may be for a bad value."""
    from biso_cosim.vehicle.tyres import SURFACES, TYRE_MODELS, surface_friction

    tyres = data.get("tyres", DEFAULT_TYRE_MODEL)
    if tyres not in TYRE_MODELS or not isinstance(tyres, str):
        raise ValueError(f"{where}: tyres must be one of {', '.join(repr(t) for t in TYRE_MODELS)}, got {tyres!r}")
    surface = data.get("surface", "dry")
    allowed = f"one of {', '.join(repr(s) for s in SURFACES)} or a friction scale in (0, 1.5]"
    if isinstance(surface, bool) or not isinstance(surface, (str, int, float)):
        raise ValueError(f"{where}: surface must be {allowed}, got {surface!r}")
    try:
        surface_friction(surface)
    except ValueError:
        raise ValueError(f"{where}: surface must be {allowed}, got {surface!r}") from None
    surface = surface if isinstance(surface, str) else float(surface)
    if tyres == "coulomb" and surface != "dry":
        raise ValueError(f"{where}: surface = {surface!r} needs tyres = \"magic_formula\" (the coulomb tyres "
                         "drive on dry asphalt only)")
    return tyres, surface


def _boolean(value, where: str) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{where} must be true or false, got {value!r}")
    return value


def _latitude(value, where):
    v = _number(value, where)
    if not -90.0 <= v <= 90.0:
        raise ValueError(f"{where} must be in [-90, 90] degrees, got {v}")
    return v


def _longitude(value, where):
    v = _number(value, where)
    if not -180.0 <= v <= 360.0:
        raise ValueError(f"{where} must be in [-180, 360] degrees, got {v}")
    return v


def read_route_file(path: str | FilePath) -> Route:
    """Read and validate a route file."""
    path = FilePath(path)
    if path.is_dir():
        raise ValueError(f"{path} is a directory; expected a .toml route file")
    try:
        with path.open("rb") as handle:
            data = tomllib.load(handle)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.start}); expected a TOML route file") from None
    return parse_route(data, source=str(path))
