"""What ``biso-cosim score`` shows and writes: the table, ``score.json``, a plot per trial."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from biso_cosim.score.metrics import ERRORS

__all__ = ["format_table", "write_json", "plot_trial"]

_SHORT = {"total": "total", "heading": "head", "inclination": "incl"}


def _cell(x: float) -> str:
    return f"{x:7.2f}" if math.isfinite(x) else "    nan"


def format_table(result: dict) -> str:
    """Per trial and per group: total, heading and inclination RMSE (°) of each method, and
    the mean total RMSE of each method (BROAD's score of the set)."""
    labels = list(result["methods"])
    width = max([12] + [len(t) for t in result["trials"]] + [len(g) + 2 for g in result["groups"]])
    colw = 3 * 8
    lines = [f"{'RMSE (°)':<{width}}" + "".join(f" {label[:colw - 1]:^{colw - 1}}|" for label in labels),
             f"{'trial':<{width}}" + "".join(" " + " ".join(f"{_SHORT[k]:>7}" for k in ERRORS) + "|" for _ in labels)]
    def row(name: str, values: dict) -> str:
        return f"{name:<{width}}" + "".join(
            " " + " ".join(_cell(values[label][f"{k}_rmse_deg"]) for k in ERRORS) + "|" for label in labels)
    for name, entry in result["trials"].items():
        lines.append(row(name, entry["methods"]))
    groups = result["groups"]
    if groups:
        lines.append(f"{'group (mean of trials)':<{width}}")
        for g, entry in groups.items():
            lines.append(row(f"  {g}", entry["methods"]) + f" {len(entry['trials'])} trial(s)")
    return "\n".join(lines)


def format_timing(result: dict) -> str:
    t = result["timing_s"]
    share = t["estimators_s"] / t["total_s"] if t["total_s"] > 0 else float("nan")
    per = ", ".join(f"{k} {v:.2f} s" for k, v in t["per_method_s"].items())
    return (f"wall time {t['total_s']:.1f} s: estimators {t['estimators_s']:.1f} s ({100 * share:.0f} %: {per}), "
            f"reading {t['read_s']:.1f} s, plots {t['plots_s']:.1f} s")


def _jsonable(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.generic):
        return _jsonable(x.item())
    return x


def write_json(result: dict, path: str | Path) -> Path:
    """``score.json``: the whole result (NaN written as null)."""
    from biso_cosim.output import write_text_atomic

    return write_text_atomic(path, json.dumps(_jsonable(result), indent=2) + "\n")  # whole or absent


def plot_trial(rec, errors_rad: dict[str, dict[str, np.ndarray]], path: str | Path, max_points: int = 2000) -> Path:
    """Total, heading and inclination error of each method over time (movement shaded)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(rec)
    step = max(1, int(math.ceil(n / max_points)))
    t = rec.t_s
    fig, axes = plt.subplots(3, 1, figsize=(10, 7.5), sharex=True)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], (~rec.movement).astype(np.int8), [0]))))
    spans = list(zip(edges[::2], edges[1::2]))  # [start, end) of each run of samples not scored
    for ax, key in zip(axes, ERRORS):
        for label, errs in errors_rad.items():
            e = np.degrees(errs[key])
            # the largest value of each stride, so that short peaks survive the thinning
            k = (n // step) * step
            peaks = np.fmax.reduceat(e[:k], np.arange(0, k, step)) if k else e[:0]
            ax.plot(t[:k:step], peaks, lw=0.8, label=label)
        for i, (a, b) in enumerate(spans):
            ax.axvspan(t[a], t[b - 1], color="0.88", lw=0, label="not scored" if i == 0 and key == "total" else None)
        ax.set_ylabel(f"{key} error (°)")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8, ncol=4)
    axes[0].set_title(f"{rec.name} ({rec.format}, {rec.fs_hz:.6g} Hz): BROAD errors, max per {step} samples")
    axes[-1].set_xlabel("time (s)")
    fig.subplots_adjust(left=0.07, right=0.98, top=0.95, bottom=0.07, hspace=0.08)
    from biso_cosim.output import atomic_output

    with atomic_output(path) as temporary:  # whole or absent
        fig.savefig(temporary, dpi=100)
    plt.close(fig)
    return Path(path)
