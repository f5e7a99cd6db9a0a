"""Speed of every estimator's batch call against VQF's and imufusion's, on the same data.

Prints samples per second and ns per sample of each method, and ratios to VQF's real-time
batch call (``vqf.VQF.updateBatch``), measured in this run on this machine. Targets of issue 4:
``biso`` at least 5× VQF's batch call, ``biso_plus`` at least 2×. Also the cost of the
co-simulation's usage (4 samples per call) against one ``numpy.copy`` of the same arrays.

    python benchmarks/estimators.py [--seconds 600] [--repeat 5]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from biso_cosim.estimators import estimator_names, make_estimator
from biso_cosim.motions import make_motion


def _data(seconds: float, fs: float = 200.0, seed: int = 0):
    m = make_motion("tumble", seconds, fs, seed=seed, rate_scale=0.5)
    rng = np.random.default_rng(seed)
    n = len(m)
    gyro = m.omega_b + 0.003 * rng.normal(size=(n, 3)) + [0.01, -0.02, 0.005]
    accel = m.specific_force_b + 0.05 * rng.normal(size=(n, 3))
    mag = m.mag_b + 0.3 * rng.normal(size=(n, 3))
    return [np.ascontiguousarray(a) for a in (gyro, accel, mag)], m.info, fs


def _best(fn, repeat: int) -> float:
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=600.0, help="length of the data at 200 Hz (default 600 s)")
    ap.add_argument("--repeat", type=int, default=5, help="best of N runs (default 5)")
    args = ap.parse_args(argv)
    (gyro, accel, mag), _, fs = _data(args.seconds)
    n = gyro.shape[0]
    rows: dict[str, float] = {}

    def ours(name, **params):
        est = make_estimator(name, fs, **params)
        est.update(gyro[:10], accel[:10], mag[:10])  # compile / load the cache
        kw = {"speed_mps": np.full(n, 5.0)} if "speed_mps" in est.inputs and params.pop("_speed", False) else {}

        def go():
            e = make_estimator(name, fs, **params)
            e.update(gyro, accel, mag, **kw)
        return go

    for name in estimator_names():
        rows[name] = _best(ours(name), args.repeat)
    rows["biso (reference='euler')"] = _best(ours("biso", reference="euler"), args.repeat)
    rows["biso (pattern 13, matrix exponential)"] = _best(ours("biso", pattern=13), max(1, args.repeat // 2))
    try:
        import vqf

        rows["vqf VQF.updateBatch"] = _best(lambda: vqf.VQF(1.0 / fs).updateBatch(gyro, accel, mag), args.repeat)
        rows["vqf offlineVQF (acausal)"] = _best(lambda: vqf.offlineVQF(gyro, accel, mag, 1.0 / fs), args.repeat)
    except ImportError:
        print("vqf not installed: ratios to VQF are missing (pip install biso_cosim[compare])")
    try:
        import imufusion

        m_small = min(n, 20000)

        def fusion():
            ahrs = imufusion.Ahrs()
            gd, ag = np.degrees(gyro[:m_small]), accel[:m_small] / 9.80665
            for i in range(m_small):
                ahrs.update(gd[i], ag[i], mag[i])
        rows["imufusion per-sample loop"] = _best(fusion, 2) * n / m_small
    except ImportError:
        print("imufusion not installed")

    base = rows.get("vqf VQF.updateBatch")
    print(f"{n} samples at {fs:g} Hz (tumbling, noisy); best of {args.repeat}")
    print(f"{'method':<42}{'Msamples/s':>12}{'ns/sample':>12}{'× VQF batch':>14}")
    for name, sec in rows.items():
        ratio = f"{base / sec:14.2f}" if base else f"{'—':>14}"
        print(f"{name:<42}{n / sec / 1e6:12.2f}{sec / n * 1e9:12.1f}{ratio}")

    # the co-simulation's usage: one call per control period of 4 samples
    est = make_estimator("biso", fs)
    k = 4
    chunks = n // k

    def streaming():
        for i in range(0, chunks * k, k):
            est.update(gyro[i:i + k], accel[i:i + k], mag[i:i + k])

    def copies():
        for i in range(0, chunks * k, k):
            np.copy(gyro[i:i + k])
    t_stream = _best(streaming, 2)
    t_copy = _best(copies, 2)
    print(f"\nbiso.update with {k} samples per call: {t_stream / chunks * 1e6:.2f} µs per call "
          f"({t_stream / t_copy:.1f}× one numpy.copy of a {k}×3 array per call)")


if __name__ == "__main__":
    main()
