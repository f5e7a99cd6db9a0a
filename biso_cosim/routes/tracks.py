"""Recorded tracks: GPX files and CSV tables of latitude/longitude(/height)(/speed)(/time).

``read_track(path)`` returns the points in file order as a :class:`Track`, every point checked:
latitude in [-90, 90]°, longitude in [-180, 360]°, height (if any) in [-500, 9000] m, times
(if any) parseable and never going back. Errors are one line naming the file, the line and
the point (``my.gpx, line 812: track point 802 has lat=149.4; expected a latitude in [-90,
90] degrees``). The file itself is checked first: it must exist, be a regular file no larger
than ``max_file_mb``, and be text (a binary file is named as such).

GPX is read with the standard library's streaming XML parser (expat), which gives each
point's line for the messages and keeps long 10 Hz tracks within the import's time budget
(benchmarks/route_import.py); gpxpy builds Python objects per point, too slow for them. Track points (``<trkpt>``,
all tracks and segments in order) are used, else route points (``<rtept>``); ``<ele>`` and
``<time>`` are read, other elements ignored. Times are UTC (ISO 8601; a time without a zone
is taken as UTC, as GPX prescribes).

CSV columns (header required, any order): ``lat_deg``, ``lon_deg`` and optionally ``alt_m``
(height above the WGS-84 ellipsoid), ``speed_mps``, ``t_s`` (seconds, any origin).
"""

from __future__ import annotations

import csv
import datetime
import io
import xml.parsers.expat
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Track", "read_track", "MAX_FILE_MB", "check_track_file"]

MAX_FILE_MB = 200.0
"""Largest track file read by default (a 10 Hz GPX track takes about 110 bytes a point: 200 MB is
some 500 hours of driving)."""

LAT_RANGE_DEG = (-90.0, 90.0)
LON_RANGE_DEG = (-180.0, 360.0)
ALT_RANGE_M = (-500.0, 9000.0)  # the Dead Sea shore to above the highest road
_CHUNK_BYTES = 1 << 20

Progress = Callable[[float], None]
"""Called with the fraction of the file read so far."""


@dataclass(frozen=True)
class Track:
    """Points of a recorded track, in file order; ``line`` and ``kind`` say where each came from."""

    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray | None
    speed_mps: np.ndarray | None
    t_s: np.ndarray | None
    start: datetime.datetime | None
    source: str
    line: np.ndarray | None = None
    kind: str = "point"

    def __len__(self) -> int:
        return self.lat_deg.shape[0]

    def where(self, i: int) -> str:
        """Where point ``i`` (0-based) is in its file, for messages: 'f.gpx, line 12: track point 3'."""
        line = f", line {int(self.line[i])}" if self.line is not None else ""
        return f"{self.source}{line}: {self.kind} {i + 1}"


def check_track_file(path: Path, max_file_mb: float = MAX_FILE_MB) -> None:
    """The checks on the file itself, before any reading: one-line errors naming it."""
    if not path.exists():
        raise FileNotFoundError(f"track file {str(path)!r} does not exist")
    if path.is_dir():
        raise ValueError(f"{path} is a directory; expected a .gpx or .csv track file")
    if not path.is_file():
        raise ValueError(f"{path} is not a regular file; expected a .gpx or .csv track file")
    suffix = path.suffix.lower()
    if suffix not in (".gpx", ".csv"):
        raise ValueError(f"{path}: expected a .gpx or .csv track, got {suffix or 'no extension'!r}")
    size = path.stat().st_size
    if size == 0:
        raise ValueError(f"{path} is empty; expected a {suffix[1:].upper()} track")
    if size > max_file_mb * 1e6:
        raise ValueError(f"{path} is {size / 1e6:.0f} MB, more than the {max_file_mb:g} MB a track may have "
                         "(max_file_mb); split it, or raise the limit")
    try:
        with path.open("rb") as handle:
            head = handle.read(8192)
    except OSError as exc:
        raise ValueError(f"{path} cannot be read: {exc.strerror}") from None
    if b"\0" in head:
        raise ValueError(f"{path} is a binary file; expected a {suffix[1:].upper()} text file")


def read_track(path: str | Path, *, max_file_mb: float = MAX_FILE_MB, progress: Progress | None = None) -> Track:
    """Read a ``.gpx`` or ``.csv`` track (see the module docstring); ``progress`` is told the
    fraction of the file read."""
    path = Path(path)
    check_track_file(path, max_file_mb)
    reader = _read_gpx if path.suffix.lower() == ".gpx" else _read_csv
    return reader(path, progress or (lambda fraction: None))


# --------------------------------------------------------------------------------------
# GPX
# --------------------------------------------------------------------------------------

class _GpxPoints:
    """expat handlers collecting (lat, lon, ele, time, line) of <trkpt> and <rtept>."""

    def __init__(self, parser, path: Path):
        self.parser, self.path = parser, path
        self.points: dict[str, list] = {"trkpt": [], "rtept": []}
        self.point: list | None = None
        self.field: int | None = None
        self.text: list[str] = []
        self.root_seen = False

    def start(self, name: str, attrs: dict) -> None:
        name = name.rpartition(":")[2]  # a namespace prefix (gpx:trkpt)
        if not self.root_seen:
            self.root_seen = True
            if name != "gpx":
                raise ValueError(f"{self.path}: not a GPX file (its root element is <{name}>, expected <gpx>)")
        if name in ("trkpt", "rtept"):
            self.point = [attrs.get("lat"), attrs.get("lon"), None, None, self.parser.CurrentLineNumber]
            self.points[name].append(self.point)
        elif self.point is not None and name in ("ele", "time"):
            self.field = 2 if name == "ele" else 3
            self.text = []

    def characters(self, data: str) -> None:
        if self.field is not None:
            self.text.append(data)

    def end(self, name: str) -> None:
        name = name.rpartition(":")[2]
        if self.field is not None and name in ("ele", "time"):
            self.point[self.field] = "".join(self.text).strip()
            self.field = None
        elif name in ("trkpt", "rtept"):
            self.point = None


def _read_gpx(path: Path, progress: Progress) -> Track:
    parser = xml.parsers.expat.ParserCreate()
    handlers = _GpxPoints(parser, path)
    parser.StartElementHandler = handlers.start
    parser.EndElementHandler = handlers.end
    parser.CharacterDataHandler = handlers.characters
    parser.buffer_text = True
    size = max(path.stat().st_size, 1)
    done = 0
    try:
        with path.open("rb") as handle:
            while chunk := handle.read(_CHUNK_BYTES):
                parser.Parse(chunk, False)
                done += len(chunk)
                progress(done / size)
            parser.Parse(b"", True)
    except xml.parsers.expat.ExpatError as exc:
        raise ValueError(f"{path}, line {exc.lineno}: not valid XML (a GPX file is XML): "
                         f"{xml.parsers.expat.ErrorString(exc.code)} at column {exc.offset + 1}") from None
    if not handlers.root_seen:
        raise ValueError(f"{path}: not a GPX file (no <gpx> element)")
    kind, points = "track point", handlers.points["trkpt"]
    if len(points) < 2:
        kind, points = "route point", handlers.points["rtept"]
    if len(points) < 2:
        raise ValueError(f"{path}: a route needs at least two track points (<trkpt>) or route points (<rtept>), "
                         f"found {max(len(handlers.points['trkpt']), len(handlers.points['rtept']))}")
    line = np.array([p[4] for p in points], dtype=np.int64)
    tag = "<trkpt>" if kind == "track point" else "<rtept>"

    def where(i: int) -> str:
        return f"{path}, line {line[i]}: {kind} {i + 1}"

    coords = {}
    for k, key in ((0, "lat"), (1, "lon")):
        raw = [p[k] for p in points]
        try:
            if None in raw:  # numpy would read a missing attribute as NaN
                raise ValueError(key)
            coords[key] = np.array(raw, dtype=np.float64)
        except (TypeError, ValueError):
            for i, value in enumerate(raw):
                try:
                    float(value)
                except (TypeError, ValueError):
                    got = f"no {key} attribute" if value is None else f"{key}={value!r}"
                    raise ValueError(f"{where(i)} ({tag}) has {got}; expected {key}=\"<degrees>\"") from None
    alt = None
    eles = [p[2] for p in points]
    if any(e is not None for e in eles):
        missing = [i for i, e in enumerate(eles) if e is None]
        if missing:
            raise ValueError(f"{where(missing[0])} has no <ele> while others have one")
        alt = _floats(eles, where, "<ele>", "a height in metres")
    t_s, start = None, None
    times = [p[3] for p in points]
    if any(t is not None for t in times):
        missing = [i for i, t in enumerate(times) if t is None]
        if missing:
            raise ValueError(f"{where(missing[0])} has no <time> while others have one")
        t_s, start = _gpx_times(times, where)
    return _checked(Track(coords["lat"], coords["lon"], alt, None, t_s, start, str(path), line, kind))


def _floats(texts: list[str], where, what: str, expected: str) -> np.ndarray:
    try:
        return np.array(texts, dtype=np.float64)
    except ValueError:
        for i, text in enumerate(texts):
            try:
                float(text)
            except ValueError:
                raise ValueError(f"{where(i)} has {what} {text!r}; expected {expected}") from None
        raise


def _gpx_times(texts: list[str], where) -> tuple[np.ndarray, datetime.datetime]:
    stamps = []
    for i, text in enumerate(texts):
        try:
            stamp = datetime.datetime.fromisoformat(text)
        except ValueError:
            raise ValueError(f"{where(i)} has <time> {text!r}; expected an ISO 8601 time like "
                             "2024-05-01T12:00:00Z") from None
        stamps.append(stamp if stamp.tzinfo is not None else stamp.replace(tzinfo=datetime.timezone.utc))
    start = stamps[0]
    return np.array([(s - start).total_seconds() for s in stamps]), start


# --------------------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------------------

_CSV_COLUMNS = ("lat_deg", "lon_deg", "alt_m", "speed_mps", "t_s")


def _read_csv(path: Path, progress: Progress) -> Track:
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not UTF-8 text (byte {exc.start} is {exc.object[exc.start]:#04x}); "
                         "expected a CSV text file") from None
    progress(0.5)
    reader = csv.reader(io.StringIO(text))
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise ValueError(f"{path}: the file is empty") from None
    except csv.Error as exc:
        raise ValueError(f"{path}, line 1: not a CSV header: {exc}") from None
    for needed in ("lat_deg", "lon_deg"):
        if needed not in header:
            raise ValueError(f"{path}, line 1: missing column {needed!r}; columns are lat_deg, lon_deg "
                             "and optionally alt_m, speed_mps, t_s")
    columns = [c for c in _CSV_COLUMNS if c in header]
    index = [header.index(c) for c in columns]
    rows, lines = [], []
    try:
        for row in reader:
            if not row or all(not cell.strip() for cell in row):
                continue
            try:
                rows.append([float(row[i]) for i in index])
            except (ValueError, IndexError):
                raise ValueError(f"{path}, line {reader.line_num}: expected numbers in columns "
                                 f"{', '.join(columns)}, got {','.join(row)!r}") from None
            lines.append(reader.line_num)
    except csv.Error as exc:
        raise ValueError(f"{path}, line {reader.line_num}: not valid CSV: {exc}") from None
    progress(1.0)
    if len(rows) < 2:
        raise ValueError(f"{path}: a route needs at least two points, found {len(rows)}")
    data = np.array(rows)
    col = {c: data[:, k] for k, c in enumerate(columns)}
    line = np.array(lines, dtype=np.int64)
    for name in columns:
        bad = np.flatnonzero(~np.isfinite(col[name]))
        if bad.size:
            i = bad[0]
            raise ValueError(f"{path}, line {line[i]}: row {i + 1} has {name}={col[name][i]}; values must be finite")
    speed = col.get("speed_mps")
    if speed is not None and (speed < 0.0).any():
        i = int(np.flatnonzero(speed < 0.0)[0])
        raise ValueError(f"{path}, line {line[i]}: row {i + 1} has speed_mps={speed[i]:g}; expected >= 0")
    t_s = col.get("t_s")
    return _checked(Track(col["lat_deg"], col["lon_deg"], col.get("alt_m"), speed,
                          None if t_s is None else t_s - t_s[0], None, str(path), line, "row"))


# --------------------------------------------------------------------------------------
# Checks common to both formats
# --------------------------------------------------------------------------------------

def _checked(track: Track) -> Track:
    """Every point's values in range and times never going back, else ValueError naming it."""
    for values, name, (low, high), what in (
            (track.lat_deg, "lat", LAT_RANGE_DEG, "a latitude"),
            (track.lon_deg, "lon", LON_RANGE_DEG, "a longitude"),
            (track.alt_m, "height", ALT_RANGE_M, "a height above the WGS-84 ellipsoid")):
        if values is None:
            continue
        bad = np.flatnonzero(~((values >= low) & (values <= high)))  # NaN fails too
        if bad.size:
            i = int(bad[0])
            more = f" ({bad.size - 1} more point(s) too)" if bad.size > 1 else ""
            unit = "m" if name == "height" else "degrees"
            raise ValueError(f"{track.where(i)} has {name}={values[i]:g}{more}; expected {what} in "
                             f"[{low:g}, {high:g}] {unit}")
    if track.t_s is not None:
        back = np.flatnonzero(np.diff(track.t_s) < 0.0)
        if back.size:
            i = int(back[0]) + 1
            raise ValueError(f"{track.where(i)}'s time is {track.t_s[i - 1] - track.t_s[i]:g} s earlier than the "
                             "point before's; times must never go back")
    return track
