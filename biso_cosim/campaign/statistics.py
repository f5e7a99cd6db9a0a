"""Statistics over a campaign's runs: error distributions and paired comparisons.

For each estimator and route (and all routes pooled, ``route = "all"``), the mean, median,
95th percentile and maximum of the runs' RMS and largest errors in roll, pitch and heading,
each with a bootstrap confidence interval (percentile method, Efron & Tibshirani 1993
ch. 13; :func:`scipy.stats.bootstrap`, resampling the runs). The interval of a maximum is
indicative only: no resample can exceed the largest run, so it lies at or below it.

A paired comparison of estimators A and B uses the runs in which both have a result (the
same route, sensor part and samples): the share of runs in which each has the smaller error
(and ties), and the mean of the paired difference A − B with its bootstrap interval
(resampling the runs, hence the pairs, together).

Failed runs have no figures and are left out; runs that did not complete their route (a
duration shorter than the route) count, over the part they drove.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd

__all__ = ["METRICS", "STATISTICS", "ALL_ROUTES", "error_statistics", "paired_comparisons", "result_rows"]

_ANGLES = ("roll", "pitch", "heading")
METRICS = tuple(f"{angle}_{kind}" for kind in ("rms_deg", "max_abs_deg") for angle in _ANGLES)
"""The figures summarised: RMS and largest error of each angle, per run (degrees)."""
STATISTICS = ("mean", "median", "p95", "max")
# resamples drawn at once: memory stays near _BATCH_VALUES floats however many runs
_BATCH_VALUES = 2_000_000
ALL_ROUTES = "all"
"""The route name under which the statistics of all routes pooled are reported."""


def _stats(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.stack([np.mean(x, axis=axis), np.median(x, axis=axis), np.percentile(x, 95, axis=axis),
                     np.max(x, axis=axis)])


def _bootstrap(data: tuple[np.ndarray, ...], statistic, confidence: float, resamples: int,
               rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Percentile bootstrap interval of a (vector-valued) statistic; NaN below two runs."""
    from scipy.stats import bootstrap

    value = np.atleast_1d(statistic(*data, axis=-1))
    if data[0].shape[0] < 2:
        return np.full(value.shape, np.nan), np.full(value.shape, np.nan)
    res = bootstrap(data, statistic, n_resamples=resamples, confidence_level=confidence, method="percentile",
                    vectorized=True, batch=max(1, _BATCH_VALUES // data[0].shape[0]), rng=rng)
    return np.atleast_1d(res.confidence_interval.low), np.atleast_1d(res.confidence_interval.high)


def result_rows(frame: pd.DataFrame) -> pd.DataFrame:
    """The rows with figures: failed runs left out."""
    if frame.empty or "status" not in frame:
        return frame
    return frame[frame["status"] != "failed"]


def _groups(frame: pd.DataFrame) -> list[tuple[str, pd.DataFrame]]:
    routes = list(dict.fromkeys(frame["route"]))
    return [(route, frame[frame["route"] == route]) for route in routes] + ([(ALL_ROUTES, frame)] if len(routes) > 1
                                                                           else [])


def error_statistics(frame: pd.DataFrame, confidence: float = 0.95, resamples: int = 2000,
                     seed: int = 0) -> pd.DataFrame:
    """One row per (estimator, route, metric): the number of runs and each statistic with
    its interval (columns ``mean``, ``mean_low``, ``mean_high``, ... ``max_high``)."""
    frame = result_rows(frame)
    out = []
    if frame.empty:
        return pd.DataFrame(out)
    estimators = list(dict.fromkeys(frame["estimator"]))
    for g, (route, group) in enumerate(_groups(frame)):
        for e, estimator in enumerate(estimators):
            rows = group[group["estimator"] == estimator]
            for m, metric in enumerate(METRICS):
                x = rows[metric].to_numpy(dtype=float)
                x = x[np.isfinite(x)]
                entry = {"estimator": estimator, "route": route, "metric": metric, "runs": int(x.size)}
                if x.size:
                    value = _stats(x)
                    rng = np.random.default_rng([seed, g, e, m])
                    low, high = _bootstrap((x,), _stats, confidence, resamples, rng)
                    for name, v, lo, hi in zip(STATISTICS, value, low, high):
                        entry |= {name: float(v), f"{name}_low": float(lo), f"{name}_high": float(hi)}
                out.append(entry)
    return pd.DataFrame(out)


def _mean(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(x, axis=axis)


def paired_comparisons(frame: pd.DataFrame, baseline: str | None = None, confidence: float = 0.95,
                       resamples: int = 2000, seed: int = 0) -> pd.DataFrame:
    """One row per (A, B, route, metric): the runs compared, the shares of runs in which A
    and B have the smaller error and of ties, and the mean paired difference A − B
    (``mean_diff``) with its interval; B is ``baseline`` when given, else every pair."""
    frame = result_rows(frame)
    out = []
    if frame.empty:
        return pd.DataFrame(out)
    estimators = list(dict.fromkeys(frame["estimator"]))
    if baseline is not None:
        if baseline not in estimators:
            raise ValueError(f"baseline: no estimator {baseline!r} among {', '.join(estimators)}")
        pairs = [(a, baseline) for a in estimators if a != baseline]
    else:
        pairs = list(itertools.combinations(estimators, 2))
    for g, (route, group) in enumerate(_groups(frame)):
        for m, metric in enumerate(METRICS):
            wide = group.pivot_table(index="run_id", columns="estimator", values=metric, aggfunc="first")
            for p, (a, b) in enumerate(pairs):
                if a not in wide or b not in wide:
                    continue
                both = wide[[a, b]].dropna()
                xa, xb = both[a].to_numpy(dtype=float), both[b].to_numpy(dtype=float)
                n = int(xa.size)
                entry = {"a": a, "b": b, "route": route, "metric": metric, "runs": n}
                if n:
                    diff = xa - xb
                    rng = np.random.default_rng([seed, g, m, p])
                    low, high = _bootstrap((diff,), _mean, confidence, resamples, rng)
                    entry |= {"a_wins": float(np.mean(xa < xb)), "b_wins": float(np.mean(xb < xa)),
                              "ties": float(np.mean(xa == xb)), "mean_diff": float(diff.mean()),
                              "mean_diff_low": float(low[0]), "mean_diff_high": float(high[0]),
                              "median_diff": float(np.median(diff))}
                out.append(entry)
    return pd.DataFrame(out)
