"""The run figure ``attitude.png``: truth and estimates of each angle, and their errors.

Left column: roll, pitch and heading over time, truth in black, each estimator in colour.
Right column: each estimator's error on a symmetric-log scale (linear within ±1°), so that a
drifting baseline and a sub-degree estimator are both readable; the legend gives RMS errors.
A strip at the top shows the route driven (plan view, coloured by time) and the speed.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from biso_cosim.metrics import ANGLES, attitude_angles_deg  # noqa: E402
from biso_cosim.output import atomic_output  # noqa: E402

__all__ = ["plot_run", "plot_navigation"]

_LABELS = {"roll": "roll (°)", "pitch": "pitch (°)", "heading": "heading (°, from N)"}


def _break_wraps(t: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert NaN where a heading wraps through 0/360 so lines do not cross the plot."""
    jumps = np.flatnonzero(np.abs(np.diff(heading)) > 180.0) + 1
    return np.insert(t, jumps, np.nan), np.insert(heading, jumps, np.nan)


def plot_run(result, path: str | Path) -> Path:
    """Draw the figure of a :class:`biso_cosim.cosim.RunResult` into ``path`` (PNG)."""
    path = Path(path)
    t = result.t_s
    truth = attitude_angles_deg(result.truth.q_wb)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig = plt.figure(figsize=(15, 11), layout="constrained")
    grid = fig.add_gridspec(4, 2, height_ratios=[1.1, 1, 1, 1])
    ax_map = fig.add_subplot(grid[0, 0])
    ax_speed = fig.add_subplot(grid[0, 1])
    pos = result.truth.pos_w
    sc = ax_map.scatter(pos[:, 0], pos[:, 1], c=t, s=1, cmap="viridis")
    ax_map.plot(result.route.path.x_m, result.route.path.y_m, color="0.8", lw=0.8, zorder=0)
    ax_map.set_aspect("equal", adjustable="datalim")
    ax_map.set_xlabel("East (m)")
    ax_map.set_ylabel("North (m)")
    fig.colorbar(sc, ax=ax_map, label="time (s)", shrink=0.8)
    ax_speed.plot(t, result.truth.speed_mps * 3.6, color="k", lw=0.8)
    ax_speed.set_ylabel("speed (km/h)")
    ax_speed.set_xlabel("time (s)")
    ax_speed.grid(alpha=0.3)

    summary = result.summary()
    errors = {key: result.errors(key) for key in result.estimates}
    for row, angle in enumerate(ANGLES, start=1):
        ax = fig.add_subplot(grid[row, 0])
        ax_err = fig.add_subplot(grid[row, 1], sharex=ax)
        series = [("truth", truth[angle], "k", 1.4)]
        for i, (key, (q, _)) in enumerate(result.estimates.items()):
            series.append((key, attitude_angles_deg(q)[angle], colors[i % len(colors)], 0.8))
        for label, values, color, width in series:
            tt, vv = _break_wraps(t, values) if angle == "heading" else (t, values)
            ax.plot(tt, vv, color=color, lw=width, label=label)
        ax.set_ylabel(_LABELS[angle])
        ax.grid(alpha=0.3)
        for i, key in enumerate(result.estimates):
            err = errors[key][angle]
            rms = summary["estimators"][key]["errors"][angle]["rms_deg"]
            ax_err.plot(t, err, color=colors[i % len(colors)], lw=0.8, label=f"{key}: RMS {rms:.2f}°")
        ax_err.set_yscale("symlog", linthresh=1.0)
        ax_err.axhline(0.0, color="k", lw=0.5)
        ax_err.set_ylabel(f"{angle} error (°)")
        ax_err.grid(alpha=0.3, which="both")
        ax_err.legend(loc="upper left", fontsize=8)
        if row == 1:
            ax.legend(loc="upper left", fontsize=8, ncol=len(series))
        if row == len(ANGLES):
            ax.set_xlabel("time (s)")
            ax_err.set_xlabel("time (s)")
    fig.suptitle(
        f"route {result.route.name}, seed {result.seed}, {result.duration_s:.0f} s simulated; "
        f"MPU-9250 '{result.sensor['profile']}' at {result.sensor['output_rate_hz']:g} Hz"
    )
    with atomic_output(path) as temporary:  # the image whole or not at all
        fig.savefig(temporary, dpi=110)
    plt.close(fig)
    return path


def plot_navigation(result, path: str | Path) -> Path:
    """Dead-reckoning navigators of a run: plan view against the truth, horizontal position
    error and attitude error over time (log scales: the errors grow by decades)."""
    from biso_cosim.frames import quat_angle_between

    path = Path(path)
    t = result.t_s
    truth = result.truth
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, axes = plt.subplots(1, 3, figsize=(16, 5), layout="constrained")
    axes[0].plot(truth.pos_w[:, 0], truth.pos_w[:, 1], color="k", lw=1.5, label="truth")
    for i, (key, nav) in enumerate(result.navigation.items()):
        c = colors[i % len(colors)]
        axes[0].plot(nav["p_w"][:, 0], nav["p_w"][:, 1], color=c, lw=0.8, label=key)
        horizontal = np.linalg.norm(nav["p_w"][:, :2] - truth.pos_w[:, :2], axis=1)
        axes[1].plot(t, np.maximum(horizontal, 1e-6), color=c, lw=0.8, label=key)
        axes[2].plot(t, np.maximum(np.degrees(quat_angle_between(nav["q_wb"], truth.q_wb)), 1e-6), color=c,
                     lw=0.8, label=key)
    axes[0].set_aspect("equal", adjustable="datalim")
    axes[0].set_xlabel("East (m)")
    axes[0].set_ylabel("North (m)")
    axes[0].legend(fontsize=8)
    for ax, label in ((axes[1], "horizontal position error (m)"), (axes[2], "attitude error (°)")):
        ax.set_yscale("log")
        ax.set_xlabel("time (s)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(f"dead reckoning from the true initial state: route {result.route.name}, seed {result.seed}, "
                 f"MPU-9250 '{result.sensor['profile']}'")
    with atomic_output(path) as temporary:  # the image whole or not at all
        fig.savefig(temporary, dpi=110)
    plt.close(fig)
    return path
