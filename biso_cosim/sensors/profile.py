"""Sensor profiles: the error parameters of a virtual MPU-9250, and the errors a seed draws.

A profile is a TOML file of values in the units of the schema ``data/parameters.toml``
(datasheet units: °/s, mg, µg/√Hz, %, ...). Built-in profiles live in ``profiles/``:

* ``mpu9250``: typical datasheet values, turn-on errors drawn per seed within the
  datasheet tolerances, labelled assumptions where the datasheet is silent;
* ``ideal``: no errors, no filter, no quantization (for debugging).

A custom profile file either lists every key, or names a ``base`` profile and overrides
some keys::

    base = "mpu9250"
    [gyro]
    noise_density = 0.005            # °/s/√Hz
    bias_initial = {value = 0.05, source = "after a static calibration"}

Unknown keys and (without a base) missing keys are errors that name them. Values are
converted to SI in one place, `_SI_PER_UNIT`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from biso_cosim.units import DEG, DEG_PER_H, G0, MICRO_G, MILLI_G

__all__ = ["Profile", "DrawnErrors", "InertialErrors", "MagErrors", "profile_names", "parameter_schema"]

# Display unit -> SI factor. The one place where datasheet units become SI.
_SI_PER_UNIT = {
    "°/s/√Hz": DEG,  # -> rad/s/√Hz
    "°/s": DEG,  # -> rad/s
    "°/s/°C": DEG,  # -> rad/s/°C
    "°/h": DEG_PER_H,  # -> rad/s
    "°/h/√h": DEG_PER_H / 60.0,  # -> rad/s/√s
    "°/s/g": DEG / G0,  # -> (rad/s)/(m/s²)
    "µg/√Hz": MICRO_G,  # -> m/s²/√Hz
    "mg": MILLI_G,  # -> m/s²
    "mg/°C": MILLI_G,  # -> m/s²/°C
    "mg/√h": MILLI_G / 60.0,  # -> m/s²/√s
    "%": 0.01,
    "%/°C": 0.01,
    "%FS": 0.01,
    "µT": 1.0,
    "s": 1.0,
    "°C": 1.0,
    "code": 1.0,
    "-": 1.0,
}


@functools.cache
def parameter_schema() -> dict[str, dict[str, Any]]:
    """The schema: ``{"gyro.noise_density": {"symbol", "unit", "kind", "shape", "peers", "doc"}}``."""
    text = resources.files("biso_cosim.sensors").joinpath("data/parameters.toml").read_text("utf-8")
    raw = tomllib.loads(text)
    schema = {}
    for section, params in raw.items():
        for key, meta in params.items():
            if meta["unit"] not in _SI_PER_UNIT:
                raise RuntimeError(f"parameters.toml: unknown unit {meta['unit']!r} for {section}.{key}")
            schema[f"{section}.{key}"] = meta
    return schema


def profile_names() -> list[str]:
    """Names of the built-in profiles."""
    folder = resources.files("biso_cosim.sensors").joinpath("profiles")
    return sorted(p.name[: -len(".toml")] for p in folder.iterdir() if p.name.endswith(".toml"))


def _check_value(key: str, value: Any, meta: Mapping[str, Any], origin: str) -> Any:
    """Validate one display-unit value against the schema; return it as float/array/bool."""
    shape, kind = meta["shape"], meta["kind"]
    where = f"{origin}: {key}"
    if kind == "flag":
        if not isinstance(value, bool):
            raise ValueError(f"{where} must be true or false, got {value!r}")
        return value
    if isinstance(value, bool):
        raise ValueError(f"{where} must be a number, got {value!r}")
    arr = np.asarray(value, dtype=np.float64) if not isinstance(value, str) else None
    if arr is None or arr.dtype.kind != "f":
        raise ValueError(f"{where} must be a number, got {value!r}")
    if shape == "scalar" and arr.ndim != 0:
        raise ValueError(f"{where} must be a single number ({meta['unit']}), got {value!r}")
    if shape == "axes" and not (arr.ndim == 0 or arr.shape == (3,)):
        raise ValueError(f"{where} must be a number or a list of 3 (x, y, z) in {meta['unit']}, got {value!r}")
    if shape == "pair" and (arr.shape != (2,) or arr[0] > arr[1]):
        raise ValueError(f"{where} must be [low, high] with low <= high in {meta['unit']}, got {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{where} must be finite, got {value!r}")
    if kind in ("tolerance", "value") and key != "temperature.reference" and key != "temperature.default":
        if np.any(arr < 0):
            raise ValueError(f"{where} must be >= 0 ({meta['unit']}), got {value!r}")
    return float(arr) if arr.ndim == 0 else arr.copy()


@dataclasses.dataclass(frozen=True, eq=False)
class Profile:
    """A complete set of profile values in display units (see `parameter_schema`).

    Build with `Profile.load` (name, path or Profile) or `Profile.from_dict`; use
    `replace` to change values; `si(key)` gives a value in SI.
    """

    name: str
    description: str
    values: Mapping[str, Any]
    sources: Mapping[str, str]

    def __post_init__(self) -> None:
        schema = parameter_schema()
        unknown = sorted(set(self.values) - set(schema))
        if unknown:
            raise ValueError(f"profile {self.name!r}: unknown key(s) {unknown}; known keys: {sorted(schema)}")
        missing = sorted(set(schema) - set(self.values))
        if missing:
            raise ValueError(f"profile {self.name!r}: missing key(s) {missing} (or name a base profile)")

    # ---- construction ------------------------------------------------------------------

    @classmethod
    def load(cls, profile: "str | os.PathLike | Profile") -> "Profile":
        """A built-in profile by name, a profile TOML file by path, or the Profile itself."""
        if isinstance(profile, Profile):
            return profile
        if isinstance(profile, (str, os.PathLike)):
            text = str(profile)
            if text in profile_names():
                return _builtin(text)
            path = Path(profile)
            if path.suffix == ".toml" or path.exists():
                if not path.is_file():
                    raise FileNotFoundError(f"profile file {str(path)!r} not found")
                with open(path, "rb") as fh:
                    try:
                        data = tomllib.load(fh)
                    except tomllib.TOMLDecodeError as exc:
                        raise ValueError(f"profile file {str(path)!r}: {exc}") from None
                return cls.from_dict(data, origin=str(path), default_name=path.stem)
            raise ValueError(f"profile {text!r} is neither a built-in profile ({', '.join(profile_names())}) nor a .toml file")
        raise TypeError(f"profile must be a name, a path or a Profile, got {type(profile).__name__}")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], origin: str = "profile", default_name: str = "custom") -> "Profile":
        """A profile from the TOML structure (sections of keys; optional base, name, description)."""
        data = dict(data)
        base_name = data.pop("base", None)
        name = data.pop("name", default_name)
        description = data.pop("description", "")
        base = cls.load(base_name) if base_name is not None else None
        values = dict(base.values) if base else {}
        sources = dict(base.sources) if base else {}
        schema = parameter_schema()
        for section, params in data.items():
            if not isinstance(params, Mapping):
                raise ValueError(f"{origin}: unknown top-level key {section!r} (expected sections {sorted({k.split('.')[0] for k in schema})})")
            for key, entry in params.items():
                full = f"{section}.{key}"
                if full not in schema:
                    raise ValueError(f"{origin}: unknown key {full!r}; known keys: {sorted(schema)}")
                if isinstance(entry, Mapping):
                    extra = set(entry) - {"value", "source"}
                    if "value" not in entry or extra:
                        raise ValueError(f"{origin}: {full} must be a value or {{value = ..., source = \"...\"}}")
                    sources[full] = str(entry.get("source", ""))
                    entry = entry["value"]
                else:
                    sources[full] = f"{origin}"
                values[full] = _check_value(full, entry, schema[full], origin)
        if base is None:
            missing = sorted(set(schema) - set(values))
            if missing:
                raise ValueError(f"{origin}: missing key(s) {missing}; list them all or set base = \"mpu9250\"")
        return cls(str(name), str(description), values, sources)

    def replace(self, name: str | None = None, **values: Any) -> "Profile":
        """A copy with some values changed: ``profile.replace(gyro__noise_density=0.005)``.

        Keys are ``section__key`` (display units, see `parameter_schema`).
        """
        schema = parameter_schema()
        new_values, new_sources = dict(self.values), dict(self.sources)
        for arg, value in values.items():
            key = arg.replace("__", ".", 1)
            if key not in schema:
                raise ValueError(f"unknown profile key {key!r}; known keys: {sorted(schema)}")
            new_values[key] = _check_value(key, value, schema[key], "replace()")
            new_sources[key] = "set in code"
        return Profile(name or f"{self.name}*", self.description, new_values, new_sources)

    # ---- access ------------------------------------------------------------------------

    def si(self, key: str) -> Any:
        """Value of ``key`` in SI (rad, rad/s, m/s², µT, s, fractions for %)."""
        meta = parameter_schema()[key]
        value = self.values[key]
        if meta["kind"] == "flag" or meta["unit"] == "°C":
            return value
        return value * _SI_PER_UNIT[meta["unit"]]

    def axes(self, key: str) -> np.ndarray:
        """SI value of ``key`` as a (3,) per-axis array."""
        return np.broadcast_to(np.asarray(self.si(key), dtype=np.float64), (3,)).copy()

    def to_toml(self) -> str:
        """The profile as a complete TOML file (values and sources)."""
        sections: dict[str, list[str]] = {}
        for key in parameter_schema():
            section, name = key.split(".")
            value = self.values[key]
            if isinstance(value, bool):
                text = "true" if value else "false"
            elif isinstance(value, np.ndarray):
                text = "[" + ", ".join(repr(float(v)) for v in value) + "]"
            else:
                text = repr(float(value))
            source = self.sources.get(key, "").replace('"', "'")
            sections.setdefault(section, []).append(f'{name} = {{ value = {text}, source = "{source}" }}')
        head = [f'name = "{self.name}"', f'description = "{self.description}"']
        body = [f"\n[{s}]\n" + "\n".join(lines) for s, lines in sections.items()]
        return "\n".join(head) + "\n" + "\n".join(body) + "\n"


@functools.cache
def _builtin(name: str) -> Profile:
    path = resources.files("biso_cosim.sensors").joinpath(f"profiles/{name}.toml")
    return Profile.from_dict(tomllib.loads(path.read_text("utf-8")), origin=f"profiles/{name}.toml", default_name=name)


# --------------------------------------------------------------------------------------
# Errors drawn per seed
# --------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class InertialErrors:
    """Turn-on errors of the gyro or the accelerometer, SI, chip axes.

    The reading before noise, filter and quantization is
    ``y = (M + diag(k_s)·ΔT)·x + 2.5·κ·FS·(x/FS)³ + b + k_b·ΔT + G·f + bias processes``
    with ``ΔT = T - T_0`` (see `MPU9250`).
    """

    sensitivity: np.ndarray  # M (3, 3): I + diag(scale-factor errors) + cross-axis terms
    scale_factor_tempco: np.ndarray  # k_s (3,): 1/°C
    bias: np.ndarray  # b (3,): rad/s or m/s²
    bias_tempco: np.ndarray  # k_b (3,): per °C
    nonlinearity: np.ndarray  # κ (3,): fraction of full scale
    g_sensitivity: np.ndarray  # G (3, 3): (rad/s)/(m/s²); zero for the accelerometer


@dataclasses.dataclass(frozen=True)
class MagErrors:
    """Turn-on errors of the AK8963, in its own axes."""

    offset_ut: np.ndarray  # (3,) zero-field offset
    sensitivity_factor: np.ndarray  # (3,) true factor: H_adj = H_raw · factor would be exact
    asa: np.ndarray  # (3,) uint8 fuse-ROM codes a driver reads


@dataclasses.dataclass(frozen=True)
class DrawnErrors:
    """Everything a seed draws at turn-on."""

    gyro: InertialErrors
    accel: InertialErrors
    mag: MagErrors


def _truncated_normal(rng: np.random.Generator, tolerance: np.ndarray) -> np.ndarray:
    """One draw per element: N(0, (tol/3)²) truncated at ±tol (rejection, deterministic per seed)."""
    tol = np.asarray(tolerance, dtype=np.float64)
    out = np.empty(tol.shape)
    for idx in np.ndindex(tol.shape):
        z = rng.standard_normal()
        while abs(z) > 3.0:
            z = rng.standard_normal()
        out[idx] = tol[idx] * z / 3.0
    return out


def _draw_inertial(rng: np.random.Generator, profile: Profile, sensor: str) -> InertialErrors:
    scale = _truncated_normal(rng, profile.axes(f"{sensor}.scale_factor"))
    cross = _truncated_normal(rng, np.full((3, 3), float(profile.si(f"{sensor}.cross_axis"))))
    np.fill_diagonal(cross, 0.0)
    sensitivity = np.eye(3) + np.diag(scale) + cross
    sf_tc = _truncated_normal(rng, profile.axes(f"{sensor}.scale_factor_tempco"))
    bias = _truncated_normal(rng, profile.axes(f"{sensor}.bias_initial"))
    bias_tc = _truncated_normal(rng, profile.axes(f"{sensor}.bias_tempco"))
    nonlin = _truncated_normal(rng, profile.axes(f"{sensor}.nonlinearity"))
    if sensor == "gyro":
        gsens = _truncated_normal(rng, np.full((3, 3), float(profile.si("gyro.g_sensitivity"))))
    else:
        gsens = np.zeros((3, 3))
    return InertialErrors(sensitivity, sf_tc, bias, bias_tc, nonlin, gsens)


def draw_errors(profile: Profile, rng: np.random.Generator) -> DrawnErrors:
    """Turn-on errors for one part, drawn from ``rng`` in a fixed order."""
    gyro = _draw_inertial(rng, profile, "gyro")
    accel = _draw_inertial(rng, profile, "accel")
    offset = _truncated_normal(rng, profile.axes("mag.offset"))
    lo, hi = profile.si("mag.asa_range")
    factor_lo, factor_hi = (lo - 128.0) / 256.0 + 1.0, (hi - 128.0) / 256.0 + 1.0
    factor = rng.uniform(factor_lo, factor_hi, size=3) if hi > lo else np.full(3, factor_lo)
    asa = np.clip(np.round((factor - 1.0) * 256.0 + 128.0), 0, 255).astype(np.uint8)
    return DrawnErrors(gyro, accel, MagErrors(offset, factor, asa))


def flicker_terms(bias_instability: np.ndarray, corner_times_s: np.ndarray, per_decade: int = 2):
    """Correlation times and per-axis standard deviations of the Gauss-Markov sum
    approximating flicker bias noise with Allan floor 0.664·B.

    A one-sided PSD h/f has the Allan variance 2·ln2·h; the floor (2 ln2/π)·B² (IEEE
    Std 952 bias instability) needs h = B²/π. Lorentzians with log-spaced correlation times,
    ``per_decade`` of them per decade and variance σ² each, sum to the PSD σ²·per_decade/(f·ln10)
    inside the band, hence σ² = B²·ln10 / (π·per_decade) (B²·Δ/π for a spacing Δ in ln τ).
    """
    t_lo, t_hi = float(corner_times_s[0]), float(corner_times_s[1])
    if t_lo <= 0.0:
        raise ValueError("bias_corner_times must be positive")
    n = max(2, int(round(per_decade * math.log10(t_hi / t_lo))) + 1)
    taus = np.geomspace(t_lo, t_hi, n)
    # density of processes per unit ln(τ) is 1/Δ for the actual spacing Δ
    spacing = math.log(t_hi / t_lo) / (n - 1) if t_hi > t_lo else 1.0
    sigma = np.sqrt(np.asarray(bias_instability, dtype=np.float64) ** 2 * spacing / math.pi)
    return taus, np.broadcast_to(sigma, (n, 3)).copy()
