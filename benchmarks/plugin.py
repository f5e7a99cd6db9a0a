"""Cost of the plug-in (biso_cosim.plugin.ImuPlugin: the MPU-9250 and one biso_plus) per 1 ms
truth tick, against the host simulator's own step measured in the same run.

The host is pybullet's racecar (biso_cosim.plugin.pybullet_racecar): its step is one
``stepSimulation`` at 1 ms plus the two state queries the bridge makes. Its truth of a drive
(standing, then a steady circle) is recorded once; the plug-in is then timed alone on those
rows, fed

* one call per tick (what a host's per-tick callback does), and
* one call per block of 20 ticks (one call per 20 ms control period: the same outputs, bit
  for bit, the Python overhead of a call shared by the block);

with the public ``MPU9250.simulate`` on one row per call as the sensor's own floor. Goals
(issue 24): at most 10 % of the host's step and at most 20 µs per tick.

    python benchmarks/plugin.py            # about a minute
    python benchmarks/plugin.py --ticks 2000 --repeat 3
"""

from __future__ import annotations

import argparse
import gc
import time

import numpy as np

from biso_cosim.plugin import ImuPlugin
from biso_cosim.plugin.pybullet_racecar import FRAMES, RacecarBridge
from biso_cosim.sensors import MPU9250, EarthField, MagneticEnvironment


def best_of(fn, repeat: int) -> float:
    """Best wall time of ``fn()`` over ``repeat`` rounds (after one warm-up), seconds."""
    fn()
    best = float("inf")
    for _ in range(repeat):
        gc.collect()
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ticks", type=int, default=4000, help="truth ticks of the recorded drive (1 ms each)")
    parser.add_argument("--repeat", type=int, default=5, help="rounds per measurement (the best is kept)")
    parser.add_argument("--block", type=int, default=20, help="ticks per call in the block measurement")
    args = parser.parse_args(argv)
    n = args.ticks

    with RacecarBridge(seed=0, speed_from_velocity=True) as bridge:
        ticks = [bridge.step_host() for _ in range(500)]  # the car settles on its wheels
        bridge.command(1.5, 0.3)

        def host_steps():
            for _ in range(n):
                ticks.append(bridge.step_host())

        host_s = best_of(host_steps, args.repeat) / n
    rows = ticks[-n:]
    cols = {name: np.array([getattr(r, name) for r in rows]) for name in ("t_s", "q_wb", "omega_b", "accel_w", "p_w", "v_w")}
    cols["t_s"] = np.arange(n) * 0.001

    def make():
        return ImuPlugin(tick_s=0.001, frames=FRAMES, gravity_w=(0.0, 0.0, -9.80665), seed=0,
                         estimators=["biso_plus"], speed_from_velocity=True)

    per_tick_rows = [(r.q_wb, r.omega_b, r.accel_w, r.p_w, r.v_w) for r in rows]
    plugin = make()

    def tick_by_tick():
        plugin.reset()
        for i, (q, w, a, p, v) in enumerate(per_tick_rows):
            plugin.step(i * 0.001, q, w, accel_w=a, p_w=p, v_w=v)

    blocks = [{k: v[s:s + args.block] for k, v in cols.items()} for s in range(0, n, args.block)]

    def in_blocks():
        plugin.reset()
        for b in blocks:
            plugin.step(b["t_s"], b["q_wb"], b["omega_b"], accel_w=b["accel_w"], p_w=b["p_w"], v_w=b["v_w"])

    tick_s = best_of(tick_by_tick, args.repeat) / n
    block_s = best_of(in_blocks, args.repeat) / n

    imu = MPU9250("mpu9250_calibrated", seed=0)
    w1, f1 = np.zeros((1, 3)), np.array([[0.0, 0.0, 9.80665]])
    m1 = MagneticEnvironment(EarthField()).field_b(np.array([[1.0, 0.0, 0.0, 0.0]]), np.zeros((1, 3)))

    def sensor_rows():
        imu.reset()
        for _ in range(n):
            imu.simulate(w1, f1, m1)

    sensor_s = best_of(sensor_rows, args.repeat) / n

    print(f"plug-in (MPU-9250 + biso_plus) per 1 ms truth tick against pybullet's racecar step; "
          f"{n} ticks, best of {args.repeat}")
    print(f"{'':44} {'µs/tick':>9} {'× host step':>12}")
    print(f"{'host: pybullet stepSimulation + state reads':44} {host_s * 1e6:9.1f} {1.0:12.3f}")
    for label, cost in ((f"plug-in, one call per tick", tick_s),
                        (f"plug-in, one call per {args.block} ticks", block_s),
                        ("(MPU9250.simulate alone, one row per call)", sensor_s)):
        print(f"{label:44} {cost * 1e6:9.1f} {cost / host_s:12.3f}")
    print()
    for label, cost in (("one call per tick", tick_s), (f"one call per {args.block} ticks", block_s)):
        share, micro = cost / host_s, cost * 1e6
        verdict = "met" if share <= 0.10 and micro <= 20.0 else "NOT met"
        print(f"goal (≤ 10 % of the host step and ≤ 20 µs per tick), {label}: {verdict} "
              f"({100 * share:.1f} %, {micro:.1f} µs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
