"""The virtual MPU-9250: streaming, seeds, timing, quantization, saturation, axes, raw registers."""

import math

import numpy as np
import pytest

from biso_cosim.frames import quat_from_euler, quat_to_matrix
from biso_cosim.sensors import (
    ACCEL_SATURATED,
    GYRO_SATURATED,
    MAG_INVALID,
    MAG_OVERFLOW,
    MPU9250,
    ImuSamples,
    Profile,
    RawSamples,
    Registers,
    raw_to_si,
)
from biso_cosim.units import DEG, G0

FS = 1000.0


def motion(n, seed=0, fs=FS):
    """Smooth random-looking truth: rates within ±100 °/s, forces around +g, field ~50 µT."""
    t = np.arange(n) / fs
    rng = np.random.default_rng(seed)
    freq = rng.uniform(0.2, 3.0, size=(3, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(3, 3))
    waves = np.sin(2 * np.pi * freq[None, :, :] * t[:, None, None] + phase[None])
    omega = 1.5 * waves[:, 0, :]
    force = np.array([0.0, 0.0, G0]) + 3.0 * waves[:, 1, :]
    mag = np.array([5.0, 18.0, -47.0]) + 4.0 * waves[:, 2, :]
    temp = 25.0 + 5.0 * np.sin(2 * np.pi * 0.1 * t)
    return omega, force, mag, temp


def stream(imu, arrays, sizes, **kw):
    parts, start = [], 0
    n = arrays[0].shape[0]
    for size in sizes:
        stop = min(n, start + size)
        parts.append(imu.simulate(*(a[start:stop] for a in arrays), **kw))
        start = stop
    assert start == n
    return ImuSamples.concatenate(parts)


def assert_same(a: ImuSamples, b: ImuSamples):
    for name in ("t_s", "gyro_b", "accel_b", "mag_b", "mag_fresh", "temperature_c", "flags", "dtheta", "dv", "dtheta_sub", "dv_sub"):
        x, y = getattr(a, name), getattr(b, name)
        if x is None:
            assert y is None
            continue
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert np.array_equal(x, y, equal_nan=True), name
    for name in ("accel", "temp", "gyro", "mag", "st1", "st2"):
        assert np.array_equal(getattr(a.raw, name), getattr(b.raw, name)), name


def test_batch_equals_streaming_bit_for_bit():
    arrays = motion(3000)
    imu = MPU9250("mpu9250", seed=3)
    whole = imu.simulate(*arrays, increments=4, subintervals=5)
    rng = np.random.default_rng(0)
    sizes = list(rng.integers(0, 50, size=400)) + [3000]
    imu.reset()
    chunked = stream(imu, arrays, sizes, increments=4, subintervals=5)
    assert_same(whole, chunked)
    # one sample at a time, and a chunk of the co-simulation's size
    for size in (1, 20):
        imu.reset()
        assert_same(whole, stream(imu, arrays, [size] * 3000, increments=4, subintervals=5))


def test_same_seed_same_readings_other_seed_differs():
    arrays = motion(500)
    a = MPU9250(seed=11).simulate(*arrays)
    b = MPU9250(seed=11).simulate(*arrays)
    c = MPU9250(seed=12).simulate(*arrays)
    assert_same(a, b)
    assert not np.array_equal(a.gyro_b, c.gyro_b)
    # reset with a new seed is the same as a new object with that seed
    imu = MPU9250(seed=11)
    imu.simulate(*arrays)
    imu.reset(seed=12)
    assert_same(c, imu.simulate(*arrays))


def test_get_set_state_resumes_exactly():
    arrays = motion(1000)
    imu = MPU9250(seed=5)
    imu.simulate(*(a[:400] for a in arrays))
    state = imu.get_state()
    rest = imu.simulate(*(a[400:] for a in arrays))
    imu.simulate(*(a[:100] for a in arrays))  # wander off
    imu.set_state(state)
    assert_same(rest, imu.simulate(*(a[400:] for a in arrays)))


@pytest.mark.parametrize("smplrt_div", [0, 4, 9])
def test_output_timing_and_chunk_ownership(smplrt_div):
    imu = MPU9250("ideal", registers={"smplrt_div": smplrt_div})
    odr = 1000.0 / (1 + smplrt_div)
    assert imu.output_rate_hz == pytest.approx(odr)
    omega, force, mag, temp = motion(1000)
    s = imu.simulate(omega[:20], force[:20], mag[:20])
    # the call spanning inputs at t = 0..19 ms returns the outputs latched at t in [0, 19] ms
    np.testing.assert_allclose(s.t_s, np.arange(0, 0.0195, 1 / odr))
    s2 = imu.simulate(omega[20:40], force[20:40], mag[20:40])
    assert np.all((s2.t_s >= 0.02 - 1e-12) & (s2.t_s <= 0.039 + 1e-12))
    # ideal readings are the truth at the output instants
    idx = np.round(s.t_s * FS).astype(int)
    np.testing.assert_allclose(s.gyro_b, omega[idx], atol=1e-12)
    np.testing.assert_allclose(s.accel_b, force[idx], atol=1e-12)


@pytest.mark.parametrize("registers", [{}, {"mag_mode": 0x0}, {"mag_mode": 0x1}])
def test_the_kernel_writes_every_output_entry(monkeypatch, registers):
    """The co-simulation reuses the sensor's output arrays between periods: whatever they
    held before (here garbage), the samples and raw registers are the same, with the
    magnetometer measuring, powered down, or in single-measurement mode."""
    arrays = motion(400)[:3]
    expected = MPU9250("mpu9250", seed=4, registers=registers).simulate(*arrays, increments=2, subintervals=2)
    fresh = MPU9250.output_arrays

    def garbage(self, n, increments, subintervals):
        out = fresh(self, n, increments, subintervals)
        for a in out:
            a.view(np.uint8)[...] = 0x5A
        return out

    monkeypatch.setattr(MPU9250, "output_arrays", garbage)
    got = MPU9250("mpu9250", seed=4, registers=registers).simulate(*arrays, increments=2, subintervals=2)
    assert_same(got, expected)
    np.testing.assert_array_equal(got.raw.words, expected.raw.words)
    np.testing.assert_array_equal(got.raw.status, expected.raw.status)


def test_output_bound_holds_every_output_a_call_completes():
    """The caller allocates the kernel's outputs by output_bound; it must never be short
    (``_n_outputs`` written plainly), and it wastes at most the ticks of one input row."""
    from biso_cosim.sensors._kernels import output_bound

    def n_outputs(up, out_div, n_in, tick, n):
        if n == 0:
            return 0
        b0 = tick
        b1 = b0 + (1 + (n - 1) * up if n_in == 0 else n * up) - 1
        return b1 // out_div - (b0 + out_div - 1) // out_div + 1

    for up in (1, 8):
        for out_div in (1, 5, 8, 40):
            for tick in range(3 * out_div):
                for n in range(60):
                    for n_in in ((0,) if tick == 0 else (1,)):
                        due = n_outputs(up, out_div, n_in, tick, n)
                        assert due <= output_bound(n, up, out_div) <= due + up // out_div + 1
    # and through the chip in odd chunks, upsampling (8 kHz from 1 kHz) and decimating
    for registers in ({"dlpf_cfg": 0}, {"smplrt_div": 7}):
        arrays = motion(997)[:3]
        whole = MPU9250("mpu9250", seed=2, registers=registers).simulate(*arrays)
        assert_same(stream(MPU9250("mpu9250", seed=2, registers=registers), arrays, [1, 2, 3, 5, 7, 11, 13] * 40 + [500]),
                    whole)


def test_bypass_rates_upsample_and_decimate():
    # DLPF_CFG = 0: gyro at 8 kHz, output 8 kHz; the truth at 1 kHz is interpolated linearly
    imu = MPU9250("ideal", registers={"dlpf_cfg": 0})
    assert imu.output_rate_hz == 8000.0
    n = 50
    t = np.arange(n) / FS
    omega = np.stack([t, 2 * t, -t], axis=1)  # linear: interpolation is exact
    s = imu.simulate(omega, np.zeros((n, 3)), np.ones((n, 3)))
    assert len(s) == 8 * (n - 1) + 1
    np.testing.assert_allclose(s.gyro_b, np.stack([s.t_s, 2 * s.t_s, -s.t_s], axis=1), atol=1e-12)
    # truth at 8 kHz into a 1 kHz chip: the chip point-samples every 8th input
    imu = MPU9250("ideal", input_rate_hz=8000.0)
    omega8 = np.random.default_rng(1).normal(size=(800, 3))
    s = imu.simulate(omega8, np.zeros((800, 3)), np.ones((800, 3)))
    np.testing.assert_array_equal(s.gyro_b, omega8[::40])
    np.testing.assert_allclose(s.t_s, np.arange(20) / 200.0)


def test_mag_rate_hold_and_fresh():
    for mode, rate in ((0x6, 100.0), (0x2, 8.0)):
        imu = MPU9250("ideal", registers={"mag_mode": mode})
        n = 1000
        t = np.arange(n) / FS
        mag = np.stack([t, 0 * t + 1, 0 * t], axis=1)
        s = imu.simulate(np.zeros((n, 3)), np.zeros((n, 3)), mag)
        fresh_t = s.t_s[s.mag_fresh]
        np.testing.assert_allclose(np.diff(fresh_t), 1 / rate)
        # held value = the field at the last AK8963 instant before the output
        last = np.floor(s.t_s * rate + 1e-9) / rate
        np.testing.assert_allclose(s.mag_b[:, 0], last, atol=1e-12)
    off = MPU9250("ideal", registers={"mag_mode": 0x0}).simulate(np.zeros((10, 3)), np.zeros((10, 3)), np.ones((10, 3)))
    assert np.all(np.isnan(off.mag_b)) and np.all(off.flagged(MAG_INVALID)) and not off.mag_fresh.any()


def test_quantization_steps_and_raw_to_si_bit_for_bit():
    mounting = quat_from_euler(0.3, -0.2, 1.1)
    regs = Registers(gyro_fs_sel=2, accel_fs_sel=0, mag_bit16=False)
    imu = MPU9250("mpu9250", seed=1, registers=regs, mounting=mounting)
    s = imu.simulate(*motion(2000))
    # SI readings are codes / sensitivity, rotated into the body: undo the rotation
    r_cb = quat_to_matrix(mounting).T
    gyro_chip = s.gyro_b @ r_cb.T
    np.testing.assert_allclose(gyro_chip * (32.8 / DEG), s.raw.gyro, atol=1e-6)
    accel_chip = s.accel_b @ r_cb.T
    np.testing.assert_allclose(accel_chip * (16384 / G0), s.raw.accel, atol=1e-6)
    # the documented conversion reproduces the SI readings exactly
    si = raw_to_si(s.raw, regs, imu.asa, mounting)
    np.testing.assert_array_equal(si.gyro_b, s.gyro_b)
    np.testing.assert_array_equal(si.accel_b, s.accel_b)
    np.testing.assert_array_equal(si.mag_b, s.mag_b)
    np.testing.assert_array_equal(si.temperature_c, s.temperature_c)
    # 14-bit AK8963: 0.6 µT per code
    assert np.all(np.abs(s.raw.mag) <= 8190)
    assert np.all(s.raw.st2 & 16 == 0)


def test_register_bytes_round_trip_and_endianness():
    imu = MPU9250("mpu9250", seed=2)
    s = imu.simulate(*motion(200))
    mb, ab = s.raw.mpu_bytes(), s.raw.ak8963_bytes()
    assert mb.shape == (len(s), 14) and ab.shape == (len(s), 8)
    # ACCEL_XOUT_H is the high byte (big-endian); HXL the low byte (little-endian)
    assert np.array_equal((mb[:, 0].astype(np.int16) << 8) | mb[:, 1], s.raw.accel[:, 0])
    hx = (ab[:, 2].astype(np.int16) << 8) | ab[:, 1]
    assert np.array_equal(hx, s.raw.mag[:, 0])
    back = RawSamples.from_bytes(mb, ab)
    for name in ("accel", "temp", "gyro", "mag", "st1", "st2"):
        assert np.array_equal(getattr(back, name), getattr(s.raw, name))


def test_saturation_is_flagged_never_wrapped():
    imu = MPU9250("mpu9250", seed=0)  # ±250 °/s, ±4 g
    n = 400
    omega = np.zeros((n, 3))
    omega[100:200, 2] = 300 * DEG
    omega[200:300, 2] = -300 * DEG
    force = np.tile([0.0, 0.0, G0], (n, 1))
    force[250:, 0] = 6 * G0
    s = imu.simulate(omega, force, np.ones((n, 3)))
    sat_g = s.flagged(GYRO_SATURATED)
    sat_a = s.flagged(ACCEL_SATURATED)
    # the DLPF delays the edges by ~6 ms: look well inside the intervals
    inside_pos = (s.t_s > 0.12) & (s.t_s < 0.2)
    inside_neg = (s.t_s > 0.22) & (s.t_s < 0.3)
    assert sat_g[inside_pos].all() and sat_g[inside_neg].all() and not sat_g[s.t_s < 0.09].any()
    # the ADC clips before the DLPF, so the register settles at the end codes
    settled_pos = (s.t_s > 0.15) & (s.t_s < 0.2)
    settled_neg = (s.t_s > 0.25) & (s.t_s < 0.3)
    assert np.all(s.raw.gyro[settled_pos, 2] == 32767) and np.all(s.raw.gyro[settled_neg, 2] == -32768)
    assert np.all(np.abs(s.gyro_b[:, 2]) <= 32768 / (131 / DEG))
    assert sat_a[s.t_s > 0.27].all() and not sat_a[s.t_s < 0.24].any()
    assert np.all(s.raw.accel[s.t_s > 0.3, 0] == 32767)


def test_ak8963_axes_asa_and_overflow():
    prof = Profile.load("ideal").replace(model__quantization=True, mag__asa_range=[176.0, 176.0])
    imu = MPU9250(prof, seed=0)
    assert np.all(imu.asa == 176)
    field = np.array([[30.0, 0.0, 0.0], [0.0, 30.0, 0.0], [0.0, 0.0, 30.0]])
    outs = []
    for b in field:
        imu.reset()
        outs.append(imu.simulate(np.zeros((1, 3)), np.zeros((1, 3)), b[None]))
    # identity mounting: chip axes = body axes; AK8963: m_x = a_y, m_y = a_x, m_z = -a_z
    adj = (176 - 128) / 256 + 1
    code = round(30.0 / (0.15 * adj))
    assert outs[0].raw.mag[0].tolist() == [0, code, 0]
    assert outs[1].raw.mag[0].tolist() == [code, 0, 0]
    assert outs[2].raw.mag[0].tolist() == [0, 0, -code]
    for o, b in zip(outs, field):
        np.testing.assert_allclose(o.mag_b[0], b, atol=0.15 * adj / 2 + 1e-12)
    imu.reset()
    big = imu.simulate(np.zeros((1, 3)), np.zeros((1, 3)), np.array([[3000.0, 2000.0, 100.0]]))
    assert big.flagged(MAG_OVERFLOW)[0] and big.raw.st2[0] & 8


def test_ideal_profile_reads_the_truth_in_body_axes():
    mounting = quat_from_euler(0.1, 0.2, -2.0)
    imu = MPU9250("ideal", mounting=mounting)
    omega, force, mag, temp = motion(500)
    s = imu.simulate(omega, force, mag, temp)
    idx = np.round(s.t_s * FS).astype(int)
    np.testing.assert_allclose(s.gyro_b, omega[idx], atol=1e-12)
    np.testing.assert_allclose(s.accel_b, force[idx], atol=1e-12)
    np.testing.assert_allclose(s.mag_b, mag[idx - idx % 10], atol=1e-12)
    np.testing.assert_allclose(s.temperature_c, temp[idx], atol=1e-12)


def test_white_noise_level_matches_density():
    prof = Profile.load("ideal").replace(gyro__noise_density=0.01, accel__noise_density=300.0)
    imu = MPU9250(prof, seed=4, registers={"smplrt_div": 0})
    n = 20000
    s = imu.simulate(np.zeros((n, 3)), np.zeros((n, 3)), np.ones((n, 3)))
    # no filter, no quantization: σ = N·√f per sample at the internal rate
    np.testing.assert_allclose(s.gyro_b.std(axis=0), 0.01 * DEG * math.sqrt(1000), rtol=0.03)
    np.testing.assert_allclose(s.accel_b.std(axis=0), 300e-6 * G0 * math.sqrt(1000), rtol=0.03)


def test_bad_input_is_refused_and_changes_nothing():
    arrays = motion(200)
    imu = MPU9250(seed=0)
    ref = MPU9250(seed=0)
    first = imu.simulate(*(a[:100] for a in arrays[:3]))
    ref.simulate(*(a[:100] for a in arrays[:3]))
    bad = arrays[0][100:].copy()
    bad[7, 1] = np.nan
    with pytest.raises(ValueError, match="omega_b must be finite: row 7"):
        imu.simulate(bad, arrays[1][100:], arrays[2][100:])
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        imu.simulate(arrays[0][100:, :2], arrays[1][100:], arrays[2][100:])
    with pytest.raises(ValueError, match="same number of rows"):
        imu.simulate(arrays[0][100:], arrays[1][101:], arrays[2][100:])
    with pytest.raises(ValueError, match="temperature_c"):
        imu.simulate(*(a[100:] for a in arrays[:3]), temperature_c=np.ones(3))
    with pytest.raises(ValueError, match="temperature_c must be finite"):
        imu.simulate(*(a[100:] for a in arrays[:3]), temperature_c=np.full(100, np.inf))
    with pytest.raises(ValueError, match="increments"):
        imu.simulate(*(a[100:] for a in arrays[:3]), increments=5)
    assert len(first) == 20
    assert_same(ref.simulate(*(a[100:] for a in arrays[:3])), imu.simulate(*(a[100:] for a in arrays[:3])))


def test_bad_settings_are_named():
    with pytest.raises(ValueError, match="registers.dlpf_cfg"):
        MPU9250(registers={"dlpf_cfg": 9})
    with pytest.raises(ValueError, match="unknown field"):
        MPU9250(registers={"dlpf": 1})
    with pytest.raises(ValueError, match="mag_mode"):
        Registers(mag_mode=0x3)
    with pytest.raises(ValueError, match="rotation"):
        MPU9250(mounting=np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="unit norm"):
        MPU9250(mounting=[1.0, 0.1, 0.0, 0.0])
    with pytest.raises(ValueError, match="input_rate_hz"):
        MPU9250(input_rate_hz=400.0)
    with pytest.raises(ValueError, match="input_rate_hz"):
        MPU9250(input_rate_hz=-1.0)
    with pytest.raises(ValueError, match="neither a built-in"):
        MPU9250("mpu6050")
    with pytest.raises(TypeError, match="seed"):
        MPU9250(seed=1.5)
    # increments need whole accelerometer samples per output interval
    imu = MPU9250("ideal", registers={"dlpf_cfg": 0})
    with pytest.raises(ValueError, match="increments need"):
        imu.simulate(np.zeros((4, 3)), np.zeros((4, 3)), np.ones((4, 3)), increments=1)


@pytest.mark.parametrize("dly,period", [(0, 0.010), (1, 0.010), (3, 0.020)])
def test_ak8963_single_mode_trigger_and_measurement_time(dly, period):
    # triggers at t = 0, period, 2·period ...; the 7.2 ms measurement is read at the next
    # output after it (10 ms later at 200 Hz)
    """Single mode: the driver triggers after reading, every 1 + I2C_MST_DLY outputs (5 ms
    apart); the data is readable 7.2 ms later; triggers during a measurement are ignored."""
    imu = MPU9250("ideal", registers={"mag_mode": 0x1, "i2c_mst_dly": dly})
    n = 200
    t = np.arange(n) / FS
    s = imu.simulate(np.zeros((n, 3)), np.zeros((n, 3)), np.stack([t, 0 * t, 0 * t + 1], axis=1))
    fresh_t = s.t_s[s.mag_fresh]
    np.testing.assert_allclose(fresh_t, 0.010 + np.arange(len(fresh_t)) * period, atol=1e-12)
    # each fresh value is the field at its trigger instant
    np.testing.assert_allclose(s.mag_b[s.mag_fresh, 0], fresh_t - 0.010, atol=1e-12)
    assert s.flagged(MAG_INVALID)[s.t_s < 0.010].all() and not s.flagged(MAG_INVALID)[s.t_s >= 0.010].any()
