"""Numba kernels of the route layer: the driver's path search, the speed profile's limits."""

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


@jit
def _feasible_speeds(v, ds, accel, decel, square):
    """Lower the speeds ``v`` (in place) to what the acceleration limits allow between samples
    ``ds`` apart: a forward pass ``v_i² ≤ v_{i−1}² + 2·accel·ds`` and a backward pass with decel.

    ``square`` is 2.0, passed in so that v² is libm's pow(v, 2) as in the plain-Python passes
    this replaces (a constant exponent would become v·v, which differs in the last bit) and the
    library's speed profiles stay the same to the bit.
    """
    n = v.shape[0]
    for i in range(1, n):
        v[i] = min(v[i], math.sqrt(math.pow(v[i - 1], square) + 2.0 * accel * ds[i - 1]))
    for i in range(n - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(math.pow(v[i + 1], square) + 2.0 * decel * ds[i]))
