"""One run of a campaign, as a worker does it: the co-simulation and its summary rows.

``execute_run`` is the task the engine sends to Dask: it takes a :class:`RunSpec` (small:
names, parameter values, a route or profile file's text) and returns one row per estimator
with every figure of :meth:`biso_cosim.cosim.RunResult.summary`, the run's parameters, its
status, and what the task cost (wall and CPU time, numba compilations inside the task). A run that
raises is returned as rows with ``status = "failed"`` and the error, never as an exception,
so that the campaign goes on. ``WarmUp`` is the worker plugin that readies a worker before
its first task. This module is all a worker imports of the campaign package.
"""

from __future__ import annotations

import asyncio
import dataclasses
import gc
import json
import math
import os
import socket
import time
import traceback
from typing import Any, Mapping

from distributed.diagnostics.plugin import WorkerPlugin

from biso_cosim.campaign.spec import RunSpec

__all__ = ["execute_run", "run_rows", "failed_rows", "WarmUp", "warm_up_report", "RUN_COLUMNS", "STATUS_FAILED"]

STATUS_FAILED = "failed"
"""Status of a run that raised (its rows carry the error)."""

RUN_COLUMNS = ("run_id", "route", "sensor", "profile", "registers", "gyro_calibration_s", "seed", "duration_s",
               "estimator", "method", "params", "status", "error")
"""The columns that every row has, failed or not: the run's parameters and its outcome."""

_WARM_UP_S = 1.0  # simulated seconds of a worker's warm-up run
_ANGLES = ("roll", "pitch", "heading")
# summary fields that may be None; flattened to the same columns as when present (NaN), so
# that every run's rows share one schema
_OPTIONAL_GROUPS = {"truth_start_end_deg": _ANGLES, "start_end_deg": _ANGLES, "start_end_error_deg": _ANGLES,
                    "gnss": ("fixes", "valid")}
# summary fields the row holds as run parameters already (from the spec, as named there)
_RUN_LEVEL_SKIP = {"estimators", "navigators", "seed", "duration_s", "status"}
_SENSOR_SKIP = {"profile", "registers", "gyro_calibration_s"}
_ESTIMATOR_SKIP = {"method", "params"}
# summary groups whose figures are columns of their own names: ``roll_rms_deg``, not ``errors_roll_rms_deg``
_INLINE = {"errors"}


def _json(value: Any) -> str:
    return json.dumps(value, sort_keys=True, default=str)


def _flatten(entry: Mapping[str, Any], prefix: str, out: dict[str, Any], skip: set[str] = frozenset()) -> None:
    """Nested summary figures as flat columns ``a_b_c``; lists as JSON text."""
    for key, value in entry.items():
        if key in skip:
            continue
        name = f"{prefix}{key}"
        if value is None and key in _OPTIONAL_GROUPS:
            out.update({f"{name}_{sub}": math.nan for sub in _OPTIONAL_GROUPS[key]})
        elif isinstance(value, Mapping):
            skip_inner = _SENSOR_SKIP if key == "sensor" and not prefix else frozenset()
            _flatten(value, prefix if key in _INLINE else f"{name}_", out, skip_inner)
        elif isinstance(value, (list, tuple)):
            out[name] = _json(value)
        else:
            out[name] = value


def _base_row(run: RunSpec, estimator) -> dict[str, Any]:
    return {"run_id": run.run_id, "route": run.route.route, "sensor": run.sensor.label, "profile": run.sensor.profile,
            "registers": _json(dict(run.sensor.registers)), "gyro_calibration_s": run.sensor.gyro_calibration_s,
            "seed": run.seed, "duration_s": run.route.duration_s, "estimator": estimator.label,
            "method": estimator.name, "params": _json(dict(estimator.params))}


def run_rows(run: RunSpec, summary: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The rows of a finished run: one per estimator, from ``RunResult.summary()``."""
    common: dict[str, Any] = {}
    _flatten(summary, "", common, _RUN_LEVEL_SKIP)
    common["simulated_s"] = summary["duration_s"]
    # a summary that states its own status (completed, off route, ...) is taken at its word
    status = summary.get("status") or ("completed" if summary["completed_route"] else "incomplete")
    rows = []
    for est in run.estimators:
        row = _base_row(run, est) | {"status": status, "error": None} | common
        entry = dict(summary["estimators"][est.label])
        for group in ("start_end_deg", "start_end_error_deg"):
            entry.setdefault(group, None)
        _flatten(entry, "", row, _ESTIMATOR_SKIP)
        rows.append(row)
    return rows


def failed_rows(run: RunSpec, error: str) -> list[dict[str, Any]]:
    """The rows of a run that did not produce a result: one per estimator, with the error."""
    return [_base_row(run, est) | {"status": STATUS_FAILED, "error": error} for est in run.estimators]


def execute_run(run: RunSpec) -> list[dict[str, Any]]:
    """Run one co-simulation (a :class:`biso_cosim.cosim.CoSimulation`, as
    :func:`~biso_cosim.cosim.run_route` makes it) and return its rows."""
    from numba.core import event

    start, cpu_start = time.perf_counter(), time.thread_time()
    with event.install_recorder("numba:compile") as compiled:
        try:
            from biso_cosim.cosim import CoSimulation

            sim = CoSimulation(run.route.load(), duration_s=run.route.duration_s, seed=run.seed,
                               estimators=[e.cosim_spec() for e in run.estimators],
                               sensor_profile=run.sensor.load_profile(), registers=dict(run.sensor.registers),
                               gyro_calibration_s=run.sensor.gyro_calibration_s)
            result = sim.run()  # as run_route does
            from biso_cosim.runstatus import judge_run

            summary = result.summary()
            summary.update(judge_run(result).as_dict())  # completed, partial, rolled_over, left_route, ...
            rows = run_rows(run, summary)
            if run.log_dir is not None:
                _write_log(sim, result, summary, run.log_dir)
        except Exception as exc:  # noqa: BLE001  (a failed run is a result of the campaign)
            last = traceback.extract_tb(exc.__traceback__)[-1]
            rows = failed_rows(run, f"{type(exc).__name__}: {exc} ({os.path.basename(last.filename)}:{last.lineno})")
    task = {"worker": f"{socket.gethostname()}:{os.getpid()}", "task_wall_s": time.perf_counter() - start,
            "task_cpu_s": time.thread_time() - cpu_start,
            "numba_compilations": sum(1 for _, ev in compiled.buffer if ev.is_start),
            "finished_at": time.time()}
    return [row | task for row in rows]


def _write_log(sim, result, summary: Mapping[str, Any], log_dir: str) -> None:
    """The run's log.csv and summary.json as ``biso-cosim run`` writes them (the same writer,
    with what the run fed its estimators), so that ``biso-cosim estimate`` repeats the run."""
    from pathlib import Path

    from biso_cosim.logs import run_log_inputs, write_run_log
    from biso_cosim.output import write_text_atomic

    out = Path(log_dir)
    out.mkdir(parents=True, exist_ok=True)
    fed = run_log_inputs(sim, result)
    write_run_log(result, out / "log.csv", fed)  # each file whole or absent, the log before the summary
    summary = dict(summary) | {"estimator_inputs": fed.estimators}
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2, default=str) + "\n")


def _warm_up(runs: tuple[RunSpec, ...]) -> int:
    """Run the first second of each run, then freeze what is alive; the numba compilations
    it took.

    What the warm-up leaves alive (modules, kernels, numba's types) lives as long as the
    worker: ``gc.freeze`` takes it out of the garbage collector's view, so that no full
    collection during a task scans it again, nor the interpreter's at exit (several seconds
    in a process that has loaded the co-simulation, past the four a Dask nanny waits
    before it kills a closing worker)."""
    total = 0
    for run in runs:
        short = dataclasses.replace(run, route=dataclasses.replace(run.route, duration_s=min(_WARM_UP_S,
                                                                                             run.route.duration_s)),
                                    log_dir=None)
        total += execute_run(short)[0]["numba_compilations"]
    gc.collect()
    gc.freeze()
    return total


class WarmUp(WorkerPlugin):
    """A worker's warm-up before its first task, and on every worker that joins later: the
    first second of each run given (one per sensor set-up), so that the numba kernels are
    loaded from the cache (or compiled once per machine when it is cold) and no task
    compiles, then ``gc.freeze`` (see ``_warm_up``). It runs in a thread, so the worker keeps
    answering the scheduler while a cold cache compiles."""

    idempotent = False

    def __init__(self, runs: tuple[RunSpec, ...]):
        self.runs = runs
        self.compilations: int | None = None
        self.seconds: float | None = None
        self.cpu_seconds: float | None = None

    async def setup(self, worker) -> None:
        start = time.perf_counter()
        self.compilations, self.cpu_seconds = await asyncio.get_running_loop().run_in_executor(None, self._run)
        self.seconds = time.perf_counter() - start

    def _run(self) -> tuple[int, float]:
        cpu = time.thread_time()
        compilations = _warm_up(self.runs)
        return compilations, time.thread_time() - cpu


def warm_up_report(name: str, dask_worker=None) -> dict[str, Any]:
    """A worker's warm-up (``client.run(warm_up_report, name)``)."""
    plugin = dask_worker.plugins.get(name)
    return {"compilations": getattr(plugin, "compilations", None), "seconds": getattr(plugin, "seconds", None),
            "cpu_seconds": getattr(plugin, "cpu_seconds", None)}
