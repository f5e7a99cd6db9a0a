"""The virtual GNSS receiver: position and velocity fixes from the true motion, 1–10 Hz.

The receiver takes the true position and velocity of its antenna in the route's local ENU
frame at the physics rate and returns fixes at its own update rate, streaming like the
MPU-9250 (:mod:`biso_cosim.sensors.mpu9250`)::

    rx = GnssReceiver("consumer", seed=0, rate_hz=5.0, site=route.site, outages=(
        ZoneOutage((400.0, -20.0), (400.0, 20.0), 8.0, label="bridge"),
        TimeOutage(120.0, 135.0, label="tunnel")))
    fixes = rx.simulate(pos_w, vel_w)     # (n, 3) m and m/s at input_rate_hz; k fixes (k may be 0)
    fixes.t_s, fixes.t_arrival_s, fixes.pos_w, fixes.vel_w, fixes.lat_deg, fixes.valid

Model, per ENU axis (horizontal axes E, N alike; Up with its own numbers)::

    p_fix(t_j) = p(t_j) + b_p(t_j) + w_p,    v_fix(t_j) = v(t_j) + b_v(t_j) + w_v
    b(t_{j+1}) = φ b(t_j) + σ_gm √(1 − φ²) ξ,   φ = exp(−Δt / τ)          (first-order Gauss–Markov)
    w ~ N(0, σ_white²) independent at each fix

* Epochs (times of validity) are ``t_j = j / rate_hz`` on the input clock (input sample i is
  at ``i / input_rate_hz`` since the last reset); the truth is interpolated linearly between
  input samples. The correlated parts start in their stationary distribution.
* **Latency**: a fix is computed at its epoch and delivered ``latency_s`` later
  (``t_arrival_s``); a ``simulate`` call returns the fixes delivered during its input span,
  i.e. whose arrival lies in ``(t_first − 1/input_rate_hz, t_last]`` of its samples (a fix is
  delivered at the first input sample at or after its arrival). ``t_s`` stays the time of
  validity: a consumer of the fix aligns it with its own data by ``t_s``.
* **Outages**: :class:`TimeOutage` (a time window) and :class:`ZoneOutage` (a region of the
  ground: the points within ``half_width_m`` of a segment, e.g. a tunnel or the road under a
  bridge, tested on the true horizontal position at the epoch). During an outage, and for
  ``reacquisition_s`` after it (the receiver's hot-start time to first fix), the epochs are
  still reported, with ``valid = False`` and NaN in every value: a log shows the gap at the
  receiver's rate. The noise processes run on through an outage (same draws whatever the
  outages, so one seed gives comparable runs with and without them).
* Random numbers: xoshiro256++ with ziggurat normals (``sensors._rng``) held in the state,
  twelve draws per epoch: any chunking of the input gives the same fixes, bit for bit.

Profiles (:data:`GNSS_PROFILES`): ``"consumer"`` (a u-blox M8-class single-frequency
receiver in open sky; every number with its source in :data:`CONSUMER`) and ``"ideal"``
(no errors, no latency). Pass a :class:`GnssProfile` for other receivers, e.g.
``dataclasses.replace(CONSUMER, latency_s=0.0)``.

Not modelled: the antenna's lever arm from the IMU (the truth given is the antenna's),
the receiver's own navigation filter lag, multipath bursts and partial degradation
(urban canyons), quantisation of the message fields, clock steering.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Sequence

import numpy as np

from biso_cosim._numba import jit
from biso_cosim.sensors._rng import _normal, seed_state
from biso_cosim.sensors.mpu9250 import _check_seed

__all__ = [
    "GnssReceiver",
    "GnssFixes",
    "GnssProfile",
    "TimeOutage",
    "ZoneOutage",
    "GNSS_PROFILES",
    "FIX_LAYOUT",
    "GnssLoopArrays",
    "CONSUMER",
    "IDEAL",
    "gnss_profile_table",
]

MAX_LATENCY_S = 1.0
"""Largest latency a profile may have (bounds the queue of fixes computed but not yet delivered)."""

RATE_RANGE_HZ = (1.0, 10.0)
"""Update rates the receiver accepts (consumer receivers offer 1–10 Hz)."""


# --------------------------------------------------------------------------------------
# Profiles
# --------------------------------------------------------------------------------------


def _spec(*, symbol: str, unit: str, doc: str) -> Any:
    """A profile field with its documentation (the source is per profile, in ``sources``)."""
    return field(metadata={"symbol": symbol, "unit": unit, "doc": doc})


@dataclass(frozen=True)
class GnssProfile:
    """Error model of a receiver. Each value is per axis: ``(horizontal, vertical)`` pairs
    apply to East and North alike, and to Up. ``sources`` names where each number comes from."""

    name: str = field(metadata={"symbol": "", "unit": "", "doc": "profile name"})
    description: str = field(metadata={"symbol": "", "unit": "", "doc": "one line"})
    pos_white_m: tuple[float, float] = _spec(
        symbol="σ_pw", unit="m", doc="white position noise per axis (horizontal, vertical)")
    pos_gm_m: tuple[float, float] = _spec(
        symbol="σ_pc", unit="m", doc="correlated position error per axis, stationary σ (horizontal, vertical)")
    pos_gm_tau_s: float = _spec(symbol="τ_p", unit="s", doc="correlation time of the position error")
    vel_white_mps: tuple[float, float] = _spec(
        symbol="σ_vw", unit="m/s", doc="white velocity noise per axis (horizontal, vertical)")
    vel_gm_mps: tuple[float, float] = _spec(
        symbol="σ_vc", unit="m/s", doc="correlated velocity error per axis, stationary σ (horizontal, vertical)")
    vel_gm_tau_s: float = _spec(symbol="τ_v", unit="s", doc="correlation time of the velocity error")
    latency_s: float = _spec(symbol="L", unit="s", doc="delay from the time of validity to the delivery of a fix")
    reacquisition_s: float = _spec(
        symbol="t_acq", unit="s", doc="time after an outage before fixes are valid again (hot start)")
    sources: dict[str, str] = field(default_factory=dict, compare=False,
                                    metadata={"symbol": "", "unit": "", "doc": "field → source"})

    def __post_init__(self) -> None:
        for name in ("pos_white_m", "pos_gm_m", "vel_white_mps", "vel_gm_mps"):
            value = getattr(self, name)
            if (not isinstance(value, (tuple, list)) or len(value) != 2
                    or not all(_finite_number(v) and v >= 0.0 for v in value)):
                raise ValueError(f"GnssProfile.{name} must be two finite numbers >= 0 (horizontal, vertical), "
                                 f"got {value!r}")
            object.__setattr__(self, name, (float(value[0]), float(value[1])))
        for name in ("pos_gm_tau_s", "vel_gm_tau_s"):
            if not (_finite_number(getattr(self, name)) and getattr(self, name) > 0.0):
                raise ValueError(f"GnssProfile.{name} must be a positive number of seconds, got {getattr(self, name)!r}")
        if not (_finite_number(self.latency_s) and 0.0 <= self.latency_s <= MAX_LATENCY_S):
            raise ValueError(f"GnssProfile.latency_s must be in [0, {MAX_LATENCY_S}] s, got {self.latency_s!r}")
        if not (_finite_number(self.reacquisition_s) and self.reacquisition_s >= 0.0):
            raise ValueError(f"GnssProfile.reacquisition_s must be >= 0 s, got {self.reacquisition_s!r}")

    @property
    def vel_sigma_mps(self) -> tuple[float, float]:
        """Total velocity error σ per axis (horizontal, vertical): white and correlated parts."""
        return tuple(math.hypot(w, c) for w, c in zip(self.vel_white_mps, self.vel_gm_mps))  # type: ignore[return-value]

    @property
    def pos_sigma_m(self) -> tuple[float, float]:
        """Total position error σ per axis (horizontal, vertical)."""
        return tuple(math.hypot(w, c) for w, c in zip(self.pos_white_m, self.pos_gm_m))  # type: ignore[return-value]


def _finite_number(x: Any) -> bool:
    return (not isinstance(x, bool)) and isinstance(x, (int, float, np.integer, np.floating)) and math.isfinite(x)


_UBLOX = "u-blox NEO-M8 data sheet (UBX-15031086)"
CONSUMER = GnssProfile(
    name="consumer",
    description="single-frequency consumer receiver (u-blox M8 class), open sky; assumptions labelled",
    pos_white_m=(0.7, 1.0),
    pos_gm_m=(2.0, 3.0),
    pos_gm_tau_s=60.0,
    vel_white_mps=(0.035, 0.05),
    vel_gm_mps=(0.024, 0.035),
    vel_gm_tau_s=10.0,
    latency_s=0.1,
    reacquisition_s=1.0,
    sources={
        "pos_white_m": f"{_UBLOX}: horizontal accuracy 2.5 m CEP → 2.12 m per axis (CEP = 1.177σ), split "
                       "into 2.0 m correlated and 0.7 m white (assumption); vertical 1.5× horizontal (assumption)",
        "pos_gm_m": "the 2.12 m per axis of the data sheet, mostly slow: position errors of stationary "
                    "single-frequency receivers are strongly autocorrelated (Sensors 20(21):6050, 2020)",
        "pos_gm_tau_s": "assumption: autocorrelation of consumer-receiver horizontal errors bends at about "
                        "1 min (D. L. Wilson, 'GPS accuracy', erols.com/dlwilson/gpscorr.htm)",
        "vel_white_mps": f"{_UBLOX}: velocity accuracy 0.05 m/s (50 % at 30 m/s) → 0.042 m/s per "
                         "horizontal axis (median of a 2-D error = 1.177σ), split 0.035 white + 0.024 "
                         "correlated (assumption); vertical 1.5× horizontal (assumption)",
        "vel_gm_mps": "see vel_white_mps (assumption: the receiver's navigation filter correlates part of the "
                      "Doppler velocity error)",
        "vel_gm_tau_s": "assumption",
        "latency_s": "assumption: order of the output delay of consumer receivers at 5 Hz; not specified "
                     "by u-blox",
        "reacquisition_s": f"{_UBLOX}: time to first fix, hot start 1 s",
    },
)
"""The default receiver: a consumer single-frequency GNSS module in open sky."""

IDEAL = GnssProfile(
    name="ideal", description="no errors, no latency, immediate reacquisition",
    pos_white_m=(0.0, 0.0), pos_gm_m=(0.0, 0.0), pos_gm_tau_s=60.0,
    vel_white_mps=(0.0, 0.0), vel_gm_mps=(0.0, 0.0), vel_gm_tau_s=10.0,
    latency_s=0.0, reacquisition_s=0.0,
    sources={k: "ideal" for k in ("pos_white_m", "pos_gm_m", "pos_gm_tau_s", "vel_white_mps", "vel_gm_mps",
                                   "vel_gm_tau_s", "latency_s", "reacquisition_s")},
)
"""A perfect receiver (tests, and isolating the estimator's own errors)."""

GNSS_PROFILES: dict[str, GnssProfile] = {"consumer": CONSUMER, "ideal": IDEAL}
"""Receiver profiles by name."""


def gnss_profile_table(profile: GnssProfile | str = "consumer") -> list[dict[str, Any]]:
    """Rows ``{name, symbol, unit, value, doc, source}`` of a profile (docs/gnss.md is drawn from it)."""
    prof = GNSS_PROFILES[profile] if isinstance(profile, str) else profile
    rows = []
    for f in dataclasses.fields(GnssProfile):
        if f.name in ("name", "description", "sources"):
            continue
        rows.append({"name": f.name, "symbol": f.metadata["symbol"], "unit": f.metadata["unit"],
                     "value": getattr(prof, f.name), "doc": f.metadata["doc"],
                     "source": prof.sources.get(f.name, "")})
    return rows


# --------------------------------------------------------------------------------------
# Outages
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TimeOutage:
    """No fix from ``start_s`` to ``end_s`` (times of validity, s since the receiver's reset)."""

    start_s: float
    end_s: float
    label: str = ""

    def __post_init__(self) -> None:
        if not (_finite_number(self.start_s) and _finite_number(self.end_s) and self.end_s > self.start_s):
            raise ValueError(f"TimeOutage needs finite start_s < end_s, got {self.start_s!r}, {self.end_s!r}")


@dataclass(frozen=True)
class ZoneOutage:
    """No fix while the antenna is within ``half_width_m`` (horizontally) of the segment from
    ``start_w`` to ``end_w`` (x East, y North in m, local ENU): a tunnel or the road under a
    bridge. A zero-length segment is a disc."""

    start_w: tuple[float, float]
    end_w: tuple[float, float]
    half_width_m: float
    label: str = ""

    def __post_init__(self) -> None:
        for name in ("start_w", "end_w"):
            v = getattr(self, name)
            if not (isinstance(v, (tuple, list, np.ndarray)) and len(v) == 2 and all(_finite_number(x) for x in v)):
                raise ValueError(f"ZoneOutage.{name} must be two finite numbers (x East, y North in m), got {v!r}")
            object.__setattr__(self, name, (float(v[0]), float(v[1])))
        if not (_finite_number(self.half_width_m) and self.half_width_m > 0.0):
            raise ValueError(f"ZoneOutage.half_width_m must be > 0 m, got {self.half_width_m!r}")

    def contains(self, xy: Any) -> np.ndarray:
        """(n,) bool: which of the points ``xy`` (n, 2) lie in the zone (the kernel's test)."""
        p = np.atleast_2d(np.asarray(xy, dtype=np.float64))
        out = np.empty(p.shape[0], dtype=np.bool_)
        z = np.array([[*self.start_w, *self.end_w, self.half_width_m]])
        for i in range(p.shape[0]):
            out[i] = _in_zones(z, p[i, 0], p[i, 1])
        return out


# --------------------------------------------------------------------------------------
# Fixes
# --------------------------------------------------------------------------------------


@dataclass
class GnssFixes:
    """The fixes of one ``simulate`` call (k fixes, k may be 0), or fixes from a log.

    Attributes:
        t_s: (k,) time of validity, s, on the IMU's clock.
        t_arrival_s: (k,) when the fix was delivered (t_s + latency).
        pos_w: (k, 3) antenna position in the local ENU frame, m (NaN when not valid).
        vel_w: (k, 3) antenna velocity, ENU, m/s (NaN when not valid).
        lat_deg, lon_deg, alt_m: (k,) the position as WGS-84 latitude, longitude, height.
        valid: (k,) bool: a fix; False during outages and reacquisition.
    """

    t_s: np.ndarray
    t_arrival_s: np.ndarray
    pos_w: np.ndarray
    vel_w: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    valid: np.ndarray

    def __len__(self) -> int:
        return int(np.shape(self.t_s)[0])

    @classmethod
    def empty(cls) -> "GnssFixes":
        z = np.empty(0)
        return cls(z, z.copy(), np.empty((0, 3)), np.empty((0, 3)), z.copy(), z.copy(), z.copy(),
                   np.empty(0, dtype=np.bool_))

    @classmethod
    def from_arrays(cls, t_s: Any, vel_w: Any, *, pos_w: Any = None, valid: Any = None,
                    t_arrival_s: Any = None) -> "GnssFixes":
        """Fixes from a log: times of validity and ENU velocities (what the GNSS-aided
        estimators use); position, validity and arrival times optional (default NaN, all
        valid, arrival = validity). Shapes are checked; values are checked by the consumer."""
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        k = t.shape[0]
        v = np.asarray(vel_w, dtype=np.float64)
        if v.shape != (k, 3):
            raise ValueError(f"vel_w must have shape ({k}, 3) like t_s, got {v.shape}")
        p = np.full((k, 3), np.nan) if pos_w is None else np.asarray(pos_w, dtype=np.float64)
        if p.shape != (k, 3):
            raise ValueError(f"pos_w must have shape ({k}, 3) like t_s, got {p.shape}")
        ok = np.ones(k, dtype=np.bool_) if valid is None else np.asarray(valid, dtype=np.bool_)
        if ok.shape != (k,):
            raise ValueError(f"valid must have shape ({k},) like t_s, got {ok.shape}")
        ta = t.copy() if t_arrival_s is None else np.asarray(t_arrival_s, dtype=np.float64).reshape(-1)
        if ta.shape != (k,):
            raise ValueError(f"t_arrival_s must have shape ({k},) like t_s, got {ta.shape}")
        nan = np.full(k, np.nan)
        return cls(t, ta, p, v, nan, nan.copy(), nan.copy(), ok)

    @classmethod
    def concatenate(cls, parts: Sequence["GnssFixes"]) -> "GnssFixes":
        """One record from consecutive ones (e.g. the outputs of streaming calls)."""
        parts = list(parts)
        if not parts:
            return cls.empty()
        return cls(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in dataclasses.fields(cls)))

    CSV_COLUMNS = ("t_s", "t_arrival_s", "pos_e_m", "pos_n_m", "pos_u_m", "vel_e_mps", "vel_n_mps", "vel_u_mps",
                   "lat_deg", "lon_deg", "alt_m", "valid")
    """Columns of :meth:`write_csv`; :meth:`read_csv` needs ``t_s`` and the three velocities only."""

    def write_csv(self, path: Any) -> Any:
        """Write the fixes as CSV (:attr:`CSV_COLUMNS`, one row per fix); returns the path."""
        from pathlib import Path

        path = Path(path)
        cols = np.column_stack([self.t_s, self.t_arrival_s, self.pos_w, self.vel_w, self.lat_deg, self.lon_deg,
                                self.alt_m, self.valid.astype(np.float64)])
        np.savetxt(path, cols, delimiter=",", header=",".join(self.CSV_COLUMNS), comments="",
                   fmt=["%.6f"] * 2 + ["%.4f"] * 6 + ["%.9f"] * 2 + ["%.4f", "%d"])
        return path

    @classmethod
    def read_csv(cls, path: Any) -> "GnssFixes":
        """Fixes from a CSV with a header row: ``t_s`` and ``vel_e_mps``, ``vel_n_mps``, ``vel_u_mps``
        required, the other :attr:`CSV_COLUMNS` optional (``valid`` 0/1; missing: all valid;
        ``t_arrival_s`` missing: the time of validity). Unknown columns are an error."""
        import csv

        with open(path, newline="") as fh:
            header = [h.strip() for h in next(csv.reader(fh))]
        unknown = sorted(set(header) - set(cls.CSV_COLUMNS))
        if unknown:
            raise ValueError(f"{path}: unknown GNSS column(s) {unknown}; known: {', '.join(cls.CSV_COLUMNS)}")
        missing = [c for c in ("t_s", "vel_e_mps", "vel_n_mps", "vel_u_mps") if c not in header]
        if missing:
            raise ValueError(f"{path}: GNSS column(s) {missing} are required")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        col = {name: data[:, i] for i, name in enumerate(header)}
        out = cls.from_arrays(col["t_s"], np.column_stack([col["vel_e_mps"], col["vel_n_mps"], col["vel_u_mps"]]),
                              pos_w=(np.column_stack([col["pos_e_m"], col["pos_n_m"], col["pos_u_m"]])
                                     if all(c in col for c in ("pos_e_m", "pos_n_m", "pos_u_m")) else None),
                              valid=(col["valid"] != 0.0) if "valid" in col else None,
                              t_arrival_s=col.get("t_arrival_s"))
        for name in ("lat_deg", "lon_deg", "alt_m"):
            if name in col:
                setattr(out, name, col[name])
        return out

    def __getitem__(self, index: Any) -> "GnssFixes":
        """A subset of the fixes (slice, boolean mask or index array)."""
        return GnssFixes(*(np.atleast_1d(getattr(self, f.name)[index]) if getattr(self, f.name).ndim == 1
                           else np.atleast_2d(getattr(self, f.name)[index]) for f in dataclasses.fields(self)))


# --------------------------------------------------------------------------------------
# Kernel
# --------------------------------------------------------------------------------------

class FixLayout(NamedTuple):
    """Where each quantity sits in a fix row (the receiver's output rows, ``GnssFixes`` in
    one (m, width) array: the co-simulation's ``PeriodSamples.gnss``): the first column of each."""

    t_s: int = 0
    t_arrival_s: int = 1
    pos_w: int = 2  # (3) ENU, m
    vel_w: int = 5  # (3) ENU, m/s
    valid: int = 8  # 1.0 a fix, 0.0 an epoch without one
    width: int = 9


FIX_LAYOUT = FixLayout()
"""The columns of a fix row (``FixLayout``)."""


# coefficients
(_C_FIN, _C_RATE, _C_LAT, _C_ACQ, _C_PHI_P, _C_PHI_V) = range(6)
_C_SIG = 6  # stationary σ of the correlated parts: pos (h, h, v), vel (h, h, v)
_C_DRV = 12  # their drive σ√(1 − φ²)
_C_WHITE = 18  # white σ: pos (h, h, v), vel (h, h, v)
_C_SIZE = 24

# state
_S_N, _S_EPOCH, _S_STARTED, _S_ACQ_UNTIL, _S_PENDING = range(5)
_S_PREV = 5  # last input sample: pos (3), vel (3)
_S_GM = 11  # correlated errors: pos (3), vel (3)
_S_QUEUE = 17
_Q_COLS = FIX_LAYOUT.width  # a fix row (FIX_LAYOUT)
_Q_CAP = 16
_S_SIZE = _S_QUEUE + _Q_COLS * _Q_CAP


@jit
def _in_zones(zones, x, y):
    """Whether (x, y) lies within half-width zones[k, 4] of a segment zones[k, 0:4]."""
    for k in range(zones.shape[0]):
        ax, ay, bx, by, hw = zones[k, 0], zones[k, 1], zones[k, 2], zones[k, 3], zones[k, 4]
        dx, dy = bx - ax, by - ay
        d2 = dx * dx + dy * dy
        u = 0.0
        if d2 > 0.0:
            u = ((x - ax) * dx + (y - ay) * dy) / d2
            u = min(1.0, max(0.0, u))
        ex, ey = x - (ax + u * dx), y - (ay + u * dy)
        if ex * ex + ey * ey <= hw * hw:
            return True
    return False


@jit
def _in_windows(windows, t):
    for k in range(windows.shape[0]):
        if windows[k, 0] <= t < windows[k, 1]:
            return True
    return False


@jit
def _epoch(c, st, rng, zones, windows, t_j, px, py, pz, vx, vy, vz):
    """Compute the fix of epoch t_j from the true antenna state and append it to the queue."""
    if st[_S_STARTED] == 0.0:  # correlated errors start stationary
        for a in range(6):
            st[_S_GM + a] = c[_C_SIG + a] * _normal(rng)
        st[_S_STARTED] = 1.0
    else:
        for a in range(3):
            st[_S_GM + a] = c[_C_PHI_P] * st[_S_GM + a] + c[_C_DRV + a] * _normal(rng)
        for a in range(3, 6):
            st[_S_GM + a] = c[_C_PHI_V] * st[_S_GM + a] + c[_C_DRV + a] * _normal(rng)
    w0, w1, w2 = c[_C_WHITE] * _normal(rng), c[_C_WHITE + 1] * _normal(rng), c[_C_WHITE + 2] * _normal(rng)
    w3, w4, w5 = c[_C_WHITE + 3] * _normal(rng), c[_C_WHITE + 4] * _normal(rng), c[_C_WHITE + 5] * _normal(rng)
    white = (w0, w1, w2, w3, w4, w5)
    blocked = _in_windows(windows, t_j) or _in_zones(zones, px, py)
    if blocked:
        st[_S_ACQ_UNTIL] = t_j + c[_C_ACQ]
    valid = (not blocked) and t_j >= st[_S_ACQ_UNTIL]
    row = _S_QUEUE + _Q_COLS * int(st[_S_PENDING])
    st[row], st[row + 1] = t_j, t_j + c[_C_LAT]
    truth = (px, py, pz, vx, vy, vz)
    for a in range(6):
        st[row + 2 + a] = truth[a] + st[_S_GM + a] + white[a] if valid else np.nan
    st[row + 8] = 1.0 if valid else 0.0
    st[_S_PENDING] += 1.0


@jit
def _deliver(st, t, out, k):
    """Move the queued fixes with arrival <= t to out[k:]; returns the new k."""
    n = int(st[_S_PENDING])
    done = 0
    while done < n and st[_S_QUEUE + _Q_COLS * done + 1] <= t + 1e-12:
        for a in range(_Q_COLS):
            out[k, a] = st[_S_QUEUE + _Q_COLS * done + a]
        k += 1
        done += 1
    if done:
        for i in range(n - done):
            for a in range(_Q_COLS):
                st[_S_QUEUE + _Q_COLS * i + a] = st[_S_QUEUE + _Q_COLS * (i + done) + a]
        st[_S_PENDING] = n - done
    return k


@jit
def _gnss_simulate(c, st, rng, zones, windows, pos, vel, out):
    """Advance the receiver over the input samples; returns the number of fixes in ``out``."""
    f_in, rate = c[_C_FIN], c[_C_RATE]
    k = 0
    for i in range(pos.shape[0]):
        n = st[_S_N]
        t = n / f_in
        # epochs in (t − 1/f_in, t]: interpolate between the previous sample and this one
        while True:
            t_j = st[_S_EPOCH] / rate
            if t_j > t + 1e-12:
                break
            if n == 0.0 or t_j >= t - 1e-12:
                u = 1.0
            else:
                u = (t_j - (n - 1.0) / f_in) * f_in
            s = 1.0 - u
            _epoch(c, st, rng, zones, windows, t_j,
                   s * st[_S_PREV] + u * pos[i, 0], s * st[_S_PREV + 1] + u * pos[i, 1],
                   s * st[_S_PREV + 2] + u * pos[i, 2], s * st[_S_PREV + 3] + u * vel[i, 0],
                   s * st[_S_PREV + 4] + u * vel[i, 1], s * st[_S_PREV + 5] + u * vel[i, 2])
            st[_S_EPOCH] += 1.0
        k = _deliver(st, t, out, k)
        for a in range(3):
            st[_S_PREV + a] = pos[i, a]
            st[_S_PREV + 3 + a] = vel[i, a]
        st[_S_N] = n + 1.0
    return k


@jit
def _receiver_check(arrays, pos, vel):
    """Whether the receiver takes these input rows (every position and velocity finite): the
    loop's check before the period's chip runs (``GnssReceiver.loop_check``)."""
    for i in range(pos.shape[0]):
        for a in range(3):
            if not (math.isfinite(pos[i, a]) and math.isfinite(vel[i, a])):
                return False
    return True


@jit
def _receiver_loop(arrays, pos, vel):
    """``GnssReceiver.simulate_rows`` on checked rows in the period call: the fixes delivered
    into ``arrays.fixes``; returns their number."""
    return _gnss_simulate(arrays.coef, arrays.state, arrays.rng, arrays.zones, arrays.windows, pos, vel, arrays.fixes)


class GnssLoopArrays(NamedTuple):
    """The receiver's arrays in the co-simulation's period call (``GnssReceiver.loop_arrays``):
    coefficients, state and random stream (advanced in place), outage zones and windows, and
    the output fix rows (``FIX_LAYOUT``) of one call."""

    coef: np.ndarray
    state: np.ndarray
    rng: np.ndarray
    zones: np.ndarray
    windows: np.ndarray
    fixes: np.ndarray


# --------------------------------------------------------------------------------------
# The receiver
# --------------------------------------------------------------------------------------


def _rows3(name: str, value: Any) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be an array of real numbers, got {type(value).__name__}") from None
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {a.shape}")
    return a if a.flags.c_contiguous else np.ascontiguousarray(a)


class GnssReceiver:
    """A virtual GNSS receiver (see the module docstring for the model).

    Args:
        profile: ``"consumer"``, ``"ideal"`` or a :class:`GnssProfile`.
        seed: int or None (fresh entropy); the same seed gives the same fixes, bit for bit.
        rate_hz: update rate, 1–10 Hz.
        site: where the local ENU origin lies (anything with ``lat_deg``, ``lon_deg``,
            ``alt_m``, e.g. ``biso_cosim.routes.Site`` or a route's ``site``); None = the
            default site (Saratov).
        input_rate_hz: rate of the truth arrays given to :meth:`simulate`.
        outages: :class:`TimeOutage` and :class:`ZoneOutage` objects.
    """

    def __init__(self, profile: GnssProfile | str = "consumer", *, seed: int | None = 0, rate_hz: float = 5.0,
                 site: Any = None, input_rate_hz: float = 1000.0, outages: Sequence[Any] = ()) -> None:
        if isinstance(profile, str):
            if profile not in GNSS_PROFILES:
                raise ValueError(f"unknown GNSS profile {profile!r}; known: {', '.join(GNSS_PROFILES)}")
            profile = GNSS_PROFILES[profile]
        if not isinstance(profile, GnssProfile):
            raise TypeError(f"profile must be a profile name or a GnssProfile, got {type(profile).__name__}")
        self.profile = profile
        _check_seed(seed)
        for name, value in (("rate_hz", rate_hz), ("input_rate_hz", input_rate_hz)):
            if not _finite_number(value):
                raise TypeError(f"{name} must be a finite number, got {value!r}")
        if not RATE_RANGE_HZ[0] <= rate_hz <= RATE_RANGE_HZ[1]:
            raise ValueError(f"rate_hz must be in [{RATE_RANGE_HZ[0]:g}, {RATE_RANGE_HZ[1]:g}] Hz, got {rate_hz}")
        if not input_rate_hz >= rate_hz:
            raise ValueError(f"input_rate_hz must be at least rate_hz ({rate_hz}), got {input_rate_hz}")
        self.rate_hz, self.input_rate_hz = float(rate_hz), float(input_rate_hz)
        if site is None:
            from biso_cosim.routes.route import Site

            site = Site()
        try:
            self.origin = (float(site.lat_deg), float(site.lon_deg), float(site.alt_m))
        except (AttributeError, TypeError, ValueError):
            raise TypeError(f"site must have numeric lat_deg, lon_deg, alt_m (e.g. a routes.Site), got {site!r}") from None
        if not (-90.0 <= self.origin[0] <= 90.0 and -180.0 <= self.origin[1] <= 180.0):
            raise ValueError(f"site latitude/longitude out of range: {self.origin[:2]}")
        self.site = site
        self.outages = tuple(outages)
        zones, windows = [], []
        for o in self.outages:
            if isinstance(o, ZoneOutage):
                zones.append([*o.start_w, *o.end_w, o.half_width_m])
            elif isinstance(o, TimeOutage):
                windows.append([o.start_s, o.end_s])
            else:
                raise TypeError(f"outages must be TimeOutage or ZoneOutage objects, got {type(o).__name__}")
        self._zones = np.array(zones, dtype=np.float64).reshape(-1, 5)
        self._windows = np.array(windows, dtype=np.float64).reshape(-1, 2)
        self._coef = self._coefficients()
        self._seed = seed
        self._seed_sequence = np.random.SeedSequence(seed)
        self.arrays_version = 0
        """Counts the replacements of the state arrays (``loop_arrays``): reset, set_state."""
        self._new_state()

    def _coefficients(self) -> np.ndarray:
        p, dt = self.profile, 1.0 / self.rate_hz
        c = np.zeros(_C_SIZE)
        c[_C_FIN], c[_C_RATE], c[_C_LAT], c[_C_ACQ] = self.input_rate_hz, self.rate_hz, p.latency_s, p.reacquisition_s
        phi_p, phi_v = math.exp(-dt / p.pos_gm_tau_s), math.exp(-dt / p.vel_gm_tau_s)
        c[_C_PHI_P], c[_C_PHI_V] = phi_p, phi_v
        sig = [p.pos_gm_m[0], p.pos_gm_m[0], p.pos_gm_m[1], p.vel_gm_mps[0], p.vel_gm_mps[0], p.vel_gm_mps[1]]
        c[_C_SIG:_C_SIG + 6] = sig
        c[_C_DRV:_C_DRV + 3] = np.array(sig[:3]) * math.sqrt(1.0 - phi_p * phi_p)
        c[_C_DRV + 3:_C_DRV + 6] = np.array(sig[3:]) * math.sqrt(1.0 - phi_v * phi_v)
        c[_C_WHITE:_C_WHITE + 6] = [p.pos_white_m[0], p.pos_white_m[0], p.pos_white_m[1],
                                    p.vel_white_mps[0], p.vel_white_mps[0], p.vel_white_mps[1]]
        return c

    def _new_state(self) -> None:
        self._state = np.zeros(_S_SIZE)
        self._rng = seed_state(self._seed_sequence)
        self.arrays_version += 1

    # ---- public ------------------------------------------------------------------------

    @property
    def time_s(self) -> float:
        """Time of the next input sample the stream expects."""
        return self._state[_S_N] / self.input_rate_hz

    @property
    def seed_entropy(self) -> int | list[int]:
        """The entropy of the seed sequence (equal to ``seed`` when one was given)."""
        return self._seed_sequence.entropy

    def reset(self, seed: int | None = None) -> None:
        """Back to time 0: the same noise stream starts again; with an int ``seed``, a new one."""
        if seed is not None:
            _check_seed(seed)
            self._seed = seed
            self._seed_sequence = np.random.SeedSequence(seed)
        self._new_state()

    def get_state(self) -> dict[str, np.ndarray]:
        """A copy of the whole dynamic state (clock, noise processes, queue, random stream)."""
        return {"state": self._state.copy(), "rng": self._rng.copy()}

    def set_state(self, state: dict[str, np.ndarray]) -> None:
        """Restore a state from :meth:`get_state` of a receiver with the same settings."""
        try:
            s, r = np.asarray(state["state"], dtype=np.float64), np.asarray(state["rng"])
        except (KeyError, TypeError):
            raise ValueError("state must be a dict from get_state() with keys 'state' and 'rng'") from None
        if s.shape != (_S_SIZE,) or r.shape != (4,) or r.dtype != np.uint64:
            raise ValueError("state does not come from GnssReceiver.get_state()")
        self._state, self._rng = s.copy(), r.copy()
        self.arrays_version += 1

    def simulate(self, pos_w: Any, vel_w: Any) -> GnssFixes:
        """Run the receiver over the next input samples; return the fixes delivered meanwhile.

        Args:
            pos_w: (n, 3) true antenna position in the local ENU frame, m.
            vel_w: (n, 3) true antenna velocity, ENU, m/s.

        Input sample i of the stream is the truth at ``i / input_rate_hz`` since the reset.
        A refused call (wrong shape, non-finite values) changes nothing.
        """
        return self.fixes_of(self.simulate_rows(pos_w, vel_w))

    def simulate_rows(self, pos_w: Any, vel_w: Any) -> np.ndarray:
        """``simulate`` without the record: the fixes as (m, 9) rows (``FIX_LAYOUT``), without
        the geodetic position (``fixes_of`` adds it)."""
        p, v = _rows3("pos_w", pos_w), _rows3("vel_w", vel_w)
        if p.shape[0] != v.shape[0]:
            raise ValueError(f"pos_w and vel_w must have the same number of rows, got {p.shape[0]} and {v.shape[0]}")
        for name, a in (("pos_w", p), ("vel_w", v)):
            bad = np.flatnonzero(~np.isfinite(a).all(axis=1))
            if bad.size:
                raise ValueError(f"{name} must be finite: row {bad[0]} is not (nothing was simulated)")
        out = np.empty((self._capacity(p.shape[0]), _Q_COLS))
        k = _gnss_simulate(self._coef, self._state, self._rng, self._zones, self._windows, p, v, out)
        return out[:k]

    def _capacity(self, n: int) -> int:
        """The most fixes a call over n input samples can deliver (the queue, and the epochs)."""
        return _Q_CAP + int(math.ceil(n / self.input_rate_hz * self.rate_hz)) + 2

    def fixes_of(self, rows: np.ndarray) -> GnssFixes:
        """The record of fix rows (``simulate_rows``, or several calls' rows concatenated),
        with the WGS-84 position of each valid fix (``pymap3d.enu2geodetic`` about the site;
        element by element, so the same numbers whatever the rows are concatenated from)."""
        k = rows.shape[0]
        valid = rows[:, FIX_LAYOUT.valid] != 0.0
        lat, lon, alt = (np.full(k, np.nan) for _ in range(3))
        if valid.any():
            import pymap3d

            p = FIX_LAYOUT.pos_w
            e, nn, u = rows[valid, p], rows[valid, p + 1], rows[valid, p + 2]
            lat[valid], lon[valid], alt[valid] = pymap3d.enu2geodetic(e, nn, u, *self.origin)
        p, v = FIX_LAYOUT.pos_w, FIX_LAYOUT.vel_w
        return GnssFixes(rows[:, FIX_LAYOUT.t_s].copy(), rows[:, FIX_LAYOUT.t_arrival_s].copy(),
                         rows[:, p:p + 3].copy(), rows[:, v:v + 3].copy(), lat, lon, alt, valid)

    # ---- in the co-simulation's period call (biso_cosim.loop) --------------------------

    loop_check = _receiver_check
    """``check(arrays, pos_w, vel_w) -> bool``: whether ``simulate_rows`` would take these rows."""
    loop_kernel = _receiver_loop
    """``kernel(arrays, pos_w, vel_w) -> m``: ``simulate_rows`` on checked rows, the m fixes in
    ``arrays.fixes`` (the same arithmetic, so the same fixes bit for bit)."""

    def loop_arrays(self, n: int) -> GnssLoopArrays:
        """The arrays ``loop_kernel`` runs on for calls of n input samples: the receiver's own
        (advanced in place; ``arrays_version`` counts their replacements) and the output rows."""
        return GnssLoopArrays(self._coef, self._state, self._rng, self._zones, self._windows,
                              np.empty((self._capacity(n), _Q_COLS)))

    def __repr__(self) -> str:
        return (f"GnssReceiver(profile={self.profile.name!r}, seed={self._seed!r}, rate={self.rate_hz:g} Hz, "
                f"input={self.input_rate_hz:g} Hz, outages={len(self.outages)})")
