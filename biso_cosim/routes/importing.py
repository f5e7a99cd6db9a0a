"""Real routes: a GPX track or a CSV of latitude/longitude(/height)(/speed) becomes a route.

The track's points are converted to the local ENU frame of its first point (WGS-84, with
pymap3d), resampled every ``spacing_m`` along the track and smoothed over ``smoothing_m`` (a
consumer GNSS track jitters by metres, which would otherwise read as sharp curvature). The
route's site (latitude, longitude, height; date from the track's first time stamp, else the
default) sets the Earth's magnetic field and the GNSS location. Speeds come from the data
(a ``speed_mps`` column, or GPX time stamps) when present, else from ``speed_mps``; either
way the driver slows for curvature (``max_lateral_accel_mps2``). Heights, when present,
become a ``road`` terrain feature along the track, relative to its lowest point. A track
that ends within ``close_within_m`` of its start becomes a closed route.

CSV columns (header required, any order): ``lat_deg``, ``lon_deg`` and optionally ``alt_m``
(height above the WGS-84 ellipsoid), ``speed_mps``, ``t_s``.

Errors name the file and the line (CSV) or the element (GPX: XML syntax errors by line, bad
points by line through a second look at the XML).
"""

from __future__ import annotations

import csv
import datetime
import math
import xml.parsers.expat
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from biso_cosim.routes.route import Route, parse_route

__all__ = ["Track", "read_track", "track_to_route_data", "import_track", "write_route_file"]


@dataclass(frozen=True)
class Track:
    """Points of a recorded track, in file order."""

    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray | None
    speed_mps: np.ndarray | None
    t_s: np.ndarray | None
    start: datetime.datetime | None
    source: str


def _bad_gpx_point_line(text: str) -> str:
    """Where the first track/route point with a missing or bad lat/lon is (for gpxpy's errors,
    which do not say)."""
    found: list[str] = []

    def start(name, attrs):
        if found or name not in ("trkpt", "rtept", "wpt"):
            return
        for key, low, high in (("lat", -90.0, 90.0), ("lon", -180.0, 360.0)):
            value = attrs.get(key)
            try:
                ok = value is not None and low <= float(value) <= high
            except ValueError:
                ok = False
            if not ok:
                found.append(f"line {parser.CurrentLineNumber}: <{name}> has {key}={value!r} "
                             f"(expected a number in [{low:g}, {high:g}])")
                return

    parser = xml.parsers.expat.ParserCreate()
    parser.StartElementHandler = start
    try:
        parser.Parse(text, True)
    except xml.parsers.expat.ExpatError:
        pass
    return found[0] if found else "a point is not valid"


def _read_gpx(path: Path) -> Track:
    import gpxpy
    import gpxpy.gpx

    text = path.read_text(encoding="utf-8", errors="replace")
    try:
        gpx = gpxpy.parse(text)
    except gpxpy.gpx.GPXXMLSyntaxException as exc:
        raise ValueError(f"{path}: not valid XML: {exc}") from None
    except gpxpy.gpx.GPXException as exc:
        raise ValueError(f"{path}: {_bad_gpx_point_line(text)} ({exc})") from None
    points = [pt for trk in gpx.tracks for seg in trk.segments for pt in seg.points]
    kind = "track points <trkpt>"
    if len(points) < 2:
        points = [pt for rte in gpx.routes for pt in rte.points]
        kind = "route points <rtept>"
    if len(points) < 2:
        raise ValueError(f"{path}: a route needs at least two track points (<trkpt>) or route points (<rtept>)")
    lat = np.array([p.latitude for p in points], dtype=np.float64)
    lon = np.array([p.longitude for p in points], dtype=np.float64)
    alts = [p.elevation for p in points]
    alt = None
    if any(a is not None for a in alts):
        missing = [i for i, a in enumerate(alts) if a is None]
        if missing:
            raise ValueError(f"{path}: {kind} number {missing[0] + 1} has no <ele> while others have one")
        alt = np.array(alts, dtype=np.float64)
    times = [p.time for p in points]
    t_s, start = None, None
    if all(t is not None for t in times):
        start = times[0]
        t_s = np.array([(t - start).total_seconds() for t in times])
        back = np.flatnonzero(np.diff(t_s) < 0)
        if back.size:
            raise ValueError(f"{path}: the <time> of {kind} number {back[0] + 2} is earlier than the one before")
    return Track(lat, lon, alt, None, t_s, start, str(path))


def _read_csv(path: Path) -> Track:
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.reader(handle)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise ValueError(f"{path}: the file is empty") from None
        for needed in ("lat_deg", "lon_deg"):
            if needed not in header:
                raise ValueError(f"{path}, line 1: missing column {needed!r}; columns are lat_deg, lon_deg "
                                 "and optionally alt_m, speed_mps, t_s")
        columns = [c for c in ("lat_deg", "lon_deg", "alt_m", "speed_mps", "t_s") if c in header]
        index = [header.index(c) for c in columns]
        rows = []
        for line_no, row in enumerate(reader, start=2):
            if not row or all(not cell.strip() for cell in row):
                continue
            try:
                values = [float(row[i]) for i in index]
            except (ValueError, IndexError):
                raise ValueError(f"{path}, line {line_no}: expected numbers in columns {columns}, got {row}") from None
            if not all(math.isfinite(v) for v in values):
                raise ValueError(f"{path}, line {line_no}: values must be finite, got {row}")
            lat, lon = values[0], values[1]
            if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0):
                raise ValueError(f"{path}, line {line_no}: lat_deg must be in [-90, 90] and lon_deg in "
                                 f"[-180, 360], got {lat}, {lon}")
            if "speed_mps" in columns and values[columns.index("speed_mps")] < 0.0:
                raise ValueError(f"{path}, line {line_no}: speed_mps must be >= 0")
            if "t_s" in columns and rows and values[columns.index("t_s")] < rows[-1][0][columns.index("t_s")]:
                raise ValueError(f"{path}, line {line_no}: t_s is earlier than on the line before")
            rows.append((values, line_no))
    if len(rows) < 2:
        raise ValueError(f"{path}: a route needs at least two points")
    data = np.array([r[0] for r in rows])
    col = {c: data[:, k] for k, c in enumerate(columns)}
    return Track(col["lat_deg"], col["lon_deg"], col.get("alt_m"), col.get("speed_mps"), col.get("t_s"), None,
                 str(path))


def read_track(path: str | Path) -> Track:
    """Read a ``.gpx`` or ``.csv`` track (see the module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"track file {str(path)!r} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".gpx":
        return _read_gpx(path)
    if suffix == ".csv":
        return _read_csv(path)
    raise ValueError(f"{path}: expected a .gpx or .csv track, got {suffix or 'no extension'!r}")


def _smooth(values: np.ndarray, half: int, circular: bool) -> np.ndarray:
    """Centred moving average over 2·half + 1 samples: around the loop for a closed track,
    with a window that shrinks towards the ends for an open one (so the ends stay put)."""
    if half <= 0:
        return values.copy()
    n = values.shape[0]
    if circular:
        padded = np.concatenate([values[-half:], values, values[:half]])
        kernel = np.ones(2 * half + 1) / (2 * half + 1)
        return np.convolve(padded, kernel, mode="valid")
    csum = np.concatenate([[0.0], np.cumsum(values)])
    out = np.empty(n)
    for i in range(n):
        h = min(half, i, n - 1 - i)
        out[i] = (csum[i + h + 1] - csum[i - h]) / (2 * h + 1)
    return out


def _resample(s: np.ndarray, values: np.ndarray, spacing_m: float, closed: bool) -> np.ndarray:
    """Columns of ``values`` at every ``spacing_m`` of arc length ``s`` (a closed track's last
    sample, which would repeat its first, is left out)."""
    count = max(int(round(s[-1] / spacing_m)), 1)
    grid = np.linspace(0.0, s[-1], count + 1)
    if closed:
        grid = grid[:-1]
    return np.column_stack([np.interp(grid, s, values[:, k]) for k in range(values.shape[1])])


def track_to_route_data(track: Track, *, name: str | None = None, description: str | None = None,
                        speed_mps: float = 10.0, max_lateral_accel_mps2: float = 2.5,
                        spacing_m: float = 5.0, smoothing_m: float = 15.0, height_smoothing_m: float = 60.0,
                        close_within_m: float = 15.0, road_half_width_m: float = 4.0) -> dict:
    """The route-file data (a dict in the TOML schema) for a track.

    Positions and speeds are smoothed over ``smoothing_m``, heights over the longer
    ``height_smoothing_m`` (GNSS heights scatter by metres; over 60 m a scatter of ±3 m still
    reads as a ±5 % grade, so heights are best taken from a map where that matters).
    """
    import pymap3d

    for label, value in (("speed_mps", speed_mps), ("max_lateral_accel_mps2", max_lateral_accel_mps2),
                         ("spacing_m", spacing_m), ("close_within_m", close_within_m),
                         ("road_half_width_m", road_half_width_m)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{label} must be a positive number, got {value!r}")
    for label, value in (("smoothing_m", smoothing_m), ("height_smoothing_m", height_smoothing_m)):
        if not (math.isfinite(value) and value >= 0.0):
            raise ValueError(f"{label} must be >= 0, got {value!r}")
    h = track.alt_m if track.alt_m is not None else np.zeros_like(track.lat_deg)
    e, n, _ = pymap3d.geodetic2enu(track.lat_deg, track.lon_deg, h, track.lat_deg[0], track.lon_deg[0], h[0])
    # heights from the ellipsoidal heights themselves: ENU "up" drops with the Earth's
    # curvature (7.8 m over 10 km), which is not a grade of the road
    xyz = np.column_stack([e, n, h - h[0]])
    step = np.hypot(np.diff(xyz[:, 0]), np.diff(xyz[:, 1]))
    s = np.concatenate([[0.0], np.cumsum(step)])
    if s[-1] < 2.0 * spacing_m:
        raise ValueError(f"{track.source}: the track is only {s[-1]:.1f} m long")
    keep = np.concatenate([[True], step > 1e-6])  # drop repeated points (a parked receiver)
    speed = track.speed_mps
    if speed is None and track.t_s is not None:
        dt = np.diff(track.t_s)
        with np.errstate(divide="ignore", invalid="ignore"):
            v = np.where(dt > 0, step / dt, np.nan)
        v = np.concatenate([v[:1], 0.5 * (v[:-1] + v[1:]), v[-1:]]) if v.size > 1 else np.array([v[0], v[0]])
        speed = np.where(np.isfinite(v), v, speed_mps)
    closed = math.hypot(xyz[-1, 0] - xyz[0, 0], xyz[-1, 1] - xyz[0, 1]) <= close_within_m
    if closed:  # a logger often repeats the start at the end: leave those points out
        back_home = np.hypot(xyz[:, 0] - xyz[0, 0], xyz[:, 1] - xyz[0, 1]) < 0.5 * spacing_m
        tail = len(back_home) - np.argmin(back_home[::-1]) if not back_home.all() else len(back_home)
        keep[tail:] = False
    columns = [xyz[keep], (speed[keep, None] if speed is not None else np.zeros((keep.sum(), 0)))]
    sk, table = s[keep], np.hstack(columns)
    if closed:  # close the loop exactly: the route returns to its first point by itself
        sk = np.append(sk, sk[-1] + math.hypot(xyz[-1, 0] - xyz[0, 0], xyz[-1, 1] - xyz[0, 1]))
        table = np.vstack([table, table[:1]])
    # resample, smooth the positions, then resample along the smoothed path, so that the
    # spacing is even on the road itself (jitter lengthens the raw track) and heights are
    # smoothed over true distance
    res = _resample(sk, table, spacing_m, closed)
    half = int(round(0.5 * smoothing_m / spacing_m))
    res[:, 0], res[:, 1] = _smooth(res[:, 0], half, closed), _smooth(res[:, 1], half, closed)
    if closed:
        res = np.vstack([res, res[:1]])
    s_road = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(res[:, 0]), np.diff(res[:, 1])))])
    res = _resample(s_road, res, spacing_m, closed)
    x, y = res[:, 0], res[:, 1]
    z = _smooth(res[:, 2], int(round(0.5 * height_smoothing_m / spacing_m)), closed)
    v = np.clip(_smooth(res[:, 3], half, closed), 1.0, None) if speed is not None else None
    stem = Path(track.source).stem
    waypoints = []
    for i in range(x.shape[0]):
        wp = {"x_m": round(float(x[i]), 3), "y_m": round(float(y[i]), 3)}
        wp["speed_mps"] = round(float(v[i]), 2) if v is not None else float(speed_mps)
        waypoints.append(wp)
    site = {"lat_deg": float(track.lat_deg[0]), "lon_deg": float(track.lon_deg[0]), "alt_m": float(h[0])}
    if track.start is not None:
        site["date"] = track.start.date()
    data = {
        "format": 1,
        "name": name or stem,
        "description": description or f"imported from {Path(track.source).name}: {s[-1] / 1000:.2f} km",
        "excites": "a real road's turns and grades",
        "closed": bool(closed),
        "driving": {"default_speed_mps": float(speed_mps), "max_lateral_accel_mps2": float(max_lateral_accel_mps2)},
        "site": site,
        "waypoint": waypoints,
    }
    if track.alt_m is not None:
        zrel = z - z.min()
        if np.ptp(zrel) > 0.05:
            points = [[round(float(a), 3), round(float(b), 3), round(float(c), 3)] for a, b, c in zip(x, y, zrel)]
            if closed:
                points.append(points[0])
            data["terrain"] = {"feature": [{"type": "road", "points": points, "half_width_m": road_half_width_m}]}
    return data


def import_track(path: str | Path, **options) -> Route:
    """A route from a GPX or CSV track (options: see ``track_to_route_data``)."""
    track = read_track(path)
    return parse_route(track_to_route_data(track, **options), source=str(path))


def write_route_file(data: dict, path: str | Path) -> Path:
    """Write route-file data as TOML (readable by ``load_route``)."""
    import tomli_w

    path = Path(path)
    path.write_text(tomli_w.dumps(data))
    return path
