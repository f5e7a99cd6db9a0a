"""Cost per sample of the C estimators (the native FMUs' path) against the numba kernels.

Compiles the C library (``biso_cosim.fmu.native``) with the system C compiler and the
project's flags, then times, on the same samples (tumbling through all attitudes, with
gyro bias and noise; biso_plus also with a speed input):

* **C**: ``biso_est_run`` over the whole block, i.e. ``biso_est_update`` once per sample
  from C (what an FMU's doStep of one sample calls; one ctypes call per block, so no
  Python in the loop);
* **numba**: a fresh Python estimator's ``update`` of the whole block (the batch kernel).

Both in this run, round-robin (each repetition times every method once; the best
repetition counts), so that a change of load affects both alike. Prints ns per sample and
the ratio C/numba. The issue's goal is 1 µs per doStep of biso_plus in a C master with the
FMI overhead; the update alone must be well below it.

``--instructions`` counts instructions per sample instead, with valgrind's callgrind (not
affected by the machine's load): each path runs in a child process once with one pass and
once with six passes over 100 000 samples, and the difference is divided by five passes
(numba compiles under valgrind the first time: several minutes; its cache is shared with
``benchmarks/estimators.py --instructions``).

    python benchmarks/native_estimators.py [--seconds 300] [--repeat 9]
    python benchmarks/native_estimators.py --instructions [--cases biso_plus,poisson]

``measure(...)`` returns the numbers for other benchmarks (``benchmarks/fmu_overhead.py``).
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

from biso_cosim.estimators import make_estimator
from biso_cosim.fmu.native.binding import NativeEstimator, NativeLibrary, compile_estimators
from biso_cosim.motions import make_motion

FS = 200.0
CASES = (("biso", {}, False), ("positional", {}, False), ("poisson", {}, False), ("dcm_pi", {}, False),
         ("biso_plus", {}, False), ("biso_plus", {}, True), ("biso", {"reference": "euler"}, False),
         ("biso", {"pattern": 13}, False))
"""(estimator, parameters, with a speed input)."""


def samples(seconds: float, seed: int = 0) -> dict[str, np.ndarray]:
    """Tumbling through all attitudes at up to ~2.5 rad/s, with gyro bias and sensor noise."""
    m = make_motion("tumble", seconds, FS, seed=seed, rate_scale=0.5)
    rng = np.random.default_rng(seed)
    n = len(m)
    return {"gyro_b": np.ascontiguousarray(m.omega_b + 0.003 * rng.normal(size=(n, 3)) + [0.01, -0.02, 0.005]),
            "accel_b": np.ascontiguousarray(m.specific_force_b + 0.05 * rng.normal(size=(n, 3))),
            "mag_b": np.ascontiguousarray(m.mag_b + 0.3 * rng.normal(size=(n, 3))),
            "speed_mps": np.full(n, 5.0)}


def _label(name: str, params: dict, speed: bool) -> str:
    extra = [f"{k}={v!r}" for k, v in params.items()] + (["speed input"] if speed else [])
    return f"{name} ({', '.join(extra)})" if extra else name


def measure(seconds: float = 300.0, repeat: int = 9, lib: NativeLibrary | None = None) -> dict[str, dict[str, float]]:
    """label → {"c_ns", "numba_ns"}: the best ns per sample of each, measured round-robin."""
    if lib is None:
        lib = NativeLibrary(compile_estimators(tempfile.mkdtemp(prefix="biso_native_bench_")))
    s = samples(seconds)
    n = len(s["gyro_b"])
    runs = {}
    for name, params, speed in CASES:
        extra = {"speed_mps": s["speed_mps"]} if speed else {}
        make_estimator(name, FS, **params).update(s["gyro_b"][:10], s["accel_b"][:10], s["mag_b"][:10])  # compile
        label = _label(name, params, speed)

        def c_run(name=name, params=params, extra=extra):
            NativeEstimator(lib, name, FS, **params).update(s["gyro_b"], s["accel_b"], s["mag_b"], **extra)

        def numba_run(name=name, params=params, extra=extra):
            make_estimator(name, FS, **params).update(s["gyro_b"], s["accel_b"], s["mag_b"], **extra)

        runs[label] = {"c_ns": c_run, "numba_ns": numba_run}
    best = {label: {k: np.inf for k in fns} for label, fns in runs.items()}
    for _ in range(repeat):
        for label, fns in runs.items():
            for key, fn in fns.items():
                t0 = time.perf_counter()
                fn()
                best[label][key] = min(best[label][key], (time.perf_counter() - t0) / n * 1e9)
    return best


_COUNT_SECONDS = 500.0  # 100 000 samples per pass


def _count_pass(label: str, path: str, lib_path: str, passes: int) -> None:
    """Child process: warm up, then ``passes`` runs of one case on one path ("c" or "numba")."""
    name, params, speed = next(c for c in CASES if _label(*c) == label)
    s = samples(_COUNT_SECONDS)
    extra = {"speed_mps": s["speed_mps"]} if speed else {}
    if path == "c":
        lib = NativeLibrary(lib_path)
        make = lambda: NativeEstimator(lib, name, FS, **params)  # noqa: E731
    else:
        make = lambda: make_estimator(name, FS, **params)  # noqa: E731
    make().update(s["gyro_b"][:10], s["accel_b"][:10], s["mag_b"][:10])
    for _ in range(passes):
        make().update(s["gyro_b"], s["accel_b"], s["mag_b"], **extra)


def instructions(labels: list[str]) -> None:
    if shutil.which("valgrind") is None:
        sys.exit("--instructions needs valgrind (callgrind) on the PATH")
    lib_path = str(compile_estimators(tempfile.mkdtemp(prefix="biso_native_bench_")))
    cache = os.path.join(tempfile.gettempdir(), "biso_cosim_numba_cache_valgrind")
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONHASHSEED="0")
    n = int(round(_COUNT_SECONDS * FS))
    print(f"instructions per sample (callgrind, {n} samples per pass)")
    print(f"{'estimator':44s} {'C update':>10s} {'numba batch':>12s} {'C/numba':>8s}")
    for label in labels:
        counts = {}
        for path in ("c", "numba"):
            total = []
            # passes 0: a warm-up run that fills the numba cache (compiling under valgrind would
            # otherwise count in the first measured run), then the two counted ones
            for passes in ((0, 1, 6) if path == "numba" else (1, 6)):
                cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable, __file__,
                       "--count-pass", label, path, lib_path, str(passes)]
                res = subprocess.run(cmd, env=env, capture_output=True, text=True)
                found = re.search(r"Collected : (\d+)", res.stderr)
                if res.returncode != 0 or not found:
                    sys.exit(f"callgrind run of {label} ({path}) failed:\n{res.stderr[-2000:]}")
                total.append(int(found.group(1)))
            counts[path] = (total[-1] - total[-2]) / (5 * n)
        print(f"{label:44s} {counts['c']:10.0f} {counts['numba']:12.0f} {counts['c'] / counts['numba']:8.2f}",
              flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=300.0, help="length of the data at 200 Hz")
    parser.add_argument("--repeat", type=int, default=9, help="repetitions (the best counts)")
    parser.add_argument("--instructions", action="store_true", help="count instructions per sample with callgrind")
    parser.add_argument("--cases", default="biso,poisson,dcm_pi,biso_plus (speed input)",
                        help="comma-separated cases for --instructions (labels as printed)")
    parser.add_argument("--count-pass", nargs=4, metavar=("CASE", "PATH", "LIB", "PASSES"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.count_pass:
        label, path, lib_path, passes = args.count_pass
        _count_pass(label, path, lib_path, int(passes))
        return
    if args.instructions:
        known = [_label(*c) for c in CASES]
        labels = [c.strip() for c in args.cases.split(",")]
        unknown = [c for c in labels if c not in known]
        if unknown:
            sys.exit(f"unknown case(s) {unknown}; known: {known}")
        instructions(labels)
        return
    best = measure(args.seconds, args.repeat)
    n = int(round(args.seconds * FS))
    print(f"{n} samples at {FS:g} Hz, best of {args.repeat} (round-robin); ns per sample")
    print(f"{'estimator':44s} {'C update':>10s} {'numba batch':>12s} {'C/numba':>8s}")
    for label, r in best.items():
        print(f"{label:44s} {r['c_ns']:10.1f} {r['numba_ns']:12.1f} {r['c_ns'] / r['numba_ns']:8.2f}")
    plus = best["biso_plus (speed input)"]["c_ns"]
    print(f"biso_plus with speed: {plus:.0f} ns per C update = {plus / 1000.0:.1%} of the 1 µs doStep goal "
          "(FMI overhead not included: benchmarks/fmu_overhead.py)")


if __name__ == "__main__":
    main()
