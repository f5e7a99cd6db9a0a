"""Smoothing of a recorded track along its arc length, keeping its ends.

The Whittaker–Henderson smoother (Whittaker 1923; Eilers 2003, "A perfect smoother", Anal.
Chem. 75, 3631) on a uniform grid of spacing h: the smoothed values z minimise

    Σ w_j (y_j − z_j)² + λ Σ (Δ² z_j)²,     i.e.  (W + λ DᵀD) z = W y,

with D the second differences (circular for a closed track). It is the discrete cubic
smoothing spline: where data are missing (w = 0: a dropout) it bridges with a smooth curve,
and at the ends of an open track it neither shrinks its window nor pins the first sample (the
penalty leaves straight lines untouched, so the ends follow the trend of their neighbours).

For evenly weighted data its gain at wavelength Λ is ``1 / (1 + λ (2 sin(π h/Λ))⁴)`` (from
the eigenvalues of DᵀD); ``cutoff_m`` is the wavelength whose amplitude is halved, so
``λ = (2 sin(π h/cutoff_m))⁻⁴``. Samples at arc lengths ``s`` between grid nodes are spread
over their two neighbours (linear binning), each weighted by the arc length it stands for, so
that the node weights are about 1 wherever the track is sampled more densely than the grid.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp
from scipy.linalg import solveh_banded
from scipy.sparse.linalg import splu

__all__ = ["whittaker", "smooth_along", "bin_along", "whittaker_lambda"]


def whittaker_lambda(cutoff_m: float, grid_m: float) -> float:
    """λ that halves the amplitude of wavelength ``cutoff_m`` on a grid of spacing ``grid_m``."""
    # a cutoff at or below the grid's Nyquist wavelength (2 h) smooths as little as the grid can
    # and still bridges the nodes without data
    ratio = min(grid_m / cutoff_m, 0.5)
    return (2.0 * math.sin(math.pi * ratio)) ** -4


TIE_WEIGHT = 100.0
"""Weight of a tie relative to the smoothing penalty (the tied values end up within about 1 %
of their difference untied)."""


def _second_differences(n: int, closed: bool) -> sp.csc_matrix:
    if closed:
        eye = sp.identity(n, format="csc")
        shift = sp.eye(n, n, k=1, format="csc") + sp.eye(n, n, k=1 - n, format="csc")
        return (shift @ shift - 2.0 * shift + eye).tocsc()
    return sp.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n), format="csc")


def _banded_normal_matrix(w: np.ndarray, lam: float) -> np.ndarray:
    """W + λ DᵀD of an open grid in the lower banded form of ``solveh_banded`` (bandwidth 2):
    DᵀD has diagonal 1, 5, 6, ..., 6, 5, 1, first off-diagonal -2, -4, ..., -4, -2, second 1."""
    n = w.shape[0]
    band = np.zeros((3, n))
    diag = np.full(n, 6.0)
    diag[[0, -1]], diag[[1, -2]] = 1.0, 5.0
    off1 = np.full(n - 1, -4.0)
    off1[[0, -1]] = -2.0
    band[0] = w + lam * diag
    band[1, :-1] = lam * off1
    band[2, :-2] = lam
    return band


def whittaker(values: np.ndarray, weights: np.ndarray, lam: float, closed: bool = False,
              ties: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Whittaker–Henderson (order 2) smoothing of the columns of ``values`` (n, k) with node
    ``weights`` (n,); the grid is circular when ``closed``. Nodes of weight 0 are bridged.

    ``ties`` (two index arrays) are pairs of nodes made (nearly) equal by a penalty
    ``TIE_WEIGHT·max(λ, 1)·(z_i − z_j)²`` on each: where a road passes over itself, its
    heights must agree (a height-field ground has one height per place).
    """
    values = np.asarray(values, dtype=np.float64)
    column = values.ndim == 1
    y = values.reshape(values.shape[0], -1)
    n = y.shape[0]
    w = np.asarray(weights, dtype=np.float64)
    if n < 3:
        out = y.copy()
    elif not closed and n >= 4 and (ties is None or not len(ties[0])):
        out = solveh_banded(_banded_normal_matrix(w, lam), w[:, None] * y, lower=True)
    else:
        d = _second_differences(n, closed)
        a = sp.diags(w, 0, format="csc") + lam * (d.T @ d)
        if ties is not None and len(ties[0]):
            rows = np.arange(len(ties[0]))
            c = sp.csc_matrix((np.concatenate([np.ones(rows.size), -np.ones(rows.size)]),
                               (np.concatenate([rows, rows]), np.concatenate([ties[0], ties[1]]))),
                              shape=(rows.size, n))
            a = a + TIE_WEIGHT * max(lam, 1.0) * (c.T @ c)
        a = a.tocsc()
        out = splu(a).solve(w[:, None] * y)
    return out[:, 0] if column else out


def bin_along(s_m: np.ndarray, values: np.ndarray, *, grid_m: float = 1.0,
              period_m: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Samples ``values`` (n, k) at increasing arc lengths ``s_m`` (n,) spread onto a uniform
    grid of about ``grid_m`` (over [s_m[0], s_m[-1]], or [0, period_m) for a closed track).

    Returns the grid's arc lengths, the weighted mean value at each node (0 where no sample
    falls) and the node weights (the arc length of the samples there, in grid cells).
    """
    s = np.asarray(s_m, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    y2 = y.reshape(y.shape[0], -1)
    closed = period_m is not None
    start = 0.0 if closed else float(s[0])
    span = float(period_m) if closed else float(s[-1] - s[0])
    cells = max(int(math.ceil(span / grid_m)), 2)
    h = span / cells
    nodes = cells if closed else cells + 1
    grid = start + h * np.arange(nodes)
    # the arc length each sample stands for (half the gaps to its neighbours), in grid cells
    if closed:
        gaps = np.diff(np.append(s, s[0] + span))
        share = 0.5 * (gaps + np.roll(gaps, 1)) / h
    else:
        gaps = np.diff(s)
        share = 0.5 * (np.append(gaps, 0.0) + np.insert(gaps, 0, 0.0)) / h
    u = (s - start) / h
    j = np.floor(u).astype(np.int64)
    if closed:
        f = u - j
        j0, j1 = j % nodes, (j + 1) % nodes
    else:
        j = np.minimum(j, nodes - 2)
        f = u - j
        j0, j1 = j, j + 1
    w0, w1 = share * (1.0 - f), share * f
    weights = np.bincount(j0, w0, nodes) + np.bincount(j1, w1, nodes)
    sums = np.column_stack([np.bincount(j0, w0 * y2[:, k], nodes) + np.bincount(j1, w1 * y2[:, k], nodes)
                            for k in range(y2.shape[1])])
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(weights[:, None] > 0.0, sums / weights[:, None], 0.0)
    return grid, (means[:, 0] if y.ndim == 1 else means), weights


def smooth_along(s_m: np.ndarray, values: np.ndarray, cutoff_m: float, *, grid_m: float = 1.0,
                 period_m: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Smooth samples ``values`` (n, k) taken at increasing arc lengths ``s_m`` (n,) with the
    cutoff wavelength ``cutoff_m``; ``period_m`` for a closed track (s wraps at it).

    Returns the grid's arc lengths (see ``bin_along``) and the smoothed values there.
    """
    grid, means, weights = bin_along(s_m, values, grid_m=grid_m, period_m=period_m)
    h = grid[1] - grid[0]
    return grid, whittaker(means, weights, whittaker_lambda(cutoff_m, h), period_m is not None)
