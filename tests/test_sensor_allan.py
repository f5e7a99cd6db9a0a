"""Allan deviation: the estimator, the model's theoretical curves, a short static check."""

import json
import math

import numpy as np
import pytest
from scipy import integrate

from biso_cosim.sensors import MPU9250
from biso_cosim.sensors.allan import (
    _gauss_markov_avar,
    allan_deviation,
    theoretical_adev,
    validate_static,
    white_noise_aliasing,
)
from biso_cosim.units import DEG, G0


def test_white_noise_has_slope_minus_half_and_density_at_one_second():
    fs, density = 200.0, 0.02
    x = np.random.default_rng(0).standard_normal((400_000, 2)) * density * math.sqrt(fs)
    taus, adev = allan_deviation(x, fs, [0.05, 0.1, 0.5, 1.0, 5.0])
    np.testing.assert_allclose(adev, np.broadcast_to(density / np.sqrt(taus)[:, None], adev.shape), rtol=0.05)
    slope = np.polyfit(np.log(taus), np.log(adev[:, 0]), 1)[0]
    assert slope == pytest.approx(-0.5, abs=0.03)


def test_random_walk_has_slope_plus_half():
    fs, k = 100.0, 1e-3
    x = np.cumsum(np.random.default_rng(1).standard_normal(400_000)) * k / math.sqrt(fs)
    taus, adev = allan_deviation(x, fs, [10.0, 30.0, 100.0, 300.0])
    np.testing.assert_allclose(adev, k * np.sqrt(taus / 3.0), rtol=0.25)


def test_matches_allantools_when_installed():
    allantools = pytest.importorskip("allantools")
    x = np.random.default_rng(2).standard_normal(20000)
    taus, ours = allan_deviation(x, 50.0, [0.02, 0.1, 1.0, 10.0])
    t2, theirs, _, _ = allantools.oadev(x, rate=50.0, data_type="freq", taus=taus)
    np.testing.assert_allclose(t2, taus)
    np.testing.assert_allclose(ours, theirs, rtol=1e-9)


def test_gauss_markov_allan_formula_against_the_psd_integral():
    """AVAR(τ) = 2∫ S(f) sin⁴(πfτ)/(πfτ)² df with the one-sided Lorentzian S = 4σ²T/(1+(2πfT)²)."""
    sigma, corr = 0.7, 5.0
    for tau in (0.01, 0.5, 5.0, 50.0, 500.0):
        def integrand(f):
            return 2 * 4 * sigma**2 * corr / (1 + (2 * np.pi * f * corr) ** 2) * np.sin(np.pi * f * tau) ** 4 / (np.pi * f * tau) ** 2
        numeric = sum(integrate.quad(integrand, a, b, limit=400)[0] for a, b in ((0, 1 / tau), (1 / tau, 1000 / tau)))
        assert _gauss_markov_avar(np.array([tau]), sigma, corr)[0] == pytest.approx(numeric, rel=1e-4)


def test_aliasing_factor_of_decimation_behind_the_dlpf():
    imu = MPU9250("mpu9250")  # 41 Hz gyro, 44.8 Hz accel, 1 kHz -> 200 Hz
    assert math.sqrt(white_noise_aliasing(imu, "gyro")) == pytest.approx(1.0616, abs=5e-4)
    assert math.sqrt(white_noise_aliasing(imu, "accel")) == pytest.approx(1.0724, abs=5e-4)
    assert white_noise_aliasing(MPU9250("mpu9250", registers={"smplrt_div": 0}), "gyro") == 1.0
    # the decimation the factor sums over: 1 kHz internal samples, 5 to an output at 200 Hz
    assert imu.internal_samples_per_output("gyro") == imu.internal_samples_per_output("accel") == 5
    with pytest.raises(ValueError, match="sensor must be 'gyro' or 'accel'"):
        imu.internal_samples_per_output("mag")


def test_short_static_run_follows_the_model():
    imu = MPU9250("mpu9250", seed=3, registers={"smplrt_div": 4})
    n = 300_000  # 300 s
    s = imu.simulate(np.zeros((n, 3)), np.tile([0.0, 0.0, G0], (n, 1)), np.tile([3.7, 18.3, -49.8], (n, 1)))
    taus = np.array([0.05, 0.1, 0.2, 0.5])
    for sensor, data in (("gyro", s.gyro_b), ("accel", s.accel_b)):
        t, adev = allan_deviation(data, imu.output_rate_hz, taus)
        model = theoretical_adev(imu, sensor, t)["total"]
        np.testing.assert_allclose(adev, model, rtol=0.06)  # statistical spread ~2 % here
        for a in range(3):
            assert np.polyfit(np.log(t), np.log(adev[:, a]), 1)[0] == pytest.approx(-0.5, abs=0.06)


def test_each_channel_keeps_all_its_flicker_terms(tmp_path):
    """A gyro with a wider flicker band (more Gauss-Markov terms) than the accelerometer keeps
    all its terms: its Allan deviation at long τ, set by the slow terms alone, follows the
    model (it fell by about 3x at 100 s when the accelerometer's count was used for both)."""
    path = tmp_path / "wide_gyro.toml"
    path.write_text('name = "wide_gyro"\nbase = "ideal"\n[gyro]\nbias_instability = 50.0\n'
                    'bias_corner_times = [1.0, 3000.0]\n[accel]\nbias_instability = 0.1\n'
                    'bias_corner_times = [1.0, 3.0]\n', "utf-8")
    imu = MPU9250(path, seed=5, registers={"smplrt_div": 9})
    n = 1_200_000  # 1200 s at the 1 kHz input rate
    s = imu.simulate(np.zeros((n, 3)), np.tile([0.0, 0.0, G0], (n, 1)), np.tile([3.7, 18.3, -49.8], (n, 1)))
    taus = np.array([30.0, 100.0])
    t, adev = allan_deviation(s.gyro_b, imu.output_rate_hz, taus)
    model = theoretical_adev(imu, "gyro", t)["total"]
    np.testing.assert_allclose(adev.mean(axis=1), model.mean(axis=1), rtol=0.35)  # few long clusters


def test_validate_static_writes_results_and_plot(tmp_path):
    r = validate_static(0.02, seed=1, out_dir=tmp_path)
    saved = json.loads((tmp_path / "results.json").read_text(encoding="utf-8"))
    assert saved["gyro"]["noise_density"] == pytest.approx([36.0] * 3)  # 0.01 °/s/√Hz in the plot's °/h units
    assert (tmp_path / "allan.png").stat().st_size > 10_000
    assert set(r) >= {"gyro", "accel", "pass", "output_rate_hz"}
    with pytest.raises(ValueError, match="hours"):
        validate_static(-1.0)
