"""Throughput of a campaign on Dask against calling run_route in a plain loop.

The same runs (one route, sensor parts 0 … N−1, the default estimators) three ways, in one
process, each after its own warm-up so that no compilation or first load is timed:

* ``plain``: ``run_route`` in a loop here (what a user writes without the campaign), and the
  same loop after ``gc.freeze()`` as the campaign's workers do after their warm-up (so the
  difference between the two is the garbage collector's, not the campaign's);
* ``1 worker`` / ``2 workers``: ``run_campaign`` on a LocalCluster of that many worker
  processes, rows stored as Parquet as runs finish. Timed from the campaign's start to its
  table; the warm-up each campaign does first (numba cache loads, one second of each sensor
  set-up) is printed apart, as a one-off cost, like the cluster's start.

Prints runs per second of each, wall and CPU seconds per run (CPU summed over every process
of a campaign: this one with the scheduler, the nannies, the workers), 2 workers / 1 worker
(goal ≥ 1.8 on 2 cores), the campaign's overhead per run against the plain loop (goal ≤ 5 %
of a 60 s route run) split into what the tasks cost beyond a plain run and what the
machinery costs per campaign, the numba compilations inside tasks (0: workers load the
cache), what a task carries and returns, and on paper the time and cost of 10^5 such runs
on 100 machines of this kind. On a machine shared with other jobs the wall-time figures
drift between configurations; the CPU figures much less.

    python benchmarks/campaign.py                        # figure8, 60 s, 8 runs per configuration
    python benchmarks/campaign.py --route loop600 --duration 600 --runs 4
"""

from __future__ import annotations

import argparse
import gc
import os
import pickle
import statistics
import tempfile
import time

import psutil

from biso_cosim.campaign import dask_client, parse_spec, run_campaign
from biso_cosim.campaign.run import execute_run
from biso_cosim.cosim import DEFAULT_ESTIMATORS, run_route


def plain_loop(route: str, duration_s: float, seeds: range) -> tuple[float, float]:
    """(wall s, CPU s) of run_route over the seeds, one after the other."""
    start, cpu = time.perf_counter(), time.process_time()
    for seed in seeds:
        run_route(route, duration_s=duration_s, seed=seed, estimators=list(DEFAULT_ESTIMATORS)).summary()
    return time.perf_counter() - start, time.process_time() - cpu


def _cpu_s(processes: list[psutil.Process]) -> float:
    total = 0.0
    for p in processes:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except psutil.NoSuchProcess:
            pass
    return total


def campaign(spec, workers: int) -> dict[str, float]:
    """A campaign on a new LocalCluster of ``workers`` processes: the cluster's start, the
    campaign's wall time, the largest warm-up (wall) and all warm-ups' CPU, the CPU of
    every process of the campaign (this one with the scheduler, the nannies, the workers),
    the numba compilations in tasks, and the load average while it ran."""
    start = time.perf_counter()
    with dask_client(workers=workers) as client:
        started = time.perf_counter() - start
        me = psutil.Process()
        processes = [me, *me.children(recursive=True)]
        with tempfile.TemporaryDirectory() as out:
            cpu, t = _cpu_s(processes), time.perf_counter()
            table = run_campaign(spec, client, out=out)
            wall, cpu = time.perf_counter() - t, _cpu_s(processes) - cpu
    assert (table["status"] != "failed").all(), table["error"].dropna().iloc[0]
    warm = table.attrs["warm_up"].values()
    return {"start": started, "wall": wall, "warm": max(w["seconds"] for w in warm),
            "warm_cpu": sum(w["cpu_seconds"] for w in warm), "cpu": cpu,
            "compiled": int(table.drop_duplicates("run_id")["numba_compilations"].sum()),
            "task_cpu": float(table.drop_duplicates("run_id")["task_cpu_s"].sum()),
            "load": os.getloadavg()[0]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--route", default="figure8")
    parser.add_argument("--duration", type=float, default=60.0, help="simulated seconds per run (default 60)")
    parser.add_argument("--runs", type=int, default=8, help="runs per configuration (default 8)")
    parser.add_argument("--repeats", type=int, default=1,
                        help="passes over the four configurations; medians are printed (default 1)")
    parser.add_argument("--price", type=float, default=0.10,
                        help="assumed price of one 2-core machine-hour, for the estimate on paper (default 0.10)")
    args = parser.parse_args()
    seeds = range(args.runs)
    spec = parse_spec({"name": "benchmark", "routes": [args.route], "duration_s": args.duration, "parts": args.runs,
                       "estimators": [{"name": name} for name in DEFAULT_ESTIMATORS]})
    run = spec.runs()[0]
    rows = execute_run(run)  # this process's warm-up (and the payload of one task)
    print(f"route {args.route}, {args.duration:g} s simulated per run, estimators {', '.join(DEFAULT_ESTIMATORS)}; "
          f"{args.runs} runs per configuration (seeds 0…{args.runs - 1})")
    print(f"a task carries {len(pickle.dumps(run))} bytes (its RunSpec) and returns {len(pickle.dumps(rows))} "
          f"bytes ({len(rows)} rows of {len(rows[0])} columns)")

    n = args.runs
    passes = []
    for _ in range(args.repeats):  # each pass: the four configurations, minutes apart at most
        plain = plain_loop(args.route, args.duration, seeds) + (os.getloadavg()[0],)
        gc.collect()
        gc.freeze()
        frozen = plain_loop(args.route, args.duration, seeds) + (os.getloadavg()[0],)
        gc.unfreeze()
        passes.append({"plain": plain, "frozen": frozen, "1": campaign(spec, 1), "2": campaign(spec, 2)})

    def med(key, field):
        return statistics.median(p[key][field] for p in passes)

    plain_s, plain_cpu = med("plain", 0), med("plain", 1)
    frozen_s, frozen_cpu = med("frozen", 0), med("frozen", 1)
    c1 = {f: med("1", f) for f in passes[0]["1"]}
    c2 = {f: med("2", f) for f in passes[0]["2"]}
    rate = {"1": n / (c1["wall"] - c1["warm"]), "2": n / (c2["wall"] - c2["warm"])}
    print(f"{args.repeats} pass(es), medians over them; load average (1 min) "
          f"{min(p['plain'][2] for p in passes):.1f}…{max(p['2']['load'] for p in passes):.1f} on "
          f"{os.cpu_count()} cores: other jobs took their share of the cores")
    print(f"{'':34}{'runs/s':>8}{'wall s/run':>12}{'CPU s/run':>11}")
    print(f"{'plain loop of run_route':34}{n / plain_s:8.3f}{plain_s / n:12.2f}{plain_cpu / n:11.2f}")
    print(f"{'  the same after gc.freeze()':34}{n / frozen_s:8.3f}{frozen_s / n:12.2f}{frozen_cpu / n:11.2f}")
    for label, c in (("campaign, 1 worker", c1), ("campaign, 2 workers", c2)):
        cpu = (c["cpu"] - c["warm_cpu"]) / n
        print(f"{label:34}{rate[label[10]]:8.3f}{(c['wall'] - c['warm']) / n:12.2f}{cpu:11.2f}"
              f"   one-off: cluster start {c['start']:.1f} s, warm-up {c['warm']:.1f} s")
    print(f"2 workers / 1 worker: {rate['2'] / rate['1']:.2f}x (goal >= 1.8x on 2 cores)")
    print("campaign (1 worker) overhead per run against the plain loop (goal <= 5 %):")
    machinery = c1["cpu"] - c1["warm_cpu"] - c1["task_cpu"]
    print(f"  inside the tasks: CPU {100 * (c1['task_cpu'] / plain_cpu - 1):+.1f} % (each task's thread against a "
          f"plain run)")
    print(f"  the machinery (client and scheduler, nanny, worker outside its tasks; warm-up apart): {machinery:.2f} s "
          f"CPU for the campaign, {100 * machinery / plain_cpu:+.1f} % of a run per run at {n} runs")
    for name, base_s, base_cpu in (("plain loop", plain_s, plain_cpu),
                                   ("plain loop after gc.freeze()", frozen_s, frozen_cpu)):
        wall = ((c1["wall"] - c1["warm"]) - base_s) / base_s
        cpu = (c1["cpu"] - c1["warm_cpu"] - base_cpu) / base_cpu
        print(f"  all together, against the {name}: CPU {100 * cpu:+.1f} %, wall {100 * wall:+.1f} %")
    compiled = sum(p[k]["compiled"] for p in passes for k in ("1", "2"))
    print(f"numba compilations inside the campaigns' {2 * n * args.repeats} tasks: {compiled}")
    # on paper: 10^5 runs on 100 machines like this one, two workers each
    runs, machines = 100_000, 100
    hours = runs / (machines * rate["2"]) / 3600.0 + (c2["start"] + c2["warm"]) / 3600.0
    print(f"on paper: {runs:.0e} such runs on {machines} machines of 2 cores at {rate['2']:.3f} runs/s each: "
          f"{hours:.2f} h of wall time, {machines * hours:.0f} machine-hours "
          f"(${machines * hours * args.price:,.0f} at an assumed ${args.price:.2f} per machine-hour)")


if __name__ == "__main__":
    main()
