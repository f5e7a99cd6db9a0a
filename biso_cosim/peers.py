"""The open peers our estimators are compared with, run one way for `compare` and `score`.

``vqf``: VQF of Laidig & Seel (2023), the real-time (causal) ``vqf.VQF.updateBatch``;
``vqf_offline``: ``vqf.offlineVQF``, which looks ahead (not comparable with a real-time
filter); ``imufusion``: x-io Fusion AHRS with its documented example settings (gain 0.5,
acceleration and magnetic rejection 10°, recovery 5 s) and its gyro offset corrector. Each
takes sensor-axis samples (rad/s, m/s², µT) and VQF's or these settings' parameters, and
returns ``q_wb`` (N, 4) to true north: the peers reference magnetic north and are turned by
the declination, which our estimators receive as a parameter.
"""

from __future__ import annotations

import numpy as np

from biso_cosim.frames import quat_from_euler, quat_multiply
from biso_cosim.units import G0

IMUFUSION_DEFAULTS = {"gain": 0.5, "acceleration_rejection": 10.0, "magnetic_rejection": 10.0,
                      "recovery_trigger_period_s": 5.0, "gyroscope_range": 2000.0}
"""imufusion's settings (degrees, seconds, °/s) unless given."""


def magnetic_to_true(q_mag: np.ndarray, declination_rad: float) -> np.ndarray:
    """Attitude relative to magnetic north → true north (the world turned by −D about Up)."""
    if declination_rad == 0.0:
        return q_mag
    qz = quat_from_euler(0.0, 0.0, -declination_rad)
    return quat_multiply(np.broadcast_to(qz, q_mag.shape).copy(), q_mag)


def _c64(*arrays: np.ndarray) -> list[np.ndarray]:
    return [np.ascontiguousarray(a, dtype=np.float64) for a in arrays]


def vqf(gyro_b, accel_b, mag_b, fs_hz: float, declination_rad: float, **params) -> np.ndarray:
    import vqf as _vqf

    out = _vqf.VQF(1.0 / fs_hz, **params).updateBatch(*_c64(gyro_b, accel_b, mag_b))
    return magnetic_to_true(out["quat9D"], declination_rad)


def vqf_offline(gyro_b, accel_b, mag_b, fs_hz: float, declination_rad: float, **params) -> np.ndarray:
    import vqf as _vqf

    out = _vqf.offlineVQF(*_c64(gyro_b, accel_b, mag_b), 1.0 / fs_hz, dict(params) or None)
    return magnetic_to_true(out["quat9D"], declination_rad)


def imufusion(gyro_b, accel_b, mag_b, fs_hz: float, declination_rad: float, **params) -> np.ndarray:
    import imufusion as _fusion

    p = {**IMUFUSION_DEFAULTS, **params}
    settings = _fusion.AhrsSettings()
    settings.convention = _fusion.CONVENTION_ENU
    settings.gain = float(p["gain"])
    settings.gyroscope_range = float(p["gyroscope_range"])
    settings.acceleration_rejection = float(p["acceleration_rejection"])
    settings.magnetic_rejection = float(p["magnetic_rejection"])
    settings.rejection_timeout = int(p["recovery_trigger_period_s"] * fs_hz)
    settings.sample_rate = fs_hz
    ahrs = _fusion.Ahrs()
    ahrs.set_settings(settings)
    ahrs.set_sample_period(1.0 / fs_hz)
    bias_settings = _fusion.BiasSettings()
    bias_settings.sample_rate = fs_hz
    offset = _fusion.Bias()
    offset.set_settings(bias_settings)
    gyro_deg = np.degrees(gyro_b)
    accel_g = np.asarray(accel_b) / G0
    mag = np.ascontiguousarray(mag_b, dtype=np.float64)
    out = np.empty((len(gyro_deg), 4))
    update, get_q, correct = ahrs.update, ahrs.get_quaternion, offset.update
    for i in range(len(gyro_deg)):  # imufusion's Python API has no batch call
        update(correct(gyro_deg[i]), accel_g[i], mag[i])
        out[i] = get_q()
    return magnetic_to_true(out, declination_rad)
