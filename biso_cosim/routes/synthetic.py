"""Tracks made with a seed like real recordings: a known road, driven, logged by a noisy receiver.

For testing the import (and your own tools) where the true road must be known. A road of
the chosen kind is laid out from random segments:

* ``"urban"``: a street grid, blocks of 60-140 m, 90° corners of 8-12 m radius, stops at a
  third of the crossings (6-30 s), nearly flat (grades up to 3 %), 12 m/s between corners;
* ``"mountain"``: curves of 25-90 m radius turning 40-140°, now and then a hairpin of 12-15 m,
  grades up to 10 %, up to 18 m/s;
* ``"highway"``: straights of 300-1200 m, curves of 600-1500 m radius, grades up to 4 %, 30 m/s.

Curvature changes over 15 m (like a road's transition curves). The heights are those of a
landscape under the road (waves of 200 m to 2 km), so that where the road crosses itself it
meets itself. A driver follows it at the
road's speed, slowing to 2.5 m/s² of lateral acceleration in curves, accelerating at 1.5 and
braking at 2.0 m/s², standing ``standing_s`` before driving off and after arriving. The
receiver logs at ``rate_hz`` with the error of a consumer GNSS receiver: per axis a
first-order Gauss-Markov process (correlation time ``noise_time_s``) smoothed over
``noise_smoothing_s`` (its error wanders by metres over minutes but by centimetres from fix to
fix), of standard deviation ``horizontal_noise_m`` and ``vertical_noise_m``, plus white noise
(``white_noise_m`` horizontally, 1.5 times that vertically), fixes lost
at random (``drop_fraction``) and in ``dropouts`` outages of 3-10 s; with ``static_hold`` the
receiver repeats its last position while the car stands, as automotive receivers do.
"""

from __future__ import annotations

import datetime
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

from biso_cosim.routes.tracks import Track

__all__ = ["Road", "SyntheticTrack", "synthetic_track", "write_gpx", "ROAD_KINDS"]

ROAD_KINDS = ("urban", "mountain", "highway")
_STEP_M = 0.5
_LATERAL_MPS2, _ACCEL_MPS2, _DECEL_MPS2 = 2.5, 1.5, 2.0


@dataclass(frozen=True)
class Road:
    """The true road, every 0.5 m: ENU positions and heights relative to the start, and the stops."""

    s_m: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray
    stops: tuple[tuple[float, float], ...]
    """(arc length m, dwell s)."""


@dataclass(frozen=True)
class SyntheticTrack:
    track: Track
    road: Road
    origin: tuple[float, float, float]
    """Latitude, longitude (degrees) and height (m) of the road's start."""


def _segments(kind: str, length_m: float, rng: np.random.Generator):
    """(length m, curvature 1/m, cruise speed m/s, stop dwell at its end s) pieces of road."""
    out, total = [], 0.0
    while total < length_m:
        if kind == "urban":
            block = rng.uniform(60.0, 140.0)
            radius = rng.uniform(8.0, 12.0)
            turn = rng.choice([-1.0, 1.0]) * math.pi / 2
            stop = rng.uniform(6.0, 30.0) if rng.random() < 1 / 3 else 0.0
            pieces = [(block, 0.0, 12.0, stop), (radius * abs(turn), turn / abs(turn) / radius, 12.0, 0.0)]
        elif kind == "mountain":
            if rng.random() < 0.1:
                radius, turn = rng.uniform(12.0, 15.0), rng.uniform(math.radians(160), math.radians(180))
            else:
                radius, turn = rng.uniform(25.0, 90.0), rng.uniform(math.radians(40), math.radians(140))
            sign = rng.choice([-1.0, 1.0])
            pieces = [(rng.uniform(20.0, 80.0), 0.0, 18.0, 0.0), (radius * turn, sign / radius, 18.0, 0.0)]
        else:
            radius, turn = rng.uniform(600.0, 1500.0), rng.uniform(math.radians(10), math.radians(40))
            pieces = [(rng.uniform(300.0, 1200.0), 0.0, 30.0, 0.0),
                      (radius * turn, rng.choice([-1.0, 1.0]) / radius, 30.0, 0.0)]
        out.extend(pieces)
        total += sum(p[0] for p in pieces)
    return out


def _moving_average(values: np.ndarray, width: int) -> np.ndarray:
    if width <= 1:
        return values
    padded = np.concatenate([np.full(width, values[0]), values, np.full(width, values[-1])])
    return np.convolve(padded, np.ones(width) / width, mode="same")[width:-width]


def _road(kind: str, length_m: float, rng: np.random.Generator, stop_at,
          top_grade: float | None) -> tuple[Road, np.ndarray]:
    pieces = _segments(kind, length_m, rng)
    n = int(round(length_m / _STEP_M)) + 1
    s = _STEP_M * np.arange(n)
    kappa, cruise = np.zeros(n), np.zeros(n)
    stops = []
    start = 0.0
    for length, k, v, dwell in pieces:
        sel = (s >= start) & (s < start + length)
        kappa[sel], cruise[sel] = k, v
        start += length
        if dwell > 0.0 and start < s[-1] - 20.0:
            stops.append((start, dwell))
    if stop_at is not None:
        stops = [(float(a), float(b)) for a, b in stop_at]
    kappa = _moving_average(kappa, int(round(15.0 / _STEP_M)))  # transition curves
    heading = np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * _STEP_M)])
    heading += rng.uniform(-math.pi, math.pi)
    x = np.concatenate([[0.0], np.cumsum(np.cos(0.5 * (heading[1:] + heading[:-1])) * _STEP_M)])
    y = np.concatenate([[0.0], np.cumsum(np.sin(0.5 * (heading[1:] + heading[:-1])) * _STEP_M)])
    # heights from a landscape z(x, y), so that a road crossing itself meets itself: a sum of
    # waves of 200 m to 2 km scaled to the kind's steepest grade along the road
    if top_grade is None:
        top_grade = {"urban": 0.03, "mountain": 0.10, "highway": 0.04}[kind]
    waves = 12
    wavelength = np.exp(rng.uniform(math.log(200.0), math.log(2000.0), waves))
    direction = rng.uniform(0.0, 2 * math.pi, waves)
    phase = rng.uniform(0.0, 2 * math.pi, waves)
    kx, ky = (2 * math.pi / wavelength) * np.cos(direction), (2 * math.pi / wavelength) * np.sin(direction)
    amplitude = wavelength / wavelength.sum()
    arg = np.outer(x, kx) + np.outer(y, ky) + phase
    z = np.cos(arg) @ amplitude
    grade = np.gradient(z, _STEP_M)
    scale = top_grade / max(float(np.max(np.abs(grade))), 1e-12)
    z = (z - z[0]) * scale
    # the driver's speed: cruise, slower in curves, feasible accelerations, at rest at stops
    v = np.minimum(cruise, np.sqrt(_LATERAL_MPS2 / np.maximum(np.abs(kappa), 1e-9)))
    v[0] = v[-1] = 0.0
    stops = [(float(s[int(round(a / _STEP_M))]), dwell) for a, dwell in stops]
    for a, _ in stops:
        v[int(round(a / _STEP_M))] = 0.0
    for i in range(1, n):
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * _ACCEL_MPS2 * _STEP_M))
    for i in range(n - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * _DECEL_MPS2 * _STEP_M))
    return Road(s, x, y, z, tuple(stops)), v


def synthetic_track(kind: str = "urban", *, length_m: float = 1000.0, rate_hz: float = 1.0, seed: int = 0,
                    horizontal_noise_m: float = 2.5, vertical_noise_m: float = 3.0, white_noise_m: float = 0.2,
                    noise_time_s: float = 60.0, noise_smoothing_s: float = 10.0,
                    drop_fraction: float = 0.02, dropouts: int = 0,
                    standing_s: float = 10.0, static_hold: bool = False,
                    stop_at: list[tuple[float, float]] | None = None, top_grade: float | None = None,
                    origin: tuple[float, float, float] = (51.53, 46.03, 50.0),
                    start: datetime.datetime = datetime.datetime(2024, 5, 1, 9, 0, tzinfo=datetime.timezone.utc),
                    name: str = "synthetic") -> SyntheticTrack:
    """A recorded-like track of a road of ``kind`` (see the module docstring); ``stop_at``
    replaces the road's own stops with (arc length m, dwell s) pairs, ``top_grade`` the kind's
    steepest grade (0: a flat road). The same seed gives the same track."""
    import pymap3d

    if kind not in ROAD_KINDS:
        raise ValueError(f"kind must be one of {', '.join(ROAD_KINDS)}, got {kind!r}")
    rng = np.random.default_rng(seed)
    road, v = _road(kind, length_m, rng, stop_at, top_grade)
    # time along the road: driving, and each stop's dwell at its place
    dt = _STEP_M / np.maximum(0.5 * (v[1:] + v[:-1]), 0.05)
    t_drive = standing_s + np.concatenate([[0.0], np.cumsum(dt)])
    at = sorted((int(round(a / _STEP_M)), dwell) for a, dwell in road.stops)
    shift = np.zeros_like(t_drive)
    for k, dwell in at:
        shift[k + 1:] += dwell
    t_road = t_drive + shift
    t_pairs = np.concatenate([[0.0], t_road, [t_road[k] + dwell for k, dwell in at], [t_road[-1] + standing_s]])
    s_pairs = np.concatenate([[0.0], road.s_m, [road.s_m[k] for k, _ in at], [road.s_m[-1]]])
    order = np.argsort(t_pairs, kind="stable")
    t_pairs, s_pairs = t_pairs[order], s_pairs[order]
    t_fix = np.arange(0.0, t_pairs[-1], 1.0 / rate_hz)
    s_fix = np.interp(t_fix, t_pairs, s_pairs)
    x, y, z = (np.interp(s_fix, road.s_m, c) for c in (road.x_m, road.y_m, road.z_m))

    def slow_error(sigma: float, count: int) -> np.ndarray:
        """Gauss-Markov (time constant noise_time_s) through a first-order low-pass of
        noise_smoothing_s, scaled to the standard deviation sigma: a receiver's error wanders
        by metres over minutes but by centimetres from one fix to the next."""
        dt = 1.0 / rate_hz
        phi = math.exp(-dt / noise_time_s)
        scale = sigma * math.sqrt((noise_time_s + noise_smoothing_s) / noise_time_s)
        w = rng.normal(0.0, scale * math.sqrt(1.0 - phi * phi), count)
        w[0] = rng.normal(0.0, scale)
        markov = lfilter([1.0], [1.0, -phi], w)
        beta = math.exp(-dt / noise_smoothing_s)
        return lfilter([1.0 - beta], [1.0, -beta], markov, zi=[beta * markov[0]])[0]

    m = t_fix.shape[0]
    ex = slow_error(horizontal_noise_m, m) + rng.normal(0.0, white_noise_m, m)
    ey = slow_error(horizontal_noise_m, m) + rng.normal(0.0, white_noise_m, m)
    ez = slow_error(vertical_noise_m, m) + rng.normal(0.0, 1.5 * white_noise_m, m)
    fx, fy, fz = x + ex, y + ey, z + ez
    if static_hold:  # the receiver freezes its position while the car stands
        standing = np.concatenate([[True], np.diff(s_fix) < 1e-6])
        for i in range(1, m):
            if standing[i]:
                fx[i], fy[i], fz[i] = fx[i - 1], fy[i - 1], fz[i - 1]
    keep = rng.random(m) >= drop_fraction
    keep[0] = keep[-1] = True
    for _ in range(dropouts):
        a = rng.uniform(0.1, 0.9) * t_fix[-1]
        keep[(t_fix >= a) & (t_fix < a + rng.uniform(3.0, 10.0))] = False
    lat0, lon0, h0 = origin
    lat, lon, _ = pymap3d.enu2geodetic(fx[keep], fy[keep], np.zeros(int(keep.sum())), lat0, lon0, h0)
    track = Track(lat_deg=np.asarray(lat), lon_deg=np.asarray(lon), alt_m=h0 + fz[keep], speed_mps=None,
                  t_s=t_fix[keep] - t_fix[keep][0], start=start + datetime.timedelta(seconds=float(t_fix[keep][0])),
                  source=f"{name}.gpx", line=None, kind="track point")
    return SyntheticTrack(track=track, road=road, origin=origin)


def write_gpx(track: Track, path: str | Path, name: str = "") -> Path:
    """Write a track as GPX 1.1 (latitude and longitude to 1e-8°, heights to the mm, times to the ms)."""
    path = Path(path)
    start = track.start or datetime.datetime(2024, 5, 1, tzinfo=datetime.timezone.utc)
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<gpx version="1.1" creator="biso_cosim.routes.synthetic" xmlns="http://www.topografix.com/GPX/1/1">',
             f"<trk><name>{name or path.stem}</name><trkseg>"]
    for i in range(len(track)):
        ele = f"<ele>{track.alt_m[i]:.3f}</ele>" if track.alt_m is not None else ""
        time = ""
        if track.t_s is not None:
            stamp = start + datetime.timedelta(seconds=float(track.t_s[i]))
            time = f"<time>{stamp.strftime('%Y-%m-%dT%H:%M:%S.%f')[:-3]}Z</time>"
        lines.append(f'<trkpt lat="{track.lat_deg[i]:.8f}" lon="{track.lon_deg[i]:.8f}">{ele}{time}</trkpt>')
    lines.append("</trkseg></trk></gpx>")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
