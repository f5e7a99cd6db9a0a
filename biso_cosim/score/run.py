"""Score methods on a folder of recordings: per trial, per group, with the time each part took."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from biso_cosim.score.methods import Method, make_method, user_method
from biso_cosim.score.metrics import ERRORS, broad_errors_rad, rmse_deg
from biso_cosim.score.readers import Recording, read_folder

__all__ = ["score", "as_methods", "DEFAULT_METHODS"]

DEFAULT_METHODS = ("biso_plus", "vqf", "imufusion")
"""Scored when no method is given (peers that are not installed are left out)."""


def as_methods(items: Iterable[Any]) -> list[Method]:
    """Methods from names ``[LABEL=]NAME[:P=V,...]``, ``EstimatorSpec``s, ``Method``s, or a user's
    estimator instances and factories; labels must be unique."""
    from biso_cosim.cli import estimator_spec
    from biso_cosim.cosim import EstimatorSpec

    if isinstance(items, (str, Method)):
        items = [items]
    methods = []
    for item in items:
        if isinstance(item, Method):
            methods.append(item)
        elif isinstance(item, str):
            spec = estimator_spec(item, "--method")
            methods.append(make_method(spec.name, spec.params, spec.label))
        elif isinstance(item, EstimatorSpec):
            methods.append(user_method(item.instance, item.key, item.params) if item.instance is not None
                           else make_method(item.name, item.params, item.key))
        else:
            methods.append(user_method(item))
    if not methods:
        raise ValueError("--method: give at least one method")
    labels = [m.label for m in methods]
    if len(set(labels)) != len(labels):
        raise ValueError(f"--method: labels must be unique, got {labels} (use LABEL=NAME:...)")
    return methods


def default_methods() -> list[Method]:
    from biso_cosim.score.methods import PEERS, peer_available

    return [make_method(n) for n in DEFAULT_METHODS if n not in PEERS or peer_available(n)]


def score_recording(rec: Recording, methods: list[Method], keep_errors: bool = False) -> tuple[dict, dict]:
    """Run every method on one recording: (entry with the RMSE of each error measure and the
    estimator's seconds per method, {label: per-sample errors (rad)} if ``keep_errors``)."""
    entry: dict[str, Any] = {
        "path": rec.path, "format": rec.format, "fs_hz": rec.fs_hz, "samples": len(rec),
        "scored_samples": int(np.count_nonzero(rec.movement & np.all(np.isfinite(rec.q_ref), axis=1))),
        "groups": list(rec.groups), "methods": {},
    }
    errors = {}
    for m in methods:
        t0 = time.perf_counter()
        q = m.run(rec)
        seconds = time.perf_counter() - t0
        errs = broad_errors_rad(q, rec.q_ref)
        entry["methods"][m.label] = {**{f"{k}_rmse_deg": rmse_deg(errs[k], rec.movement) for k in ERRORS},
                                     "seconds": seconds}
        if keep_errors:
            errors[m.label] = errs
    return entry, errors


def group_means(trials: dict[str, dict], labels: list[str]) -> dict[str, dict]:
    """BROAD's group score: the mean over the group's trials of each per-trial RMSE."""
    names: dict[str, list[str]] = {}
    for trial, entry in trials.items():
        for g in entry["groups"]:
            names.setdefault(g, []).append(trial)
    out = {}
    for g, members in names.items():
        out[g] = {"trials": members, "methods": {
            label: {f"{k}_rmse_deg": float(np.mean([trials[t]["methods"][label][f"{k}_rmse_deg"] for t in members]))
                    for k in ERRORS} for label in labels}}
    return out


def score(folder: str | Path, methods: Iterable[Any] | None = None, *, out: str | Path | None = None,
          fs_hz: float | None = None, plots: bool = True,
          progress: Callable[[str], None] | None = None) -> dict:
    """Score ``methods`` (default ``DEFAULT_METHODS``) on every recording of ``folder``.

    Returns ``{"trials": {name: {..., "methods": {label: {total_rmse_deg, heading_rmse_deg,
    inclination_rmse_deg, seconds}}}}, "groups": {group: {"trials", "methods"}}, "methods":
    {label: description}, "timing_s": {...}}``. With ``out``, writes ``score.json`` and (with
    ``plots``) one ``<trial>.png`` per recording there.
    """
    from biso_cosim.score import report

    t_start = time.perf_counter()
    ms = default_methods() if methods is None else as_methods(methods)
    labels = [m.label for m in ms]
    out_dir = None if out is None else Path(out)
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    timing = {"read_s": 0.0, "estimators_s": 0.0, "plots_s": 0.0}
    trials: dict[str, dict] = {}
    recordings = read_folder(folder, fs_hz)
    while True:
        t0 = time.perf_counter()
        rec = next(recordings, None)
        timing["read_s"] += time.perf_counter() - t0
        if rec is None:
            break
        if rec.name in trials:
            raise ValueError(f"DIR: two recordings are named {rec.name!r} ({trials[rec.name]['path']}, {rec.path})")
        if progress:
            progress(f"{rec.name}: {len(rec)} samples at {rec.fs_hz:.6g} Hz")
        entry, errors = score_recording(rec, ms, keep_errors=plots and out_dir is not None)
        trials[rec.name] = entry
        timing["estimators_s"] += sum(v["seconds"] for v in entry["methods"].values())
        if errors:
            t0 = time.perf_counter()
            report.plot_trial(rec, errors, out_dir / f"{rec.name}.png")
            timing["plots_s"] += time.perf_counter() - t0
    per_method = {label: float(sum(t["methods"][label]["seconds"] for t in trials.values())) for label in labels}
    timing["per_method_s"] = per_method
    result = {"trials": trials, "groups": group_means(trials, labels),
              "methods": {m.label: m.describe() for m in ms}, "timing_s": timing}
    timing["total_s"] = time.perf_counter() - t_start
    if out_dir is not None:
        report.write_json(result, out_dir / "score.json")
        timing["total_s"] = time.perf_counter() - t_start
    return result
