"""`biso-cosim compare` scores a motion over its movement only (``Dataset.info["moving"]``),
as BROAD scores its trials, and a route over every sample."""

import math

import numpy as np
import pytest

from biso_cosim import frames as fr
from biso_cosim.compare import Dataset, _stats


def _dataset(moving=None):
    n = 100
    info = {} if moving is None else {"moving": moving}
    return Dataset(name="d", kind="motion", seed=0, fs_hz=100.0, t_s=np.arange(n) / 100.0,
                   gyro_b=np.zeros((n, 3)), accel_b=np.zeros((n, 3)), mag_b=np.zeros((n, 3)),
                   q_true=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), declination_rad=0.0, info=info)


def _headings(deg):
    """Estimates turned about Up by ``deg`` (a pure heading error) from the identity."""
    half = np.radians(np.asarray(deg, float)) / 2.0
    return np.stack([np.cos(half), 0.0 * half, 0.0 * half, np.sin(half)], axis=1)


def test_the_rest_before_a_motion_is_not_scored():
    """30 samples of rest 10° off, then 70 of movement 1° off: the scored RMS is 1°, not
    √((30·100 + 70·1)/100)°."""
    moving = np.arange(100) >= 30
    q = _headings(np.where(moving, 1.0, 10.0))
    st = _stats(q, _dataset(moving))
    assert st["heading"]["rms_deg"] == pytest.approx(1.0, abs=1e-9)
    assert st["heading"]["max_abs_deg"] == pytest.approx(1.0, abs=1e-9)
    assert st["total"]["rms_deg"] == pytest.approx(1.0, abs=1e-9)
    assert st["roll"]["rms_deg"] == pytest.approx(0.0, abs=1e-9)
    every = _stats(q, _dataset())  # a route: no mask, every sample
    assert every["heading"]["rms_deg"] == pytest.approx(math.sqrt((30 * 100.0 + 70 * 1.0) / 100.0), abs=1e-9)
    assert every["heading"]["max_abs_deg"] == pytest.approx(10.0, abs=1e-9)
    assert np.degrees(fr.quat_angle_between(q[:1], _dataset().q_true[:1]))[0] == pytest.approx(10.0)
