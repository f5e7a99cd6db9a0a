"""Markdown tables of the sensor model, rendered from the data the code uses.

`parameter_table` renders the error parameters (schema ``data/parameters.toml`` with the
values and sources of a profile); `chip_table` the register-set behaviour (``data/
features.toml`` with values from ``data/mpu9250.toml``). docs/sensors.md embeds both
between markers, and a test checks that it is in sync (``biso-cosim sensor table``
prints them).
"""

from __future__ import annotations

import functools
import tomllib
from importlib import resources

import numpy as np

from biso_cosim.sensors.profile import Profile, parameter_schema
from biso_cosim.sensors.registers import chip_tables

__all__ = ["parameter_table", "chip_table", "fill_docs", "PEERS"]

PEERS = {"M": "MATLAB imuSensor", "G": "Gazebo gz-sensors", "I": "gnss-ins-sim", "J": "MuJoCo"}


def _fmt(value) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, np.ndarray):
        if np.all(value == value.flat[0]) and value.size == 3:
            return _fmt(float(value.flat[0]))
        return "[" + ", ".join(_fmt(float(v)) for v in value) + "]"
    return f"{value:g}"


def _marks(peers: str) -> list[str]:
    return ["✓" if letter in peers.split() else "" for letter in PEERS]


def _row(cells: list[str]) -> str:
    return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"


def parameter_table(profile: str | Profile = "mpu9250") -> str:
    """The error parameters with the profile's values, units, kinds, sources and peers."""
    prof = Profile.load(profile)
    head = ["parameter", "symbol", "value", "unit", "kind", "source", *PEERS.values()]
    lines = [_row(head), _row(["---"] * len(head))]
    for key, meta in parameter_schema().items():
        kind = {"tolerance": "± tol.", "range": "range", "value": "value", "flag": "switch"}[meta["kind"]]
        lines.append(_row([f"`{key}`", meta["symbol"], _fmt(prof.values[key]), meta["unit"], kind, prof.sources[key], *_marks(meta["peers"])]))
    return "\n".join(lines) + "\n"


@functools.cache
def _features() -> list[dict]:
    text = resources.files("biso_cosim.sensors").joinpath("data/features.toml").read_text("utf-8")
    return tomllib.loads(text)["feature"]


def _feature_value(key: str) -> str:
    t = chip_tables()
    ak = t["ak8963"]
    if key == "gyro_full_scale":
        return ", ".join(f"±{fs:g} °/s: {s:g} LSB/(°/s)" for fs, s in zip(t["gyro"]["full_scale_dps"], t["gyro"]["sensitivity_lsb_per_dps"]))
    if key == "accel_full_scale":
        return ", ".join(f"±{fs:g} g: {s:g} LSB/g" for fs, s in zip(t["accel"]["full_scale_g"], t["accel"]["sensitivity_lsb_per_g"]))
    if key == "saturation":
        return "codes −32768 … 32767"
    if key == "gyro_dlpf":
        g = t["gyro_dlpf"]
        rows = [f"{i}: {r[0]:g} Hz / {r[1]:g} ms / {r[2] / 1000:g} kHz" for i, r in enumerate(g["dlpf_cfg"])]
        rows += [f"FCHOICE_B=x1: {g['fchoice_b_x1'][0]:g} Hz / {g['fchoice_b_x1'][1]:g} ms / 32 kHz",
                 f"FCHOICE_B=10: {g['fchoice_b_10'][0]:g} Hz / {g['fchoice_b_10'][1]:g} ms / 32 kHz"]
        return "; ".join(rows)
    if key == "accel_dlpf":
        a = t["accel_dlpf"]
        rows = [f"{i}: {r[0]:g} Hz / {r[1]:g} ms" for i, r in enumerate(a["a_dlpf_cfg"])]
        rows.append(f"FCHOICE_B=1: {a['accel_fchoice_b_1'][0]:g} Hz / {a['accel_fchoice_b_1'][1]:g} ms / 4 kHz")
        return "; ".join(rows) + " (1 kHz unless stated)"
    if key == "sample_rate":
        return f"{t['sample_rate']['dlpf_internal_rate_hz']:g} Hz / (1 + SMPLRT_DIV), DLPF_CFG 1…6 only"
    if key == "temperature":
        return f"{t['temperature']['sensitivity_lsb_per_c']:g} LSB/°C, 0 LSB at {t['temperature']['offset_c']:g} °C"
    if key == "ak8963_modes":
        return (f"continuous 1: {ak['continuous_1_rate_hz']:g} Hz, continuous 2: {ak['continuous_2_rate_hz']:g} Hz, "
                f"single (driver trigger every 1 + I2C_MST_DLY samples, ready after {ak['single_measurement_time_ms']:g} ms), power-down")
    if key == "ak8963_resolution":
        return f"{ak['resolution_14bit_ut']:g} µT/LSB (±{ak['max_code_14bit']}), {ak['resolution_16bit_ut']:g} µT/LSB (±{ak['max_code_16bit']})"
    if key == "ak8963_overflow":
        return f"|X| + |Y| + |Z| ≥ {ak['overflow_sum_ut']:g} µT"
    if key == "ak8963_asa":
        return "H_adj = H · ((ASA − 128)/256 + 1)"
    if key == "ak8963_axes":
        return "m_x = a_y, m_y = a_x, m_z = −a_z"
    if key == "raw_registers":
        return "0x3B…0x48 (14 bytes), AK8963 0x02…0x09 (8 bytes)"
    if key == "increments":
        return "r-fold iterated integrals over each output interval"
    if key == "vehicle_iron":
        return "S·B + h (body axes)"
    if key == "earth_field":
        return "ENU µT; default Saratov 51.53° N 46.03° E, 2024-05-01"
    if key == "vibration":
        return "resonant modes (f, ζ, RMS) added to the truth"
    raise KeyError(f"features.toml: no value renderer for {key!r}")


def chip_table() -> str:
    """The register-set behaviour of the chip with values, sources and peers."""
    head = ["feature", "value", "source", *PEERS.values(), "note"]
    lines = [_row(head), _row(["---"] * len(head))]
    for f in _features():
        lines.append(_row([f["name"], _feature_value(f["key"]), f["source"], *_marks(f["peers"]), f["note"]]))
    return "\n".join(lines) + "\n"


_BLOCKS = {
    "parameter table": lambda: parameter_table("mpu9250"),
    "chip table": chip_table,
}


def fill_docs(text: str) -> str:
    """``text`` with every ``<!-- BEGIN name ... -->`` … ``<!-- END name -->`` block replaced by
    the freshly rendered table (used on docs/sensors.md; a test checks it is unchanged)."""
    for name, render in _BLOCKS.items():
        begin = text.find(f"<!-- BEGIN {name}")
        end = text.find(f"<!-- END {name} -->")
        if begin < 0 or end < 0:
            raise ValueError(f"no '{name}' block in the text")
        head_end = text.index("-->", begin) + 3
        text = text[:head_end] + "\n" + render() + text[end:]
    return text
