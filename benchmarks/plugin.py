"""Cost of the plug-in (biso_cosim.plugin.ImuPlugin: the MPU-9250 and one biso_plus) per 1 ms
truth tick, against the host simulator's own step measured in the same run.

The host is pybullet's racecar (biso_cosim.plugin.pybullet_racecar): its step is one
``stepSimulation`` at 1 ms plus the two state queries the bridge makes. Its truth of a drive
(standing, then a steady circle) is recorded once; the plug-in is then timed alone on those
rows, fed

* one call per tick (what a host's per-tick callback does), with outputs of their own and
  with ``reuse_outputs=True`` (views of the plug-in's buffers, written again by the next
  tick), and
* one call per block of 20 ticks (one call per 20 ms control period: the same outputs, bit
  for bit, the Python overhead of a call shared by the block);

with the public ``MPU9250.simulate`` on one row per call as the sensor's own floor. Goals
(issue 24): at most 10 % of the host's step and at most 20 µs per tick.

Each cost is the best over windows of ``--window`` consecutive ticks (500: 100 of the
chip's 200 Hz samples in each) of every round, the host's as the plug-in's: on a machine
shared with other work a window short enough to run undisturbed gives a number for each
that the others' load has not inflated. The load average is printed with the numbers.

With ``--callgrind`` (valgrind, its headers and a C compiler installed) it also counts the
instructions per tick of the host's step and of the plug-in's call per tick (both ways), a
figure the machine's load does not change: each is counted in a process of its own under
``valgrind --tool=callgrind --instr-atstart=no``, instrumented only over the measured loop
(callgrind's client requests, from a four-line C helper the script compiles and calls
through ctypes).

    python benchmarks/plugin.py            # about a minute
    python benchmarks/plugin.py --ticks 2000 --repeat 3
    python benchmarks/plugin.py --callgrind # and the instruction counts (some minutes more)
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from biso_cosim.plugin import ImuPlugin
from biso_cosim.plugin.pybullet_racecar import FRAMES, RacecarBridge
from biso_cosim.sensors import MPU9250, EarthField, MagneticEnvironment


def best_window(run, repeat: int) -> float:
    """The best mean cost per tick, s, of the windows ``run()`` times over ``repeat`` rounds
    (after one warm-up): ``run`` returns a list of (seconds, ticks) per window."""
    run()
    best = float("inf")
    for _ in range(repeat):
        gc.collect()
        best = min(best, min(seconds / ticks for seconds, ticks in run()))
    return best


def timed_windows(calls, window: int) -> list[tuple[float, int]]:
    """Run ``calls`` ((callable, ticks) in order), timing each run of them that covers
    ``window`` ticks: the (seconds, ticks) of every window."""
    out, clock = [], time.perf_counter
    start, ticks = clock(), 0
    for call, n in calls:
        call()
        ticks += n
        if ticks >= window:
            now = clock()
            out.append((now - start, ticks))
            start, ticks = clock(), 0
    return out


def plugin_for_bench(reuse_outputs: bool) -> ImuPlugin:
    """The plug-in measured: the MPU-9250 and one biso_plus fed the speed, pybullet's frames."""
    return ImuPlugin(tick_s=0.001, frames=FRAMES, gravity_w=(0.0, 0.0, -9.80665), seed=0, estimators=["biso_plus"],
                     speed_from_velocity=True, reuse_outputs=reuse_outputs)


def drive_ticks(bridge: RacecarBridge, n: int) -> list:
    """n host ticks of the measured drive after the car settled: a steady circle."""
    for _ in range(500):  # the car settles on its wheels
        bridge.step_host()
    bridge.command(1.5, 0.3)
    return [bridge.step_host() for _ in range(n)]


def feed(step, rows, first: int = 0) -> None:
    """The plug-in's ``step`` on recorded host ticks ``first``, ``first`` + 1 ..., one call per tick."""
    for i, r in enumerate(rows, first):
        step(i * 0.001, r.q_wb, r.omega_b, accel_w=r.accel_w, p_w=r.p_w, v_w=r.v_w)


_CALLGRIND_HELPER = """#include <valgrind/callgrind.h>
void count_start(void) { CALLGRIND_START_INSTRUMENTATION; CALLGRIND_ZERO_STATS; }
void count_stop(void) { CALLGRIND_DUMP_STATS; CALLGRIND_STOP_INSTRUMENTATION; }
"""


def count_one(what: str, n: int, helper: str) -> None:
    """(Under callgrind) the loop ``what`` ("host", "tick", "tick_reused") over n ticks,
    instrumented alone (``helper``: the compiled ``_CALLGRIND_HELPER``). The plug-in's
    loop is ticks 1..n of a plug-in whose first tick made its plan (once per plug-in,
    reset and restored state)."""
    counter = ctypes.CDLL(helper)
    with RacecarBridge(seed=0, speed_from_velocity=True) as bridge:
        rows = drive_ticks(bridge, n + 1)
        if what == "host":
            loop = lambda: [bridge.step_host() for _ in range(n)]  # noqa: E731
        else:
            feed(plugin_for_bench(what == "tick_reused").step, rows)  # compiled, every kind of output made once
            step = plugin_for_bench(what == "tick_reused").step
            feed(step, rows[:1])
            loop = lambda: feed(step, rows[1:], 1)  # noqa: E731
        counter.count_start()
        loop()
        counter.count_stop()


def instructions_per_tick(what: str, n: int, tmp: Path) -> float:
    """Instructions per tick of ``count_one(what, n)`` under callgrind."""
    helper = tmp / "count.so"
    if not helper.exists():
        (tmp / "count.c").write_text(_CALLGRIND_HELPER)
        subprocess.run(["cc", "-O1", "-shared", "-fPIC", "-o", str(helper), str(tmp / "count.c")], check=True)
    out = tmp / f"callgrind.{what}"
    run = subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}",
                          sys.executable, __file__, "--count", what, "--ticks", str(n), "--helper", str(helper)],
                         capture_output=True, text=True)
    if run.returncode:
        raise RuntimeError(run.stderr[-2000:])
    dump = Path(f"{out}.1").read_text()  # (the dump of count_stop)
    return int(re.search(r"^summary: (\d+)", dump, re.M).group(1)) / n


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ticks", type=int, default=4000, help="truth ticks of the recorded drive (1 ms each)")
    parser.add_argument("--repeat", type=int, default=5, help="rounds per measurement (the best is kept)")
    parser.add_argument("--block", type=int, default=20, help="ticks per call in the block measurement")
    parser.add_argument("--window", type=int, default=500, help="ticks per timed window (the best window counts)")
    parser.add_argument("--callgrind", action="store_true", help="also count instructions per tick (valgrind)")
    parser.add_argument("--count", choices=("host", "tick", "tick_reused"), help=argparse.SUPPRESS)
    parser.add_argument("--helper", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    n = args.ticks
    if args.count:  # (a process of instructions_per_tick)
        count_one(args.count, n, args.helper)
        return 0
    load_before = os.getloadavg()[0]

    window = args.window
    with RacecarBridge(seed=0, speed_from_velocity=True) as bridge:
        ticks = drive_ticks(bridge, 0)

        def host_step():
            ticks.append(bridge.step_host())

        host_s = best_window(lambda: timed_windows([(host_step, 1)] * n, window), args.repeat)
    rows = ticks[-n:]
    cols = {name: np.array([getattr(r, name) for r in rows]) for name in ("t_s", "q_wb", "omega_b", "accel_w", "p_w", "v_w")}
    cols["t_s"] = np.arange(n) * 0.001
    plugin, reused = plugin_for_bench(False), plugin_for_bench(True)
    step = plugin.step

    def tick_by_tick(plugin=plugin):
        plugin.reset()
        step = plugin.step
        calls = [(lambda i=i, r=r: step(i * 0.001, r.q_wb, r.omega_b, accel_w=r.accel_w, p_w=r.p_w, v_w=r.v_w), 1)
                 for i, r in enumerate(rows)]
        return timed_windows(calls, window)

    blocks = [{k: v[s:s + args.block] for k, v in cols.items()} for s in range(0, n, args.block)]

    def in_blocks():
        plugin.reset()
        calls = [(lambda b=b: step(b["t_s"], b["q_wb"], b["omega_b"], accel_w=b["accel_w"], p_w=b["p_w"],
                                   v_w=b["v_w"]), len(b["t_s"])) for b in blocks]
        return timed_windows(calls, window)

    tick_s = best_window(tick_by_tick, args.repeat)
    reused_s = best_window(lambda: tick_by_tick(reused), args.repeat)
    block_s = best_window(in_blocks, args.repeat)

    imu = MPU9250("mpu9250_calibrated", seed=0)
    w1, f1 = np.zeros((1, 3)), np.array([[0.0, 0.0, 9.80665]])
    m1 = MagneticEnvironment(EarthField()).field_b(np.array([[1.0, 0.0, 0.0, 0.0]]), np.zeros((1, 3)))

    def sensor_rows():
        imu.reset()
        return timed_windows([(lambda: imu.simulate(w1, f1, m1), 1)] * n, window)

    sensor_s = best_window(sensor_rows, args.repeat)

    print(f"plug-in (MPU-9250 + biso_plus) per 1 ms truth tick against pybullet's racecar step; "
          f"{n} ticks, the best {args.window}-tick window of {args.repeat} rounds; load average {load_before:.1f} before, "
          f"{os.getloadavg()[0]:.1f} after ({os.cpu_count()} cores)")
    print(f"{'':44} {'µs/tick':>9} {'× host step':>12}")
    print(f"{'host: pybullet stepSimulation + state reads':44} {host_s * 1e6:9.1f} {1.0:12.3f}")
    for label, cost in (("plug-in, one call per tick", tick_s),
                        ("plug-in, one call per tick, reuse_outputs", reused_s),
                        (f"plug-in, one call per {args.block} ticks", block_s),
                        ("(MPU9250.simulate alone, one row per call)", sensor_s)):
        print(f"{label:44} {cost * 1e6:9.1f} {cost / host_s:12.3f}")
    print()
    for label, cost in (("one call per tick", tick_s), ("one call per tick, reuse_outputs", reused_s),
                        (f"one call per {args.block} ticks", block_s)):
        share, micro = cost / host_s, cost * 1e6
        verdict = "met" if share <= 0.10 and micro <= 20.0 else "NOT met"
        print(f"goal (≤ 10 % of the host step and ≤ 20 µs per tick), {label}: {verdict} "
              f"({100 * share:.1f} %, {micro:.1f} µs)")
    if args.callgrind:
        if shutil.which("valgrind") is None or shutil.which("cc") is None:
            raise SystemExit("--callgrind needs valgrind (with its headers) and a C compiler (cc)")
        with tempfile.TemporaryDirectory() as tmp:
            counts = {what: instructions_per_tick(what, 1000, Path(tmp)) for what in ("host", "tick", "tick_reused")}
        print(f"callgrind, instructions per tick (1000 ticks): host step {counts['host']:.0f}")
        for what, label in (("tick", "one call per tick"), ("tick_reused", "one call per tick, reuse_outputs")):
            print(f"  plug-in, {label}: {counts[what]:.0f} ({100 * counts[what] / counts['host']:.1f} % of the host's)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
