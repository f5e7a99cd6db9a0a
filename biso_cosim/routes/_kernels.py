"""Numba kernels of the route layer: the driver's path search."""

from __future__ import annotations

import math

from biso_cosim._numba import jit

# The window ``Path.locate`` searches by default, in samples behind and ahead of its hint.
LOCATE_BACK, LOCATE_AHEAD = 8, 80


@jit
def _locate(xs, ys, ss, x, y, lo, hi):
    """Nearest point to (x, y) on the polyline segments lo..hi: (segment, s, signed offset).

    The offset is positive when the point lies left of the direction of travel.
    """
    best = 1e300
    best_i = lo
    best_t = 0.0
    for i in range(lo, hi):
        dx = xs[i + 1] - xs[i]
        dy = ys[i + 1] - ys[i]
        seg2 = dx * dx + dy * dy
        t = 0.0
        if seg2 > 0.0:
            t = ((x - xs[i]) * dx + (y - ys[i]) * dy) / seg2
            t = min(max(t, 0.0), 1.0)
        px = xs[i] + t * dx
        py = ys[i] + t * dy
        d2 = (x - px) * (x - px) + (y - py) * (y - py)
        if d2 < best:
            best = d2
            best_i = i
            best_t = t
    i = best_i
    dx = xs[i + 1] - xs[i]
    dy = ys[i + 1] - ys[i]
    px = xs[i] + best_t * dx
    py = ys[i] + best_t * dy
    length = math.sqrt(max(dx * dx + dy * dy, 1e-24))
    cross = (dx * (y - py) - dy * (x - px)) / length
    return i, ss[i] + best_t * (ss[i + 1] - ss[i]), cross
