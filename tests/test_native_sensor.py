"""The C virtual MPU-9250 of the native FMUs against the Python model (issue 20): bit for bit,
with the same seeds, on every DLPF row, range, AK8963 mode, input rate and error term; the
random generators against NumPy and the project's xoshiro/ziggurat; the WMM against pygeomag
through EarthField. The C data is generated from the Python data at build time, so these
tests are also the check that the two agree."""

from __future__ import annotations

import datetime

import numpy as np
import pytest

from biso_cosim.fmu.native.compiler import CompilerNotFound, find_compiler
from biso_cosim.frames import quat_from_euler
from biso_cosim.sensors import EarthField, MPU9250, Registers
from biso_cosim.sensors._rng import _normal
from biso_cosim.sensors.magnetic import _decimal_year
from biso_cosim.sensors.samples import mounting_matrix

try:
    find_compiler()
except CompilerNotFound:
    pytest.skip("no C compiler", allow_module_level=True)

from biso_cosim.fmu.native.sensor_library import SensorLibrary  # noqa: E402


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return SensorLibrary.build(tmp_path_factory.mktemp("native_sensor"))


def _motion(n, rate, amp=1.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    omega = amp * np.stack([0.3 * np.sin(3 * t), 0.2 * np.cos(2 * t), 0.5 * np.sin(0.5 * t)], 1)
    force = np.stack([0.5 * np.sin(t), 0.1 * np.cos(3 * t), 9.8 + 0.2 * np.sin(t)], 1) * max(amp, 1.0)
    mag = np.stack([3.0 + np.sin(t), 18.0 + 0.0 * t, -45.0 + 2 * np.cos(t)], 1)
    return omega + rng.normal(0, 1e-3, omega.shape), force, mag


def _assert_same(py, c):
    assert len(py) == len(c)
    for name, a, b in (("t_s", py.t_s, c["t_s"]), ("gyro_b", py.gyro_b, c["gyro_b"]),
                       ("accel_b", py.accel_b, c["accel_b"]), ("temperature_c", py.temperature_c, c["temperature_c"]),
                       ("flags", py.flags, c["flags"]), ("words", py.raw.words, c["words"]),
                       ("st1", py.raw.st1, c["st1"]), ("st2", py.raw.st2, c["st2"]),
                       ("mag_fresh", py.mag_fresh, c["mag_fresh"].astype(bool))):
        assert np.array_equal(a, b), name
    assert np.array_equal(py.mag_b, c["mag_b"], equal_nan=True), "mag_b"


def _run_both(lib, *, profile="mpu9250", seed=0, registers=None, rate=1000.0, n=1200, amp=1.0, temp=None,
              mounting=None, hard=None, soft=None):
    omega, force, mag = _motion(n, rate, amp, seed)
    py = MPU9250(profile, seed=seed, registers=registers, input_rate_hz=rate, mounting=mounting, hard_iron_ut=hard,
                 soft_iron=soft)
    out = py.simulate(omega, force, mag, temp)
    chip = lib.sensor(profile=profile, seed=seed, registers=registers, input_rate_hz=rate, r_bc=py.r_bc,
                      hard_iron_ut=hard, soft_iron=soft)
    c = chip.simulate(omega, force, mag, temperature_c=temp, temp_default=py._kernel_state()[4])
    return out, c


@pytest.mark.parametrize("profile", ["mpu9250", "mpu9250_calibrated", "ideal"])
@pytest.mark.parametrize("seed", [0, 1, 2**31 - 1])
def test_profiles_and_seeds_bit_for_bit(lib, profile, seed):
    py, c = _run_both(lib, profile=profile, seed=seed)
    assert len(py) == 240
    _assert_same(py, c)


@pytest.mark.parametrize("registers, rate", [
    ({"dlpf_cfg": 0, "smplrt_div": 0}, 8000.0),       # 8 kHz internal, SMPLRT_DIV ignored
    ({"dlpf_cfg": 1}, 1000.0), ({"dlpf_cfg": 2}, 500.0), ({"dlpf_cfg": 4}, 2000.0), ({"dlpf_cfg": 5}, 1000.0),
    ({"dlpf_cfg": 6, "a_dlpf_cfg": 6, "smplrt_div": 0}, 200.0),   # input slower than the internal rate
    ({"dlpf_cfg": 7}, 1000.0),
    ({"gyro_fchoice_b": 1}, 1000.0), ({"gyro_fchoice_b": 2, "accel_fchoice_b": 1}, 8000.0),  # 32 kHz bypass
    ({"a_dlpf_cfg": 0}, 1000.0), ({"a_dlpf_cfg": 1}, 1000.0), ({"a_dlpf_cfg": 2}, 1000.0), ({"a_dlpf_cfg": 7}, 1000.0),
    ({"mag_mode": 1, "i2c_mst_dly": 3}, 1000.0),       # AK8963 single mode, triggered by the driver
    ({"mag_mode": 2, "mag_bit16": False}, 500.0),      # 8 Hz, 14 bit
    ({"mag_mode": 0}, 1000.0),                          # powered down: NaN, MAG_INVALID
    ({"smplrt_div": 9}, 1000.0 + 1e-13),                # a rate that is not exactly 1000 Hz
])
def test_register_setups_and_rates_bit_for_bit(lib, registers, rate):
    py, c = _run_both(lib, registers=registers, rate=rate, n=int(0.6 * rate) + 1)
    assert len(py) > 0
    _assert_same(py, c)


@pytest.mark.parametrize("fs_sel", [0, 1, 2, 3])
def test_full_scales_saturation_and_flags_bit_for_bit(lib, fs_sel):
    py, c = _run_both(lib, registers={"gyro_fs_sel": fs_sel, "accel_fs_sel": fs_sel}, amp=20.0 * 2**fs_sel)
    assert np.any(py.flags & 1) and np.any(py.flags & 2)  # both channels clipped somewhere
    _assert_same(py, c)


def test_temperature_mounting_and_iron_bit_for_bit(lib):
    py, c = _run_both(lib, temp=np.linspace(-20.0, 70.0, 1200), mounting=quat_from_euler(0.3, -0.2, 1.1),
                      hard=[10.0, -5.0, 3.0], soft=[[1.1, 0.05, 0.0], [0.05, 0.95, 0.01], [0.0, 0.01, 1.02]])
    _assert_same(py, c)
    # a field beyond the AK8963's range: HOFL in ST2 and the MAG_OVERFLOW flag
    py, c = _run_both(lib, hard=[3000.0, 2000.0, 1000.0])
    assert np.all(py.flags & 4) and np.all(py.raw.st2 & 8)
    _assert_same(py, c)


def test_streaming_and_state_restore(lib):
    omega, force, mag = _motion(900, 1000.0)
    py = MPU9250(seed=4)
    whole = py.simulate(omega, force, mag)
    chip = lib.sensor(seed=4)
    first = chip.simulate(omega[:400], force[:400], mag[:400])
    saved = chip.get_state()
    rest = chip.simulate(omega[400:], force[400:], mag[400:])
    chip.set_state(saved)
    again = chip.simulate(omega[400:], force[400:], mag[400:])
    assert np.array_equal(rest, again)
    joined = np.concatenate([first, rest])
    _assert_same(whole, joined)
    chip.reset()
    assert np.array_equal(chip.simulate(omega, force, mag), joined)


def test_mounting_matrix_equals_python(lib):
    q = np.random.default_rng(1).normal(size=(500, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    for x in q:
        assert np.array_equal(lib.mounting_matrix(x), mounting_matrix(x))


# ------------------------------------------------------------------------- generators


def test_seed_sequence_and_pcg64_equal_numpy(lib):
    for entropy in (0, 5, 2**31 - 1, 2**40 + 7):
        for child in (0, 1, 3):
            assert np.array_equal(lib.seed_pool(entropy, child), np.random.SeedSequence(entropy).spawn(4)[child].pool)
    child = np.random.SeedSequence(7).spawn(1)[0]
    pool = lib.seed_pool(7, 0)
    assert np.array_equal(lib.generate_state64(pool, 4), child.generate_state(4, np.uint64))
    assert np.array_equal(lib.numpy_draws(pool, 2000, "raw"), np.random.PCG64(child).random_raw(2000))
    assert np.array_equal(lib.numpy_draws(pool, 500, "uniform", 0.9, 1.1),
                          np.random.default_rng(child).uniform(0.9, 1.1, 500))


def test_numpy_standard_normal_in_every_block(lib):
    """NumPy's ziggurat: 2·10⁵ draws reach every block many times, the wedges and the tail."""
    child = np.random.SeedSequence(11).spawn(1)[0]
    c = lib.numpy_draws(lib.seed_pool(11, 0), 200_000, "normal")
    py = np.random.default_rng(child).standard_normal(200_000)
    assert np.array_equal(c, py)
    assert np.max(np.abs(py)) > 3.66  # beyond R: the tail branch was taken


def test_xoshiro_ziggurat_equals_the_kernel(lib):
    words = np.array([1, 2, 3, 0xFFFFFFFFFFFFFFFF], dtype=np.uint64)
    c = lib.xoshiro_normals(words, 100_000)
    state = words.copy()
    py = np.array([_normal(state) for _ in range(100_000)])
    assert np.array_equal(c, py) and np.max(np.abs(py)) > 3.45  # the tail beyond R = 3.44


# --------------------------------------------------------------------------- the field


def test_earth_field_equals_pygeomag_through_earthfield(lib):
    rng = np.random.default_rng(0)
    sites = [(51.53, 46.03, 50.0), (90.0, 10.0, 0.0), (-90.0, -10.0, 0.0), (0.0, 0.0, -1000.0), (-33.9, 151.2, 850000.0)]
    sites += [(float(rng.uniform(-90, 90)), float(rng.uniform(-180, 180)), float(rng.uniform(-1000, 9000)))
              for _ in range(60)]
    for k, (lat, lon, alt) in enumerate(sites):
        date = datetime.date(2010, 1, 1) + datetime.timedelta(days=int(rng.integers(0, 7304)))
        year = lib.decimal_year(date.isoformat())
        assert year == _decimal_year(date)
        ref = EarthField(lat, lon, alt, date)
        c = lib.earth_field(lat, lon, alt, year)
        assert np.array_equal(c["field_enu_ut"], ref.field_enu_ut), (lat, lon, alt, date)
        assert (c["declination_rad"], c["inclination_rad"], c["total_ut"], c["horizontal_ut"], c["model"]) == \
            (ref.declination_rad, ref.inclination_rad, ref.total_ut, ref.horizontal_ut, ref.model)


def test_earth_field_refusals_name_the_variable(lib):
    for text in ("2024-02-30", "2024-13-01", "24-05-01", ""):
        with pytest.raises(ValueError, match="site.date must be an ISO date"):
            lib.decimal_year(text)
    with pytest.raises(ValueError, match=r"site.date must lie within .*2010-2030"):
        lib.earth_field(0.0, 0.0, 0.0, lib.decimal_year("2030-01-01"))
    for args, name in (((91.0, 0.0, 0.0), "site.lat_deg"), ((0.0, -181.0, 0.0), "site.lon_deg"),
                       ((0.0, 0.0, 9e5), "site.alt_m")):
        with pytest.raises(ValueError, match=rf"{name} must be in"):
            lib.earth_field(*args, 2024.3)


def test_register_checks_follow_registers(lib):
    """The C checks accept exactly what sensors.Registers accepts (their allowed values are
    generated from it) and name the field and the allowed values."""
    from biso_cosim.fmu.native.constants import REGISTER_FIELDS

    for field, name in enumerate(REGISTER_FIELDS):
        for value in range(-2, 258):
            try:
                Registers(**{name: bool(value) if name == "mag_bit16" and value in (0, 1) else value})
                python_ok = True
            except (ValueError, TypeError):
                python_ok = False
            assert (lib.register_check(field, value) is None) == python_ok, (name, value)
    assert lib.register_check(REGISTER_FIELDS.index("mag_mode"), 3) == "registers.mag_mode must be one of 0..2, 6, got 3"
    assert lib.register_check(0, 256) == "registers.smplrt_div must be one of 0..255, got 256"
    with pytest.raises(ValueError, match=r"input_rate_hz=300 must be an integer multiple or fraction of the gyro"):
        lib.sensor(input_rate_hz=300.0)


def test_a_profile_file_built_in_gives_the_python_numbers(tmp_path):
    """biso-cosim fmu build --profile FILE: the file's values become C data beside the
    built-in profiles, and the C chip with it equals MPU9250 with that file."""
    path = tmp_path / "my_part.toml"
    path.write_text('name = "my_part"\nbase = "mpu9250"\n[gyro]\nnoise_density = 0.02\n'
                    'bias_corner_times = [0.5, 5000.0]\n[accel]\nbias_corner_times = [1.0, 10.0]\n'
                    '[mag]\noffset = 3.0\n', "utf-8")  # the gyro has more flicker terms
    lib = SensorLibrary.build(tmp_path / "lib", extra_profiles=[path])
    omega, force, mag = _motion(800, 1000.0)
    model = MPU9250(path, seed=9)
    py = model.simulate(omega, force, mag)
    chip = lib.sensor(profile="my_part", seed=9)
    _assert_same(py, chip.simulate(omega, force, mag, temp_default=model._kernel_state()[4]))
    with pytest.raises(ValueError, match="is taken"):
        SensorLibrary.build(tmp_path / "again", extra_profiles=[path, path])
