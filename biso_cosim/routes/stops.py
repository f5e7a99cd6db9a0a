"""Stops in a recorded track, found from its time stamps.

A receiver standing still keeps reporting fixes (scattered by its noise, or repeated exactly
by a receiver with a static hold); between its stops a car moves at metres per second. The
speed at each fix is taken over a window of ``window_s`` centred on it (positions interpolated
in time, so gaps in the fixes count as driving at the gap's mean speed); a run of fixes slower
than ``speed_mps`` that lasts at least ``min_stop_s`` is a stop, its dwell the time from the
run's first fix to its last plus one fix interval (the standing lasts about that long
between the fixes that see it).
"""

from __future__ import annotations

import numpy as np

__all__ = ["find_stops", "STOP_SPEED_MPS", "STOP_WINDOW_S"]

STOP_SPEED_MPS = 0.5
"""Below this the receiver stands (GNSS noise moves a standing receiver by a few dm/s)."""

STOP_WINDOW_S = 2.0
"""Window over which the speed at a fix is measured."""


def find_stops(t_s: np.ndarray, x_m: np.ndarray, y_m: np.ndarray, *, min_stop_s: float,
               speed_mps: float = STOP_SPEED_MPS, window_s: float = STOP_WINDOW_S) -> list[tuple[int, int, float]]:
    """Runs of fixes ``(first, last, dwell_s)`` (inclusive indices) where the receiver stood
    still for at least ``min_stop_s``; ``t_s`` strictly increasing."""
    t = np.asarray(t_s, dtype=np.float64)
    half = 0.5 * window_s
    before = np.maximum(t - half, t[0])
    after = np.minimum(t + half, t[-1])
    span = np.maximum(after - before, 1e-9)
    dx = np.interp(after, t, x_m) - np.interp(before, t, x_m)
    dy = np.interp(after, t, y_m) - np.interp(before, t, y_m)
    still = np.hypot(dx, dy) / span < speed_mps
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    firsts, lasts = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    interval = float(np.median(np.diff(t))) if t.shape[0] > 1 else 0.0
    runs = [(int(a), int(b), float(t[b] - t[a]) + interval) for a, b in zip(firsts, lasts)]
    return [run for run in runs if run[2] >= min_stop_s]
