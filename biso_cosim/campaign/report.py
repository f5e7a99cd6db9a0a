"""A campaign's report: the table on screen, ``report.md`` with its figures, the statistics as CSV.

Figures (matplotlib): ``cdf.png``, the empirical distribution over runs of each estimator's
RMS and largest error per angle, all routes pooled; ``box.png``, box plots of the same
figures per route (whiskers at 1.5 × the interquartile range, runs beyond them as points).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from biso_cosim.campaign.statistics import ALL_ROUTES, METRICS, result_rows

__all__ = ["format_table", "format_comparisons", "write_report", "plot_cdfs", "plot_boxes"]

_ANGLES = ("roll", "pitch", "heading")
_KINDS = {"rms_deg": "RMS error", "max_abs_deg": "largest error"}


def _f(value: float, digits: int = 3) -> str:
    return "" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def format_table(stats: pd.DataFrame) -> str:
    """Per route and estimator: the mean, 95th percentile and maximum over runs of the RMS
    and of the largest error of each angle (degrees)."""
    if stats.empty:
        return "(no runs with results)"
    w_route = max(5, *(len(r) for r in stats["route"])) + 2
    w_est = max(9, *(len(e) for e in stats["estimator"])) + 2
    blocks = []
    for kind, title in _KINDS.items():
        head = f"{'route':<{w_route}}{'estimator':<{w_est}}{'runs':>5}" + "".join(
            f"{a + ' (°)':>24}" for a in _ANGLES)
        sub = " " * (w_route + w_est + 5) + "    mean     p95     max" * 3
        lines = [f"{title} over runs: mean, 95th percentile, maximum", head, sub]
        for (route, estimator), group in stats.groupby(["route", "estimator"], sort=False):
            by_metric = group.set_index("metric")
            line = f"{route:<{w_route}}{estimator:<{w_est}}{int(by_metric['runs'].max()):>5}"
            for angle in _ANGLES:
                row = by_metric.loc[f"{angle}_{kind}"]
                line += "".join(f"{_f(row.get(s, math.nan)):>8}" for s in ("mean", "p95", "max"))
            lines.append(line)
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks)


def format_comparisons(paired: pd.DataFrame, metric: str = "heading_rms_deg") -> str:
    """One line per pair, pooled over routes (or the only route): who wins how often, and
    the mean paired difference with its interval."""
    if paired.empty:
        return ""
    rows = paired[paired["metric"] == metric]
    if ALL_ROUTES in set(rows["route"]):
        rows = rows[rows["route"] == ALL_ROUTES]
    lines = [f"paired comparisons, {metric.replace('_', ' ')} (A − B, °):"]
    for _, r in rows.iterrows():
        if not r["runs"]:
            continue
        lines.append(f"  {r['a']} vs {r['b']}: {r['a']} smaller in {100 * r['a_wins']:.0f} % of {r['runs']} runs, "
                     f"{r['b']} in {100 * r['b_wins']:.0f} %; mean difference {_f(r['mean_diff'])} "
                     f"[{_f(r['mean_diff_low'])}, {_f(r['mean_diff_high'])}]")
    return "\n".join(lines)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _log_ticks(axis) -> None:
    """Labels at 1, 2 and 5 × 10^k, none at the other minor ticks (they collide in a narrow panel)."""
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_formatter(NullFormatter())


def plot_cdfs(frame: pd.DataFrame, path: str | Path) -> Path:
    """Empirical CDFs over runs, one line per estimator, all routes pooled."""
    plt = _plt()

    frame = result_rows(frame)
    fig, axes = plt.subplots(2, 3, figsize=(14, 7.5), layout="constrained")
    for ax, metric in zip(axes.flat, METRICS):
        for estimator, group in frame.groupby("estimator", sort=False):
            x = np.sort(group[metric].to_numpy(dtype=float))
            x = x[np.isfinite(x)]
            if x.size:
                ax.step(np.r_[x[0], x], np.r_[0.0, np.arange(1, x.size + 1) / x.size], where="post",
                        label=estimator)
        angle, _, kind = metric.partition("_")
        ax.set_xlabel(f"{angle} {_KINDS[kind]} (°)")
        ax.set_ylabel("share of runs")
        ax.set_xscale("log")
        _log_ticks(ax.xaxis)
        ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize="small")
    fig.suptitle("Error distribution over runs (all routes)")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_boxes(frame: pd.DataFrame, path: str | Path) -> Path:
    """Box plots over runs per route, one box per estimator."""
    plt = _plt()

    frame = result_rows(frame)
    routes = list(dict.fromkeys(frame["route"]))
    estimators = list(dict.fromkeys(frame["estimator"]))
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    width = 0.8 / max(len(estimators), 1)
    fig, axes = plt.subplots(2, 3, figsize=(max(14, 1.2 * len(routes) * max(len(estimators), 2)), 7.5),
                             layout="constrained")
    for ax, metric in zip(axes.flat, METRICS):
        for e, estimator in enumerate(estimators):
            data, positions = [], []
            for r, route in enumerate(routes):
                x = frame[(frame["route"] == route) & (frame["estimator"] == estimator)][metric].to_numpy(dtype=float)
                x = x[np.isfinite(x)]
                if x.size:
                    data.append(x)
                    positions.append(r + (e - (len(estimators) - 1) / 2) * width)
            if data:
                color = colors[e % len(colors)]
                ax.boxplot(data, positions=positions, widths=width * 0.9, patch_artist=True,
                           boxprops={"facecolor": color, "alpha": 0.5}, medianprops={"color": "black"},
                           flierprops={"markersize": 3})
                ax.plot([], [], color=color, lw=6, alpha=0.5, label=estimator)
        ax.set_xticks(range(len(routes)), routes, rotation=30, ha="right")
        angle, _, kind = metric.partition("_")
        ax.set_ylabel(f"{angle} {_KINDS[kind]} (°)")
        ax.set_yscale("log")
        _log_ticks(ax.yaxis)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    axes[0, 0].legend(fontsize="small")
    fig.suptitle("Errors over runs, per route")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def _ci(row: Mapping, name: str) -> str:
    value = row.get(name, math.nan)
    if not isinstance(value, float) or not math.isfinite(value):
        return ""
    low, high = row.get(f"{name}_low", math.nan), row.get(f"{name}_high", math.nan)
    return f"{value:.3f} [{_f(low)}, {_f(high)}]" if math.isfinite(low) else f"{value:.3f}"


def write_report(frame: pd.DataFrame, stats: pd.DataFrame, paired: pd.DataFrame, directory: str | Path,
                 canonical: Mapping, wall_s: float | None = None) -> Path:
    """``report.md``, ``cdf.png``, ``box.png``, ``statistics.csv`` and ``paired.csv`` in ``directory``."""
    directory = Path(directory)
    stats.to_csv(directory / "statistics.csv", index=False)
    paired.to_csv(directory / "paired.csv", index=False)
    level = canonical["statistics"]["confidence"]
    runs = frame.drop_duplicates("run_id") if not frame.empty else frame
    lines = [f"# Campaign {canonical['name']}", ""]
    lines += [f"{len(runs)} runs ({canonical['parts']} sensor parts, seeds {canonical['first_seed']}…"
              f"{canonical['first_seed'] + canonical['parts'] - 1}, per route and sensor set-up), "
              f"{frame['estimator'].nunique() if not frame.empty else 0} estimators in the loop of each"
              + (f"; {wall_s:.0f} s of wall time for this session's runs." if wall_s is not None else "."), ""]
    lines += ["| route | duration (s) |", "|---|---|"]
    lines += [f"| `{r['route']}` | {r['duration_s']:g} |" for r in canonical["routes"]]
    lines += ["", "| sensor set-up | profile | registers | gyro calibration (s) |", "|---|---|---|---|"]
    lines += [f"| `{s['label']}` | `{s['profile']}` | {dict(s['registers']) or 'defaults'} | "
              f"{s['gyro_calibration_s']:g} |" for s in canonical["sensors"]]
    lines += ["", "| estimator | method | parameters |", "|---|---|---|"]
    lines += [f"| `{e['label']}` | `{e['name']}` | {dict(e['params']) or 'defaults'} |"
              for e in canonical["estimators"]]
    if not runs.empty:
        lines += ["", "## Runs", "", "| route | " + " | ".join(sorted(set(runs["status"]))) + " |",
                  "|---|" + "---|" * runs["status"].nunique()]
        counts = runs.groupby(["route", "status"]).size().unstack(fill_value=0)
        for route, row in counts.iterrows():
            lines.append(f"| `{route}` | " + " | ".join(str(int(row.get(s, 0))) for s in sorted(set(runs["status"])))
                         + " |")
        failed = runs[runs["status"] == "failed"]
        if not failed.empty:
            lines += ["", "Failed runs (first ten):", ""]
            lines += [f"* `{r['run_id']}` ({r['route']}, {r['sensor']}, seed {r['seed']}): {r['error']}"
                      for _, r in failed.head(10).iterrows()]
    lines += ["", "## Errors over runs", "",
              f"Degrees; each figure with its {100 * level:g} % bootstrap interval (percentile method, "
              f"{canonical['statistics']['resamples']} resamples of the runs). The interval of the maximum "
              f"cannot exceed the largest run: indicative only.", ""]
    for metric in METRICS:
        angle, _, kind = metric.partition("_")
        lines += [f"### {angle}: {_KINDS[kind]}", "",
                  "| route | estimator | runs | mean | median | 95th percentile | maximum |",
                  "|---|---|---|---|---|---|---|"]
        for _, row in stats[stats["metric"] == metric].iterrows():
            lines.append(f"| `{row['route']}` | `{row['estimator']}` | {row['runs']} | {_ci(row, 'mean')} | "
                         f"{_ci(row, 'median')} | {_ci(row, 'p95')} | {_ci(row, 'max')} |")
        lines.append("")
    if not paired.empty:
        lines += ["## Paired comparisons", "",
                  "Over the runs in which both estimators have a result (same route, sensor part and samples): "
                  "the share of runs in which each has the smaller error, and the mean paired difference A − B "
                  f"(degrees) with its {100 * level:g} % bootstrap interval.", ""]
        for metric in METRICS:
            angle, _, kind = metric.partition("_")
            lines += [f"### {angle}: {_KINDS[kind]}", "",
                      "| route | A | B | runs | A smaller | B smaller | ties | mean A − B |",
                      "|---|---|---|---|---|---|---|---|"]
            for _, r in paired[paired["metric"] == metric].iterrows():
                if not r["runs"]:
                    continue
                lines.append(f"| `{r['route']}` | `{r['a']}` | `{r['b']}` | {r['runs']} | {100 * r['a_wins']:.0f} % | "
                             f"{100 * r['b_wins']:.0f} % | {100 * r['ties']:.0f} % | {_ci(r, 'mean_diff')} |")
            lines.append("")
    if not result_rows(frame).empty:
        plot_cdfs(frame, directory / "cdf.png")
        plot_boxes(frame, directory / "box.png")
        lines += ["## Figures", "", "![error distributions](cdf.png)", "", "![errors per route](box.png)", ""]
    lines += ["## Files", "",
              "* `results/`: the rows, one per (run, estimator), as a Parquet dataset "
              "(`biso_cosim.campaign.load_campaign(DIR)` reads them into pandas);",
              "* `statistics.csv`, `paired.csv`: the tables above;",
              "* `campaign.json`: the campaign's spec, as checked.", ""]
    path = directory / "report.md"
    path.write_text("\n".join(lines))
    return path
