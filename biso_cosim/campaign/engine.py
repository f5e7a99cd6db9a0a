"""The campaign engine: a campaign's runs as Dask tasks, their rows stored as they finish.

The engine is Dask distributed: a :class:`distributed.LocalCluster` of one single-threaded
worker process per core by default, or any cluster by its scheduler's address (SLURM and
PBS through dask-jobqueue, Kubernetes, cloud: see docs/campaigns.md). Each task carries one
:class:`~biso_cosim.campaign.spec.RunSpec` and returns that run's rows; Dask runs a task
again elsewhere when its worker is lost. Before the first task every worker runs each
sensor set-up's first second once (:class:`WarmUp`, a worker plugin, so workers that join
later do it too): the numba kernels are then loaded from the cache (or compiled once per
machine when the cache is cold), and no task compiles (each row counts the compilations in
its task).
"""

from __future__ import annotations

import logging
import math
import os
import signal
import threading
import time
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

import pandas as pd

from biso_cosim.campaign.run import STATUS_FAILED, WarmUp, execute_run, failed_rows, warm_up_report
from biso_cosim.campaign.spec import CampaignSpec, RunSpec, SpecError, load_spec, parse_spec
from biso_cosim.campaign.store import ResultStore

__all__ = ["run_campaign", "load_campaign", "dask_client", "EngineError", "CampaignInterrupted", "LOCAL_CLUSTER_CONFIG"]

LOCAL_CLUSTER_CONFIG = {
    # no dashboard, so no use for the statistical profiler sampling each task's thread every 10 ms
    "distributed.worker.profile.enabled": False,
    # housekeeping at the pace of tasks that last seconds: each event loop's responsiveness
    # tick (20 ms), the system monitor (0.5 s), the nanny's memory check (0.1 s) and work
    # stealing (0.1 s) cost an idle one-worker cluster 0.09 CPU-seconds a second, 0.01 so
    "distributed.admin.tick.interval": "500ms",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.scheduler.work-stealing-interval": "1s",
}
"""Dask settings of the LocalCluster a campaign starts (an existing cluster keeps its own;
docs/campaigns.md shows them as a Dask config file)."""
# finished runs between two merges of their Parquet files (ResultStore.compact)
_COMPACT_EVERY = 500


class EngineError(ValueError):
    """A cluster the campaign cannot use (one line, naming the address or the setting)."""


class CampaignInterrupted(KeyboardInterrupt):
    """Ctrl-C during a campaign: the finished runs are stored, the runs in flight are lost."""

    def __init__(self, done: int, total: int, directory: str | None):
        super().__init__(f"interrupted: {done} of {total} runs stored"
                         + (f" in {directory}; --resume completes the campaign" if directory else ""))
        self.done, self.total, self.directory = done, total, directory


def _package_version() -> str:
    import biso_cosim

    return biso_cosim.__version__


@contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored in this process meanwhile (so in the processes it starts), where it can be set."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None, timeout_s: float = 10.0) -> Iterator[Any]:
    """A Dask client: to a new LocalCluster of ``workers`` single-threaded worker processes
    (default: one per core), or to the scheduler at ``scheduler``; closed on exit."""
    import dask
    from distributed import Client, LocalCluster

    if workers is not None and scheduler is not None:
        raise EngineError("give --workers or --scheduler, not both")
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout=f"{timeout_s}s")
        except Exception as exc:  # noqa: BLE001  (timeouts, refused connections, malformed addresses)
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise EngineError(f"--scheduler {scheduler!r}: no Dask scheduler answered within {timeout_s:g} s "
                              f"({reason})") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = (os.cpu_count() or 1) if workers is None else workers
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise EngineError(f"--workers must be a positive integer, got {workers!r}")
    # The scheduler and its workers take the config as it stands when they start, and the
    # worker processes the disposition of SIGINT: Ctrl-C in a terminal reaches the whole
    # process group, and it is this process that stops the campaign and closes the workers.
    with dask.config.set(LOCAL_CLUSTER_CONFIG), _sigint_ignored():
        # (its workers' warnings when closed with tasks in flight, after Ctrl-C, say nothing the
        # campaign does not: errors only)
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    with cluster, Client(cluster) as client:
        yield client


def _coerce_spec(spec: CampaignSpec | str | Path | Mapping) -> CampaignSpec:
    if isinstance(spec, CampaignSpec):
        return spec
    if isinstance(spec, (str, Path)):
        return load_spec(spec)
    if isinstance(spec, Mapping):
        return parse_spec(spec)
    raise SpecError(f"spec: expected a CampaignSpec, a TOML file or a table of settings, got {type(spec).__name__}")


def _check_workers(client) -> None:
    ours = _package_version()
    for address, version in client.run(_package_version).items():
        if version != ours:
            raise EngineError(f"worker {address} runs biso_cosim {version}, this client {ours}: install the same "
                              f"version on every worker")


def _ordered(frame: pd.DataFrame, canonical: Mapping) -> pd.DataFrame:
    """Rows in the campaign's order: routes, sensor set-ups and estimators as the spec lists
    them, seeds ascending."""
    if frame.empty:
        return frame
    ranks = {"route": [r["route"] for r in canonical["routes"]], "sensor": [s["label"] for s in canonical["sensors"]],
             "estimator": [e["label"] for e in canonical["estimators"]]}
    keys = pd.DataFrame({col: frame[col].map({v: i for i, v in enumerate(values)}) for col, values in ranks.items()})
    keys["seed"] = frame["seed"]
    order = keys.sort_values(["route", "sensor", "seed", "estimator"], kind="stable").index
    return frame.loc[order].reset_index(drop=True)


def run_campaign(spec: CampaignSpec | str | Path | Mapping, client: Any = None, *, out: str | Path | None = None,
                 resume: bool = False, workers: int | None = None, progress: bool = False,
                 on_run: Callable[[list[dict]], None] | None = None) -> pd.DataFrame:
    """Run a campaign; the results table, one row per (run, estimator), in the spec's order.

    spec : a :class:`CampaignSpec`, a campaign TOML file, or its parsed table.
    client : a :class:`distributed.Client`; None starts a LocalCluster of ``workers``
        processes (default one per core) for this campaign.
    out : the campaign directory (results as a Parquet dataset, written as runs finish;
        see :mod:`biso_cosim.campaign.store`); None keeps the rows in memory only.
    resume : skip the runs already in ``out`` (the spec must be the same).
    progress : a progress bar with the time left (tqdm, on stderr).
    on_run : called with each finished run's rows once they are stored.

    Ctrl-C (KeyboardInterrupt) cancels the runs in flight and raises
    :class:`CampaignInterrupted` once the finished ones are stored.
    """
    spec = _coerce_spec(spec)
    if spec.keep == "logs" and out is None:
        raise SpecError(f"{spec.source}: keep: 'logs' needs an output directory (out)")
    store = None
    done: set[str] = set()
    if out is not None:
        store = ResultStore(out)
        store.open(spec.canonical(), resume)
        if resume:
            done = store.finished_run_ids()
    runs = spec.runs(log_root=None if store is None else store.logs.resolve())
    todo = [run for run in runs if run.run_id not in done]
    rows: list[dict] = []
    warm_up: dict = {}
    start = time.perf_counter()
    if todo:
        if client is None:
            with dask_client(workers=workers) as own:
                rows, warm_up = _execute(own, spec, todo, len(runs), store, progress, on_run)
        else:
            rows, warm_up = _execute(client, spec, todo, len(runs), store, progress, on_run)
    if store is None:
        frame = pd.DataFrame(rows)
    else:
        store.compact()
        frame = store.table().to_pandas()
        ids = {run.run_id for run in runs}
        frame = frame[frame["run_id"].isin(ids)] if not frame.empty else frame
    frame = _ordered(frame, spec.canonical())
    frame.attrs.update(runs=len(runs), ran=len(todo), skipped=len(runs) - len(todo), warm_up=warm_up,
                       wall_s=time.perf_counter() - start)
    return frame


def _execute(client, spec: CampaignSpec, todo: list[RunSpec], total: int, store: ResultStore | None,
             progress: bool, on_run) -> tuple[list[dict], dict]:
    """Every run of ``todo`` as a task; the rows, and each worker's warm-up (numba
    compilations, wall and CPU seconds)."""
    from distributed import as_completed

    _check_workers(client)
    name = f"biso-campaign-warm-up-{uuid.uuid4().hex[:8]}"
    seen, warm = set(), []
    for run in todo:  # one warm-up run per sensor set-up, on the first route
        if run.sensor not in seen:
            seen.add(run.sensor)
            warm.append(run)
    bar = None
    futures: dict = {}
    rows: list[dict] = []
    finished = failed = 0
    try:
        client.register_plugin(WarmUp(tuple(warm)), name=name)
        warm_up = client.run(warm_up_report, name)
        if progress:
            from tqdm import tqdm

            bar = tqdm(total=total, initial=total - len(todo), unit="run", desc=spec.name, dynamic_ncols=True)
        futures = {client.submit(execute_run, run, key=f"biso-run-{run.run_id}-{uuid.uuid4().hex[:6]}",
                                 pure=False): run for run in todo}
        for future in as_completed(futures):
            run = futures.pop(future)
            try:
                run_rows = future.result()
            except Exception as exc:  # noqa: BLE001  (a lost worker, every time: KilledWorker)
                lost = {"finished_at": time.time(), "task_wall_s": math.nan, "task_cpu_s": math.nan, "worker": None,
                        "numba_compilations": None}
                run_rows = [row | lost
                            for row in failed_rows(run, f"{type(exc).__name__}: {exc}")]
            if store is not None:
                store.append(run_rows)
            rows.extend(run_rows)
            finished += 1
            if store is not None and finished % _COMPACT_EVERY == 0:
                store.compact()
            failed += run_rows[0]["status"] == STATUS_FAILED
            if bar is not None:
                bar.update(1)
                if failed:
                    bar.set_postfix(failed=failed)
            if on_run is not None:
                on_run(run_rows)
    except KeyboardInterrupt:
        client.cancel(list(futures))
        raise CampaignInterrupted(total - len(todo) + finished, total,
                                  None if store is None else str(store.directory)) from None
    finally:
        if bar is not None:
            bar.close()
        try:
            client.unregister_worker_plugin(name)
        except Exception:  # noqa: BLE001  (workers already gone: nothing to remove)
            pass
    return rows, warm_up


def load_campaign(directory: str | Path) -> pd.DataFrame:
    """The results table of a campaign directory (all the rows stored so far)."""
    store = ResultStore(directory)
    return _ordered(store.table().to_pandas(), store.spec())
