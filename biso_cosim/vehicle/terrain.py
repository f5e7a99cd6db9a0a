"""Terrain: an analytic height function built from documented features, sampled into a
MuJoCo height field.

The ground of a route is flat (z = 0) except where its features raise it. Every feature is
a smooth, non-negative bump with a closed-form height, so tests can compare what the car
measures (pitch on a grade, roll on a bank) with the geometry:

* ``hill``: a round cosine bump, ``h·(1 + cos(π r/R))/2`` for r < R;
* ``ridge``: a cosine bump across a straight crest line (a road crossing it climbs and
  descends with maximum grade ``π h / (2 w)`` for height h and half-width w);
* ``bank``: a banked curve: on an annular road sector the surface rises outward with the
  bank angle, tapering in and out over ``ramp_deg`` at both ends, with an embankment that
  brings the outer edge back to the ground;
* ``hump``: a speed hump across a road: a cosine profile along the road (default 3.7 m long,
  7.5 cm high, the common "Watts" hump dimensions);
* ``washboard``: corrugations along a straight stretch of road, ``A·(1 − cos 2πu/λ)/2``;
* ``rough``: random roughness of ISO 8608 class A–E along a straight stretch: an isotropic
  Gaussian surface whose profile along the road has the displacement PSD
  ``G_d(n) = G_d(n₀)·(n/n₀)⁻²`` (n₀ = 0.1 cycle/m), drawn from a seed.

* ``road``: a road that follows a polyline of (x, y, z) points (an imported track with
  heights): the surface within ``half_width_m`` of the polyline has the height of its nearest
  point, falling to the ground over ``shoulder_m``. It is sampled in pieces along the road,
  so a long track costs no more than its own corridor.

The road features (hump, washboard, rough) lie on straight stretches given by their end
points and width; they fade in and out over a short ramp at both ends and over 0.5 m beyond
the edges, and are sampled on their own finer grid (``resolution_m``, default 0.1 m).

The ground is the plane z = 0; the features are sampled into height-field patches at
``resolution_m`` (default 0.5 m: MuJoCo interpolates linearly between grid points; for the
shipped hills the interpolation error is below 1 mm). Plane contacts are cheap, so the car
costs less to simulate wherever the ground is flat.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields
from functools import cached_property

import numpy as np

__all__ = ["Hill", "Ridge", "Bank", "Hump", "Washboard", "Rough", "Road", "Terrain", "SurfacePatch", "FEATURE_TYPES",
           "HeightField",
           "ISO8608_GD_N0"]


def _cosine_bump(u: np.ndarray) -> np.ndarray:
    """(1 + cos(π u))/2 for |u| < 1, else 0: a smooth bump of height 1 and half-width 1."""
    u = np.abs(u)
    return np.where(u < 1.0, 0.5 * (1.0 + np.cos(np.pi * np.minimum(u, 1.0))), 0.0)


def _smoothstep(u: np.ndarray) -> np.ndarray:
    """0 for u ≤ 0, 1 for u ≥ 1, a cosine ramp in between."""
    u = np.clip(u, 0.0, 1.0)
    return 0.5 * (1.0 - np.cos(np.pi * u))


@dataclass(frozen=True)
class Hill:
    """A round hill: a cosine bump of ``height_m`` and base radius ``radius_m`` at (x_m, y_m)."""

    x_m: float
    y_m: float
    radius_m: float
    height_m: float

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        r = np.hypot(x - self.x_m, y - self.y_m)
        return self.height_m * _cosine_bump(r / self.radius_m)

    def extent(self) -> tuple[float, float, float, float]:
        r = self.radius_m
        return self.x_m - r, self.x_m + r, self.y_m - r, self.y_m + r

    def check(self) -> None:
        _positive(self, "radius_m")
        _positive(self, "height_m")


@dataclass(frozen=True)
class Ridge:
    """A ridge whose crest runs from (x0_m, y0_m) to (x1_m, y1_m).

    Across the crest the profile is a cosine bump of ``height_m`` and half-width
    ``half_width_m``; along the crest it is constant, and it fades out beyond the crest ends
    over the same half-width. A road crossing the crest at right angles climbs with a
    maximum grade of ``π·height_m/(2·half_width_m)``.
    """

    x0_m: float
    y0_m: float
    x1_m: float
    y1_m: float
    half_width_m: float
    height_m: float

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        dx, dy = self.x1_m - self.x0_m, self.y1_m - self.y0_m
        length = math.hypot(dx, dy)
        ux, uy = dx / length, dy / length
        along = (x - self.x0_m) * ux + (y - self.y0_m) * uy
        across = -(x - self.x0_m) * uy + (y - self.y0_m) * ux
        beyond = np.maximum(np.maximum(-along, along - length), 0.0)
        return self.height_m * _cosine_bump(across / self.half_width_m) * _cosine_bump(beyond / self.half_width_m)

    def extent(self) -> tuple[float, float, float, float]:
        w = self.half_width_m
        return (min(self.x0_m, self.x1_m) - w, max(self.x0_m, self.x1_m) + w,
                min(self.y0_m, self.y1_m) - w, max(self.y0_m, self.y1_m) + w)

    def check(self) -> None:
        _positive(self, "half_width_m")
        _positive(self, "height_m")
        if math.hypot(self.x1_m - self.x0_m, self.y1_m - self.y0_m) == 0.0:
            raise ValueError("ridge: the crest ends (x0_m, y0_m) and (x1_m, y1_m) must differ")


@dataclass(frozen=True)
class Bank:
    """A banked curve: the road sector of centre (cx_m, cy_m) and centre-line radius
    ``radius_m``, ``width_m`` wide, from ``start_deg`` to ``end_deg`` (polar angles, ENU,
    counter-clockwise from East; the sector runs counter-clockwise from start to end).

    Across the road the surface rises outward at ``bank_deg``, from ground level at the inner
    edge; the bank fades in and out over ``ramp_deg`` inside both ends of the sector. Beyond
    the outer edge an embankment ``embankment_m`` wide brings the surface back to the ground.
    """

    cx_m: float
    cy_m: float
    radius_m: float
    width_m: float
    start_deg: float
    end_deg: float
    bank_deg: float
    ramp_deg: float = 20.0
    embankment_m: float = 6.0

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        r = np.hypot(x - self.cx_m, y - self.cy_m)
        theta = np.degrees(np.arctan2(y - self.cy_m, x - self.cx_m))
        span = (self.end_deg - self.start_deg) % 360.0
        into = (theta - self.start_deg) % 360.0  # angle travelled into the sector
        ramp = min(self.ramp_deg, 0.5 * span)
        taper = np.where(into <= span, _smoothstep(into / ramp) * _smoothstep((span - into) / ramp), 0.0)
        inner = self.radius_m - 0.5 * self.width_m
        outer = self.radius_m + 0.5 * self.width_m
        top = self.width_m * math.tan(math.radians(self.bank_deg))
        rise = np.clip(r - inner, 0.0, self.width_m) * math.tan(math.radians(self.bank_deg))
        fall = top * (1.0 - _smoothstep((r - outer) / self.embankment_m))
        profile = np.where(r <= outer, rise, fall)
        return profile * taper

    def extent(self) -> tuple[float, float, float, float]:
        r = self.radius_m + 0.5 * self.width_m + self.embankment_m
        return self.cx_m - r, self.cx_m + r, self.cy_m - r, self.cy_m + r

    def check(self) -> None:
        _positive(self, "radius_m")
        _positive(self, "width_m")
        _positive(self, "embankment_m")
        if not 0.0 < self.bank_deg < 45.0:
            raise ValueError(f"bank: bank_deg must be in (0, 45), got {self.bank_deg}")
        if self.width_m >= 2.0 * self.radius_m:
            raise ValueError("bank: width_m must be smaller than the diameter 2·radius_m")
        if self.ramp_deg <= 0.0:
            raise ValueError(f"bank: ramp_deg must be > 0, got {self.ramp_deg}")
        if (self.end_deg - self.start_deg) % 360.0 == 0.0:
            raise ValueError("bank: start_deg and end_deg must differ (modulo 360); a bank runs "
                             "counter-clockwise from start_deg to end_deg")


class _Stretch:
    """Mixin of the road features: a straight stretch from (x0_m, y0_m) to (x1_m, y1_m),
    ``width_m`` wide; local coordinates u along, v across."""

    _EDGE_M = 0.5  # fade beyond the road edges

    def _local(self, x, y):
        dx, dy = self.x1_m - self.x0_m, self.y1_m - self.y0_m
        length = math.hypot(dx, dy)
        ux, uy = dx / length, dy / length
        u = (x - self.x0_m) * ux + (y - self.y0_m) * uy
        v = -(x - self.x0_m) * uy + (y - self.y0_m) * ux
        return u, v, length

    def _mask(self, u, v, length, ramp):
        """1 on the stretch, smooth ramps to 0 at the ends (over ``ramp``) and edges."""
        along = _smoothstep(u / ramp) * _smoothstep((length - u) / ramp)
        across = _smoothstep((0.5 * self.width_m + self._EDGE_M - np.abs(v)) / self._EDGE_M)
        return along * across

    def extent(self) -> tuple[float, float, float, float]:
        pad = 0.5 * self.width_m + self._EDGE_M
        return (min(self.x0_m, self.x1_m) - pad, max(self.x0_m, self.x1_m) + pad,
                min(self.y0_m, self.y1_m) - pad, max(self.y0_m, self.y1_m) + pad)

    def _check_stretch(self) -> None:
        _positive(self, "width_m")
        _positive(self, "resolution_m")
        if math.hypot(self.x1_m - self.x0_m, self.y1_m - self.y0_m) == 0.0:
            raise ValueError(f"{type(self).__name__.lower()}: the ends (x0_m, y0_m) and (x1_m, y1_m) must differ")


@dataclass(frozen=True)
class Hump(_Stretch):
    """A speed hump across the road at (x_m, y_m), the road heading ``heading_deg`` (CCW from
    East): a cosine profile ``length_m`` long along the road and ``height_m`` high."""

    x_m: float
    y_m: float
    heading_deg: float
    length_m: float = 3.7
    height_m: float = 0.075
    width_m: float = 7.0
    resolution_m: float = 0.1

    @property
    def _ends(self):
        h = math.radians(self.heading_deg)
        half = 0.5 * self.length_m
        return (self.x_m - half * math.cos(h), self.y_m - half * math.sin(h),
                self.x_m + half * math.cos(h), self.y_m + half * math.sin(h))

    x0_m = property(lambda self: self._ends[0])
    y0_m = property(lambda self: self._ends[1])
    x1_m = property(lambda self: self._ends[2])
    y1_m = property(lambda self: self._ends[3])

    def height(self, x, y):
        u, v, length = self._local(x, y)
        profile = self.height_m * _cosine_bump((u - 0.5 * length) / (0.5 * length))
        across = _smoothstep((0.5 * self.width_m + self._EDGE_M - np.abs(v)) / self._EDGE_M)
        return profile * across

    def check(self) -> None:
        _positive(self, "length_m")
        _positive(self, "height_m")
        self._check_stretch()


@dataclass(frozen=True)
class Washboard(_Stretch):
    """Corrugations ``A·(1 − cos 2πu/λ)/2`` along the stretch (peak height ``amplitude_m``,
    wavelength ``wavelength_m``), faded in and out over two wavelengths."""

    x0_m: float
    y0_m: float
    x1_m: float
    y1_m: float
    width_m: float = 7.0
    amplitude_m: float = 0.02
    wavelength_m: float = 0.8
    resolution_m: float = 0.1

    def height(self, x, y):
        u, v, length = self._local(x, y)
        ripple = 0.5 * self.amplitude_m * (1.0 - np.cos(2.0 * np.pi * u / self.wavelength_m))
        return ripple * self._mask(u, v, length, 2.0 * self.wavelength_m)

    def check(self) -> None:
        _positive(self, "amplitude_m")
        _positive(self, "wavelength_m")
        self._check_stretch()
        if self.wavelength_m < 4.0 * self.resolution_m:
            raise ValueError("washboard: wavelength_m must be at least 4·resolution_m to be resolved")


ISO8608_GD_N0 = {"A": 16e-6, "B": 64e-6, "C": 256e-6, "D": 1024e-6, "E": 4096e-6}
"""ISO 8608 road classes: geometric-mean displacement PSD G_d(n₀) in m³ at n₀ = 0.1 cycle/m."""
_ISO_N0 = 0.1
_ROUGH_LONGEST_M = 20.0


@dataclass(frozen=True)
class Rough(_Stretch):
    """Random roughness of ISO 8608 class ``road_class`` (A very good … E very poor) on the
    stretch, from ``seed``. The surface is raised by its lowest point so that it never dips
    below the ground plane, and faded in over 2 m at both ends."""

    x0_m: float
    y0_m: float
    x1_m: float
    y1_m: float
    road_class: str = "C"
    seed: int = 0
    width_m: float = 7.0
    resolution_m: float = 0.1

    @cached_property
    def _grid(self) -> tuple[np.ndarray, float, float]:
        """The surface on a (u, v) grid: an isotropic field with a 2-D spectrum ∝ |k|⁻³ (its
        profiles then have the ISO 8608 slope n⁻²) for wavelengths up to 20 m (longer ones
        are terrain, not roughness), scaled to G_d(n₀) along the road. It is synthesised on a
        domain at least 20 m wide so that the profiles keep the n⁻² slope, then cropped."""
        _, _, length = self._local(self.x0_m, self.y0_m)
        res = self.resolution_m
        pad = self._EDGE_M
        nu = int(math.ceil(length / res)) + 1
        nv = int(math.ceil((self.width_m + 2 * pad) / res)) + 1
        nv_domain = max(nv, int(math.ceil(_ROUGH_LONGEST_M / res)))
        rng = np.random.default_rng(self.seed)
        white = rng.standard_normal((nu, nv_domain))
        ku = np.fft.fftfreq(nu, d=res)
        kv = np.fft.rfftfreq(nv_domain, d=res)
        k = np.hypot(ku[:, None], kv[None, :])
        amplitude = np.where(k >= 1.0 / _ROUGH_LONGEST_M, k, np.inf) ** -1.5
        field = np.fft.irfft2(np.fft.rfft2(white) * amplitude, s=(nu, nv_domain))[:, :nv]
        field *= math.sqrt(ISO8608_GD_N0[self.road_class] / _profile_psd_at_n0(field, res))
        field -= field.min()
        return field, res, -0.5 * self.width_m - pad

    def height(self, x, y):
        u, v, length = self._local(x, y)
        field, res, v0 = self._grid
        iu = np.clip(u / res, 0.0, field.shape[0] - 1.001)
        iv = np.clip((v - v0) / res, 0.0, field.shape[1] - 1.001)
        i0, j0 = np.floor(iu).astype(int), np.floor(iv).astype(int)
        fu, fv = iu - i0, iv - j0
        z = ((1 - fu) * (1 - fv) * field[i0, j0] + fu * (1 - fv) * field[i0 + 1, j0]
             + (1 - fu) * fv * field[i0, j0 + 1] + fu * fv * field[i0 + 1, j0 + 1])
        return z * self._mask(u, v, length, 2.0)

    def check(self) -> None:
        if self.road_class not in ISO8608_GD_N0:
            raise ValueError(f"rough: road_class must be one of {', '.join(ISO8608_GD_N0)}, got {self.road_class!r}")
        if not float(self.seed).is_integer() or self.seed < 0:
            raise ValueError(f"rough: seed must be a non-negative integer, got {self.seed!r}")
        self._check_stretch()


def _profile_psd_at_n0(field: np.ndarray, res: float) -> float:
    """One-sided displacement PSD (m³) of the profiles along axis 0 at n₀, from a power-law
    fit over 0.1–1 cycle/m (periodogram averaged over the profiles)."""
    n = field.shape[0]
    spectrum = np.abs(np.fft.rfft(field - field.mean(axis=0), axis=0)) ** 2
    psd = 2.0 * res / n * spectrum.mean(axis=1)
    freq = np.fft.rfftfreq(n, d=res)
    band = (freq >= 0.1) & (freq <= 1.0)
    # fit log G = log G0 − 2 log(n/n0) with the slope fixed by ISO 8608
    log_g0 = np.mean(np.log(psd[band]) + 2.0 * np.log(freq[band] / _ISO_N0))
    return float(np.exp(log_g0))


@dataclass(frozen=True)
class Road:
    """A road surface along a polyline of (x_m, y_m, z_m) points; see the module docstring."""

    points: tuple
    half_width_m: float = 4.0
    shoulder_m: float = 3.0
    resolution_m: float = 1.0
    piece_m: float = 150.0

    @cached_property
    def _xyz(self) -> np.ndarray:
        return np.asarray(self.points, dtype=np.float64).reshape(-1, 3)

    def _height_near(self, x, y, segments: np.ndarray) -> np.ndarray:
        """Height from the nearest of the given segments (indices into the polyline)."""
        p = self._xyz
        a, b = p[segments], p[segments + 1]
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        qx, qy = x.reshape(-1, 1), y.reshape(-1, 1)
        dx, dy = (b[:, 0] - a[:, 0])[None, :], (b[:, 1] - a[:, 1])[None, :]
        seg2 = np.maximum(dx * dx + dy * dy, 1e-12)
        t = np.clip(((qx - a[None, :, 0]) * dx + (qy - a[None, :, 1]) * dy) / seg2, 0.0, 1.0)
        d2 = (qx - a[None, :, 0] - t * dx) ** 2 + (qy - a[None, :, 1] - t * dy) ** 2
        k = np.argmin(d2, axis=1)
        rows = np.arange(k.shape[0])
        z = a[k, 2] + t[rows, k] * (b[k, 2] - a[k, 2])
        fade = _smoothstep((self.half_width_m + self.shoulder_m - np.sqrt(d2[rows, k])) / self.shoulder_m)
        return (z * fade).reshape(np.broadcast(x, y).shape)

    def height(self, x, y):
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        return self._height_near(x, y, np.arange(self._xyz.shape[0] - 1))

    def extent(self) -> tuple[float, float, float, float]:
        pad = self.half_width_m + self.shoulder_m
        p = self._xyz
        return p[:, 0].min() - pad, p[:, 0].max() + pad, p[:, 1].min() - pad, p[:, 1].max() + pad

    def own_patches(self) -> list["HeightField"]:
        """Patches along the road, one per ``piece_m`` of it, each covering its corridor."""
        p = self._xyz
        s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1])))])
        pad = self.half_width_m + self.shoulder_m
        res = self.resolution_m
        cuts = np.searchsorted(s, np.arange(0.0, s[-1], self.piece_m))
        bounds = list(cuts) + [p.shape[0] - 1]
        out = []
        for lo, hi in zip(bounds[:-1], bounds[1:]):
            piece = p[lo:hi + 1]
            x0 = math.floor((piece[:, 0].min() - pad) / res) * res - res
            y0 = math.floor((piece[:, 1].min() - pad) / res) * res - res
            ncol = int(math.ceil((piece[:, 0].max() + pad + res - x0) / res)) + 1
            nrow = int(math.ceil((piece[:, 1].max() + pad + res - y0) / res)) + 1
            xs, ys = np.meshgrid(x0 + res * np.arange(ncol), y0 + res * np.arange(nrow))
            # candidate segments: those that come within reach of this patch
            near = np.flatnonzero((np.maximum(p[:-1, 0], p[1:, 0]) >= x0 - pad)
                                  & (np.minimum(p[:-1, 0], p[1:, 0]) <= x0 + res * ncol + pad)
                                  & (np.maximum(p[:-1, 1], p[1:, 1]) >= y0 - pad)
                                  & (np.minimum(p[:-1, 1], p[1:, 1]) <= y0 + res * nrow + pad))
            heights = self._height_near(xs.ravel(), ys.ravel(), near).reshape(nrow, ncol)
            out.append(HeightField(heights_m=heights, x_min_m=x0, y_min_m=y0, resolution_m=res))
        return out

    def check(self) -> None:
        p = np.asarray(self.points, dtype=object)
        if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 2:
            raise ValueError("road: points must be a list of at least two [x_m, y_m, z_m] triples")
        xyz = self._xyz
        if not np.all(np.isfinite(xyz)) or xyz[:, 2].min() < 0.0:
            raise ValueError("road: points must be finite with z_m >= 0 (heights above the ground plane)")
        if np.hypot(np.diff(xyz[:, 0]), np.diff(xyz[:, 1])).sum() < 1.0:
            raise ValueError("road: the points must span at least 1 m horizontally")
        _positive(self, "half_width_m")
        _positive(self, "shoulder_m")
        _positive(self, "resolution_m")
        _positive(self, "piece_m")


def _positive(feature, name: str) -> None:
    value = getattr(feature, name)
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
        kind = type(feature).__name__.lower()
        raise ValueError(f"{kind}: {name} must be a positive number, got {value!r}")


_MAX_PATCH_CELLS = 2e7  # 80 MB of float32 heights per patch

FEATURE_TYPES = {"hill": Hill, "ridge": Ridge, "bank": Bank, "hump": Hump, "washboard": Washboard,
                 "rough": Rough, "road": Road}
"""Terrain feature classes by the name used in route files."""


@dataclass(frozen=True)
class HeightField:
    """A sampled terrain ready for MuJoCo: heights[row, col] at y = y_min + row·res,
    x = x_min + col·res (MuJoCo's hfield rows run along +y)."""

    heights_m: np.ndarray
    x_min_m: float
    y_min_m: float
    resolution_m: float

    @property
    def nrow(self) -> int:
        return self.heights_m.shape[0]

    @property
    def ncol(self) -> int:
        return self.heights_m.shape[1]

    @property
    def center_m(self) -> tuple[float, float]:
        return (self.x_min_m + 0.5 * (self.ncol - 1) * self.resolution_m,
                self.y_min_m + 0.5 * (self.nrow - 1) * self.resolution_m)

    @property
    def half_size_m(self) -> tuple[float, float]:
        return 0.5 * (self.ncol - 1) * self.resolution_m, 0.5 * (self.nrow - 1) * self.resolution_m


@dataclass(frozen=True)
class SurfacePatch:
    """A stretch of road with its own surface: the rectangle from (x0_m, y0_m) to (x1_m, y1_m),
    ``width_m`` wide, of ``surface`` (a name of ``vehicle.tyres.SURFACES`` or a friction scale
    in (0, 1.5] of dry asphalt's). It raises nothing; the slip-based tyres read its friction
    where their contact lies in it (a later patch over an earlier one), sharp at its edges."""

    x0_m: float
    y0_m: float
    x1_m: float
    y1_m: float
    surface: str | float
    width_m: float = 8.0

    @property
    def friction_scale(self) -> float:
        from biso_cosim.vehicle.tyres import surface_friction

        return surface_friction(self.surface)

    def plugin_numbers(self) -> tuple[float, ...]:
        """The tyre plugin's 7 numbers: centre, unit vector along, half length, half width, λ_μ."""
        dx, dy = self.x1_m - self.x0_m, self.y1_m - self.y0_m
        length = math.hypot(dx, dy)
        return (0.5 * (self.x0_m + self.x1_m), 0.5 * (self.y0_m + self.y1_m), dx / length, dy / length,
                0.5 * length, 0.5 * self.width_m, self.friction_scale)

    def check(self) -> None:
        if not (math.isfinite(self.width_m) and self.width_m > 0.0):
            raise ValueError(f"surface: width_m must be a positive number, got {self.width_m!r}")
        if math.hypot(self.x1_m - self.x0_m, self.y1_m - self.y0_m) == 0.0:
            raise ValueError("surface: the ends (x0_m, y0_m) and (x1_m, y1_m) must differ")
        self.friction_scale  # noqa: B018 -- a bad name or scale: one line naming the allowed ones


@dataclass(frozen=True)
class Terrain:
    """The ground of a route: flat, plus a tuple of features (heights add up), and surface
    patches (``SurfacePatch``: friction, no height)."""

    features: tuple = field(default_factory=tuple)
    resolution_m: float = 0.5
    surfaces: tuple = field(default_factory=tuple)

    def height(self, x, y) -> np.ndarray:
        """Terrain height (m) at ENU positions x, y (m); broadcasts like NumPy."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        z = np.zeros(np.broadcast(x, y).shape)
        for feature in self.features:
            z = z + feature.height(x, y)
        return z

    def gradient(self, x, y, step_m: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
        """(∂z/∂x, ∂z/∂y) by central differences."""
        gx = (self.height(np.add(x, step_m), y) - self.height(np.subtract(x, step_m), y)) / (2 * step_m)
        gy = (self.height(x, np.add(y, step_m)) - self.height(x, np.subtract(y, step_m))) / (2 * step_m)
        return gx, gy

    def patches(self) -> list[HeightField]:
        """Sample the features into height-field patches on a grid of ``resolution_m``.

        Features whose extents overlap share a patch; elsewhere the ground is the plane
        z = 0, which costs MuJoCo far less than a height field. Each patch is padded by one
        cell so that its border lies at ground level, where it meets the plane.
        """
        # boxes [x_min, x_max, y_min, y_max, grid]: a feature's own grid or the terrain's;
        # features that cut their own patches (roads) stand apart
        boxes = [[*f.extent(), getattr(f, "resolution_m", self.resolution_m)] for f in self.features
                 if not hasattr(f, "own_patches")]
        merged: list[list[float]] = []
        for box in boxes:
            # absorb every merged box that overlaps this one, until none does
            while True:
                hit = next((m for m in merged if box[0] <= m[1] and m[0] <= box[1]
                            and box[2] <= m[3] and m[2] <= box[3]), None)
                if hit is None:
                    break
                merged.remove(hit)
                box = [min(box[0], hit[0]), max(box[1], hit[1]), min(box[2], hit[2]), max(box[3], hit[3]),
                       min(box[4], hit[4])]
            merged.append(box)
        out = []
        for x_min, x_max, y_min, y_max, res in merged:
            cells = ((x_max - x_min) / res + 3) * ((y_max - y_min) / res + 3)
            if cells > _MAX_PATCH_CELLS:
                raise ValueError(f"terrain: features covering {x_max - x_min:.0f} m × {y_max - y_min:.0f} m at "
                                 f"{res} m make a height field of {cells:.3g} cells (at most {_MAX_PATCH_CELLS:.0e}); "
                                 "make the features smaller or their grid coarser")
            x0 = math.floor(x_min / res) * res - res
            y0 = math.floor(y_min / res) * res - res
            ncol = int(math.ceil((x_max + res - x0) / res)) + 1
            nrow = int(math.ceil((y_max + res - y0) / res)) + 1
            xs = x0 + res * np.arange(ncol)
            ys = y0 + res * np.arange(nrow)
            heights = self.height(xs[None, :], ys[:, None])
            out.append(HeightField(heights_m=heights, x_min_m=x0, y_min_m=y0, resolution_m=res))
        for feature in self.features:
            if hasattr(feature, "own_patches"):
                out.extend(feature.own_patches())
        return out

    @staticmethod
    def from_dict(items: list[dict], resolution_m: float = 0.5, where: str = "terrain") -> "Terrain":
        """Build from route-file entries ``{"type": "hill", "x_m": ..., ...}``; errors name the entry."""
        features = []
        for index, item in enumerate(items):
            label = f"{where}[{index}]"
            if not isinstance(item, dict) or "type" not in item:
                raise ValueError(f"{label}: each terrain feature needs a 'type' ({', '.join(FEATURE_TYPES)})")
            kind = item["type"]
            cls = FEATURE_TYPES.get(kind)
            if cls is None:
                raise ValueError(f"{label}: unknown terrain type {kind!r}; known: {', '.join(FEATURE_TYPES)}")
            names = {f.name for f in fields(cls)}
            required = {f.name for f in fields(cls) if f.default is MISSING}
            given = set(item) - {"type"}
            unknown = given - names
            if unknown:
                raise ValueError(f"{label} ({kind}): unknown field(s) {sorted(unknown)}; expected {sorted(names)}")
            missing = required - given
            if missing:
                raise ValueError(f"{label} ({kind}): missing field(s) {sorted(missing)}")
            values = {}
            for key in given:
                value = item[key]
                if key == "road_class":
                    values[key] = value  # checked by the feature
                elif key == "points":
                    if not (isinstance(value, list) and all(
                            isinstance(pt, list) and len(pt) == 3
                            and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in pt)
                            for pt in value)):
                        raise ValueError(f"{label} ({kind}): points must be a list of [x_m, y_m, z_m] numbers")
                    values[key] = tuple(tuple(float(c) for c in pt) for pt in value)
                elif key == "seed":
                    if isinstance(value, bool) or not isinstance(value, int):
                        raise ValueError(f"{label} ({kind}): field 'seed' must be an integer, got {value!r}")
                    values[key] = value
                else:
                    values[key] = _field_number(value, f"{label} ({kind})", key)
            feature = cls(**values)
            try:
                feature.check()
            except ValueError as exc:
                raise ValueError(f"{label}: {exc}") from None
            features.append(feature)
        if not (math.isfinite(resolution_m) and 0.02 <= resolution_m <= 5.0):
            raise ValueError(f"{where}: resolution_m must be in [0.02, 5] m, got {resolution_m}")
        return Terrain(features=tuple(features), resolution_m=resolution_m)

    @staticmethod
    def surfaces_from_dict(items: list[dict], where: str = "terrain.surface") -> tuple[SurfacePatch, ...]:
        """Surface patches from route-file entries ``{"x0_m": ..., "surface": "snow", ...}``;
        errors name the entry and the field, in one line."""
        if not isinstance(items, list):
            raise ValueError(f"{where}: must be a list of tables ([[terrain.surface]])")
        names = {f.name for f in fields(SurfacePatch)}
        required = {f.name for f in fields(SurfacePatch) if f.default is MISSING}
        out = []
        for index, item in enumerate(items):
            label = f"{where}[{index}]"
            if not isinstance(item, dict):
                raise ValueError(f"{label}: each surface patch must be a table")
            unknown = set(item) - names
            if unknown:
                raise ValueError(f"{label}: unknown field(s) {sorted(unknown)}; expected {sorted(names)}")
            missing = required - set(item)
            if missing:
                raise ValueError(f"{label}: missing field(s) {sorted(missing)}")
            values = {}
            for key, value in item.items():
                if key == "surface":
                    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
                        raise ValueError(f"{label}: surface must be a name or a friction scale, got {value!r}")
                    values[key] = value if isinstance(value, str) else float(value)
                else:
                    values[key] = _field_number(value, label, key)
            patch = SurfacePatch(**values)
            try:
                patch.check()
            except ValueError as exc:
                raise ValueError(f"{label}: {exc}") from None
            out.append(patch)
        return tuple(out)


def _field_number(value: object, label: str, key: str) -> float:
    """A route file's numeric field as a float; ValueError naming the entry and the field."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{label}: field {key!r} must be a number, got {value!r}")
    return float(value)
