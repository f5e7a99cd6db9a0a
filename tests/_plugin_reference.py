"""The plug-in model in Python: ``biso_cosim.plugin.ImuPlugin`` (issue 24, the Python
implementation of BisoImuPlugin's model), driven one tick per communication step, its
outputs laid out as the FMU's. The native BisoImuPlugin is tested against it: every output
bit for bit except ``error.*``, which ImuPlugin gives in degrees (compared in rad to 1e-12)."""

from __future__ import annotations

import datetime
import math

import numpy as np

from biso_cosim.fmu.variables import RAW_WORDS
from biso_cosim.frames import _euler_from_q, quat_from_euler
from biso_cosim.plugin import ImuPlugin, Mounting
from biso_cosim.sensors import EarthField

OUTPUTS = (["sample_time", "new_samples"] + [f"{h}.{c}" for h in ("gyro_b", "accel_b", "mag_b") for c in "xyz"]
           + ["temperature_c", "mag_fresh", "imu_flags"] + [f"raw.{w}" for w in RAW_WORDS] + ["raw.st1", "raw.st2"]
           + [f"estimate.q_wb.{c}" for c in "wxyz"]
           + ["estimate.roll", "estimate.pitch", "estimate.yaw", "estimate.heading", "estimate.flags"]
           + [f"estimate.gyro_bias_b.{c}" for c in "xyz"]
           + ["error.roll", "error.pitch", "error.heading", "error.total"])
"""The plug-in's outputs, in the column order of `plugin_reference`."""

ERRORS = slice(OUTPUTS.index("error.roll"), len(OUTPUTS))
"""The error columns (compared to 1e-12: ImuPlugin computes them in degrees)."""

_START = {"estimate.q_wb.w": 1.0, "estimate.heading": math.pi / 2, "estimate.flags": 1.0}


def _heading(yaw: float) -> float:
    h = (0.5 * math.pi - yaw) % (2.0 * math.pi)
    return 0.0 if h >= 2.0 * math.pi else h


def plugin_reference(h, omega, force, q_wb, pos=None, vel=None, temperature=None, *, profile="mpu9250_calibrated",
                     seed=0, registers=None, mounting=(0.0, 0.0, 0.0), position=(0.0, 0.0, 0.0),
                     site=(51.53, 46.03, 50.0, "2024-05-01"), estimator="biso", params=None, use_velocity=False,
                     declination_from_site=True) -> np.ndarray:
    """The outputs (``OUTPUTS`` columns) after each of the steps of size h that feed the
    truth rows to ImuPlugin (one tick each); ``temperature`` (n,) is the die temperature."""
    n = len(omega)
    params = dict(params or {})
    if not declination_from_site:
        params.setdefault("declination_rad", 0.0)  # the FMU's parameter (its start value)
    plugin = ImuPlugin(tick_s=h, profile=profile, seed=seed, registers=registers,
                       mounting=Mounting(position, None if not any(mounting) else tuple(quat_from_euler(*mounting))),
                       site=EarthField(site[0], site[1], site[2], datetime.date.fromisoformat(site[3])),
                       estimators={"est": (estimator, params)}, speed_from_velocity=use_velocity)
    col = {name: i for i, name in enumerate(OUTPUTS)}
    current = np.zeros(len(OUTPUTS))
    for name, value in _START.items():
        current[col[name]] = value
    out = np.empty((n, len(OUTPUTS)))
    for i in range(n):
        s = plugin.step(i * h, q_wb[i], omega[i], force[i], p_w=None if pos is None else pos[i],
                        v_w=None if vel is None else vel[i],
                        temperature_c=None if temperature is None else float(temperature[i]))
        current[col["new_samples"]] = len(s)
        if len(s):
            e = s.estimates["est"]
            mag = np.zeros(3) if s.flags[-1] & 16 else s.mag_b[-1]  # the FMU's sentinel for no AK8963 sample
            values = [s.t_s[-1], *s.gyro_b[-1], *s.accel_b[-1], *mag, s.temperature_c[-1], s.samples.mag_fresh[-1],
                      s.flags[-1], *s.raw.words[-1], *s.raw.status[-1]]
            current[[col[k] for k in OUTPUTS[:1] + OUTPUTS[2:col["raw.st2"] + 1]]] = values
            qe = e.estimate.q_wb[-1]
            roll, pitch, yaw = _euler_from_q(*qe)
            bias = np.zeros(3) if e.estimate.gyro_bias_b is None else e.estimate.gyro_bias_b[-1]
            err = e.errors_deg
            current[col["estimate.q_wb.w"]:] = [*qe, roll, pitch, yaw, _heading(yaw), e.estimate.flags[-1], *bias,
                                                *(math.radians(err[k][-1]) for k in ("roll", "pitch", "heading",
                                                                                      "total"))]
        out[i] = current
    return out


def assert_plugin_equal(out: np.ndarray, ref: np.ndarray) -> None:
    """Every output bit for bit, the errors (degrees in ImuPlugin) to 1e-12 rad."""
    assert np.array_equal(out[:, :ERRORS.start], ref[:, :ERRORS.start]), \
        [OUTPUTS[i] for i in np.where(np.any(out[:, :ERRORS.start] != ref[:, :ERRORS.start], axis=0))[0]]
    assert np.max(np.abs(out[:, ERRORS] - ref[:, ERRORS])) <= 1e-12
