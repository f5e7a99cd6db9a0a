"""The map of a route: plan view over the terrain, elevation and speed along the route."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from biso_cosim.output import atomic_output  # noqa: E402
from biso_cosim.routes.route import Route  # noqa: E402

__all__ = ["plot_route"]

# Terrain heights are evaluated at most this many (point, road segment) pairs at a time: a road
# feature finds each point's nearest segment among all of its segments.
_PAIRS_PER_CALL = 2_000_000
_PROFILE_SAMPLES = 4000


def _heights(route: Route, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Terrain heights at x, y, in pieces small enough for the road features' search."""
    segments = max([len(getattr(f, "points", ())) for f in route.terrain.features] + [1])
    chunk = max(_PAIRS_PER_CALL // segments, 1)
    flat_x, flat_y = np.broadcast_arrays(x, y)
    shape = flat_x.shape
    flat_x, flat_y = flat_x.ravel(), flat_y.ravel()
    out = np.empty(flat_x.shape[0])
    for lo in range(0, flat_x.shape[0], chunk):
        out[lo:lo + chunk] = route.terrain.height(flat_x[lo:lo + chunk], flat_y[lo:lo + chunk])
    return out.reshape(shape)


def plot_route(route: Route, path: str | Path) -> Path:
    """Draw ``route`` into ``path`` (PNG): the plan view with the terrain's height as shading,
    start, stops and direction; below it the elevation and the target speed along the route."""
    path = Path(path)
    p = route.path
    fig = plt.figure(figsize=(11, 10), layout="constrained")
    grid = fig.add_gridspec(3, 1, height_ratios=[3, 1, 1])
    ax = fig.add_subplot(grid[0])
    pad = 30.0
    x0, x1 = p.x_m.min() - pad, p.x_m.max() + pad
    y0, y1 = p.y_m.min() - pad, p.y_m.max() + pad
    segments = max([len(getattr(f, "points", ())) for f in route.terrain.features] + [1])
    nx = 400 if segments < 2000 else 100  # a long imported road: a coarser shading
    ny = max(int(nx * (y1 - y0) / max(x1 - x0, 1e-6)), nx // 8)
    xs, ys = np.linspace(x0, x1, nx), np.linspace(y0, y1, ny)
    heights = _heights(route, xs[None, :], ys[:, None])
    if np.ptp(heights) > 0:
        shade = ax.imshow(heights, origin="lower", extent=(x0, x1, y0, y1), cmap="terrain", alpha=0.6,
                          vmin=min(0.0, heights.min()), vmax=max(heights.max(), 1e-3))
        fig.colorbar(shade, ax=ax, label="terrain height (m)", shrink=0.7)
    backwards = route.direction < 0
    ax.plot(p.x_m, p.y_m, color="k", lw=1.2, label="route")
    if backwards.any():
        ax.plot(np.where(backwards, p.x_m, np.nan), np.where(backwards, p.y_m, np.nan), color="tab:red",
                lw=2.0, label="in reverse")
    step = max(len(p) // 25, 1)
    for i in range(step // 2, len(p) - 1, step):
        ax.annotate("", xy=(p.x_m[i + 1], p.y_m[i + 1]), xytext=(p.x_m[i], p.y_m[i]),
                    arrowprops=dict(arrowstyle="-|>", color="k", lw=0.8))
    ax.plot(p.x_m[0], p.y_m[0], "o", color="tab:green", ms=9, label="start")
    stops = route.stops[:-1]
    if stops:
        ax.plot([p.x_m[s.index] for s in stops], [p.y_m[s.index] for s in stops], "s", color="tab:red", ms=7,
                label="stops")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("East (m)")
    ax.set_ylabel("North (m)")
    ax.legend(loc="best", fontsize=8)
    summary = route.summary()
    ax.set_title(f"{route.name}: {route.description}\n{summary['length_m']:.0f} m, about "
                 f"{summary['nominal_duration_s']:.0f} s; excites: {route.excites}", fontsize=9)

    ax_z = fig.add_subplot(grid[1])
    along = np.unique(np.linspace(0, len(p) - 1, min(len(p), _PROFILE_SAMPLES)).astype(np.int64))
    ax_z.plot(p.s_m[along], _heights(route, p.x_m[along], p.y_m[along]), color="tab:brown")
    ax_z.set_ylabel("elevation (m)")
    ax_z.grid(alpha=0.3)
    ax_v = fig.add_subplot(grid[2], sharex=ax_z)
    ax_v.plot(p.s_m, route.speed_with_stops_mps * 3.6 * route.direction, color="tab:blue")
    ax_v.set_ylabel("target speed (km/h)")
    ax_v.set_xlabel("distance along the route (m)")
    ax_v.grid(alpha=0.3)
    try:
        with atomic_output(path) as temporary:
            fig.savefig(temporary, dpi=100)
    finally:
        plt.close(fig)
    return path
