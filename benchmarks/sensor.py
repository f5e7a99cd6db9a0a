"""Cost of the virtual MPU-9250, against baselines measured in the same run.

* per call, for a chunk of 20 input samples at 1 kHz (one co-simulation control period
  of 20 ms): ``MPU9250.simulate`` against one ``numpy.copy`` of the same three arrays,
  and against 20 bare ``mj_step`` of the reference car (when MuJoCo and the car load);
* throughput of one long batch call in ns per input sample, for the profiles and options;
* the wall time of the one-hour static run behind ``biso-cosim sensor allan``.

    python benchmarks/sensor.py            # about a minute
    python benchmarks/sensor.py --quick    # skip the one-hour run
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from biso_cosim.sensors import MPU9250
from biso_cosim.units import G0


def best_of(fn, number: int, repeat: int = 7) -> float:
    """Best mean time of ``number`` calls over ``repeat`` rounds, in seconds per call."""
    fn()
    best = float("inf")
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - start) / number)
    return best


def truth(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    omega = 0.3 * rng.standard_normal((n, 3))
    force = np.array([0.0, 0.0, G0]) + rng.standard_normal((n, 3))
    mag = np.array([3.7, 18.3, -49.8]) + 0.5 * rng.standard_normal((n, 3))
    return omega, force, mag


def mj_step_time(steps: int) -> float | None:
    """Seconds for ``steps`` bare mj_step of the reference car, or None if it does not load."""
    try:
        import mujoco

        from biso_cosim.vehicle.model import CAR_XML

        model = mujoco.MjModel.from_xml_path(str(CAR_XML))
    except Exception as exc:  # the benchmark still reports the rest
        print(f"(no mj_step baseline: {exc})")
        return None
    data = mujoco.MjData(model)
    for _ in range(200):  # settle
        mujoco.mj_step(model, data)

    def run():
        for _ in range(steps):
            mujoco.mj_step(model, data)

    return best_of(run, 50)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="skip the one-hour static run")
    args = parser.parse_args()

    chunk = 20
    omega, force, mag = truth(chunk)
    imu = MPU9250("mpu9250", seed=0)
    t_call = best_of(lambda: imu.simulate(omega, force, mag), 3000)
    t_copy = best_of(lambda: (np.copy(omega), np.copy(force), np.copy(mag)), 3000)
    print(f"per call, {chunk} samples at 1 kHz (default registers, mpu9250 profile):")
    print(f"  simulate                 {t_call * 1e6:8.2f} µs")
    print(f"  numpy.copy of the inputs {t_copy * 1e6:8.2f} µs   ratio {t_call / t_copy:6.1f}")
    t_step = mj_step_time(chunk)
    if t_step is not None:
        print(f"  {chunk} × mj_step (car)     {t_step * 1e6:8.2f} µs   sensor share of a step {t_call / t_step:6.1%}")
    t_inc = best_of(lambda: imu.simulate(omega, force, mag, increments=4, subintervals=5), 3000)
    print(f"  with increments=4, subintervals=5: {t_inc * 1e6:.2f} µs")

    n = 200_000
    omega, force, mag = truth(n)
    print(f"\nbatch throughput, {n} input samples at 1 kHz (ns per input sample):")
    base = best_of(lambda: (np.copy(omega), np.copy(force), np.copy(mag)), 5, 3) / n
    for label, kwargs, sim_kw in (
        ("mpu9250, default registers", {}, {}),
        ("ideal (no errors)", {"profile": "ideal"}, {}),
        ("mpu9250 + increments=4", {}, {"increments": 4}),
        ("mpu9250, DLPF_CFG=0 (8 kHz)", {"registers": {"dlpf_cfg": 0}}, {}),
    ):
        sensor = MPU9250(**kwargs)
        per = best_of(lambda: sensor.simulate(omega, force, mag, **sim_kw), 1, 3) / n
        print(f"  {label:32s} {per * 1e9:8.1f}   ({per / base:5.1f} × numpy.copy)")

    if not args.quick:
        from biso_cosim.sensors.allan import validate_static

        start = time.perf_counter()
        r = validate_static(1.0, plot=False)
        print(f"\none-hour static run and Allan analysis: {time.perf_counter() - start:.1f} s "
              f"(simulation alone {r['simulation_wall_s']:.1f} s)")


if __name__ == "__main__":
    main()
