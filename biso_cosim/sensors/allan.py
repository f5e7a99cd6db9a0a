"""Allan deviation, the model's theoretical Allan curves, and the static validation run.

`allan_deviation` is the overlapping Allan deviation of rate samples (IEEE Std 952 /
1293), computed from the integrated signal; `theoretical_adev` the Allan deviation our
noise model has by construction (white noise, the Gauss-Markov sum that stands for flicker
bias, rate random walk); `validate_static` simulates a static sensor, compares the two
and writes ``results.json`` and ``allan.png`` (``biso-cosim sensor allan``).
"""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from biso_cosim.units import DEG_PER_H, G0, MILLI_G

__all__ = ["allan_deviation", "theoretical_adev", "white_noise_aliasing", "validate_static"]

FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
"""Allan deviation floor of flicker noise per unit bias instability B: 0.664 (IEEE Std 952)."""


def allan_deviation(x: Any, fs_hz: float, taus_s: Any = None) -> tuple[np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of rate samples.

    σ²(τ) = Σ_k (θ_{k+2m} − 2θ_{k+m} + θ_k)² / (2 τ² (N − 2m)),  τ = m / fs,
    with θ the running integral of the samples (θ_0 = 0).

    Args:
        x: (n,) or (n, c) samples at ``fs_hz``.
        fs_hz: sample rate.
        taus_s: averaging times in s (rounded to whole samples, duplicates dropped);
            default: about 10 per decade from one sample to n/4 samples.

    Returns:
        (taus_s (t,), adev (t,) or (t, c)).
    """
    data = np.asarray(x, dtype=np.float64)
    if data.ndim not in (1, 2) or data.shape[0] < 4:
        raise ValueError(f"x must have shape (n,) or (n, c) with n >= 4, got {data.shape}")
    if not np.all(np.isfinite(data)):
        raise ValueError("x must be finite")
    if not (math.isfinite(fs_hz) and fs_hz > 0):
        raise ValueError(f"fs_hz must be positive, got {fs_hz}")
    n = data.shape[0]
    if taus_s is None:
        m = np.unique(np.round(np.logspace(0, math.log10(n / 4), int(10 * math.log10(n / 4)) + 1)).astype(np.int64))
    else:
        m = np.unique(np.round(np.asarray(taus_s, dtype=np.float64) * fs_hz).astype(np.int64))
        if m.size == 0 or m[0] < 1 or 2 * m[-1] >= n:
            raise ValueError(f"taus_s must lie between 1/fs and n/(2 fs) = {n / (2 * fs_hz):g} s")
    flat = data.reshape(n, -1)
    # remove the mean first: the Allan variance ignores it, the running sum keeps precision
    theta = np.zeros((n + 1, flat.shape[1]))
    np.cumsum(flat - flat.mean(axis=0), axis=0, out=theta[1:])
    theta /= fs_hz
    out = np.empty((m.size, flat.shape[1]))
    for i, mm in enumerate(m):
        d = theta[2 * mm :] - 2.0 * theta[mm:-mm] + theta[: -2 * mm]
        tau = mm / fs_hz
        out[i] = np.sqrt(np.mean(d * d, axis=0) / (2.0 * tau * tau))
    taus = m / fs_hz
    return taus, (out[:, 0] if data.ndim == 1 else out)


def _gauss_markov_avar(tau: np.ndarray, sigma: float, corr_time: float) -> np.ndarray:
    """Allan variance of a first-order Gauss-Markov process (variance σ², time constant T):
    (2σ²T/τ)·[1 − (T/2τ)(3 − 4e^{−τ/T} + e^{−2τ/T})]."""
    x = tau / corr_time
    with np.errstate(over="ignore"):
        bracket = np.where(
            x < 1e-3,
            x * x / 3.0 - x**3 / 4.0,  # series: the random-walk limit 2σ²τ/(3T)
            1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x),
        )
    return 2.0 * sigma**2 * corr_time / tau * bracket


def white_noise_aliasing(imu, sensor: str) -> float:
    """Factor by which reading every D-th filtered internal sample raises the white-noise
    Allan variance: Σ_{k<D} |H(e^{j2πk/D})|² (H the DLPF design, D internal samples per
    output). 1 when the output rate is the internal rate; 1.127 (gyro) and 1.150 (accel)
    for the default registers (200 Hz from 1 kHz behind 41/44.8 Hz filters): the chip
    decimates without further anti-aliasing, so noise above 100 Hz folds down.

    Derivation: white noise of variance N²·f at the internal rate f, filtered by H and
    sampled every D-th sample, has the two-sided PSD at zero frequency
    (1/f_out)·Σ_m R(mD) = N²·Σ_k |H(e^{j2πk/D})|², and the Allan variance of white noise
    is that PSD over τ.
    """
    from biso_cosim.sensors.dlpf import frequency_response

    per_output = imu.internal_samples_per_output(sensor)
    if per_output <= 1:
        return 1.0
    design = imu.designs[sensor]
    if not imu.profile.values["model.dlpf"]:
        return float(per_output)
    freqs = np.arange(per_output) * design.rate_hz / per_output
    return float(np.sum(np.abs(frequency_response(design, freqs)) ** 2))


def theoretical_adev(imu, sensor: str, taus_s: Any) -> dict[str, np.ndarray]:
    """The Allan deviation of one sensor of an `MPU9250` by construction, per axis.

    Returns a dict of (t, 3) arrays: ``white`` (N/√τ, times the aliasing factor of
    `white_noise_aliasing`), ``flicker`` (the Gauss-Markov sum),
    ``random_walk`` (K·√(τ/3)) and ``total`` (root sum of squares). Filter and
    quantization effects (only below ~1/bandwidth) are not included.
    """
    from biso_cosim.sensors.profile import flicker_terms

    tau = np.asarray(taus_s, dtype=np.float64)[:, None]
    prof = imu.profile
    n_density = prof.axes(f"{sensor}.noise_density")[None, :] * math.sqrt(white_noise_aliasing(imu, sensor))
    k_rw = prof.axes(f"{sensor}.random_walk")[None, :]
    corr, sig = flicker_terms(prof.axes(f"{sensor}.bias_instability"), prof.si(f"{sensor}.bias_corner_times"))
    flick = np.zeros((tau.shape[0], 3))
    for t_c, s in zip(corr, sig):
        for a in range(3):
            flick[:, a] += _gauss_markov_avar(tau[:, 0], s[a], t_c)
    white = n_density**2 / tau
    rw = k_rw**2 * tau / 3.0
    return {
        "white": np.sqrt(white) * np.ones((1, 3)),
        "flicker": np.sqrt(flick),
        "random_walk": np.sqrt(rw) * np.ones((1, 3)),
        "total": np.sqrt(white + flick + rw),
    }


def _static_run(imu, seconds: float, chunk_s: float = 60.0) -> dict[str, np.ndarray]:
    """Readings of a static, level sensor (gyro 0, +g up, a constant field), in chunks."""
    n_chunk = int(round(chunk_s * imu.input_rate_hz))
    total = int(round(seconds * imu.input_rate_hz))
    omega = np.zeros((n_chunk, 3))
    force = np.tile([0.0, 0.0, G0], (n_chunk, 1))
    mag = np.tile([3.65, 18.35, -49.84], (n_chunk, 1))
    gyro, accel = [], []
    done = 0
    while done < total:
        n = min(n_chunk, total - done)
        s = imu.simulate(omega[:n], force[:n], mag[:n])
        gyro.append(s.gyro_b)
        accel.append(s.accel_b)
        done += n
    return {"gyro": np.concatenate(gyro), "accel": np.concatenate(accel)}


def validate_static(
    hours: float = 1.0,
    *,
    seed: int = 0,
    profile: Any = "mpu9250",
    registers: Any = None,
    out_dir: str | os.PathLike | None = None,
    plot: bool = True,
) -> dict[str, Any]:
    """Simulate a static sensor for ``hours`` and compare its Allan deviation with the model.

    ``registers`` default to the package defaults with SMPLRT_DIV = 0 (output at the 1 kHz
    internal rate): then the Allan deviation at 1 s is the noise density. At lower output
    rates it is higher by `white_noise_aliasing` (6-7 % at the default 200 Hz), as on the
    real chip; the results report that factor.

    Checks, per sensor and axis: the Allan deviation at τ = 1 s against the noise density
    N (within 10 %); the floor (minimum) against the model's total curve at that τ and
    against 0.664·B; the random-walk coefficient fitted on the longest averaging times
    against K. Returns the results (also written to ``out_dir/results.json`` with the plot
    ``out_dir/allan.png`` when ``out_dir`` is given).
    """
    from biso_cosim.sensors.mpu9250 import MPU9250

    if not (isinstance(hours, (int, float)) and math.isfinite(hours) and hours > 0):
        raise ValueError(f"hours must be positive, got {hours!r}")
    imu = MPU9250(profile, seed=seed, registers={"smplrt_div": 0} if registers is None else registers)
    t0 = time.perf_counter()
    data = _static_run(imu, hours * 3600.0)
    sim_wall = time.perf_counter() - t0
    fs = imu.output_rate_hz
    n = data["gyro"].shape[0]
    taus = np.unique(np.concatenate([np.logspace(math.log10(1.0 / fs), math.log10(n / fs / 4), 60), [1.0]]))
    units = {"gyro": (DEG_PER_H, "°/h"), "accel": (MILLI_G, "mg")}
    results: dict[str, Any] = {
        "profile": imu.profile.name,
        "seed": seed,
        "hours": hours,
        "output_rate_hz": fs,
        "registers": imu.registers.describe().splitlines(),
        "simulation_wall_s": sim_wall,
        "convention": "noise density N read as the Allan deviation at τ = 1 s (σ per sample = N·√f)",
    }
    curves = {}
    for sensor in ("gyro", "accel"):
        scale, unit = units[sensor]
        t_used, adev = allan_deviation(data[sensor], fs, taus)
        theory = theoretical_adev(imu, sensor, t_used)
        i1 = int(np.argmin(np.abs(t_used - 1.0)))
        density = imu.profile.axes(f"{sensor}.noise_density")
        b = imu.profile.axes(f"{sensor}.bias_instability")
        k = imu.profile.axes(f"{sensor}.random_walk")
        # the floor: minimum over τ up to a twentieth of the run (spread below ~16 %)
        usable = t_used <= t_used[-1] * 4 / 20
        imin = np.argmin(np.where(usable[:, None], adev, np.inf), axis=0)
        # K from the last points: σ² = K²τ/3 + rest; fit on τ >= τ_end/4 where RRW dominates
        long = t_used >= t_used[-1] / 4
        rest = theory["white"] ** 2 + theory["flicker"] ** 2
        k_fit = np.sqrt(np.maximum(0.0, np.mean((adev[long] ** 2 - rest[long]) * 3.0 / t_used[long, None], axis=0)))
        # statistical spread of an overlapping Allan deviation at τ: about 1/√(2(T/τ − 1)) (rel.)
        spread = 1.0 / np.sqrt(2.0 * (n / (t_used * fs) - 1.0))
        # the model leaves out the DLPF, which shapes only the shortest averaging times
        judged = t_used >= 0.1
        within = np.abs(adev[judged] / theory["total"][judged] - 1.0) <= 3.0 * spread[judged, None] + 0.05
        results[sensor] = {
            "unit": unit,
            "noise_density": (density / scale).tolist(),
            "white_noise_aliasing_factor_adev": math.sqrt(white_noise_aliasing(imu, sensor)),
            "adev_at_1s": (adev[i1] / scale).tolist(),
            "ratio_at_1s": (adev[i1] / density).tolist(),
            "pass_at_1s_within_10pct": bool(np.all(np.abs(adev[i1] / density - 1.0) <= 0.10)),
            "bias_instability": (b / scale).tolist(),
            "floor_expected_0.664B": (FLICKER_FLOOR * b / scale).tolist(),
            "floor_measured": (adev[imin, range(3)] / scale).tolist(),
            "floor_tau_s": t_used[imin].tolist(),
            "floor_model_at_that_tau": (theory["total"][imin, range(3)] / scale).tolist(),
            "random_walk_unit": f"{unit}/√h",
            "random_walk": (k * 60.0 / scale).tolist(),
            "random_walk_fitted": (k_fit * 60.0 / scale).tolist(),
            "fraction_of_taus_from_0.1s_within_3sigma_of_model": float(np.mean(within)),
        }
        curves[sensor] = (t_used, adev, theory, scale, unit, b)
    results["pass"] = bool(results["gyro"]["pass_at_1s_within_10pct"] and results["accel"]["pass_at_1s_within_10pct"])
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "results.json").write_text(json.dumps(results, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
        if plot:
            _plot(curves, imu, out / "allan.png", hours)
    return results


def _plot(curves, imu, path: Path, hours: float) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    # the K units are shown per √h for the gyro (°/h/√h) and the accelerometer (mg/√h)
    rw_unit = {"gyro": "°/h/√h", "accel": "mg/√h"}
    n_unit = {"gyro": "°/s/√Hz", "accel": "µg/√Hz"}
    for ax, sensor in zip(axes, ("gyro", "accel")):
        taus, adev, theory, scale, unit, b = curves[sensor]
        for a, name in enumerate("xyz"):
            ax.loglog(taus, adev[:, a] / scale, lw=1.2, label=f"simulated {name}")
        ax.loglog(taus, theory["total"][:, 0] / scale, "k-", lw=2, alpha=0.6, label="model (x)")
        ax.loglog(taus, theory["white"][:, 0] / scale, "k--", lw=1, label="white: N/√τ")
        ax.loglog(taus, theory["random_walk"][:, 0] / scale, "k:", lw=1, label="random walk: K·√(τ/3)")
        ax.axhline(FLICKER_FLOOR * b[0] / scale, color="gray", ls="-.", lw=1, label="flicker floor 0.664·B")
        ax.axvline(1.0, color="gray", lw=0.5)
        ax.text(taus[0], adev[0, 0] / scale, " DLPF", fontsize=8, va="top")
        prof = imu.profile
        ax.set_title(
            f"{sensor}: N = {prof.values[f'{sensor}.noise_density']} {n_unit[sensor]}, B = {prof.values[f'{sensor}.bias_instability']} {unit}, "
            f"K = {prof.values[f'{sensor}.random_walk']} {rw_unit[sensor]}",
            fontsize=9,
        )
        ax.set_xlabel("averaging time τ (s)")
        ax.set_ylabel(f"Allan deviation ({unit})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"Static {imu.profile.name} (seed {imu.seed}), {hours:g} h at {imu.output_rate_hz:g} Hz ODR")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
