"""The native FMUs (issue 20) in FMPy, FMI 2.0 and FMI 3.0: built and validated, no
dependency, C sources a host can compile, and the same numbers as the Python path on the
same inputs, parameters and seed: BisoEstimator against ``estimate_attitude`` and the
estimators' streaming API, BisoImuPlugin against the plug-in model in Python
(tests/_plugin_reference.py); tunable changes, reset, FMU state; every refusal an error
status with a logged reason."""

from __future__ import annotations

import math
import shutil
import subprocess
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")

from _plugin_reference import OUTPUTS, assert_plugin_equal, plugin_reference  # noqa: E402

from biso_cosim.estimators import estimate_attitude, flags, make_estimator  # noqa: E402
from biso_cosim.fmu.host import FmuCallError, FmuInstance  # noqa: E402
from biso_cosim.fmu.native.compiler import CompilerNotFound, find_compiler  # noqa: E402
from biso_cosim.fmu.variables import AXES, QUAT  # noqa: E402
from biso_cosim.frames import quat_from_euler, quat_rotate  # noqa: E402
from biso_cosim.motions import make_motion  # noqa: E402

try:
    find_compiler()
except CompilerNotFound:
    pytest.skip("no C compiler", allow_module_level=True)

FS = 200.0
H = 1.0 / FS
EST_OUT = [f"estimate.q_wb.{c}" for c in QUAT]
VERSIONS = ["fmi2", "fmi3"]


@pytest.fixture(scope="module")
def fmus():
    from biso_cosim.fmu.build import built_fmus

    return built_fmus(("BisoEstimator", "BisoImuPlugin"))


def _noisy(motion, seed=1):
    rng = np.random.default_rng(seed)
    return (motion.omega_b + rng.normal(0, 0.01, motion.omega_b.shape),
            motion.specific_force_b + rng.normal(0, 0.05, motion.omega_b.shape),
            motion.mag_b + rng.normal(0, 0.3, motion.omega_b.shape))


def _sample(gyro, accel, mag, i):
    out = {}
    for head, rows in (("gyro_s", gyro), ("accel_s", accel), ("mag_s", mag)):
        out.update({f"{head}.{c}": rows[i, k] for k, c in enumerate(AXES)})
    return out


def _run_estimator(fmu, gyro, accel, mag, extra=None, step=H, names=EST_OUT):
    out = []
    for i in range(gyro.shape[0]):
        fmu.set({**_sample(gyro, accel, mag, i), **(extra(i) if extra else {})})
        assert fmu.step(step), fmu.log
        out.append(fmu.get(names))
    return np.array(out)


# ------------------------------------------------------------------------------- build


@pytest.mark.parametrize("name", ["BisoEstimator", "BisoImuPlugin"])
@pytest.mark.parametrize("version", VERSIONS)
def test_built_valid_self_contained_with_sources(fmus, name, version):
    from biso_cosim.fmu.build import validate_fmu

    path = fmus[f"{name}-{version}"]
    assert path.name == f"{name}-{version}.fmu"
    assert validate_fmu(path) == []
    with zipfile.ZipFile(path) as z:
        files = z.namelist()
        md = z.read("modelDescription.xml").decode()
        root = ET.fromstring(md)
    assert "NaN" not in md  # Modelica has no NaN literal: no start value is NaN
    cs = root.find("CoSimulation").attrib
    state = "canGetAndSetFMUstate" if version == "fmi2" else "canGetAndSetFMUState"
    assert cs[state] == "true" and cs[state.replace("GetAndSet", "Serialize")] == "true"
    assert cs["canHandleVariableCommunicationStepSize"] == ("true" if name == "BisoEstimator" else "false")
    assert "Native: needs no Python" in root.get("description")
    sources = [f for f in files if f.startswith("sources/")]
    assert "sources/fmu_core.c" in sources and "sources/biso_sensor_data.c" in sources
    assert "sources/LICENSE-FMI.txt" in sources
    if version == "fmi3":
        build = ET.fromstring(zipfile.ZipFile(path).read("sources/buildDescription.xml"))
        listed = {f.get("name") for f in build.iter("SourceFile")}
        assert root.get("fmiVersion") == "3.0" and root.find("ModelVariables")[0].get("causality") == "independent"
    else:
        listed = {f.get("name") for f in root.iter("File")}
        assert root.get("fmiVersion") == "2.0"
    assert listed == {f[len("sources/"):] for f in sources if f.endswith(".c")}
    # outputs valid after initialization: a quaternion starts at the identity
    start = {sv.get("name"): (sv[0] if version == "fmi2" else sv).get("start") for sv in root.iter()
             if sv.get("name", "").startswith("estimate.q_wb")}
    assert start == {"estimate.q_wb.w": "1.0", "estimate.q_wb.x": "0.0", "estimate.q_wb.y": "0.0",
                     "estimate.q_wb.z": "0.0"}


@pytest.mark.skipif(shutil.which("ldd") is None or shutil.which("nm") is None, reason="needs ldd and nm")
@pytest.mark.parametrize("version", VERSIONS)
def test_binary_needs_only_libc_and_libm_and_exports_only_fmi(fmus, tmp_path, version):
    for name in ("BisoEstimator", "BisoImuPlugin"):
        with zipfile.ZipFile(fmus[f"{name}-{version}"]) as z:
            binary = next(f for f in z.namelist() if f.startswith("binaries/"))
            z.extract(binary, tmp_path)
        path = tmp_path / binary
        libs = [line.split()[0] for line in subprocess.run(["ldd", str(path)], capture_output=True, text=True,
                                                             check=True).stdout.splitlines() if line.strip()]
        assert all(lib.startswith(("linux-vdso", "libc.so", "libm.so", "/lib64/ld-linux", "/lib/ld-linux"))
                   for lib in libs), libs
        symbols = subprocess.run(["nm", "-D", "--defined-only", str(path)], capture_output=True, text=True,
                                 check=True).stdout.split()
        exported = [s for s in symbols[2::3]]
        assert exported and all(s.startswith(f"fmi{version[-1]}") for s in exported), exported[:5]


def test_fmi3_interface_types_other_than_co_simulation_are_refused_with_a_reason(fmus, tmp_path):
    """fmi3InstantiateModelExchange / ScheduledExecution: NULL and a logged reason (FMI 3.0
    §2.3.1: an FMU that does not provide an interface type returns NULL)."""
    import ctypes

    with zipfile.ZipFile(fmus["BisoEstimator-fmi3"]) as z:
        binary = next(f for f in z.namelist() if f.startswith("binaries/"))
        z.extract(binary, tmp_path)
    lib = ctypes.CDLL(str(tmp_path / binary))
    logged = []
    log_type = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)
    log = log_type(lambda env, status, category, message: logged.append((status, message.decode())))
    common = [b"est", b"token", b"", ctypes.c_bool(False), ctypes.c_bool(False), None, log]
    lib.fmi3InstantiateModelExchange.restype = ctypes.c_void_p
    lib.fmi3InstantiateScheduledExecution.restype = ctypes.c_void_p
    assert lib.fmi3InstantiateModelExchange(*common) is None
    assert lib.fmi3InstantiateScheduledExecution(*common, None, None, None) is None
    fmi3_error = 3
    assert logged == [(fmi3_error, "fmi3InstantiateModelExchange: BisoEstimator is a co-simulation FMU only"),
                      (fmi3_error, "fmi3InstantiateScheduledExecution: BisoEstimator is a co-simulation FMU only")]


@pytest.mark.parametrize("version", ["fmi3"])  # FMI 2.0's SourceFiles: the same list (test above)
def test_a_host_compiles_the_sources_into_a_working_binary(fmus, tmp_path, version):
    """What a host on another platform does: compile sources/ as the FMU describes them
    (FMPy's build_platform_binary reads SourceFiles / buildDescription.xml and runs CMake)
    and run the FMU on that binary."""
    from fmpy import extract
    from fmpy.build import build_platform_binary

    unzipped = Path(extract(str(fmus[f"BisoEstimator-{version}"]), unzipdir=str(tmp_path / "fmu")))
    shutil.rmtree(unzipped / "binaries")
    (tmp_path / "build").mkdir()
    build_platform_binary(unzipped, build_dir=tmp_path / "build")
    assert any((unzipped / "binaries").rglob("BisoEstimator.*"))
    motion = make_motion("tumble", duration_s=0.25, fs_hz=FS)
    gyro, accel, mag = _noisy(motion)
    with FmuInstance(unzipped, "compiled", start_values={"estimator": "biso_plus"}) as fmu:
        q = _run_estimator(fmu, gyro, accel, mag)
    assert np.array_equal(q, estimate_attitude(gyro, accel, mag, FS, method="biso_plus"))


# --------------------------------------------------------------------------- estimator


@pytest.mark.parametrize("method", ["biso", "positional", "poisson", "dcm_pi", "biso_plus"])
@pytest.mark.parametrize("version", VERSIONS)
def test_estimator_fmu_equals_estimate_attitude(fmus, method, version):
    motion = make_motion("tumble", duration_s=1.0, fs_hz=FS)
    gyro, accel, mag = _noisy(motion)
    with FmuInstance(fmus[f"BisoEstimator-{version}"], method, start_values={"estimator": method}) as fmu:
        assert fmu.get(EST_OUT + ["estimate.flags"]) == [1.0, 0.0, 0.0, 0.0, flags.UNINITIALIZED]
        q = _run_estimator(fmu, gyro, accel, mag)
        assert fmu.errors() == []
    ref = estimate_attitude(gyro, accel, mag, FS, method=method)
    assert np.array_equal(q, ref)


@pytest.mark.parametrize("version", VERSIONS)
def test_estimator_parameters_speed_flags_and_euler_outputs(fmus, version):
    from biso_cosim.frames import _euler_from_q, euler_from_quat, heading_from_yaw

    motion = make_motion("circle", duration_s=1.0, fs_hz=FS)
    gyro, accel, mag = _noisy(motion, seed=2)
    speed = np.full(len(motion), 10.0)
    start = {"estimator": "biso_plus", "use_speed": True, "biso_plus.k_tilt": 5.0,
             "biso_plus.speed_point_b_m[1]": -1.2, "biso_plus.has_field_norm_ut": True,
             "biso_plus.field_norm_ut": 50.0}
    names = EST_OUT + ["estimate.roll", "estimate.pitch", "estimate.yaw", "estimate.heading", "estimate.flags",
                       *(f"estimate.gyro_bias_b.{c}" for c in AXES)]
    with FmuInstance(fmus[f"BisoEstimator-{version}"], "plus", start_values=start) as fmu:
        out = _run_estimator(fmu, gyro, accel, mag, extra=lambda i: {"speed": speed[i]}, names=names)
    est = make_estimator("biso_plus", FS, k_tilt=5.0, speed_point_b_m=(-1.2, 0.0, 0.0), field_norm_ut=50.0)
    ref = est.update(gyro, accel, mag, speed_mps=speed)
    assert np.array_equal(out[:, :4], ref.q_wb)
    assert np.array_equal(out[:, 8], ref.flags) and np.any(ref.flags & flags.ACCEL_COMPENSATED)
    assert np.array_equal(out[:, 9:], ref.gyro_bias_b)
    e = np.array([_euler_from_q(*q) for q in ref.q_wb])  # the Python FMU's put_estimate
    assert np.array_equal(out[:, 4:7], e) and np.array_equal(out[:, 7], heading_from_yaw(e[:, 2]))
    assert np.max(np.abs(out[:, 4:7] - euler_from_quat(ref.q_wb))) < 1e-12


@pytest.mark.parametrize("version", VERSIONS)
def test_euler_outputs_are_the_same_however_seldom_they_are_read(fmus, version):
    """estimate.roll/pitch/yaw/heading are derived outputs, computed from estimate.q_wb.*
    when first read after a step: read every step, only at the end, after a state restore or
    a serialized state, they are the same numbers."""
    motion = make_motion("tumble", duration_s=0.3, fs_hz=FS)
    gyro, accel, mag = _noisy(motion, seed=3)
    euler = ["estimate.roll", "estimate.pitch", "estimate.yaw", "estimate.heading"]
    path = fmus[f"BisoEstimator-{version}"]
    with FmuInstance(path, "every", start_values={"estimator": "biso_plus"}) as every, \
            FmuInstance(path, "seldom", start_values={"estimator": "biso_plus"}) as seldom:
        assert every.get(euler) == [0.0, 0.0, 0.0, math.pi / 2]  # the identity's, before any step
        ref = _run_estimator(every, gyro, accel, mag, names=EST_OUT + euler)
        _run_estimator(seldom, gyro[:30], accel[:30], mag[:30])
        state = seldom.get_state()  # taken while the angles were not yet computed
        blob = seldom.serialize(state)
        _run_estimator(seldom, gyro[30:], accel[30:], mag[30:])
        assert seldom.get(euler) == ref[-1, 4:].tolist()
        for restored in (state, seldom.deserialize(blob)):
            seldom.set_state(restored)
            assert seldom.get(euler) == ref[29, 4:].tolist()


@pytest.mark.parametrize("version", VERSIONS)
def test_bad_samples_are_flagged_never_nan_out(fmus, version):
    """NaN, zero and saturated samples, and the sensor's flags: the estimator's own handling
    (flags, no correction from that sample), exactly as in Python; never NaN out."""
    motion = make_motion("rotation", duration_s=0.5, fs_hz=FS)
    gyro, accel, mag = (np.array(a) for a in _noisy(motion, seed=4))
    imu_flags = np.zeros(len(motion), dtype=np.int64)
    gyro[10] = np.nan
    accel[20] = 0.0
    mag[30] = np.inf
    accel[40, 2] = 200.0          # beyond the declared ±16 g: saturated
    imu_flags[50] = 2             # the sensor says: accelerometer saturated
    imu_flags[60] = 16            # the sensor says: no magnetometer sample
    start = {"estimator": "biso_plus", "biso_plus.has_accel_range_mps2": True, "biso_plus.accel_range_mps2": 156.9}
    names = EST_OUT + ["estimate.flags"]
    with FmuInstance(fmus[f"BisoEstimator-{version}"], "bad", start_values=start) as fmu:
        out = _run_estimator(fmu, gyro, accel, mag, extra=lambda i: {"imu_flags": int(imu_flags[i])}, names=names)
        assert fmu.errors() == []
    ref = make_estimator("biso_plus", FS, accel_range_mps2=156.9).update(gyro, accel, mag, imu_flags=imu_flags)
    assert np.all(np.isfinite(out))
    assert np.array_equal(out[:, :4], ref.q_wb) and np.array_equal(out[:, 4], ref.flags)
    f = out[:, 4].astype(int)
    assert f[10] & flags.GYRO_INVALID and f[20] & flags.ACCEL_INVALID and f[30] & flags.MAG_INVALID
    assert f[40] & flags.SATURATED and f[50] & flags.ACCEL_INVALID and f[60] & flags.MAG_INVALID


@pytest.mark.parametrize("version", VERSIONS)
def test_estimator_mounting_and_held_samples(fmus, version):
    motion = make_motion("rotation", duration_s=1.0, fs_hz=FS)
    gyro, accel, mag = _noisy(motion, seed=3)
    rpy = (0.3, -0.2, 1.0)
    q_bs = quat_from_euler(*rpy)
    chip = [quat_rotate(np.array([q_bs[0], *-q_bs[1:]]), x) for x in (gyro, accel, mag)]  # body -> sensor axes
    start = {f"mounting.{a}": v for a, v in zip(("roll", "pitch", "yaw"), rpy)}
    with FmuInstance(fmus[f"BisoEstimator-{version}"], "mounted", start_values=start) as fmu:
        q = _run_estimator(fmu, *chip)
    assert np.max(np.abs(q - estimate_attitude(gyro, accel, mag, FS))) < 1e-12
    # a step of three sample periods holds the inputs for three samples
    with FmuInstance(fmus[f"BisoEstimator-{version}"], "held") as fmu:
        q3 = _run_estimator(fmu, gyro[:20], accel[:20], mag[:20], step=3 * H)
    held = [np.repeat(x[:20], 3, axis=0) for x in (gyro, accel, mag)]
    assert np.array_equal(q3, estimate_attitude(*held, FS)[2::3])


@pytest.mark.parametrize("version", VERSIONS)
def test_tunable_change_acts_like_set_params_and_a_bad_one_is_refused(fmus, version):
    motion = make_motion("tumble", duration_s=0.6, fs_hz=FS)
    gyro, accel, mag = _noisy(motion, seed=5)
    est = make_estimator("dcm_pi", FS)
    ref = [est.update(gyro[:60], accel[:60], mag[:60]).q_wb]
    est.set_params(kp_rp=3.0, ki_rp=0.1)
    ref.append(est.update(gyro[60:], accel[60:], mag[60:]).q_wb)
    with FmuInstance(fmus[f"BisoEstimator-{version}"], "tuned", start_values={"estimator": "dcm_pi"}) as fmu:
        first = _run_estimator(fmu, gyro[:60], accel[:60], mag[:60])
        fmu.set({"dcm_pi.kp_rp": 3.0, "dcm_pi.ki_rp": 0.1})
        with pytest.raises(FmuCallError, match=r"dcm_pi.kp_yaw.*(>= 0|allowed)"):
            fmu.set({"dcm_pi.kp_yaw": -1.0})     # refused at the setter, value kept
        assert fmu.get(["dcm_pi.kp_yaw"]) == [1.0]
        with pytest.raises(FmuCallError, match="fs_hz is a fixed parameter"):
            fmu.set({"fs_hz": 100.0})
        second = _run_estimator(fmu, gyro[60:], accel[60:], mag[60:])
    assert np.array_equal(np.vstack([first, second]), np.vstack(ref))


@pytest.mark.parametrize("version", VERSIONS)
def test_estimator_reset_state_and_serialization(fmus, version):
    motion = make_motion("tumble", duration_s=0.5, fs_hz=FS)
    gyro, accel, mag = _noisy(motion, seed=6)
    with FmuInstance(fmus[f"BisoEstimator-{version}"], "a", start_values={"estimator": "biso_plus"}) as a, \
            FmuInstance(fmus[f"BisoEstimator-{version}"], "b", start_values={"estimator": "biso"}) as b:
        qa = _run_estimator(a, gyro[:40], accel[:40], mag[:40])
        qb = _run_estimator(b, gyro[:40], accel[:40], mag[:40])  # instances do not share anything
        assert np.array_equal(qb, estimate_attitude(gyro[:40], accel[:40], mag[:40], FS))
        state = a.get_state()
        blob = a.serialize(state)
        later = _run_estimator(a, gyro[40:], accel[40:], mag[40:])
        a.set_state(state)
        assert np.array_equal(_run_estimator(a, gyro[40:], accel[40:], mag[40:]), later)
        restored = a.deserialize(blob)
        a.set_state(restored)
        assert np.array_equal(_run_estimator(a, gyro[40:], accel[40:], mag[40:]), later)
        a.free_state(state)
        a.free_state(restored)
        with pytest.raises(FmuCallError, match="not a serialized state"):
            a.deserialize((blob[0][:-1] + b"x", 0.0) if False else (b"garbage" * 10, 0.0))
        a.reset(start_values={"estimator": "biso_plus"})
        assert a.get(EST_OUT) == [1.0, 0.0, 0.0, 0.0]
        assert np.array_equal(_run_estimator(a, gyro[:40], accel[:40], mag[:40]), qa)


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("start, words", [
    ({"estimator": "kalman9000"}, ["estimator", "must be one of", "biso_plus"]),
    ({"fs_hz": 0.0}, ["fs_hz", "> 0"]),
    ({"fs_hz": float("nan")}, ["fs_hz", "finite"]),
    ({"biso.has_cutoff_hz": True, "biso.cutoff_hz": -5.0}, ["biso.cutoff_hz", "> 0"]),
    ({"biso.pattern": 14}, ["biso.pattern", "13"]),
    ({"biso.reading": "Z"}, ["biso.reading", "one of D, L"]),
    ({"use_speed": True}, ["use_speed", "only biso_plus"]),
])
def test_invalid_parameters_are_errors_naming_the_variable(fmus, version, start, words):
    with pytest.raises(FmuCallError) as info:
        FmuInstance(fmus[f"BisoEstimator-{version}"], "bad", start_values=start)
    text = " ".join(info.value.messages)
    assert all(w in text for w in words), text


@pytest.mark.parametrize("version", VERSIONS)
def test_step_not_a_whole_number_of_periods_is_an_error_giving_the_allowed_steps(fmus, version):
    with FmuInstance(fmus[f"BisoEstimator-{version}"], "steps") as fmu:
        assert not fmu.step(0.003)
        assert "allowed steps: n * 0.005" in fmu.errors()[-1]
        assert fmu.step(0.005) and fmu.step(0.01)  # nothing was computed: the instance goes on
        with pytest.raises(FmuCallError, match="estimate.q_wb.w is an output"):
            fmu.set({"estimate.q_wb.w": 2.0})


# ------------------------------------------------------------------------------ plug-in


def _truth(motion, i, pos=None, vel=None, temperature=None):
    out = {}
    for head, rows in (("omega_b", motion.omega_b), ("specific_force_b", motion.specific_force_b)):
        out.update({f"{head}.{c}": rows[i, k] for k, c in enumerate(AXES)})
    out.update({f"q_wb.{c}": motion.q_wb[i, k] for k, c in enumerate(QUAT)})
    if pos is not None:
        out.update({f"pos_w.{c}": pos[i, k] for k, c in enumerate(AXES)})
    if vel is not None:
        out.update({f"vel_w.{c}": vel[i, k] for k, c in enumerate(AXES)})
    if temperature is not None:
        out["temperature"] = temperature[i]
    return out


def _run_plugin(fmu, motion, h, **extra):
    rows = []
    for i in range(len(motion.t_s)):
        fmu.set(_truth(motion, i, **extra))
        assert fmu.step(h), fmu.errors()
        rows.append(fmu.get(OUTPUTS))
    return np.array(rows, dtype=float)


def _params_start(params):
    return {f"{k}": v for k, v in params.items()}


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("estimator", ["biso", "dcm_pi", "biso_plus"])
def test_plugin_equals_the_python_plugin_bit_for_bit(fmus, version, estimator):
    h = 0.001
    motion = make_motion("tumble", duration_s=0.6, fs_hz=1.0 / h)
    with FmuInstance(fmus[f"BisoImuPlugin-{version}"], "p", start_values={"estimator": estimator}) as fmu:
        out = _run_plugin(fmu, motion, h)
        assert fmu.errors() == []
    ref = plugin_reference(h, motion.omega_b, motion.specific_force_b, motion.q_wb, estimator=estimator)
    assert_plugin_equal(out, ref)
    assert out[:, OUTPUTS.index("new_samples")].sum() == 120


@pytest.mark.parametrize("version", VERSIONS)
def test_plugin_options_bit_for_bit(fmus, version):
    """Steps of several samples, other registers (14-bit 8 Hz AK8963, ±1000 °/s, ±8 g,
    SMPLRT_DIV 9), a mounting, the die temperature, a site and seed, velocity for biso_plus."""
    h = 0.02
    motion = make_motion("circle", duration_s=2.0, fs_hz=1.0 / h, speed_mps=8.0)
    vel = 8.0 * quat_rotate(motion.q_wb, np.array([1.0, 0.0, 0.0]))
    pos = np.cumsum(vel * h, axis=0)
    temperature = np.linspace(15.0, 45.0, len(motion.t_s))
    registers = {"mag_mode": 2, "mag_bit16": False, "gyro_fs_sel": 2, "accel_fs_sel": 2, "smplrt_div": 9}
    mounting = (0.1, -0.05, 0.3)
    position = (0.4, -0.2, 0.1)  # a lever arm
    start = {**{f"sensor.position_b.{c}": x for c, x in zip(AXES, position)},
             **{f"biso_plus.speed_point_b_m[{k + 1}]": -x for k, x in enumerate(position)},"estimator": "biso_plus", "sensor.seed": 7, "sensor.profile": "mpu9250", "use_temperature": True,
             "use_velocity": True, "site.lat_deg": -33.9, "site.lon_deg": 151.2, "site.alt_m": 10.0,
             "site.date": "2021-07-15", "biso_plus.k_tilt": 4.0,
             **{f"sensor.registers.{k}": v for k, v in registers.items()},
             **{f"sensor.mounting.{a}": v for a, v in zip(("roll", "pitch", "yaw"), mounting)}}
    with FmuInstance(fmus[f"BisoImuPlugin-{version}"], "opts", start_values=start) as fmu:
        out = _run_plugin(fmu, motion, h, pos=pos, vel=vel, temperature=temperature)
    ref = plugin_reference(h, motion.omega_b, motion.specific_force_b, motion.q_wb, pos, vel, temperature,
                           profile="mpu9250", seed=7, registers=registers, mounting=mounting,
                           site=(-33.9, 151.2, 10.0, "2021-07-15"), estimator="biso_plus",
                           params={"k_tilt": 4.0, "speed_point_b_m": tuple(-x for x in position)},
                           use_velocity=True, position=position)
    assert_plugin_equal(out, ref)
    assert set(out[1:, OUTPUTS.index("new_samples")]) == {2.0}  # 100 Hz output, 50 Hz truth (tick 0: one)
    assert np.any(out[:, OUTPUTS.index("estimate.flags")].astype(int) & flags.ACCEL_COMPENSATED)


@pytest.mark.parametrize("version", VERSIONS)
def test_plugin_magnetometer_powered_down_reads_the_sentinel(fmus, version):
    h = 0.005
    motion = make_motion("rotation", duration_s=0.5, fs_hz=1.0 / h)
    with FmuInstance(fmus[f"BisoImuPlugin-{version}"], "nomag", start_values={"sensor.registers.mag_mode": 0,
                                                                              "declination_from_site": False}) as fmu:
        out = _run_plugin(fmu, motion, h)
    ref = plugin_reference(h, motion.omega_b, motion.specific_force_b, motion.q_wb, registers={"mag_mode": 0},
                           declination_from_site=False)
    assert_plugin_equal(out, ref)
    assert np.all(np.isfinite(out))
    col = OUTPUTS.index
    assert np.all(out[:, col("imu_flags")].astype(int) & 16) and np.all(out[:, col("mag_b.x"):col("mag_b.z") + 1] == 0)
    assert np.all(out[:, col("estimate.flags")].astype(int)[1:] & flags.MAG_INVALID)


@pytest.mark.parametrize("version", VERSIONS)
def test_plugin_state_reset_and_instances(fmus, version):
    h = 0.001
    motion = make_motion("tumble", duration_s=0.3, fs_hz=1.0 / h)
    path = fmus[f"BisoImuPlugin-{version}"]
    with FmuInstance(path, "a") as a, FmuInstance(path, "b", start_values={"sensor.seed": 3}) as b:
        first = _run_plugin(a, motion, h)
        _run_plugin(b, motion, h)
        a.reset()
        assert a.get(["new_samples", "estimate.q_wb.w"]) == [0, 1.0]
        again = _run_plugin(a, motion, h)
        assert np.array_equal(first, again)  # the same part and noise stream start again
        state = a.get_state()
        blob = a.serialize(state)
        cont = _run_plugin(a, motion, h)
        a.set_state(a.deserialize(blob))
        assert np.array_equal(_run_plugin(a, motion, h), cont)
        a.free_state(state)


@pytest.mark.parametrize("version", VERSIONS)
def test_plugin_refusals(fmus, version):
    path = fmus[f"BisoImuPlugin-{version}"]
    for start, words in (({"sensor.profile": "no_such_part"}, ["sensor.profile", "mpu9250_calibrated", "--profile"]),
                         ({"sensor.seed": -1}, ["sensor.seed", ">= 0"]),
                         ({"sensor.registers.mag_mode": 3}, ["registers.mag_mode must be one of 0..2, 6"]),
                         ({"sensor.registers.dlpf_cfg": 8}, ["registers.dlpf_cfg must be one of 0..7"]),
                         ({"site.lat_deg": 95.0}, ["site.lat_deg", "90"]),
                         ({"site.date": "2024-02-30"}, ["site.date must be an ISO date"]),
                         ({"site.date": "2035-01-01"}, ["site.date must lie within", "2010-2030"]),
                         ({"estimator": "biso", "use_velocity": True}, ["use_velocity", "only biso_plus"])):
        with pytest.raises(FmuCallError) as info:
            FmuInstance(path, "bad", start_values=start)
        text = " ".join(info.value.messages)
        assert all(w in text for w in words), (start, text)
    motion = make_motion("rotation", duration_s=0.1, fs_hz=1000.0)
    with FmuInstance(path, "steps") as fmu:
        fmu.set(_truth(motion, 0))
        assert not fmu.step(0.0003)
        assert "allowed steps" in fmu.errors()[-1] and "0.001" in fmu.errors()[-1]
        assert fmu.step(0.001)
        assert not fmu.step(0.002) and "the step size must stay 0.001" in fmu.errors()[-1]
        fmu.set({"omega_b.y": float("nan")})
        assert not fmu.step(0.001) and "omega_b.y = nan" in fmu.errors()[-1]
        fmu.set({"omega_b.y": 0.0, **{f"q_wb.{c}": 0.0 for c in QUAT}})
        assert not fmu.step(0.001) and "q_wb must be a unit quaternion" in fmu.errors()[-1]
        fmu.set({"q_wb.w": 1.000005})  # within 1e-5 of unit: normalised on use
        assert fmu.step(0.001)
        with pytest.raises(FmuCallError, match="sensor.seed is a fixed parameter"):
            fmu.set({"sensor.seed": 5})
