"""The magnetic field around the vehicle: the Earth's (WMM) plus local disturbances.

`EarthField` evaluates the World Magnetic Model with pygeomag (coefficients ship inside the
package, nothing is downloaded) at one site and date, and gives the field in ENU µT.
pygeomag returns north (X), east (Y) and down (Z) components in nT; ENU is (Y, X, −Z)/1000.

`MagneticEnvironment` adds local perturbations, each a documented field model in space
(world ENU, metres, µT):

* `Dipole`: a magnetised object (parked car, passing truck, buried pipe) as a point dipole,
  ``B = μ0/(4π)·(3(m·r̂)r̂ − m)/|r|³``, optionally moving at constant velocity;
* `SteelBeam`: a straight steel structure (bridge girder, rail, guard rail) as a row of
  dipoles magnetised along the Earth field by induction.
"""

from __future__ import annotations

import dataclasses
import datetime
import math
from typing import Any, Sequence

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.frames import _qrot_inv, quat_rotate

__all__ = ["EarthField", "MagneticEnvironment", "Dipole", "SteelBeam", "SARATOV"]

MU0_OVER_4PI_UT = 0.1
"""μ0/(4π) in µT·m³/(A·m²): the dipole field in µT of a moment in A·m² at a distance in m."""


@dataclasses.dataclass(frozen=True)
class Site:
    lat_deg: float
    lon_deg: float
    alt_m: float
    date: datetime.date


SARATOV = Site(51.53, 46.03, 50.0, datetime.date(2024, 5, 1))
"""Default site: Saratov, where Aleshkin et al. (2024) ran their car test."""


def _decimal_year(date: Any) -> float:
    if isinstance(date, datetime.datetime):
        date = date.date()
    if isinstance(date, datetime.date):
        start = datetime.date(date.year, 1, 1)
        days = (datetime.date(date.year + 1, 1, 1) - start).days
        return date.year + (date - start).days / days
    if isinstance(date, (int, float)) and not isinstance(date, bool) and math.isfinite(date):
        return float(date)
    raise TypeError(f"date must be a datetime.date, a datetime or a decimal year, got {date!r}")


class EarthField:
    """The Earth's main field from the World Magnetic Model at one site and date.

    Args:
        lat_deg: geodetic latitude, degrees north, [-90, 90].
        lon_deg: longitude, degrees east, [-180, 180].
        alt_m: altitude above the WGS 84 ellipsoid in metres, [-1000, 850000].
        date: `datetime.date` (or datetime, or decimal year) within WMM 2010-2030.

    Attributes:
        field_enu_ut: (3,) field in µT, ENU.
        declination_rad: east of true north positive.
        inclination_rad: downward positive.
        horizontal_ut, total_ut: intensities in µT.
        model: WMM release used.
    """

    def __init__(
        self,
        lat_deg: float = SARATOV.lat_deg,
        lon_deg: float = SARATOV.lon_deg,
        alt_m: float = SARATOV.alt_m,
        date: Any = SARATOV.date,
    ) -> None:
        for name, value, lo, hi in (("lat_deg", lat_deg, -90.0, 90.0), ("lon_deg", lon_deg, -180.0, 180.0), ("alt_m", alt_m, -1000.0, 850000.0)):
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
                raise TypeError(f"{name} must be a number, got {value!r}")
            if not (math.isfinite(value) and lo <= value <= hi):
                raise ValueError(f"{name} must be in [{lo:g}, {hi:g}], got {value}")
        from pygeomag import GeoMag

        year = _decimal_year(date)
        if not 2010.0 <= year < 2030.0:
            raise ValueError(f"date must lie within the WMM releases shipped with pygeomag (2010-2030), got {year:.2f}")
        geomag = GeoMag(base_year=int(year))
        result = geomag.calculate(glat=float(lat_deg), glon=float(lon_deg), alt=float(alt_m) / 1000.0, time=year)
        self.lat_deg, self.lon_deg, self.alt_m, self.date = float(lat_deg), float(lon_deg), float(alt_m), date
        self.model = geomag.model
        # pygeomag: x north, y east, z down, in nT
        self.field_enu_ut = np.array([result.y, result.x, -result.z]) / 1000.0
        self.declination_rad = math.radians(result.d)
        self.inclination_rad = math.radians(result.i)
        self.horizontal_ut = result.h / 1000.0
        self.total_ut = result.f / 1000.0

    @classmethod
    def from_enu(cls, field_enu_ut: Any) -> "EarthField":
        """A uniform field given directly in ENU µT (for tests and synthetic sites)."""
        v = np.asarray(field_enu_ut, dtype=np.float64)
        if v.shape != (3,) or not np.all(np.isfinite(v)):
            raise ValueError(f"field_enu_ut must be 3 finite numbers, got {field_enu_ut!r}")
        self = cls.__new__(cls)
        self.lat_deg = self.lon_deg = self.alt_m = math.nan
        self.date, self.model = None, "given"
        self.field_enu_ut = v.copy()
        self.horizontal_ut = float(math.hypot(v[0], v[1]))
        self.total_ut = float(np.linalg.norm(v))
        self.declination_rad = math.atan2(v[0], v[1])
        self.inclination_rad = math.atan2(-v[2], self.horizontal_ut)
        return self

    def __repr__(self) -> str:
        return (
            f"EarthField({self.model}, lat={self.lat_deg:g}°, lon={self.lon_deg:g}°, alt={self.alt_m:g} m: "
            f"|B|={self.total_ut:.2f} µT, D={math.degrees(self.declination_rad):+.2f}°, I={math.degrees(self.inclination_rad):+.2f}°)"
        )


@jit
def _rotate_into_body(q_wb, p_w, field_w, out):
    """out[k] = q_wb[k]* ∘ field_w ∘ q_wb[k] (the same world vector into each attitude).
    Returns whether every position p_w[k] is finite (the field does not depend on them, but
    a position that is not finite is refused like everywhere else)."""
    finite = True
    for k in range(q_wb.shape[0]):
        out[k, 0], out[k, 1], out[k, 2] = _qrot_inv(q_wb[k, 0], q_wb[k, 1], q_wb[k, 2], q_wb[k, 3],
                                                    field_w[0], field_w[1], field_w[2])
        finite &= math.isfinite(p_w[k, 0]) and math.isfinite(p_w[k, 1]) and math.isfinite(p_w[k, 2])
    return finite


def _points(p_w: Any, name: str = "p_w") -> tuple[np.ndarray, bool]:
    p = np.asarray(p_w, dtype=np.float64)
    single = p.ndim == 1
    p2 = p.reshape(1, 3) if single and p.shape == (3,) else p
    if p2.ndim != 2 or p2.shape[1] != 3:
        raise ValueError(f"{name} must have shape (3,) or (n, 3), got {p.shape}")
    if not np.all(np.isfinite(p2)):
        raise ValueError(f"{name} must be finite")
    return p2, single


def _times(t_s: Any, n: int) -> np.ndarray:
    if t_s is None:
        return np.zeros(n)
    t = np.asarray(t_s, dtype=np.float64)
    if t.ndim == 0:
        t = np.full(n, float(t))
    if t.shape != (n,) or not np.all(np.isfinite(t)):
        raise ValueError(f"t_s must be a number or have shape ({n},) with finite values")
    return t


def _dipole_field(r: np.ndarray, moment: np.ndarray) -> np.ndarray:
    """Field in µT at offsets r (..., 3) m from dipoles of moment (..., 3) A·m² (broadcast)."""
    dist = np.linalg.norm(r, axis=-1, keepdims=True)
    dist = np.maximum(dist, 1e-3)  # inside 1 mm the point model has no meaning; stay finite
    rhat = r / dist
    m_dot_r = np.sum(moment * rhat, axis=-1, keepdims=True)
    return MU0_OVER_4PI_UT * (3.0 * m_dot_r * rhat - moment) / dist**3


def _vector(name: str, value: Any) -> np.ndarray:
    v = np.asarray(value, dtype=np.float64)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


@dataclasses.dataclass(frozen=True)
class Dipole:
    """A point magnetic dipole: moment ``moment_am2`` (A·m², ENU) at ``position_w`` (m, ENU)
    at t = 0, moving at ``velocity_mps`` (m/s, ENU). A car is of order 100-300 A·m², a
    truck 1000-5000 A·m² (order of magnitude, an assumption)."""

    position_w: Sequence[float]
    moment_am2: Sequence[float]
    velocity_mps: Sequence[float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        for name in ("position_w", "moment_am2", "velocity_mps"):
            _vector(f"Dipole.{name}", getattr(self, name))

    def field_w(self, p_w: np.ndarray, t_s: np.ndarray, earth_enu_ut: np.ndarray) -> np.ndarray:
        """Field (n, 3) µT at points p_w (n, 3) and times t_s (n,)."""
        pos = np.asarray(self.position_w, dtype=np.float64) + t_s[:, None] * np.asarray(self.velocity_mps, dtype=np.float64)
        return _dipole_field(p_w - pos, np.asarray(self.moment_am2, dtype=np.float64))


@dataclasses.dataclass(frozen=True)
class SteelBeam:
    """A straight steel structure from ``start_w`` to ``end_w`` (m, ENU), e.g. a bridge girder.

    Modelled as ``n`` dipoles evenly along the segment, magnetised by induction along the
    Earth field: each carries ``susceptibility_am2_per_ut · B_earth(µT) · length / n`` A·m².
    ``susceptibility_am2_per_ut`` is the induced moment per metre of beam per µT of ambient
    field; the default 10 gives about 11 µT 3 m from the middle of a 40 m beam and 3 µT at
    6 m (an assumption to tune against measurements; no published value is built in).
    """

    start_w: Sequence[float]
    end_w: Sequence[float]
    susceptibility_am2_per_ut: float = 10.0
    n: int = 50

    def __post_init__(self) -> None:
        a = _vector("SteelBeam.start_w", self.start_w)
        b = _vector("SteelBeam.end_w", self.end_w)
        if np.array_equal(a, b):
            raise ValueError("SteelBeam: start_w and end_w must differ")
        if not (math.isfinite(self.susceptibility_am2_per_ut) and self.susceptibility_am2_per_ut >= 0):
            raise ValueError(f"SteelBeam.susceptibility_am2_per_ut must be >= 0, got {self.susceptibility_am2_per_ut}")
        if isinstance(self.n, bool) or not isinstance(self.n, int) or self.n < 1:
            raise ValueError(f"SteelBeam.n must be a positive int, got {self.n!r}")

    def field_w(self, p_w: np.ndarray, t_s: np.ndarray, earth_enu_ut: np.ndarray) -> np.ndarray:
        """Field (n, 3) µT at points p_w (n, 3), induced by the Earth field ``earth_enu_ut``."""
        a = np.asarray(self.start_w, dtype=np.float64)
        b = np.asarray(self.end_w, dtype=np.float64)
        length = float(np.linalg.norm(b - a))
        moment = self.susceptibility_am2_per_ut * earth_enu_ut * length / self.n
        centres = a + (b - a) * ((np.arange(self.n) + 0.5) / self.n)[:, None]
        return _dipole_field(p_w[:, None, :] - centres[None, :, :], moment).sum(axis=1)


class MagneticEnvironment:
    """The field the vehicle drives through: the Earth's field plus local disturbances.

    Args:
        earth: an `EarthField` (default: Saratov, 2024-05-01).
        disturbances: `Dipole` and `SteelBeam` objects.
    """

    def __init__(self, earth: EarthField | None = None, disturbances: Sequence[Any] = ()) -> None:
        self.earth = earth if earth is not None else EarthField()
        if not isinstance(self.earth, EarthField):
            raise TypeError(f"earth must be an EarthField, got {type(earth).__name__}")
        self.disturbances = tuple(disturbances)
        for d in self.disturbances:
            if not isinstance(d, (Dipole, SteelBeam)):
                raise TypeError(f"disturbances must be Dipole or SteelBeam objects, got {type(d).__name__}")

    def field_w(self, p_w: Any, t_s: Any = None) -> np.ndarray:
        """Field in µT, ENU, at positions ``p_w`` (n, 3) or (3,) in metres (local ENU)
        and times ``t_s`` (for moving disturbances; default 0)."""
        p, single = _points(p_w)
        t = _times(t_s, p.shape[0])
        out = np.broadcast_to(self.earth.field_enu_ut, p.shape).copy()
        for d in self.disturbances:
            out += d.field_w(p, t, self.earth.field_enu_ut)
        return out[0] if single else out

    def field_b(self, q_wb: Any, p_w: Any, t_s: Any = None) -> np.ndarray:
        """Field in µT in body axes: ``q_wb* ∘ field_w ∘ q_wb`` for attitudes ``q_wb`` (n, 4)."""
        q = np.asarray(q_wb, dtype=np.float64)
        if q.shape[-1:] != (4,) or q.ndim > 2:
            raise ValueError(f"q_wb must have shape (4,) or (n, 4), got {q.shape}")
        if not self.disturbances and q.ndim == 2:
            # the common case, once per control period in the loop: a constant world field,
            # rotated into each body attitude by one kernel call
            p = np.asarray(p_w, dtype=np.float64)
            out = np.empty((q.shape[0], 3))
            if p.shape != (q.shape[0], 3) or not _rotate_into_body(q, p, self.earth.field_enu_ut, out):
                _points(p_w)  # the error naming p_w
                raise ValueError(f"p_w must have shape ({q.shape[0]}, 3), got {p.shape}")
            return out
        field = self.field_w(p_w, t_s)
        return quat_rotate(q * np.array([1.0, -1.0, -1.0, -1.0]), field)
