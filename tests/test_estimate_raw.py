"""Raw MPU-9250 register logs: conversion, sensor flags from the words, the CSV format, and
``estimate_attitude`` / ``biso-cosim estimate`` on raw logs (against the simulated chip, whose
registers round-trip bit for bit through ``raw_to_si``)."""

import math

import numpy as np
import pytest

from biso_cosim import frames as fr
from biso_cosim import motions as mo
from biso_cosim.cli import main as cli_main
from biso_cosim.estimators import estimate_attitude, estimator_names, flags as fl
from biso_cosim.estimators.rawlog import imu_flags_from_raw, raw_inputs, read_raw_csv, write_raw_csv
from biso_cosim.sensors import MPU9250, EarthField, RawSamples, Registers
from biso_cosim.units import DEG

EARTH = EarthField()
MOUNT = fr.quat_from_euler(0.3, -0.2, 1.1)  # chip → body, deliberately crooked

CONFIGS = {
    "crooked_16bit": (Registers(gyro_fs_sel=1, accel_fs_sel=1), MOUNT),
    "level_14bit_single": (Registers(gyro_fs_sel=3, accel_fs_sel=0, mag_bit16=False, mag_mode=0x1, i2c_mst_dly=3),
                           None),
    "mag_off": (Registers(mag_mode=0x0), fr.quat_from_euler(math.pi, 0.0, 0.5)),
}


def _simulate(config, motion="tumble", seconds=4.0, seed=1, rate_scale=1.0):
    regs, mount = CONFIGS[config]
    m = mo.make_motion(motion, seconds, 1000.0, seed=seed, field_w=tuple(EARTH.field_enu_ut),
                       **({"rate_scale": rate_scale} if motion == "tumble" else {}))
    imu = MPU9250("mpu9250", seed=seed, registers=regs, mounting=mount, input_rate_hz=1000.0)
    return imu, imu.simulate(m.omega_b, m.specific_force_b, m.mag_b), regs, mount


@pytest.mark.parametrize("config", CONFIGS)
def test_raw_inputs_reproduce_the_simulated_readings_and_flags(config):
    imu, s, regs, mount = _simulate(config)
    conv = raw_inputs(s.raw, regs, imu.asa, mount)
    np.testing.assert_array_equal(conv.gyro_b, s.gyro_b)
    np.testing.assert_array_equal(conv.accel_b, s.accel_b)
    np.testing.assert_array_equal(conv.mag_b, s.mag_b)  # NaN where the AK8963 had nothing yet
    np.testing.assert_array_equal(conv.temperature_c, s.temperature_c)
    np.testing.assert_array_equal(conv.imu_flags, s.flags)
    assert conv.mag_bit16 == regs.mag_bit16
    # mag_bit16 left out: read from ST2.BITM
    fields = {"gyro_fs_sel": regs.gyro_fs_sel, "accel_fs_sel": regs.accel_fs_sel}
    np.testing.assert_array_equal(raw_inputs(s.raw, fields, imu.asa, mount).mag_b, s.mag_b)


@pytest.mark.parametrize("name", estimator_names())
def test_estimates_from_raw_equal_estimates_from_si(name):
    imu, s, regs, mount = _simulate("crooked_16bit", seconds=3.0)
    raw = estimate_attitude(s.raw, fs=imu.output_rate_hz, method=name, registers=regs, asa=imu.asa,
                            mounting=mount, full_output=True)
    si = estimate_attitude(s.gyro_b, s.accel_b, s.mag_b, imu.output_rate_hz, name, imu_flags=s.flags,
                           full_output=True)
    np.testing.assert_array_equal(raw.q_wb, si.q_wb)
    np.testing.assert_array_equal(raw.flags, si.flags)
    # without the mounting the body axes are wrong: the estimate is another attitude
    off = estimate_attitude(s.raw, fs=imu.output_rate_hz, method=name, registers=regs, asa=imu.asa)
    assert np.degrees(np.median(fr.quat_angle_between(off, raw.q_wb))) > 10.0


def test_saturation_is_read_from_the_words_and_flagged_by_every_estimator():
    """Tumbling at up to ~10 rad/s with ±250 °/s and ±2 g: the words stick at the full-scale
    codes; those rows are flagged (a subset of what the chip saw, which includes clipping
    inside the ADC that the filtered output hides)."""
    regs = Registers(gyro_fs_sel=0, accel_fs_sel=0)
    m = mo.make_motion("tumble", 4.0, 1000.0, seed=2, rate_scale=2.0, field_w=tuple(EARTH.field_enu_ut))
    imu = MPU9250("mpu9250", seed=2, registers=regs, input_rate_hz=1000.0)
    s = imu.simulate(m.omega_b, m.specific_force_b, m.mag_b)
    flags = imu_flags_from_raw(s.raw)
    at_limit = np.any((s.raw.gyro == 32767) | (s.raw.gyro == -32768), axis=1)
    assert at_limit.sum() > 20
    np.testing.assert_array_equal((flags & fl.IMU_GYRO_SATURATED) != 0, at_limit)
    assert np.all(s.flags[flags != 0] & flags[flags != 0] == flags[flags != 0])  # raw ⊆ chip
    for name in estimator_names():
        out = estimate_attitude(s.raw, fs=imu.output_rate_hz, method=name, registers=regs, asa=imu.asa,
                                full_output=True)
        assert np.all(out.flags[at_limit] & fl.SATURATED)
        assert np.all(np.isfinite(out.q_wb))


def test_status_bytes_overflow_overrun_and_no_data_yet():
    """Hand-made registers: AK8963 data-ready only from row 2, overflow (HOFL) in row 3, a
    skipped sample (DOR) in row 4, 14-bit output (BITM clear) throughout."""
    k = 6
    accel = np.tile([0, 0, 16384], (k, 1))
    mag = np.tile([100, 200, -300], (k, 1))
    mag[:2] = 0
    st1 = np.array([0, 0, 1, 1, 3, 0])
    st2 = np.array([0, 0, 0, 8, 0, 0])
    raw = RawSamples.from_fields(accel, np.zeros(k), np.zeros((k, 3)), mag, st1, st2)
    flags = imu_flags_from_raw(raw)
    np.testing.assert_array_equal(flags, [16, 16, 0, 4, 8, 0])
    conv = raw_inputs(raw, {"accel_fs_sel": 0})
    assert not conv.mag_bit16 and np.all(np.isnan(conv.mag_b[:2])) and np.all(np.isfinite(conv.mag_b[2:]))
    # 14-bit: 0.6 µT per code; AK8963 → chip axes: x = m_y, y = m_x, z = −m_z
    np.testing.assert_allclose(conv.mag_b[2], [200 * 0.6, 100 * 0.6, 300 * 0.6])
    np.testing.assert_allclose(conv.accel_b[2], [0, 0, 9.80665])
    out = estimate_attitude(raw, fs=100.0, method="biso", registers={"accel_fs_sel": 0}, full_output=True)
    assert out.flags[3] & fl.SATURATED and out.flags[3] & fl.MAG_INVALID
    assert out.flags[0] & fl.MAG_INVALID and not out.flags[2] & fl.MAG_INVALID
    with pytest.raises(ValueError, match="BITM"):
        raw_inputs(raw, {"mag_bit16": True})
    st2[4] = 16
    with pytest.raises(ValueError, match="changes at sample 4"):
        raw_inputs(RawSamples.from_fields(accel, np.zeros(k), np.zeros((k, 3)), mag, st1, st2))


def test_raw_csv_round_trip_and_the_cli(tmp_path, capsys):
    imu, s, regs, mount = _simulate("crooked_16bit", seconds=3.0)
    path = write_raw_csv(tmp_path / "raw.csv", s.raw, t_s=s.t_s, registers=regs, asa=imu.asa, mounting=mount,
                         fs_hz=imu.output_rate_hz)
    log = read_raw_csv(path)
    np.testing.assert_array_equal(log.raw.words, s.raw.words)
    np.testing.assert_array_equal(log.raw.status, s.raw.status)
    np.testing.assert_allclose(log.t_s, s.t_s, atol=1e-9)
    assert log.registers == {"gyro_fs_sel": 1, "accel_fs_sel": 1, "mag_bit16": True}
    assert log.asa == tuple(int(x) for x in imu.asa) and log.fs_hz == imu.output_rate_hz
    np.testing.assert_array_equal(log.mounting, mount)  # repr of floats round-trips

    want = estimate_attitude(s.raw, fs=imu.output_rate_hz, method="biso_plus", registers=regs, asa=imu.asa,
                             mounting=mount, full_output=True, declination_rad=EARTH.declination_rad)
    out = tmp_path / "est.csv"
    assert cli_main(["estimate", str(path), "--out", str(out), "--method", "biso_plus",
                     "--declination-deg", repr(math.degrees(EARTH.declination_rad))]) == 0
    assert "raw log at 200 Hz" in capsys.readouterr().out
    got = np.genfromtxt(out, delimiter=",", names=True)
    np.testing.assert_allclose(np.stack([got[f"biso_plus_q{c}"] for c in "wxyz"], axis=1), want.q_wb, atol=1e-9)
    np.testing.assert_array_equal(got["biso_plus_flags"], want.flags)
    # a command-line option overrides the header: another full scale, another attitude
    assert cli_main(["estimate", str(path), "--out", str(out), "--gyro-fs-sel", "0", "--param",
                     "reference=euler"]) == 0
    slow = np.genfromtxt(out, delimiter=",", names=True)
    assert np.max(np.abs(slow["biso_qw"] - got["biso_plus_qw"])) > 0.01


def test_raw_log_errors_name_the_problem(tmp_path, capsys):
    imu, s, regs, mount = _simulate("crooked_16bit", seconds=0.2)
    path = write_raw_csv(tmp_path / "raw.csv", s.raw, t_s=s.t_s, registers=regs)
    text = path.read_text()
    cases = {
        "header": (text.replace("# gyro_fs_sel = 1", "# gyro_fs_sel = 7"), "gyro_fs_sel must be an integer 0..3"),
        "key": (text.replace("# gyro_fs_sel = 1", "# gyro_range = 1"), "unknown key 'gyro_range'"),
        "column": (text.replace("ak_st2", "st2"), "missing raw column"),
        "word": (text.replace(text.splitlines()[5].split(",")[1], "40000", 1), "is not a word"),
        "bits": (text.replace("# mag_bit16 = 1", "# mag_bit16 = 0"), "ST2.BITM"),
    }
    for name, (content, message) in cases.items():
        bad = tmp_path / f"{name}.csv"
        bad.write_text(content)
        assert cli_main(["estimate", str(bad), "--out", str(tmp_path / "o.csv")]) == 2, name
        assert message in capsys.readouterr().err, name
    assert cli_main(["estimate", str(path), "--out", str(tmp_path / "o.csv"), "--asa", "1,2"]) == 2
    assert "--asa" in capsys.readouterr().err


def test_si_log_with_sensor_flags_and_speed_columns(tmp_path, capsys):
    """An SI log with the imu_flags column (as a run's log.csv has) passes the sensor's flags on;
    --speed-column gives biso_plus its speed input."""
    n = 400
    m = mo.make_motion("circle", n / 200.0, 200.0)
    imu_flags = np.zeros(n, dtype=np.int64)
    imu_flags[100] = fl.IMU_ACCEL_SATURATED
    cols = {"t_s": m.t_s, "imu_flags": imu_flags, "speed_mps": m.info["speed_mps"]}
    for key, name in (("gyro_%s_rad_s", m.omega_b), ("accel_%s_m_s2", m.specific_force_b), ("mag_%s_ut", m.mag_b)):
        for i, c in enumerate("xyz"):
            cols[key % c] = name[:, i]
    path = tmp_path / "si.csv"
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="",
               fmt="%.17g")
    out = tmp_path / "est.csv"
    assert cli_main(["estimate", str(path), "--out", str(out), "--method", "biso_plus",
                     "--speed-column", "speed_mps"]) == 0
    assert "saturated 1" in capsys.readouterr().out
    got = np.genfromtxt(out, delimiter=",", names=True)
    want = estimate_attitude(m.omega_b, m.specific_force_b, m.mag_b, 200.0, "biso_plus", imu_flags=imu_flags,
                             speed_mps=m.info["speed_mps"], full_output=True)
    np.testing.assert_array_equal(got["biso_plus_flags"], want.flags)
    assert np.all(want.flags[1:] & fl.ACCEL_COMPENSATED)
    assert cli_main(["estimate", str(path), "--out", str(out), "--speed-column", "speed_mps"]) == 2
    assert "takes no speed input" in capsys.readouterr().err


def test_estimate_attitude_refuses_misplaced_arguments():
    imu, s, regs, _ = _simulate("crooked_16bit", seconds=0.1)
    with pytest.raises(TypeError, match="leave accel and mag out"):
        estimate_attitude(s.raw, s.accel_b, s.mag_b, 200.0)
    with pytest.raises(TypeError, match="raw logs"):
        estimate_attitude(s.gyro_b, s.accel_b, s.mag_b, 200.0, asa=(128, 128, 128))
    with pytest.raises(TypeError, match="sample rate"):
        estimate_attitude(s.raw, registers=regs)
    with pytest.raises(TypeError, match="RawSamples"):
        raw_inputs(s.raw.words)
    assert regs.gyro_full_scale == pytest.approx(500 * DEG)
