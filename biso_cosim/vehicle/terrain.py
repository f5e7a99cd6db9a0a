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
  brings the outer edge back to the ground.

The ground is the plane z = 0; the features are sampled into height-field patches at
``resolution_m`` (default 0.5 m: MuJoCo interpolates linearly between grid points; for the
shipped hills the interpolation error is below 1 mm). Plane contacts are cheap, so the car
costs less to simulate wherever the ground is flat.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields

import numpy as np

__all__ = ["Hill", "Ridge", "Bank", "Terrain", "FEATURE_TYPES", "HeightField"]


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


def _positive(feature, name: str) -> None:
    value = getattr(feature, name)
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
        kind = type(feature).__name__.lower()
        raise ValueError(f"{kind}: {name} must be a positive number, got {value!r}")


FEATURE_TYPES = {"hill": Hill, "ridge": Ridge, "bank": Bank}
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
class Terrain:
    """The ground of a route: flat, plus a tuple of features (heights add up)."""

    features: tuple = field(default_factory=tuple)
    resolution_m: float = 0.5

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
        boxes = [list(f.extent()) for f in self.features]
        merged: list[list[float]] = []
        for box in boxes:
            # absorb every merged box that overlaps this one, until none does
            while True:
                hit = next((m for m in merged if box[0] <= m[1] and m[0] <= box[1]
                            and box[2] <= m[3] and m[2] <= box[3]), None)
                if hit is None:
                    break
                merged.remove(hit)
                box = [min(box[0], hit[0]), max(box[1], hit[1]), min(box[2], hit[2]), max(box[3], hit[3])]
            merged.append(box)
        res = self.resolution_m
        out = []
        for x_min, x_max, y_min, y_max in merged:
            x0 = math.floor(x_min / res) * res - res
            y0 = math.floor(y_min / res) * res - res
            ncol = int(math.ceil((x_max + res - x0) / res)) + 1
            nrow = int(math.ceil((y_max + res - y0) / res)) + 1
            xs = x0 + res * np.arange(ncol)
            ys = y0 + res * np.arange(nrow)
            heights = self.height(xs[None, :], ys[:, None])
            out.append(HeightField(heights_m=heights, x_min_m=x0, y_min_m=y0, resolution_m=res))
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
            for key in given:
                if not isinstance(item[key], (int, float)) or isinstance(item[key], bool):
                    raise ValueError(f"{label} ({kind}): field {key!r} must be a number, got {item[key]!r}")
            feature = cls(**{k: float(item[k]) for k in given})
            try:
                feature.check()
            except ValueError as exc:
                raise ValueError(f"{label}: {exc}") from None
            features.append(feature)
        if not (math.isfinite(resolution_m) and 0.02 <= resolution_m <= 5.0):
            raise ValueError(f"{where}: resolution_m must be in [0.02, 5] m, got {resolution_m}")
        return Terrain(features=tuple(features), resolution_m=resolution_m)
