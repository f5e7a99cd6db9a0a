"""Profiles: built-ins, custom files, errors for bad keys; the random generator."""

import tomllib

import numpy as np
import pytest
from scipy import stats

from biso_cosim.sensors import MPU9250, Profile, parameter_schema, profile_names
from biso_cosim.sensors import _rng
from biso_cosim._numba import jit


def test_builtin_profiles_cover_the_schema_with_sources():
    assert {"mpu9250", "ideal"} <= set(profile_names())
    schema = parameter_schema()
    p = Profile.load("mpu9250")
    assert set(p.values) == set(schema)
    for key in schema:
        assert p.sources[key].strip(), f"mpu9250: {key} has no source"
    assert Profile.load("ideal").si("gyro.noise_density") == 0.0


def test_custom_profile_file_with_base(tmp_path):
    path = tmp_path / "calibrated.toml"
    path.write_text('base = "mpu9250"\n[gyro]\nbias_initial = { value = 0.05, source = "static calibration" }\nnoise_density = [0.01, 0.01, 0.02]\n')
    p = Profile.load(path)
    assert p.name == "calibrated" and p.sources["gyro.bias_initial"] == "static calibration"
    np.testing.assert_allclose(p.axes("gyro.noise_density"), np.radians([0.01, 0.01, 0.02]))
    imu = MPU9250(str(path), seed=0)
    assert np.all(np.abs(imu.errors.gyro.bias) <= np.radians(0.05))
    # a complete file round-trips through to_toml
    again = Profile.from_dict(tomllib.loads(p.to_toml()))
    for key in parameter_schema():
        assert np.array_equal(np.asarray(again.values[key]), np.asarray(p.values[key]))


@pytest.mark.parametrize(
    "text,message",
    [
        ('base = "mpu9250"\n[gyro]\nnoise = 0.01\n', "unknown key 'gyro.noise'"),
        ('base = "mpu9250"\n[gyro]\nnoise_density = [0.01, 0.02]\n', "list of 3"),
        ('base = "mpu9250"\n[gyro]\nnoise_density = -1.0\n', ">= 0"),
        ('base = "mpu9250"\n[model]\ndlpf = 1\n', "true or false"),
        ('base = "mpu9250"\nfoo = 3\n', "unknown top-level key 'foo'"),
        ('[gyro]\nnoise_density = 0.01\n', "missing key"),
        ('base = "mpu9250"\n[gyro]\nbias_corner_times = [10.0, 1.0]\n', "low <= high"),
        ('base = "mpu9250"\n[gyro]\nnoise_density = {value = 1.0, src = "x"}\n', "value = ..."),
        ('base = "nope"\n', "neither a built-in"),
        ('base = "mpu9250"\n[gyro\n', "calibrated.toml"),
    ],
)
def test_bad_profile_files_are_named(tmp_path, text, message):
    path = tmp_path / "calibrated.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        Profile.load(path)


def test_replace_and_missing_file():
    p = Profile.load("mpu9250").replace(gyro__noise_density=0.02)
    assert p.values["gyro.noise_density"] == 0.02 and p.sources["gyro.noise_density"] == "set in code"
    with pytest.raises(ValueError, match="unknown profile key"):
        Profile.load("mpu9250").replace(gyro__density=0.02)
    with pytest.raises(FileNotFoundError):
        Profile.load("/nonexistent/profile.toml")


@jit
def _draw(state, n, kind):
    out = np.empty(n)
    for i in range(n):
        out[i] = _rng._normal(state) if kind == 1 else float(_rng._next_u64(state) >> np.uint64(11))
    return out


def test_xoshiro_and_ziggurat_match_their_plain_twins():
    words = _rng.seed_state(np.random.SeedSequence(42))
    ref = [int(w) for w in words]
    got = _draw(words.copy(), 1000, 0)
    want = [float(_rng.reference_next_u64(ref) >> 11) for _ in range(1000)]
    assert np.array_equal(got, want)
    ref = [int(w) for w in words]
    got = _draw(words.copy(), 20000, 1)
    want = [_rng.reference_normal(ref) for _ in range(20000)]
    assert np.array_equal(got, want)


def test_normals_are_standard_normal():
    z = _draw(_rng.seed_state(np.random.SeedSequence(7)), 400000, 1)
    assert stats.kstest(z, "norm").pvalue > 1e-3
    assert abs(z.mean()) < 5 / np.sqrt(z.size) and abs(z.std() - 1) < 5 / np.sqrt(2 * z.size)
    # the tails (beyond R = 3.44, drawn by the tail algorithm) have the right mass
    tail = np.mean(np.abs(z) > 3.442619855899)
    assert tail == pytest.approx(2 * stats.norm.sf(3.442619855899), rel=0.15)
