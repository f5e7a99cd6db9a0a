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

from biso_cosim.campaign.engine import CampaignInterrupted, EngineError, dask_client, load_campaign, run_campaign
from biso_cosim.campaign.spec import CampaignSpec, RunSpec, SpecError, load_spec, parse_spec
from biso_cosim.campaign.statistics import error_statistics, paired_comparisons
from biso_cosim.campaign.store import StoreError

__all__ = ["run_campaign", "load_campaign", "load_spec", "parse_spec", "CampaignSpec", "RunSpec", "dask_client",
           "error_statistics", "paired_comparisons", "SpecError", "StoreError", "EngineError", "CampaignInterrupted"]
