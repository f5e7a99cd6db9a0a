"""Monte Carlo campaigns: routes × sensor parts × estimators, as Dask tasks.

A campaign (:mod:`~biso_cosim.campaign.spec`, a TOML file) crosses routes, MPU-9250 set-ups
and sensor parts (seeds); every run is one co-simulation with all the campaign's
estimators in the loop on the same samples (:mod:`~biso_cosim.campaign.run`). The runs are
Dask tasks on a LocalCluster or any Dask cluster (:mod:`~biso_cosim.campaign.engine`); their
rows are stored as a Parquet dataset as they finish (:mod:`~biso_cosim.campaign.store`); the
statistics (:mod:`~biso_cosim.campaign.statistics`) and the report
(:mod:`~biso_cosim.campaign.report`) are drawn from those rows.

>>> table = run_campaign("examples/campaign.toml", out="out/campaign")   # pandas, one row per (run, estimator)
>>> table = load_campaign("out/campaign")
>>> error_statistics(table)                                               # per estimator and route

Needs the optional extra ``campaign`` (``pip install biso_cosim[campaign]``: Dask
distributed, pyarrow, pandas).
"""

from __future__ import annotations

import importlib

# Imported on first use: a worker imports only what its tasks need (``run``, ``spec``), not
# pandas and pyarrow, which the engine, the store and the statistics use on the client.
_LAZY = {
    "run_campaign": "engine", "load_campaign": "engine", "dask_client": "engine", "EngineError": "engine",
    "CampaignInterrupted": "engine", "CampaignSpec": "spec", "RunSpec": "spec", "SpecError": "spec",
    "load_spec": "spec", "parse_spec": "spec", "error_statistics": "statistics",
    "paired_comparisons": "statistics", "StoreError": "store",
}

__all__ = list(_LAZY)


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'biso_cosim.campaign' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"biso_cosim.campaign.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
