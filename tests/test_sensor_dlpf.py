"""DLPF: each table entry's -3 dB bandwidth and delay, measured through the whole model."""

import math

import numpy as np
import pytest

from biso_cosim.sensors import MPU9250, Profile, Registers
from biso_cosim.sensors.dlpf import design_dlpf, filter_reference, frequency_response
from biso_cosim.sensors.registers import chip_tables

# a part without errors but with the chip's filters
FILTERED = Profile.load("ideal").replace(name="ideal+dlpf", model__dlpf=True)

GYRO_ENTRIES = [{"dlpf_cfg": k, "smplrt_div": 0} for k in range(8)] + [
    {"gyro_fchoice_b": 1, "smplrt_div": 0},
    {"gyro_fchoice_b": 2, "smplrt_div": 0},
]
ACCEL_ENTRIES = [{"a_dlpf_cfg": k, "dlpf_cfg": 1, "smplrt_div": 0} for k in range(8)] + [
    {"accel_fchoice_b": 1, "dlpf_cfg": 1, "smplrt_div": 0}
]


def _entry(sensor, regs):
    return regs.gyro_dlpf if sensor == "gyro" else regs.accel_dlpf


def _run(sensor, regs, signal, f_in):
    """Feed a scalar signal to the x axis of one sensor; return (t_s, reading x)."""
    n = signal.size
    x = np.zeros((n, 3))
    x[:, 0] = signal
    imu = MPU9250(FILTERED, registers=regs, input_rate_hz=f_in)
    zeros, ones = np.zeros((n, 3)), np.ones((n, 3))
    s = imu.simulate(x, zeros, ones) if sensor == "gyro" else imu.simulate(zeros, x, ones)
    return s.t_s, (s.gyro_b if sensor == "gyro" else s.accel_b)[:, 0]


def _gain(sensor, regs, freq):
    entry = _entry(sensor, regs)
    f_in = max(entry.rate_hz, 1000.0)
    n = int(f_in * max(0.5, 40.0 / freq)) + int(0.2 * f_in)
    t = np.arange(n) / f_in
    t_s, y = _run(sensor, regs, np.sin(2 * np.pi * freq * t), f_in)
    keep = t_s > 0.2  # past the transient
    basis = np.stack([np.sin(2 * np.pi * freq * t_s[keep]), np.cos(2 * np.pi * freq * t_s[keep])], axis=1)
    coef, *_ = np.linalg.lstsq(basis, y[keep], rcond=None)
    return math.hypot(*coef)


@pytest.mark.parametrize("sensor,fields", [("gyro", f) for f in GYRO_ENTRIES] + [("accel", f) for f in ACCEL_ENTRIES])
def test_measured_bandwidth_and_delay_match_the_table(sensor, fields):
    regs = Registers(**fields)
    entry = _entry(sensor, regs)
    # -3 dB: the gain crosses 1/√2 between 0.9 and 1.1 times the table bandwidth
    g_at = _gain(sensor, regs, entry.bandwidth_hz)
    assert g_at == pytest.approx(1 / math.sqrt(2), rel=2e-3)
    assert _gain(sensor, regs, 0.9 * entry.bandwidth_hz) > 1 / math.sqrt(2)
    assert _gain(sensor, regs, 1.1 * entry.bandwidth_hz) < 1 / math.sqrt(2)
    # delay: a ramp comes out late by exactly the table delay (steady state)
    f_in = max(entry.rate_hz, 1000.0)
    duration = 0.1 + 40 * entry.delay_s  # the transient decays as exp(-t/delay) or faster
    t = np.arange(int(duration * f_in)) / f_in
    t_s, y = _run(sensor, regs, 2.0 * t, f_in)
    late = t_s > duration - 0.05
    lag = t_s[late] - y[late] / 2.0
    np.testing.assert_allclose(lag, entry.delay_s, atol=1e-9)


def test_every_table_entry_has_a_design_with_positive_rest():
    tables = chip_tables()
    rows = [(r[0], r[1], r[2]) for r in tables["gyro_dlpf"]["dlpf_cfg"]]
    rows += [tuple(tables["gyro_dlpf"][k][:3]) for k in ("fchoice_b_x1", "fchoice_b_10")]
    rows += [(r[0], r[1], r[2]) for r in tables["accel_dlpf"]["a_dlpf_cfg"]]
    rows.append(tuple(tables["accel_dlpf"]["accel_fchoice_b_1"][:3]))
    for bw, delay_ms, rate in rows:
        d = design_dlpf(bw, delay_ms * 1e-3, rate)
        assert abs(frequency_response(d, bw)) == pytest.approx(1 / math.sqrt(2), rel=1e-12)
        assert d.group_delay_s == pytest.approx(delay_ms * 1e-3, rel=1e-12)
        assert -1 < d.allpass_d < 1 and d.delay_samples <= 8
        # the analytic group delay at DC from the phase slope
        df = 1e-3
        phase = np.angle(frequency_response(d, [0.0, df]))
        assert -(phase[1] - phase[0]) / (2 * np.pi * df) == pytest.approx(delay_ms * 1e-3, rel=1e-5)


def test_kernel_filter_equals_the_plain_reference():
    regs = Registers(smplrt_div=0, dlpf_cfg=2)
    rng = np.random.default_rng(3)
    signal = rng.normal(size=2000)
    _, y = _run("gyro", regs, signal, 1000.0)
    ref = filter_reference(design_dlpf(92.0, 3.9e-3, 1000.0), signal)
    np.testing.assert_allclose(y, ref, rtol=0, atol=1e-13)
