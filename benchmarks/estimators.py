"""Speed of every estimator's batch call against VQF's and imufusion's, on the same data.

Prints samples per second and ns per sample of each method (the GNSS-aided ones with 5 Hz
fixes) and the ratio to VQF's real-time
batch call (``vqf.VQF.updateBatch``), all measured in this run on this machine, round-robin
(each repetition times every method once, and the best repetition counts), so that a change
of load affects all of them alike. Targets of issue 4: ``biso`` at least 5× VQF's batch
call, ``biso_plus`` at least 2×. Also the cost of the co-simulation's usage (4 samples per
``update``) against one ``numpy.copy`` of the same arrays.

``--instructions`` counts instructions per sample instead, with valgrind's callgrind (not
affected by the machine's load): each method runs in a child process once with one pass and
once with six passes over the data, and the difference is divided by five passes. The first
run compiles the kernels under valgrind (its own numba cache), which takes several minutes.

    python benchmarks/estimators.py [--seconds 300] [--repeat 15]
    python benchmarks/estimators.py --instructions [--methods biso,biso_plus,vqf]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from biso_cosim.estimators import estimator_inputs, estimator_names, make_estimator
from biso_cosim.motions import make_motion
from biso_cosim.sensors.gnss import GnssFixes

FS = 200.0
TARGETS = {"biso": 5.0, "biso_plus": 2.0}


def _data(seconds: float, fs: float = FS, seed: int = 0):
    """Tumbling through all attitudes at up to ~2.5 rad/s, with gyro bias and sensor noise."""
    m = make_motion("tumble", seconds, fs, seed=seed, rate_scale=0.5)
    rng = np.random.default_rng(seed)
    n = len(m)
    gyro = m.omega_b + 0.003 * rng.normal(size=(n, 3)) + [0.01, -0.02, 0.005]
    accel = m.specific_force_b + 0.05 * rng.normal(size=(n, 3))
    mag = m.mag_b + 0.3 * rng.normal(size=(n, 3))
    return [np.ascontiguousarray(a) for a in (gyro, accel, mag)]


def _fixes_at_rest(seconds: float, rate_hz: float = 5.0) -> GnssFixes:
    """5 Hz GNSS fixes of a body that turns in place (the tumble motion): zero velocity, 50 ms late."""
    t = np.arange(0.0, seconds - 0.1, 1.0 / rate_hz)
    k = t.shape[0]
    zeros = np.zeros((k, 3))
    return GnssFixes(t, t + 0.05, zeros, zeros.copy(), np.zeros(k), np.zeros(k), np.zeros(k), np.ones(k, dtype=bool))


def _methods(gyro, accel, mag):
    """name → function running one whole batch (a fresh estimator each time)."""
    n = gyro.shape[0]
    out = {}

    def ours(name, speed=False, **params):
        kw = {"speed_mps": np.full(n, 5.0)} if speed else {}
        if "gnss" in estimator_inputs(name):
            kw["gnss"] = _fixes_at_rest(n / FS)
        make_estimator(name, FS, **params).update(gyro[:10], accel[:10], mag[:10])  # compile / load the cache
        return lambda: make_estimator(name, FS, **params).update(gyro, accel, mag, **kw)

    for name in estimator_names():
        out[name] = ours(name)
    out["biso_plus (with speed input)"] = ours("biso_plus", speed=True)
    out["biso (reference='euler')"] = ours("biso", reference="euler")
    out["biso (pattern 13, matrix exponential)"] = ours("biso", pattern=13)
    try:
        import vqf

        out["vqf VQF.updateBatch"] = lambda: vqf.VQF(1.0 / FS).updateBatch(gyro, accel, mag)
        out["vqf offlineVQF (acausal)"] = lambda: vqf.offlineVQF(gyro, accel, mag, 1.0 / FS)
    except ImportError:
        print("vqf not installed: ratios to VQF are missing (pip install biso_cosim[compare])")
    try:
        import imufusion

        def fusion():
            ahrs = imufusion.Ahrs()
            gd, ag = np.degrees(gyro), accel / 9.80665
            for i in range(n):  # the Python API has no batch call
                ahrs.update(gd[i], ag[i], mag[i])
        out["imufusion per-sample loop"] = fusion
    except ImportError:
        print("imufusion not installed")
    return out


def timing(seconds: float, repeat: int) -> None:
    gyro, accel, mag = _data(seconds)
    n = gyro.shape[0]
    fns = _methods(gyro, accel, mag)
    slow = {"biso (pattern 13, matrix exponential)", "imufusion per-sample loop"}
    best = {name: np.inf for name in fns}
    for r in range(repeat):
        for name, fn in fns.items():
            if name in slow and r >= 2:  # seconds per call: two are enough
                continue
            t = time.perf_counter()
            fn()
            best[name] = min(best[name], time.perf_counter() - t)
    base = best.get("vqf VQF.updateBatch")
    print(f"{n} samples at {FS:g} Hz (tumbling, noisy); best of {repeat} round-robin repetitions")
    print(f"{'method':<42}{'Msamples/s':>12}{'ns/sample':>12}{'× VQF batch':>14}")
    for name, sec in best.items():
        ratio = f"{base / sec:14.2f}" if base else f"{'—':>14}"
        print(f"{name:<42}{n / sec / 1e6:12.2f}{sec / n * 1e9:12.1f}{ratio}")
    if base:
        for name, target in TARGETS.items():
            got = base / best[name]
            print(f"target {name} ≥ {target:g}× VQF batch: {got:.2f}× ({'met' if got >= target else 'NOT met'})")

    # the co-simulation's usage: one call per control period of 4 samples
    est = make_estimator("biso", FS)
    k = 4
    chunks = n // k

    def streaming():
        for i in range(0, chunks * k, k):
            est.update(gyro[i:i + k], accel[i:i + k], mag[i:i + k])

    def copies():
        for i in range(0, chunks * k, k):
            np.copy(gyro[i:i + k])
    t_stream = min(_once(streaming) for _ in range(2))
    t_copy = min(_once(copies) for _ in range(2))
    print(f"\nbiso.update with {k} samples per call: {t_stream / chunks * 1e6:.2f} µs per call "
          f"({t_stream / t_copy:.1f}× one numpy.copy of a {k}×3 array per call)")


def _once(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


# --------------------------------------------------------------------------------------
# instruction counts (callgrind)
# --------------------------------------------------------------------------------------

_COUNT_SECONDS = 500.0  # 100 000 samples per pass


def _count_pass(method: str, passes: int) -> None:
    """Child process: warm up, then ``passes`` batch calls of ``method`` over the data."""
    gyro, accel, mag = _data(_COUNT_SECONDS)
    if method == "vqf":
        import vqf

        vqf.VQF(1.0 / FS).updateBatch(gyro[:10], accel[:10], mag[:10])
        for _ in range(passes):
            vqf.VQF(1.0 / FS).updateBatch(gyro, accel, mag)
        return
    make_estimator(method, FS).update(gyro[:10], accel[:10], mag[:10])
    for _ in range(passes):
        make_estimator(method, FS).update(gyro, accel, mag)


def instructions(methods: list[str]) -> None:
    if shutil.which("valgrind") is None:
        sys.exit("--instructions needs valgrind (callgrind) on the PATH")
    cache = os.path.join(tempfile.gettempdir(), "biso_cosim_numba_cache_valgrind")
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONHASHSEED="0")
    n = _data(_COUNT_SECONDS)[0].shape[0]
    counts = {}
    for method in methods:
        total = []
        for passes in (1, 6):
            cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable, __file__,
                   "--count-pass", method, str(passes)]
            res = subprocess.run(cmd, env=env, capture_output=True, text=True)
            found = re.search(r"Collected : (\d+)", res.stderr)
            if res.returncode != 0 or not found:
                sys.exit(f"callgrind run of {method} failed:\n{res.stderr[-2000:]}")
            total.append(int(found.group(1)))
        counts[method] = (total[1] - total[0]) / (5 * n)
        print(f"{method:<12}{counts[method]:10.0f} instructions per sample", flush=True)
    if "vqf" in counts:
        for method, c in counts.items():
            print(f"{method:<12} VQF / {method} instructions: {counts['vqf'] / c:.2f}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=300.0, help="length of the data at 200 Hz (default 300 s)")
    ap.add_argument("--repeat", type=int, default=15, help="round-robin repetitions, best counts (default 15)")
    ap.add_argument("--instructions", action="store_true", help="count instructions per sample with callgrind")
    ap.add_argument("--methods", default="biso,positional,poisson,dcm_pi,biso_plus,vqf",
                    help="methods for --instructions (default biso,positional,poisson,dcm_pi,biso_plus,vqf)")
    ap.add_argument("--count-pass", nargs=2, metavar=("METHOD", "PASSES"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.count_pass:
        _count_pass(args.count_pass[0], int(args.count_pass[1]))
    elif args.instructions:
        instructions([m.strip() for m in args.methods.split(",") if m.strip()])
    else:
        timing(args.seconds, args.repeat)


if __name__ == "__main__":
    main()
