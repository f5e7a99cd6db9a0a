"""The FMI variables of the three FMUs, generated from the package's own parameter records.

Every variable is a `Var`: its FMI name, type, causality, variability, start value, unit and
description. Nothing here is written by hand twice: estimator parameters come from
``biso_cosim.estimators.describe_estimator`` (symbol, unit, default, meaning, source), the
register fields from ``biso_cosim.sensors.Registers`` (its documented attributes), and the
signals from the tables below, which also feed ``docs/fmu.md`` (``variable_table``) and the
``documentation/index.html`` inside each FMU.

Mapping of Python parameter types to FMI scalars (FMI 2 has no arrays and no None, and no
start value may be NaN: Modelica has no NaN literal):

* ``float`` → Real; ``float | None`` → a Real and a Boolean flag ``<estimator>.has_<name>``
  (start false): the Real is used only when the flag is true, else the parameter is None
  (its documented meaning); the Real's start value is then 0 and means nothing;
* gains given as "one value or four per channel" (BISO ``k``, ``k_p``) → one Real (the
  per-channel form is Python-only);
* ``tuple[float, float, float]`` → three Reals ``name[1]``, ``name[2]``, ``name[3]``;
* ``int`` → Integer, ``bool`` → Boolean, ``str`` → String (one of the listed choices).

Allowed ranges come from the estimators' C parameter tables (``native/gen.py``, checked
against the Python checks by its tests): closed bounds become ``min``/``max``, and every
range is written into the description.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import re
import typing
from dataclasses import dataclass
from typing import Any, Iterable

__all__ = [
    "Var", "UNITS", "fmi_unit", "estimator_variables", "estimator_param_groups", "python_only_params",
    "sensor_variables",
    "site_variables", "reading_outputs", "estimate_outputs", "error_outputs", "variables_of",
    "fingerprint", "variable_table", "fill_docs", "AXES", "QUAT", "Allowed", "allowed_values",
]

AXES = ("x", "y", "z")
QUAT = ("w", "x", "y", "z")


@dataclass(frozen=True)
class Var:
    """One FMI scalar variable.

    ``key`` says where its value goes in the model (e.g. ``("param", "biso", "k")``); the
    slave uses it, the model description does not.
    """

    name: str
    type: str                      # "Real" | "Integer" | "Boolean" | "String"
    causality: str                 # "parameter" | "input" | "output"
    variability: str               # "fixed" | "tunable" | "discrete" | "continuous"
    start: Any
    description: str
    unit: str = ""                 # FMI unit name (see UNITS), "" for none
    display_unit: str = ""
    key: tuple = ()
    min: float | None = None
    max: float | None = None
    min_open: bool = False         # the value must be > min (FMI's min, which is inclusive, still says min)


# --------------------------------------------------------------------------------------
# Units: FMI unit name → (SI base-unit exponents, factor, offset, {display unit: (factor, offset)})
# --------------------------------------------------------------------------------------

_DEG_PER_RAD = 180.0 / math.pi
UNITS: dict[str, tuple[dict[str, int], float, float, dict[str, tuple[float, float]]]] = {
    "rad": ({"rad": 1}, 1.0, 0.0, {"deg": (_DEG_PER_RAD, 0.0)}),
    "rad/s": ({"rad": 1, "s": -1}, 1.0, 0.0, {"deg/s": (_DEG_PER_RAD, 0.0)}),
    "deg": ({"rad": 1}, math.pi / 180.0, 0.0, {}),
    "m/s2": ({"m": 1, "s": -2}, 1.0, 0.0, {"g": (1.0 / 9.80665, 0.0)}),
    "uT": ({"kg": 1, "s": -2, "A": -1}, 1e-6, 0.0, {}),
    "s": ({"s": 1}, 1.0, 0.0, {"ms": (1e3, 0.0)}),
    "Hz": ({"s": -1}, 1.0, 0.0, {}),
    "1/s": ({"s": -1}, 1.0, 0.0, {}),
    "1/s2": ({"s": -2}, 1.0, 0.0, {}),
    "m": ({"m": 1}, 1.0, 0.0, {}),
    "m/s": ({"m": 1, "s": -1}, 1.0, 0.0, {"km/h": (3.6, 0.0)}),
    "degC": ({"K": 1}, 1.0, 273.15, {}),
}

# unit strings of the Python parameter records → FMI unit names
_PY_UNITS = {"": "", "rad": "rad", "rad/s": "rad/s", "1/s": "1/s", "1/s²": "1/s2", "Hz": "Hz",
             "s": "s", "m": "m", "m/s": "m/s", "m/s²": "m/s2", "µT": "uT", "°C": "degC", "deg": "deg"}

# the angle a user reads is in degrees: show rad variables in degrees by default
_DISPLAY = {"rad": "deg", "rad/s": "deg/s"}


def fmi_unit(py_unit: str) -> str:
    """The FMI unit name of a unit string used in the package's parameter records."""
    try:
        return _PY_UNITS[py_unit]
    except KeyError:
        raise ValueError(f"no FMI unit for {py_unit!r}; known: {sorted(_PY_UNITS)}") from None


def _real(name: str, causality: str, variability: str, start: float, description: str, unit: str = "",
          key: tuple = (), **extra: Any) -> Var:
    if causality == "output":
        variability = "discrete"  # sampled models: every output is piecewise constant between samples
    return Var(name, "Real", causality, variability, float(start), description, unit,
               _DISPLAY.get(unit, ""), key, **extra)


def _vector(prefix: str, causality: str, what: str, unit: str, key: tuple, start=(0.0, 0.0, 0.0),
            components: tuple[str, ...] = AXES, variability: str = "continuous") -> list[Var]:
    return [_real(f"{prefix}.{c}", causality, variability, s, f"{what}, {c} component", unit, key + (i,))
            for i, (c, s) in enumerate(zip(components, start))]


# --------------------------------------------------------------------------------------
# Estimator parameters (describe_estimator is the single source)
# --------------------------------------------------------------------------------------


def _optional(hint: Any) -> bool:
    return type(None) in typing.get_args(hint)


def _fmi_kind(hint: Any) -> str | None:
    """'Real', 'Integer', 'Boolean', 'String' or 'Real3' for one parameter's type hint; None
    when FMI scalars cannot carry it (the parameter is then Python-only)."""
    args = [a for a in typing.get_args(hint) if a is not type(None)] or [hint]
    if hint is bool or args == [bool]:
        return "Boolean"
    if hint is int or args == [int]:
        return "Integer"
    if hint is str or args == [str]:
        return "String"
    if typing.get_origin(hint) is tuple and len(typing.get_args(hint)) == 3:
        return "Real3"
    if float in args or hint is float:
        return "Real"  # float, float | None, float | tuple[4] | None (the scalar form)
    return None


def fmu_estimator_names() -> tuple[str, ...]:
    """The estimators an FMU can run: those whose inputs FMI variables carry. The GNSS-aided
    ones (``gnss_*``) need a stream of fixes with times of validity and arrival, which the
    FMUs do not take yet; they are Python-only."""
    from biso_cosim.estimators import estimator_inputs, estimator_names

    return tuple(n for n in estimator_names() if "gnss" not in estimator_inputs(n))


@functools.cache
def estimator_param_groups() -> dict[str, tuple[dict[str, Any], ...]]:
    """For each estimator name: its parameter rows (``describe_estimator``) with ``kind``
    (FMI type) and ``optional`` (None allowed) added; parameters FMI cannot carry are left
    out (``python_only_params``)."""
    groups = {}
    for name, rows in _typed_rows().items():
        groups[name] = tuple(r for r in rows if r["kind"] is not None)
    return groups


def python_only_params() -> dict[str, list[str]]:
    """Estimator parameters without an FMI variable (types FMI scalars cannot carry)."""
    return {name: [r["name"] for r in rows if r["kind"] is None] for name, rows in _typed_rows().items()}


# parameters whose non-default values need inputs the FMUs do not carry (gyro_step: the
# sensor's multiple-integral increments)
_NEEDS_PYTHON_INPUTS = {"gyro_step"}


@functools.cache
def _typed_rows() -> dict[str, tuple[dict[str, Any], ...]]:
    from biso_cosim.estimators import describe_estimator, make_estimator

    out = {}
    for name in fmu_estimator_names():
        hints = typing.get_type_hints(make_estimator(name, 200.0).Params)
        out[name] = tuple({**row, "kind": None if row["name"] in _NEEDS_PYTHON_INPUTS else _fmi_kind(hints[row["name"]]),
                           "optional": _optional(hints[row["name"]])}
                          for row in describe_estimator(name)["params"])
    return out


@functools.cache
def _ranges(name: str) -> dict[str, tuple[float, float, bool, tuple[str, ...]]]:
    """Allowed (min, max, min_open, choices) of each C parameter entry of one estimator."""
    from biso_cosim.fmu.native.gen import kind_entries

    entries, _ = kind_entries(name)
    return {e.name: (e.min, e.max, e.min_open, e.choices) for e in entries}


def _allowed(lo: float, hi: float, lo_open: bool, choices: tuple[str, ...]) -> str:
    if choices:
        return "one of " + ", ".join(choices)
    parts = []
    if math.isfinite(lo):
        parts.append(f"{'>' if lo_open else '>='} {lo:g}")
    if math.isfinite(hi):
        parts.append(f"<= {hi:g}")
    return " and ".join(parts) or "any finite value"


def _param_description(row: dict[str, Any], allowed: str, note: str = "") -> str:
    text = row["doc"]
    if row["symbol"]:
        text = f"{row['symbol']}: {text}"
    text += f" (allowed: {allowed})"
    if row["source"]:
        text += f" [{row['source']}]"
    return text + note


@dataclass(frozen=True)
class Allowed:
    """The values a parameter or input accepts: a range (``lo`` excluded when ``lo_open``)
    or, for a String, a list of choices. ``str()`` gives the text the descriptions and the
    refusals use ("> 0", "one of biso, ...")."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    choices: tuple[str, ...] = ()

    def admits(self, value: Any) -> bool:
        if self.choices:
            return value in self.choices
        if isinstance(value, (bool, str)):
            return True
        x = float(value)
        if not math.isfinite(x):
            return False
        return (x > self.lo if self.lo_open else x >= self.lo) and x <= self.hi

    def __str__(self) -> str:
        return _allowed(self.lo, self.hi, self.lo_open, self.choices)


def allowed_values(v: Var) -> Allowed:
    """What a variable accepts: an estimator parameter its C table's range or choices, the
    ``estimator`` the FMU estimators, any other variable its ``min``/``max`` (a Real without
    bounds: any finite value)."""
    if v.key[:1] == ("param",):
        lo, hi, lo_open, choices = _ranges(v.key[1])[v.name.split(".", 1)[1]]
        return Allowed(lo, hi, lo_open, choices)
    if v.key == ("estimator",):
        return Allowed(choices=fmu_estimator_names())
    return Allowed(-math.inf if v.min is None else v.min, math.inf if v.max is None else v.max, v.min_open)


def has_flag_name(name: str, param: str) -> str:
    """The Boolean flag that says whether an optional parameter is given (else None)."""
    return f"{name}.has_{param}"


def estimator_variables(*, tunable: bool = True) -> list[Var]:
    """``estimator`` (which one) and every estimator's parameters as ``<estimator>.<param>``.

    Only the group of the chosen estimator is used. An optional parameter (Python default
    None) has a Boolean ``<estimator>.has_<param>`` beside it (see the module docstring).
    """
    from biso_cosim.estimators import describe_estimator

    names = fmu_estimator_names()
    summary = "; ".join(f"{n}: {describe_estimator(n)['summary']}" for n in names)
    out = [Var("estimator", "String", "parameter", "fixed", "biso",
               f"attitude estimator, one of {', '.join(names)} ({summary})", key=("estimator",))]
    variability = "tunable" if tunable else "fixed"
    for name, rows in estimator_param_groups().items():
        ranges = _ranges(name)
        for row in rows:
            key = ("param", name, row["name"])
            unit = fmi_unit(row["unit"])
            default = row["default"]
            if row["kind"] == "Real3":
                for i, c in enumerate(("1", "2", "3")):
                    lo, hi, lo_open, _ = ranges[f"{row['name']}[{c}]"]
                    desc = _param_description(row, _allowed(lo, hi, lo_open, ()))
                    out.append(_real(f"{name}.{row['name']}[{c}]", "parameter", variability, default[i],
                                     f"{desc}; {AXES[i]} component", unit, key + (i,), **_bounds(lo, hi, lo_open)))
                continue
            lo, hi, lo_open, choices = ranges[row["name"]]
            if row["kind"] == "Real":
                if row["optional"]:
                    flag = has_flag_name(name, row["name"])
                    desc = _param_description(row, _allowed(lo, hi, lo_open, ()), f"; used only when {flag} is true")
                    out.append(_real(f"{name}.{row['name']}", "parameter", variability, 0.0 if default is None
                                     else float(default), desc, unit, key))
                    out.append(Var(flag, "Boolean", "parameter", variability, default is not None,
                                   f"true: {name}.{row['name']} is given; false: it is None, as in Python (see its "
                                   "description for what None means)", key=("given", name, row["name"])))
                else:
                    desc = _param_description(row, _allowed(lo, hi, lo_open, ()))
                    out.append(_real(f"{name}.{row['name']}", "parameter", variability, float(default), desc, unit,
                                     key, **_bounds(lo, hi, lo_open)))
            elif row["kind"] == "Integer":
                desc = _param_description(row, _allowed(lo, hi, lo_open, ()))
                out.append(Var(f"{name}.{row['name']}", "Integer", "parameter", variability, default, desc, key=key,
                               **_bounds(lo, hi, lo_open)))
            else:
                desc = _param_description(row, _allowed(lo, hi, lo_open, choices) if row["kind"] == "String"
                                          else "true or false")
                out.append(Var(f"{name}.{row['name']}", row["kind"], "parameter", variability, default, desc, key=key))
    return out


def _bounds(lo: float, hi: float, lo_open: bool) -> dict[str, float]:
    """FMI min/max of a range (inclusive bounds only: an open bound is in the description)."""
    out = {}
    if math.isfinite(lo) and not lo_open:
        out["min"] = lo
    if math.isfinite(hi):
        out["max"] = hi
    return out


def estimate_outputs() -> list[Var]:
    """The attitude estimate after the latest sample processed."""
    from biso_cosim.estimators import flags

    bits = ", ".join(f"{bit} {name}" for bit, name in flags.NAMES.items())
    out = _vector("estimate.q_wb", "output", "estimated attitude q_wb (Hamilton, body → ENU)", "", ("q_est",),
                  start=(1.0, 0.0, 0.0, 0.0), components=QUAT)
    out += [
        _real("estimate.roll", "output", "continuous", 0.0, "estimated roll (ZYX Euler angles of q_wb)", "rad",
              ("euler_est", 0)),
        _real("estimate.pitch", "output", "continuous", 0.0, "estimated pitch (ZYX Euler angles of q_wb)", "rad",
              ("euler_est", 1)),
        _real("estimate.yaw", "output", "continuous", 0.0,
              "estimated yaw, counter-clockwise from East (ZYX Euler angles of q_wb)", "rad", ("euler_est", 2)),
        _real("estimate.heading", "output", "continuous", math.pi / 2,
              "estimated compass heading, clockwise from true North, [0, 2π)", "rad", ("euler_est", 3)),
        Var("estimate.flags", "Integer", "output", "discrete", flags.UNINITIALIZED,
            f"estimator flags of the latest sample, a bitmask: {bits}", key=("flags_est",)),
    ]
    out += _vector("estimate.gyro_bias_b", "output", "estimated gyro bias in body axes (0 for estimators "
                   "that do not estimate it)", "rad/s", ("bias_est",))
    return out


def error_outputs() -> list[Var]:
    """Estimate minus truth at the latest sample (``biso_cosim.metrics.angle_errors_deg``)."""
    parts = (("roll", "roll"), ("pitch", "pitch"), ("heading", "compass heading"))
    out = [_real(f"error.{p}", "output", "continuous", 0.0, f"{what} error, estimate minus truth, wrapped to "
                 "(−π, π]", "rad", ("error", i)) for i, (p, what) in enumerate(parts)]
    out.append(_real("error.total", "output", "continuous", 0.0,
                     "total attitude error: rotation angle between estimate and truth", "rad", ("error", 3)))
    return out


# --------------------------------------------------------------------------------------
# The virtual MPU-9250
# --------------------------------------------------------------------------------------


@functools.cache
def _register_docs() -> dict[str, str]:
    """The documented attributes of ``Registers`` (its docstring is their single source)."""
    from biso_cosim.sensors import Registers

    docs, current = {}, None
    lines = (Registers.__doc__ or "").split("Attributes:", 1)[-1].splitlines()
    for line in lines:
        m = re.match(r"\s{8}(\w+): (.*)", line)
        if m:
            current = m.group(1)
            docs[current] = m.group(2).strip()
        elif current and line.startswith(" " * 12):
            docs[current] += " " + line.strip()
    return docs


def sensor_variables(*, profile_default: str, with_calibration: bool = False) -> list[Var]:
    """MPU-9250 configuration: profile, seed, registers, mounting (all fixed)."""
    from biso_cosim.sensors import Registers, profile_names

    docs = _register_docs()
    out = [
        Var("sensor.profile", "String", "parameter", "fixed", profile_default,
            f"MPU-9250 error profile: {', '.join(profile_names())} or the path of a profile TOML file "
            "(docs/sensors.md)", key=("sensor", "profile")),
        Var("sensor.seed", "Integer", "parameter", "fixed", 0,
            "seed of the part's turn-on errors and noise: same seed, same readings, bit for bit",
            key=("sensor", "seed"), min=0),
    ]
    for f in dataclasses.fields(Registers):
        kind = "Boolean" if f.type in (bool, "bool") else "Integer"
        out.append(Var(f"sensor.registers.{f.name}", kind, "parameter", "fixed", f.default,
                       f"register field: {docs.get(f.name, f.name)}", key=("register", f.name)))
    for i, angle in enumerate(("roll", "pitch", "yaw")):
        out.append(_real(f"sensor.mounting.{angle}", "parameter", "fixed", 0.0,
                         f"mounting of the chip in the body, ZYX Euler angles of q_body_chip: {angle}",
                         "rad", ("mounting", i)))
    if with_calibration:
        out.append(_real("sensor.gyro_calibration_s", "parameter", "fixed", 0.0,
                         "start-up gyro offset calibration at rest before time zero, as an MPU-9250 driver does "
                         "(use with the raw mpu9250 profile); 0 disables it", "s", ("cosim", "gyro_calibration_s"),
                         min=0.0, max=60.0))
    return out


def site_variables() -> list[Var]:
    """Where and when the Earth field is evaluated (WMM, ``biso_cosim.sensors.EarthField``)."""
    from biso_cosim.sensors import SARATOV

    return [
        _real("site.lat_deg", "parameter", "fixed", SARATOV.lat_deg, "geodetic latitude of the site, north "
              "positive, for the WMM Earth field", "deg", ("site", "lat_deg"), min=-90.0, max=90.0),
        _real("site.lon_deg", "parameter", "fixed", SARATOV.lon_deg, "longitude of the site, east positive",
              "deg", ("site", "lon_deg"), min=-180.0, max=180.0),
        _real("site.alt_m", "parameter", "fixed", SARATOV.alt_m, "altitude above the WGS 84 ellipsoid", "m",
              ("site", "alt_m"), min=-1000.0, max=850000.0),
        Var("site.date", "String", "parameter", "fixed", SARATOV.date.isoformat(),
            "date of the field, ISO YYYY-MM-DD within the WMM releases (2010-2030)", key=("site", "date")),
    ]


RAW_WORDS = ("accel.x", "accel.y", "accel.z", "temp", "gyro.x", "gyro.y", "gyro.z", "mag.x", "mag.y", "mag.z")


def reading_outputs() -> list[Var]:
    """The latest MPU-9250 output sample: SI readings (body axes), raw registers, flags."""
    from biso_cosim.sensors import ImuFlag

    bits = ", ".join(f"{int(f)} {f.name.lower()}" for f in ImuFlag)
    out = [
        _real("sample_time", "output", "discrete", 0.0, "time stamp of the latest output sample (the chip "
              "latches it at a multiple of 1/ODR); the outputs below belong to it", "s", ("sample_time",)),
        Var("new_samples", "Integer", "output", "discrete", 0,
            "number of output samples the chip latched during the last step (0: outputs held)",
            key=("new_samples",)),
    ]
    out += _vector("gyro_b", "output", "gyro reading, body axes", "rad/s", ("gyro",), variability="discrete")
    out += _vector("accel_b", "output", "accelerometer reading (specific force, +g up at rest), body axes",
                   "m/s2", ("accel",), variability="discrete")
    out += _vector("mag_b", "output", "magnetometer reading, body axes (latest AK8963 sample, held; 0 while "
                   "there is none, e.g. powered down: imu_flags then has mag_invalid)", "uT", ("mag",),
                   variability="discrete")
    out += [
        _real("temperature_c", "output", "discrete", 0.0, "on-chip temperature sensor reading", "degC",
              ("temperature",)),
        Var("mag_fresh", "Boolean", "output", "discrete", False,
            "a new AK8963 sample since the previous output sample (ST1.DRDY)", key=("mag_fresh",)),
        Var("imu_flags", "Integer", "output", "discrete", 0, f"sensor flags of the sample, a bitmask: {bits}",
            key=("imu_flags",)),
    ]
    for i, word in enumerate(RAW_WORDS):
        axes = "AK8963 axes" if word.startswith("mag") else "chip axes"
        what = "TEMP_OUT" if word == "temp" else f"{word.split('.')[0].upper()}_{word[-1].upper()} ({axes})"
        out.append(Var(f"raw.{word}", "Integer", "output", "discrete", 0,
                       f"raw register {what}, int16 as a driver reads it", key=("raw", i)))
    out += [Var(f"raw.{st}", "Integer", "output", "discrete", 0, f"AK8963 status register {st.upper()}",
                key=("status", i)) for i, st in enumerate(("st1", "st2"))]
    return out


# --------------------------------------------------------------------------------------
# The three FMUs
# --------------------------------------------------------------------------------------


def _estimator_fmu() -> list[Var]:
    out = [_real("fs_hz", "parameter", "fixed", 200.0, "sample rate of the inputs: each communication step "
                 "must be a whole number n of sample periods; the inputs are then held for n samples", "Hz",
                 ("fs_hz",), min=0.0)]
    for i, angle in enumerate(("roll", "pitch", "yaw")):
        out.append(_real(f"mounting.{angle}", "parameter", "fixed", 0.0,
                         f"rotation from the sensor axes of the inputs into the body axes, ZYX Euler angles "
                         f"of q_body_sensor: {angle} (0, 0, 0: the inputs are in body axes)", "rad",
                         ("mounting", i)))
    out.append(Var("use_speed", "Boolean", "parameter", "fixed", False,
                   "feed the speed input to the estimator (biso_plus only: acceleration compensation, rest "
                   "detection)", key=("use_speed",)))
    out += estimator_variables()
    out += _vector("gyro_s", "input", "angular rate from the gyro, sensor axes", "rad/s", ("gyro",))
    out += _vector("accel_s", "input", "specific force from the accelerometer (+g up at rest), sensor axes",
                   "m/s2", ("accel",), start=(0.0, 0.0, 9.80665))
    out += _vector("mag_s", "input", "magnetic field from the magnetometer, sensor axes", "uT", ("mag",),
                   start=(0.0, 20.0, -40.0))
    out.append(_real("speed", "input", "continuous", 0.0, "forward speed of the vehicle at the point "
                     "biso_plus.speed_point_b_m (used with use_speed)", "m/s", ("speed",)))
    out.append(Var("imu_flags", "Integer", "input", "discrete", 0, "the sensor's flags of the sample (as "
                   "BisoImuPlugin's imu_flags: 1 gyro saturated, 2 accelerometer saturated, 4 AK8963 overflow, 16 "
                   "magnetometer invalid); 0: none. Flagged samples are handled as the Python estimator handles "
                   "them (estimate.flags)", key=("imu_flags_in",), min=0))
    out += estimate_outputs()
    return out


def _declination_from_site(where: str) -> Var:
    return Var("declination_from_site", "Boolean", "parameter", "fixed", True,
               f"true: the estimator's declination_rad is the WMM declination at {where}; false: the "
               "<estimator>.declination_rad parameter", key=("declination_from_site",))


def _truth_inputs() -> list[Var]:
    out = _vector("omega_b", "input", "true angular rate of the body, body axes", "rad/s", ("omega",))
    out += _vector("specific_force_b", "input", "true specific force at the sensor (+g up at rest), body axes",
                   "m/s2", ("force",), start=(0.0, 0.0, 9.80665))
    out += _vector("q_wb", "input", "true attitude q_wb (Hamilton, body → ENU; a unit quaternion, |q| = 1 ± 1e-5, "
                   "normalised on use)", "", ("q",),
                   start=(1.0, 0.0, 0.0, 0.0), components=QUAT)
    out += _vector("pos_w", "input", "position of the sensor, local ENU (for the magnetic field)", "m",
                   ("pos",))
    out += _vector("vel_w", "input", "velocity of the sensor, ENU (with use_velocity: its forward component "
                   "is the speed input of biso_plus)", "m/s", ("vel",))
    out.append(_real("temperature", "input", "continuous", 25.0, "die temperature (with use_temperature; "
                     "else the profile's default)", "degC", ("temp",)))
    return out


def _imu_plugin_fmu() -> list[Var]:
    out = sensor_variables(profile_default="mpu9250_calibrated")
    out += _vector("sensor.position_b", "parameter", "position of the chip relative to the point whose motion the "
                   "inputs give (lever arm, biso_cosim.plugin.Mounting.position_m), body axes: the chip feels "
                   "f + ω × (ω × r) + ω̇ × r (ω̇ from the rate's slope between steps) and sits at p + q ∘ r ∘ q*",
                   "m", ("position",), variability="fixed")
    out += site_variables()
    out += [
        Var("use_temperature", "Boolean", "parameter", "fixed", False, "use the temperature input as the die "
            "temperature", key=("use_temperature",)),
        Var("use_velocity", "Boolean", "parameter", "fixed", False, "give biso_plus the forward speed from the "
            "velocity input", key=("use_velocity",)),
    ]
    out.append(_declination_from_site("the site's (site.*)"))
    out += estimator_variables()
    out += _truth_inputs()
    out += reading_outputs() + estimate_outputs() + error_outputs()
    return out


def _vehicle_fmu() -> list[Var]:
    from biso_cosim.routes import route_names

    out = [
        Var("route", "String", "parameter", "fixed", "loop600",
            f"route to drive: a library route ({', '.join(route_names())}) or a route file (.toml)",
            key=("cosim", "route")),
        _real("physics_rate_hz", "parameter", "fixed", 1000.0, "MuJoCo step rate (> 0)", "Hz",
              ("cosim", "physics_rate_hz"), min=0.0, min_open=True),
        _real("control_rate_hz", "parameter", "fixed", 50.0, "driver rate (a whole fraction of the physics "
              "rate, > 0); each communication step must be a whole number of control periods", "Hz",
              ("cosim", "control_rate_hz"), min=0.0, min_open=True),
        Var("external_driver", "Boolean", "parameter", "fixed", False,
            "drive with the inputs steer, drive, brake instead of the scripted driver", key=("external_driver",)),
    ]
    out += sensor_variables(profile_default="mpu9250_calibrated", with_calibration=True)
    out.append(_declination_from_site("the route's site"))
    out += estimator_variables()
    out += [
        _real("steer", "input", "continuous", 0.0, "road-wheel angle of the bicycle model, left positive "
              "(with external_driver)", "rad", ("command", 0)),
        _real("drive", "input", "continuous", 0.0, "drive torque as a fraction of the maximum, [-1, 1] (with "
              "external_driver)", "", ("command", 1), min=-1.0, max=1.0),
        _real("brake", "input", "continuous", 0.0, "brake command of each wheel, [0, 1] (with external_driver)",
              "", ("command", 2), min=0.0, max=1.0),
    ]
    out += _vector("truth.omega_b", "output", "true angular rate at the latest sample, body axes", "rad/s",
                   ("truth_omega",))
    out += _vector("truth.specific_force_b", "output", "true specific force at the IMU at the latest sample, "
                   "body axes", "m/s2", ("truth_force",))
    out += _vector("truth.q_wb", "output", "true attitude at the latest sample (body → ENU)", "",
                   ("truth_q",), start=(1.0, 0.0, 0.0, 0.0), components=QUAT)
    out += _vector("truth.pos_w", "output", "true IMU position at the latest sample, local ENU", "m",
                   ("truth_pos",))
    out += _vector("truth.vel_w", "output", "true IMU velocity at the latest sample, ENU", "m/s", ("truth_vel",))
    out += [
        _real("truth.speed", "output", "continuous", 0.0, "forward speed of the rear axle at the latest sample",
              "m/s", ("truth_speed",)),
        _real("cross_track", "output", "continuous", 0.0, "driver's cross-track error from the route", "m",
              ("cross_track",)),
        Var("route_finished", "Boolean", "output", "discrete", False, "the scripted driver reached the end of "
            "the route", key=("finished",)),
    ]
    out += reading_outputs() + estimate_outputs() + error_outputs()
    return out


_BUILDERS = {"BisoEstimator": _estimator_fmu, "BisoImuPlugin": _imu_plugin_fmu, "BisoVehicle": _vehicle_fmu}


@functools.cache
def _variables(fmu: str) -> tuple[Var, ...]:
    try:
        build = _BUILDERS[fmu]
    except KeyError:
        raise ValueError(f"unknown FMU {fmu!r}; known: {', '.join(_BUILDERS)}") from None
    out = tuple(build())
    names = [v.name for v in out]
    if len(set(names)) != len(names):
        raise RuntimeError(f"{fmu}: duplicate variable names")
    return out


def variables_of(fmu: str) -> tuple[Var, ...]:
    """All variables of one FMU (``BisoEstimator``, ``BisoImuPlugin``, ``BisoVehicle``), in
    value-reference order."""
    return _variables(fmu)


def fingerprint(fmu: str) -> str:
    """A hash of the FMU's variables: an FMU built by another version of the package that
    defines other variables is refused at instantiation instead of mis-wired."""
    rows = [(v.name, v.type, v.causality, v.variability, v.unit) for v in variables_of(fmu)]
    return hashlib.sha256(json.dumps(rows).encode()).hexdigest()[:16]


def _fmt_start(v: Var) -> str:
    if v.type == "Real":
        return f"{v.start:g}"
    return repr(v.start) if v.type == "String" else str(v.start).lower() if v.type == "Boolean" else str(v.start)


def variable_table(fmu: str, causality: str | Iterable[str] | None = None, *, estimator_params: bool = True) -> str:
    """The variables of one FMU as a Markdown table (for docs/fmu.md and ``biso-cosim fmu
    variables``); ``estimator_params=False`` leaves out the ``<estimator>.<param>`` groups."""
    wanted = {causality} if isinstance(causality, str) else set(causality or ())
    lines = ["| variable | type | causality | unit | start | description |", "|---|---|---|---|---|---|"]
    for v in variables_of(fmu):
        if (wanted and v.causality not in wanted) or (not estimator_params and v.key[0] == "param"):
            continue
        desc = v.description.replace("|", "\\|")
        lines.append(f"| `{v.name}` | {v.type} | {v.causality} ({v.variability}) | {v.unit} | {_fmt_start(v)} "
                     f"| {desc} |")
    return "\n".join(lines)


def _doc_blocks() -> dict[str, str]:
    blocks = {name: variable_table(name, estimator_params=False) for name in _BUILDERS}
    blocks["estimator parameters"] = "\n".join(
        line for line in variable_table("BisoEstimator").splitlines()
        if not line.startswith("| `") or any(line.startswith(f"| `{g}.") for g in estimator_param_groups()))
    return blocks


def fill_docs(text: str) -> str:
    """Replace the generated blocks ``<!-- BEGIN fmu NAME -->`` … ``<!-- END fmu NAME -->`` of
    docs/fmu.md with the current tables."""
    for name, table in _doc_blocks().items():
        begin, end = f"<!-- BEGIN fmu {name} -->", f"<!-- END fmu {name} -->"
        head, sep, rest = text.partition(begin)
        if not sep:
            raise ValueError(f"no block {begin!r} in the text")
        _, sep, tail = rest.partition(end)
        if not sep:
            raise ValueError(f"block {begin!r} has no end {end!r}")
        text = f"{head}{begin}\n{table}\n{end}{tail}"
    return text

