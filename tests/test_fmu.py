"""The FMUs (issue 8): built with pythonfmu, validated with FMPy, run in FMPy and compared with
the Python paths they wrap; instances, reset, FMU state, step-size rules and refusals."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

from biso_cosim.estimators import describe_estimator, estimate_attitude, estimator_names, make_estimator
from biso_cosim.fmu.build import built_fmus, validate_fmu
from biso_cosim.fmu.host import FmuInstance
from biso_cosim.fmu.variables import AXES, QUAT, fmu_estimator_names, python_only_params, variables_of
from biso_cosim.frames import quat_from_euler, quat_rotate
from biso_cosim.motions import make_motion

FS = 200.0
H = 1.0 / FS
EST_OUT = [f"estimate.q_wb.{c}" for c in QUAT]


@pytest.fixture(scope="module")
def fmus():
    return built_fmus()


def _noisy(motion, seed=1):
    rng = np.random.default_rng(seed)
    return (motion.omega_b + rng.normal(0, 0.01, motion.omega_b.shape),
            motion.specific_force_b + rng.normal(0, 0.05, motion.omega_b.shape),
            motion.mag_b + rng.normal(0, 0.3, motion.omega_b.shape))


def _sample_inputs(gyro, accel, mag, i):
    out = {}
    for head, rows in (("gyro_s", gyro), ("accel_s", accel), ("mag_s", mag)):
        out.update({f"{head}.{c}": rows[i, k] for k, c in enumerate(AXES)})
    return out


def _run_estimator(fmu, gyro, accel, mag, extra=None, step=H):
    q = []
    for i in range(gyro.shape[0]):
        fmu.set({**_sample_inputs(gyro, accel, mag, i), **(extra(i) if extra else {})})
        assert fmu.step(step), fmu.log
        q.append(fmu.get(EST_OUT))
    return np.array(q)


# ------------------------------------------------------------------------------- build


def test_build_validates_with_units_and_declared_capabilities(fmus):
    assert set(fmus) == {"BisoEstimator", "BisoImuPlugin", "BisoVehicle"}
    for name, path in fmus.items():
        assert validate_fmu(path) == [], name
        with zipfile.ZipFile(path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
            names = z.namelist()
        assert "documentation/index.html" in names and "resources/biso_cosim_fmu.json" in names
        units = {u.get("name") for u in root.iter("Unit")}
        used = {t.get("unit") for sv in root.iter("ScalarVariable") for t in sv if t.get("unit")}
        assert used and used <= units
        cs = root.find("CoSimulation").attrib
        assert cs["canBeInstantiatedOnlyOncePerProcess"] == "false"
        assert cs["canGetAndSetFMUstate"] == "true"
        # every output has an exact start value (fmpy validate and hosts need it)
        outputs = [sv for sv in root.iter("ScalarVariable") if sv.get("causality") == "output"]
        assert outputs and all(sv.get("initial") == "exact" and sv[0].get("start") is not None for sv in outputs)


def test_variables_come_from_the_parameter_records(fmus):
    with zipfile.ZipFile(fmus["BisoEstimator"]) as z:
        root = ET.fromstring(z.read("modelDescription.xml"))
    xml = {sv.get("name"): sv for sv in root.iter("ScalarVariable")}
    assert set(estimator_names()) - set(fmu_estimator_names()) == {"gnss_complementary", "gnss_kalman"}
    only_python = python_only_params()
    assert only_python["biso"] == ["gyro_step"]  # it needs the sensor's increments, an input FMUs lack
    for name in fmu_estimator_names():
        for row in describe_estimator(name)["params"]:
            if row["name"] in only_python[name]:
                continue
            candidates = [n for n in xml if n == f"{name}.{row['name']}" or n.startswith(f"{name}.{row['name']}[")]
            assert candidates, (name, row["name"])
            sv = xml[candidates[0]]
            assert row["doc"] in sv.get("description")
            start = sv[0].get("start")
            if row["default"] is None:
                assert start == "NaN"
            elif isinstance(row["default"], float):
                assert float(start) == row["default"]  # all 17 digits survive the XML
    assert xml["biso_plus.speed_point_b_m[2]"].get("causality") == "parameter"
    assert xml["biso.k"][0].get("unit") == "1/s"
    plugin = {v.name for v in variables_of("BisoImuPlugin")}
    assert {"sensor.registers.smplrt_div", "sensor.registers.mag_bit16", "site.date", "raw.gyro.x"} <= plugin


# --------------------------------------------------------------------------- estimator


@pytest.mark.parametrize("method", ["biso", "positional", "dcm_pi", "biso_plus"])
def test_estimator_fmu_equals_estimate_attitude(fmus, method):
    motion = make_motion("tumble", duration_s=1.5, fs_hz=FS)
    gyro, accel, mag = _noisy(motion)
    with FmuInstance(fmus["BisoEstimator"], method, start_values={"estimator": method}) as fmu:
        q = _run_estimator(fmu, gyro, accel, mag)
        assert fmu.errors() == []
    ref = estimate_attitude(gyro, accel, mag, FS, method=method)
    assert np.max(np.abs(q - ref)) <= 1e-12


def test_estimator_fmu_parameters_speed_and_euler_outputs(fmus):
    motion = make_motion("circle", duration_s=1.5, fs_hz=FS)
    gyro, accel, mag = _noisy(motion, seed=2)
    speed = np.full(len(motion), 10.0)
    start = {"estimator": "biso_plus", "use_speed": True, "biso_plus.k_tilt": 5.0,
             "biso_plus.speed_point_b_m[1]": -1.2, "biso_plus.field_norm_ut": float("nan")}
    with FmuInstance(fmus["BisoEstimator"], "plus", start_values=start) as fmu:
        q = _run_estimator(fmu, gyro, accel, mag, extra=lambda i: {"speed": speed[i]})
        roll, pitch, yaw, heading, flags = fmu.get(["estimate.roll", "estimate.pitch", "estimate.yaw",
                                                    "estimate.heading", "estimate.flags"])
        bias = fmu.get([f"estimate.gyro_bias_b.{c}" for c in AXES])
    est = make_estimator("biso_plus", FS, k_tilt=5.0, speed_point_b_m=(-1.2, 0.0, 0.0))
    out = est.update(gyro, accel, mag, speed_mps=speed)
    assert np.max(np.abs(q - out.q_wb)) <= 1e-12
    assert flags == out.flags[-1] and np.allclose(bias, out.gyro_bias_b[-1], atol=1e-15)
    from biso_cosim.frames import euler_from_quat, heading_from_yaw

    e = euler_from_quat(out.q_wb[-1])
    assert np.allclose([roll, pitch, yaw], e, atol=1e-12)
    assert math.isclose(heading, heading_from_yaw(e[2]), abs_tol=1e-12)


def test_estimator_fmu_mounting_and_held_samples(fmus):
    motion = make_motion("rotation", duration_s=1.0, fs_hz=FS)
    gyro, accel, mag = _noisy(motion, seed=3)
    rpy = (0.3, -0.2, 1.0)
    q_bs = quat_from_euler(*rpy)
    chip = [quat_rotate(np.array([q_bs[0], *-q_bs[1:]]), x) for x in (gyro, accel, mag)]  # body → sensor axes
    start = {f"mounting.{a}": v for a, v in zip(("roll", "pitch", "yaw"), rpy)}
    with FmuInstance(fmus["BisoEstimator"], "mounted", start_values=start) as fmu:
        q = _run_estimator(fmu, *chip)
    assert np.max(np.abs(q - estimate_attitude(gyro, accel, mag, FS))) < 1e-9  # one rotation's rounding
    # a step of two sample periods holds the inputs for two samples
    with FmuInstance(fmus["BisoEstimator"], "held") as fmu:
        q2 = _run_estimator(fmu, gyro[::2], accel[::2], mag[::2], step=2 * H)
    ref = estimate_attitude(*(np.repeat(x[::2], 2, axis=0) for x in (gyro, accel, mag)), FS)
    assert np.max(np.abs(q2 - ref[1::2])) <= 1e-12


def test_estimator_instances_are_isolated_and_reset_restarts(fmus):
    motion = make_motion("tumble", duration_s=1.0, fs_hz=FS, seed=4)
    gyro, accel, mag = _noisy(motion, seed=4)
    a = FmuInstance(fmus["BisoEstimator"], "a", start_values={"biso.cutoff_hz": 2.0})
    b = FmuInstance(fmus["BisoEstimator"], "b", start_values={"estimator": "dcm_pi"})
    c = FmuInstance(fmus["BisoImuPlugin"], "c")  # another FMU of the package in the same process
    try:
        qa, qb = [], []
        for i in range(len(motion)):
            for fmu, out in ((a, qa), (b, qb)):
                fmu.set(_sample_inputs(gyro, accel, mag, i))
                assert fmu.step(H)
                out.append(fmu.get(EST_OUT))
            assert c.step(0.001)
        assert np.max(np.abs(np.array(qa) - estimate_attitude(gyro, accel, mag, FS, cutoff_hz=2.0))) <= 1e-12
        assert np.max(np.abs(np.array(qb) - estimate_attitude(gyro, accel, mag, FS, method="dcm_pi"))) <= 1e-12
        b.reset()  # fmi2Reset: back to the start values (estimator biso), time zero
        assert b.get(["estimate.flags", "estimate.q_wb.w"]) == [1, 1.0]
        q = _run_estimator(b, gyro, accel, mag)
        assert np.max(np.abs(q - estimate_attitude(gyro, accel, mag, FS))) <= 1e-12
    finally:
        for fmu in (a, b, c):
            fmu.close()


def test_estimator_fmu_state_and_serialization(fmus):
    motion = make_motion("tumble", duration_s=0.5, fs_hz=FS, seed=5)
    gyro, accel, mag = _noisy(motion, seed=5)
    with FmuInstance(fmus["BisoEstimator"], "s", start_values={"estimator": "biso_plus"}) as fmu:
        _run_estimator(fmu, gyro[:50], accel[:50], mag[:50])
        state = fmu.fmu.getFMUstate()
        blob = fmu.fmu.serializeFMUstate(state)
        first = _run_estimator(fmu, gyro[50:], accel[50:], mag[50:])
        for restored in (state, fmu.fmu.deSerializeFMUstate(blob)):
            fmu.fmu.setFMUstate(restored)
            fmu.time = 50 * H
            again = _run_estimator(fmu, gyro[50:], accel[50:], mag[50:])
            assert np.array_equal(first, again)
        fmu.reset()  # back to the start values (estimator biso); the state brings biso_plus back
        fmu.fmu.setFMUstate(fmu.fmu.deSerializeFMUstate(blob))
        fmu.time = 50 * H
        assert np.array_equal(_run_estimator(fmu, gyro[50:], accel[50:], mag[50:]), first)
        fmu.fmu.freeFMUstate(state)
        assert fmu.errors() == []


def test_estimator_tunable_parameter_acts_like_set_params(fmus):
    motion = make_motion("tumble", duration_s=1.0, fs_hz=FS, seed=6)
    gyro, accel, mag = _noisy(motion, seed=6)
    est = make_estimator("biso", FS)
    ref = np.concatenate([est.update(gyro[:100], accel[:100], mag[:100]).q_wb, np.empty((0, 4))])
    est.set_params(cutoff_hz=3.0)
    ref = np.concatenate([ref, est.update(gyro[100:], accel[100:], mag[100:]).q_wb])
    with FmuInstance(fmus["BisoEstimator"], "tune") as fmu:
        q1 = _run_estimator(fmu, gyro[:100], accel[:100], mag[:100])
        fmu.set({"biso.cutoff_hz": 3.0})
        q2 = _run_estimator(fmu, gyro[100:], accel[100:], mag[100:])
        assert fmu.errors() == []
    assert np.max(np.abs(np.concatenate([q1, q2]) - ref)) <= 1e-12


# ------------------------------------------------------------------------------ refusals


def test_nan_input_and_bad_step_are_discarded_with_a_logged_reason(fmus):
    motion = make_motion("tumble", duration_s=0.5, fs_hz=FS, seed=7)
    gyro, accel, mag = _noisy(motion, seed=7)
    with FmuInstance(fmus["BisoEstimator"], "nan") as fmu:
        q = []
        for i in range(len(motion)):
            fmu.set(_sample_inputs(gyro, accel, mag, i))
            if i == 40:
                fmu.set({"accel_s.y": float("nan")})
                before = fmu.get(EST_OUT)
                assert not fmu.step(H)  # fmi2Discard
                assert "accel_s.y" in fmu.errors()[-1] and fmu.get(EST_OUT) == before
                fmu.set(_sample_inputs(gyro, accel, mag, i))  # the master repeats the step
            if i == 60:
                assert not fmu.step(0.003)
                assert "not a whole number" in fmu.errors()[-1]
            assert fmu.step(H)
            q.append(fmu.get(EST_OUT))
    assert np.max(np.abs(np.array(q) - estimate_attitude(gyro, accel, mag, FS))) <= 1e-12


@pytest.mark.parametrize("start, words", [
    ({"estimator": "kalman"}, ["estimator must be one of", "kalman"]),
    ({"biso.k": -1.0}, ["biso.*", "k must be >= 0"]),
    ({"estimator": "biso_plus", "biso_plus.k_tilt": float("nan")}, ["biso_plus.*", "k_tilt must be finite"]),
    ({"use_speed": True}, ["use_speed", "only biso_plus"]),
    ({"fs_hz": 0.0}, ["fs_hz"]),
])
def test_invalid_parameters_refuse_every_step(fmus, start, words):
    with FmuInstance(fmus["BisoEstimator"], "bad", start_values=start) as fmu:
        assert not fmu.step(H) and not fmu.step(H)
        message = fmu.errors()[-1]
        assert "invalid parameters" in message and all(w in message for w in words), message


def test_parameter_changes_after_initialization(fmus):
    with FmuInstance(fmus["BisoEstimator"], "late") as fmu:
        assert fmu.step(H)
        fmu.set({"fs_hz": 100.0})  # fixed: refused, kept
        assert "fixed parameter" in fmu.errors()[-1] and fmu.get(["fs_hz"]) == [200.0]
        fmu.set({"biso.k_p": -3.0})  # tunable but invalid: the step is refused, the value restored
        assert not fmu.step(H)
        assert "k_p must be >= 0" in fmu.errors()[-1] and math.isnan(fmu.get(["biso.k_p"])[0])
        assert fmu.step(H)
        fmu.set({"estimate.flags": 3})  # an output
        assert "is an output" in fmu.errors()[-1]
        fmu.set({"dcm_pi.kp_rp": 2.0})  # another estimator's parameter: ignored with a warning
        assert fmu.step(H)
        assert any(s == "warning" and "dcm_pi.kp_rp" in m for s, m in fmu.log)


# ---------------------------------------------------------------------------- IMU plug-in


def _truth_inputs(motion, i):
    out = {f"omega_b.{c}": motion.omega_b[i, k] for k, c in enumerate(AXES)}
    out.update({f"specific_force_b.{c}": motion.specific_force_b[i, k] for k, c in enumerate(AXES)})
    out.update({f"q_wb.{c}": motion.q_wb[i, k] for k, c in enumerate(QUAT)})
    return out


PLUGIN_OUT = ["new_samples", "sample_time", *(f"gyro_b.{c}" for c in AXES), *(f"accel_b.{c}" for c in AXES),
              *(f"mag_b.{c}" for c in AXES), "temperature_c", "imu_flags", "raw.gyro.x", "raw.accel.z",
              "raw.mag.y", "raw.temp", "raw.st2", *EST_OUT, "error.roll", "error.total"]


def test_plugin_readings_equal_the_python_sensor(fmus):
    from biso_cosim.metrics import angle_errors_deg
    from biso_cosim.sensors import MPU9250, EarthField, MagneticEnvironment

    h = 0.002  # truth at 500 Hz: the chip interpolates it to its 1 kHz internal rate
    motion = make_motion("circle", duration_s=1.0, fs_hz=1.0 / h)
    start = {"sensor.seed": 11, "sensor.profile": "mpu9250", "sensor.registers.smplrt_div": 9,
             "estimator": "biso_plus", "use_velocity": False}
    rows = []
    with FmuInstance(fmus["BisoImuPlugin"], "imu", start_values=start) as fmu:
        for i in range(len(motion)):
            fmu.set(_truth_inputs(motion, i))
            assert fmu.step(h), fmu.log
            rows.append(fmu.get(PLUGIN_OUT))
        assert fmu.errors() == []
    rows = np.array(rows, dtype=float)
    col = {n: rows[:, k] for k, n in enumerate(PLUGIN_OUT)}
    fresh = col["new_samples"] > 0
    assert set(col["new_samples"]) <= {0.0, 1.0}
    earth = EarthField()
    imu = MPU9250("mpu9250", seed=11, registers={"smplrt_div": 9}, input_rate_hz=1.0 / h)
    s = imu.simulate(motion.omega_b, motion.specific_force_b,
                     MagneticEnvironment(earth).field_b(motion.q_wb, np.zeros((len(motion), 3))))
    assert fresh.sum() == len(s.t_s) == 100  # 100 Hz ODR, samples at 0, 10, ..., 990 ms
    assert np.array_equal(col["sample_time"][fresh], s.t_s)
    for k, c in enumerate(AXES):
        assert np.array_equal(col[f"gyro_b.{c}"][fresh], s.gyro_b[:, k])
        assert np.array_equal(col[f"accel_b.{c}"][fresh], s.accel_b[:, k])
        assert np.array_equal(col[f"mag_b.{c}"][fresh], s.mag_b[:, k])
    assert np.array_equal(col["temperature_c"][fresh], s.temperature_c)
    assert np.array_equal(col["imu_flags"][fresh], s.flags)
    for name, j in (("raw.accel.z", 2), ("raw.temp", 3), ("raw.gyro.x", 4), ("raw.mag.y", 8)):
        assert np.array_equal(col[name][fresh], s.raw.words[:, j])
    assert np.array_equal(col["raw.st2"][fresh], s.raw.status[:, 1])
    est = make_estimator("biso_plus", imu.output_rate_hz, declination_rad=earth.declination_rad)
    q = est.update(s.gyro_b, s.accel_b, s.mag_b).q_wb
    q_fmu = np.stack([col[n][fresh] for n in EST_OUT], axis=1)
    assert np.max(np.abs(q_fmu - q)) <= 1e-12
    # samples fall on truth rows here (10 ms apart), so the error is against those rows
    truth = motion.q_wb[np.round(s.t_s / h).astype(int)]
    err = angle_errors_deg(q, truth)
    assert np.allclose(col["error.total"][fresh], np.radians(err["total"]), atol=1e-9)
    assert np.allclose(col["error.roll"][fresh], np.radians(err["roll"]), atol=1e-9)


def test_plugin_state_temperature_and_step_rules(fmus):
    motion = make_motion("tumble", duration_s=0.2, fs_hz=1000.0, seed=8)
    with FmuInstance(fmus["BisoImuPlugin"], "rate") as fmu:
        assert not fmu.step(0.0003)  # 3333 Hz truth: no common grid with the 1 kHz chip
        assert "truth rate" in fmu.errors()[-1]
        fmu.set(_truth_inputs(motion, 0))
        assert fmu.step(0.001)
        assert not fmu.step(0.002) and "must stay" in fmu.errors()[-1]
        fmu.set({"q_wb.w": 0.0, "q_wb.x": 0.0, "q_wb.y": 0.0, "q_wb.z": 0.0})
        assert not fmu.step(0.001) and "non-zero quaternion" in fmu.errors()[-1]
    start = {"use_temperature": True, "sensor.profile": "mpu9250"}
    with FmuInstance(fmus["BisoImuPlugin"], "state", start_values=start) as fmu:
        for i in range(100):
            fmu.set({**_truth_inputs(motion, i), "temperature": 40.0 + 0.1 * i})
            assert fmu.step(0.001)
        state = fmu.fmu.getFMUstate()
        runs = []
        for _ in range(2):
            fmu.fmu.setFMUstate(state)
            fmu.time = 0.1
            out = []
            for i in range(100, 200):
                fmu.set({**_truth_inputs(motion, i), "temperature": 40.0 + 0.1 * i})
                assert fmu.step(0.001)
                out.append(fmu.get(PLUGIN_OUT))
            runs.append(out)
        assert runs[0] == runs[1]
        assert fmu.get(["temperature_c"])[0] > 50.0  # the die temperature input reaches the sensor


# -------------------------------------------------------------------------------- vehicle


VEHICLE_OUT = ["sample_time", "new_samples", "gyro_b.x", "accel_b.y", "mag_b.z", "raw.gyro.z",
               *(f"truth.q_wb.{c}" for c in QUAT), "truth.pos_w.x", "truth.speed", *EST_OUT, "error.heading"]


def test_vehicle_fmu_equals_the_cosimulation_run(fmus):
    from biso_cosim.cosim import CoSimulation

    duration = 2.0
    with FmuInstance(fmus["BisoVehicle"], "car", start_values={"route": "figure8", "estimator": "biso"},
                     stop_time=duration) as fmu:
        rows = []
        for _ in range(50):
            assert fmu.step(0.02), fmu.log
            rows.append(fmu.get(VEHICLE_OUT))
        assert fmu.step(0.06)  # three control periods at once
        rows.append(fmu.get(VEHICLE_OUT))
        assert not fmu.step(0.03) and "control" in fmu.errors()[-1]
        assert fmu.get(["route_finished"]) == [False]
    rows = np.array(rows)
    col = {n: rows[:, k] for k, n in enumerate(VEHICLE_OUT)}
    result = CoSimulation("figure8", duration_s=duration + 0.06, seed=0, estimators=["biso"]).run()
    last = np.r_[np.arange(3, 200, 4), 211]  # the latest sample of each step (4 per control period)
    assert np.array_equal(col["sample_time"], result.t_s[last])
    assert np.array_equal(col["new_samples"], np.r_[np.full(50, 4), 12])
    assert np.array_equal(col["gyro_b.x"], result.imu.gyro_b[last, 0])
    assert np.array_equal(col["raw.gyro.z"], result.imu.raw.words[last, 6])
    assert np.array_equal(np.stack([col[f"truth.q_wb.{c}"] for c in QUAT], 1), result.truth.q_wb[last])
    assert np.array_equal(col["truth.speed"], result.truth.speed_mps[last])
    q = np.stack([col[n] for n in EST_OUT], axis=1)
    assert np.max(np.abs(q - result.estimates["biso"][0][last])) <= 1e-12
    assert np.allclose(col["error.heading"], np.radians(result.errors("biso")["heading"][last]), atol=1e-9)


def test_vehicle_fmu_external_driver_and_refusals(fmus):
    from biso_cosim.cosim import CoSimulation
    from biso_cosim.vehicle.driver import DriverCommand

    start = {"route": "figure8", "external_driver": True, "estimator": "poisson"}
    with FmuInstance(fmus["BisoVehicle"], "driven", start_values=start) as fmu:
        speeds = []
        for i in range(40):
            fmu.set({"drive": 0.4, "brake": 0.0, "steer": 0.1})
            assert fmu.step(0.02)
            speeds.append(fmu.get(["truth.speed", "estimate.q_wb.z"]))
        fmu.set({"drive": 2.0})
        assert not fmu.step(0.02) and "drive must be in [-1, 1]" in fmu.errors()[-1]
        fmu.set({"drive": 0.4})
        assert fmu.step(0.02)  # still usable
        # go back in time: the same inputs give the same outputs, bit for bit
        state = fmu.fmu.getFMUstate()
        blob = fmu.fmu.serializeFMUstate(state)
        first = [fmu.step(0.02) and fmu.get(["truth.speed", "estimate.q_wb.z"]) for _ in range(10)]
        fmu.fmu.setFMUstate(fmu.fmu.deSerializeFMUstate(blob))
        fmu.time -= 10 * 0.02
        assert [fmu.step(0.02) and fmu.get(["truth.speed", "estimate.q_wb.z"]) for _ in range(10)] == first
        fmu.fmu.freeFMUstate(state)
    sim = CoSimulation("figure8", seed=0, estimators=["poisson"])
    for _ in range(40):
        samples, truth, out = sim.step(DriverCommand(0.1, 0.4, 0.0))
    assert speeds[-1][0] == truth.speed_mps[-1] > 0.2
    assert speeds[-1][1] == out["poisson"].q_wb[-1, 3]


def test_vehicle_invalid_route_is_refused(fmus):
    with FmuInstance(fmus["BisoVehicle"], "nowhere", start_values={"route": "no_such_route"}) as fmu:
        assert not fmu.step(0.02)
        assert "invalid parameters" in fmu.errors()[-1] and "no_such_route" in fmu.errors()[-1]


# ------------------------------------------------------------------------------------ CLI


def test_cli_builds_validates_and_lists(tmp_path, capsys):
    import argparse

    from biso_cosim.cli import fmu as cli_fmu

    parser = argparse.ArgumentParser()
    cli_fmu.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["fmu", "build", "--out", str(tmp_path), "--only", "BisoEstimator"])
    assert args.func(args) == 0
    assert "BisoEstimator.fmu: valid" in capsys.readouterr().out
    bad = tmp_path / "broken.fmu"
    with zipfile.ZipFile(tmp_path / "BisoEstimator.fmu") as src, zipfile.ZipFile(bad, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item == "modelDescription.xml":
                data = data.replace(b'initial="exact"', b"", 1)
            dst.writestr(item, data)
    args = parser.parse_args(["fmu", "validate", str(bad)])
    assert args.func(args) == 1
    assert "problem" in capsys.readouterr().out
    args = parser.parse_args(["fmu", "variables", "BisoVehicle", "--causality", "input"])
    assert args.func(args) == 0
    table = capsys.readouterr().out
    assert "`steer`" in table and "`route`" not in table


def test_plugin_velocity_feeds_biso_plus_speed(fmus):
    from biso_cosim.sensors import MPU9250, EarthField, MagneticEnvironment

    h = 0.001
    motion = make_motion("circle", duration_s=0.6, fs_hz=1.0 / h, speed_mps=8.0)
    v_w = 8.0 * quat_rotate(motion.q_wb, np.array([1.0, 0.0, 0.0]))  # along the body x
    start = {"estimator": "biso_plus", "use_velocity": True}
    q = []
    with FmuInstance(fmus["BisoImuPlugin"], "speed", start_values=start) as fmu:
        for i in range(len(motion)):
            fmu.set({**_truth_inputs(motion, i), **{f"vel_w.{c}": v_w[i, k] for k, c in enumerate(AXES)}})
            assert fmu.step(h)
            if fmu.get(["new_samples"])[0]:
                q.append(fmu.get(EST_OUT + ["estimate.flags"]))
    q = np.array(q)
    earth = EarthField()
    imu = MPU9250("mpu9250_calibrated", seed=0, input_rate_hz=1.0 / h)
    s = imu.simulate(motion.omega_b, motion.specific_force_b,
                     MagneticEnvironment(earth).field_b(motion.q_wb, np.zeros((len(motion), 3))))
    rows = np.round(s.t_s / h).astype(int)  # 200 Hz samples fall on truth rows
    speed = quat_rotate(np.array([1, -1, -1, -1]) * motion.q_wb[rows], v_w[rows])[:, 0]
    est = make_estimator("biso_plus", imu.output_rate_hz, declination_rad=earth.declination_rad)
    out = est.update(s.gyro_b, s.accel_b, s.mag_b, speed_mps=speed)
    assert np.max(np.abs(q[:, :4] - out.q_wb)) <= 1e-9
    from biso_cosim.estimators import flags

    assert np.all(q[2:, 4].astype(int) & flags.ACCEL_COMPENSATED)


def test_fmu_built_for_other_variables_is_refused(fmus, tmp_path):
    import json

    stale = tmp_path / "BisoEstimator.fmu"
    with zipfile.ZipFile(fmus["BisoEstimator"]) as src, zipfile.ZipFile(stale, "w") as dst:
        for item in src.namelist():
            data = src.read(item)
            if item.endswith("biso_cosim_fmu.json"):
                data = json.dumps({**json.loads(data), "version": "0.0.1", "fingerprint": "0" * 16}).encode()
            dst.writestr(item, data)
    with pytest.raises(RuntimeError, match="rebuild it with `biso-cosim fmu build`"):
        FmuInstance(stale, "stale")


def test_docs_tables_are_generated_from_the_variables():
    from pathlib import Path

    from biso_cosim.fmu.variables import fill_docs

    doc = Path(__file__).resolve().parents[1] / "docs" / "fmu.md"
    text = doc.read_text("utf-8")
    assert fill_docs(text) == text, "docs/fmu.md is stale: biso-cosim fmu docs docs/fmu.md"
