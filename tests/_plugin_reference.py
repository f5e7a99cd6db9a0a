"""The plug-in model in Python, as the retired pythonfmu BisoImuPlugin slave computed it
(fmu/imu_plugin.py up to issue 20): ``MPU9250.simulate`` on each truth row, the Earth field
rotated into body axes with the row's attitude, every sample to the estimator, the error
against the nlerp of the truth attitude at the sample's time stamp. The native
BisoImuPlugin is tested against it bit for bit (until ``biso_cosim.plugin.ImuPlugin``,
issue 24, becomes the reference)."""

from __future__ import annotations

import datetime
import math

import numpy as np

from biso_cosim.estimators import make_estimator
from biso_cosim.frames import _euler_from_q, _qmul, _qnormalize, quat_conjugate, quat_from_euler, quat_rotate
from biso_cosim.fmu.variables import RAW_WORDS
from biso_cosim.sensors import MPU9250, EarthField, MagneticEnvironment

OUTPUTS = (["sample_time", "new_samples"] + [f"{h}.{c}" for h in ("gyro_b", "accel_b", "mag_b") for c in "xyz"]
           + ["temperature_c", "mag_fresh", "imu_flags"] + [f"raw.{w}" for w in RAW_WORDS] + ["raw.st1", "raw.st2"]
           + [f"estimate.q_wb.{c}" for c in "wxyz"]
           + ["estimate.roll", "estimate.pitch", "estimate.yaw", "estimate.heading", "estimate.flags"]
           + [f"estimate.gyro_bias_b.{c}" for c in "xyz"]
           + ["error.roll", "error.pitch", "error.heading", "error.total"])
"""The plug-in's outputs, in the column order of `plugin_reference`."""

_START = {"estimate.q_wb.w": 1.0, "estimate.heading": math.pi / 2, "estimate.flags": 1.0}


def _heading(yaw: float) -> float:
    h = (0.5 * math.pi - yaw) % (2.0 * math.pi)
    return 0.0 if h >= 2.0 * math.pi else h


def _nlerp(q0: np.ndarray, q1: np.ndarray, frac: np.ndarray) -> np.ndarray:
    q1 = q1 if float(np.dot(q0, q1)) >= 0.0 else -q1
    q = (1.0 - frac)[:, None] * q0 + frac[:, None] * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def plugin_reference(h, omega, force, q_wb, pos=None, vel=None, temperature=None, *, profile="mpu9250_calibrated",
                     seed=0, registers=None, mounting=(0.0, 0.0, 0.0), site=(51.53, 46.03, 50.0, "2024-05-01"),
                     estimator="biso", params=None, use_velocity=False, declination_from_site=True) -> np.ndarray:
    """The outputs (``OUTPUTS`` columns) after each of the steps of size h that feed the
    truth rows; ``temperature`` (n,) is used as the die temperature when given."""
    n = len(omega)
    pos = np.zeros((n, 3)) if pos is None else np.asarray(pos, dtype=float)
    vel = np.zeros((n, 3)) if vel is None else np.asarray(vel, dtype=float)
    earth = EarthField(site[0], site[1], site[2], datetime.date.fromisoformat(site[3]))
    magnetic = MagneticEnvironment(earth)
    imu = MPU9250(profile, seed=seed, registers=registers, input_rate_hz=1.0 / h,
                  mounting=None if not any(mounting) else quat_from_euler(*mounting))
    params = dict(params or {})
    if declination_from_site:
        params["declination_rad"] = earth.declination_rad
    est = make_estimator(estimator, imu.output_rate_hz, **params)
    col = {name: i for i, name in enumerate(OUTPUTS)}
    current = np.zeros(len(OUTPUTS))
    for name, value in _START.items():
        current[col[name]] = value
    out = np.empty((n, len(OUTPUTS)))
    prev = None
    for i in range(n):
        q = np.array(q_wb[i], dtype=float)
        q = q / float(np.linalg.norm(q))
        mag_b = magnetic.field_b(q[None, :], pos[i][None, :])
        t_in = imu.time_s
        s = imu.simulate(omega[i][None, :], force[i][None, :], mag_b,
                         None if temperature is None else float(temperature[i]))
        row = np.concatenate(([t_in], q, vel[i]))
        p = prev if prev is not None else row  # the chip starts settled
        prev = row
        current[col["new_samples"]] = len(s)
        if len(s):
            frac = np.clip((s.t_s - t_in) / h + 1.0, 0.0, 1.0)
            q_true = _nlerp(p[1:5], q, frac)
            extra = {}
            if use_velocity:
                v_w = (1.0 - frac)[:, None] * p[5:8] + frac[:, None] * vel[i]
                extra["speed_mps"] = quat_rotate(quat_conjugate(q_true), v_w)[:, 0]
            e = est.update(s.gyro_b, s.accel_b, s.mag_b, **extra)
            mag = np.zeros(3) if s.flags[-1] & 16 else s.mag_b[-1]  # the FMU's sentinel for no AK8963 sample
            values = [s.t_s[-1], *s.gyro_b[-1], *s.accel_b[-1], *mag, s.temperature_c[-1], s.mag_fresh[-1],
                      s.flags[-1], *s.raw.words[-1], *s.raw.status[-1]]
            current[[col[k] for k in OUTPUTS[:1] + OUTPUTS[2:col["raw.st2"] + 1]]] = values
            qe = e.q_wb[-1]
            roll, pitch, yaw = _euler_from_q(*qe)
            bias = np.zeros(3) if e.gyro_bias_b is None else e.gyro_bias_b[-1]
            ee, tt = _qnormalize(*qe), _qnormalize(*q_true[-1])
            ae, at = _euler_from_q(*ee), _euler_from_q(*tt)
            diff = (ae[0] - at[0], ae[1] - at[1], _heading(ae[2]) - _heading(at[2]))
            d = _qmul(ee[0], -ee[1], -ee[2], -ee[3], *tt)
            total = 2.0 * math.atan2(math.sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3]), abs(d[0]))
            current[col["estimate.q_wb.w"]:] = [*qe, roll, pitch, yaw, _heading(yaw), e.flags[-1], *bias,
                                                *(math.pi - (math.pi - a) % (2.0 * math.pi) for a in diff), total]
        out[i] = current
    return out
