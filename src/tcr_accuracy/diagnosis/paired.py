"""Comparing two models on the same held-out rows: the paired tests the selection uses, and the
residual shapes they read (one or several measured frames per row). Lengths in m.
"""

from __future__ import annotations

import math

import numpy as np


def paired_z(before: np.ndarray, after: np.ndarray) -> float:
    """z of the mean cut in per-measurement squared held-out errors (one-sided, paired).

    before, after : (N, 3) or (n_parts, N, 3) position errors (parts of a row add up), or (N,)
    squared errors per row (a fit's ``heldout_squares``).
    """
    d = row_squares(before) - row_squares(after)
    sd = d.std(ddof=1)
    if sd == 0:
        return 0.0 if d.mean() == 0 else math.copysign(math.inf, d.mean())
    return float(d.mean() / (sd / math.sqrt(d.size)))


def signed_rank_z(before: np.ndarray, after: np.ndarray) -> float:
    """z of Wilcoxon's signed-rank test that per-row squared held-out errors fall (one-sided,
    normal approximation with ties averaged, zero differences dropped): the test the paired
    mean's z misses when a few rows carry most of the error, as with few poses.

    before, after : as for :func:`paired_z`.
    """
    from scipy.stats import rankdata

    d = row_squares(before) - row_squares(after)
    d = d[d != 0]
    n = d.size
    if n == 0:
        return 0.0
    ranks = rankdata(np.abs(d))
    _, counts = np.unique(np.abs(d), return_counts=True)
    # positive for n >= 1: the ties' term is at most (n^3 - n) / 48 = n (n + 1) (n - 1) / 48
    variance = n * (n + 1) * (2 * n + 1) / 24.0 - float(np.sum(counts**3 - counts)) / 48.0
    return float((ranks[d > 0].sum() - n * (n + 1) / 4.0) / math.sqrt(variance))


def entry_z(before: np.ndarray, after: np.ndarray) -> float:
    """How clearly a model's per-row held-out squared errors fall below another's: the larger of the
    paired mean's z and Wilcoxon's signed-rank z. The mean's z is what many rows give; the ranks'
    what few rows give when a handful of them carry most of the error (36 poses of single-joint
    sweeps): either passing the selection threshold is evidence."""
    return max(paired_z(before, after), signed_rank_z(before, after))


def row_squares(residual: np.ndarray) -> np.ndarray:
    """(N,) squared position error of each row, the parts of a row added up; a (N,) array is
    taken as such squares already (a fit's ``heldout_squares``)."""
    residual = np.asarray(residual)
    if residual.ndim == 1:
        return residual
    if residual.ndim == 2:
        return np.sum(residual**2, axis=1)
    return np.sum(residual**2, axis=(0, 2))


def stacked(residual: np.ndarray) -> np.ndarray:
    """(n_parts, N, 3) or (N, 3) position errors as (n_parts * N, 3) points."""
    residual = np.asarray(residual)
    return residual if residual.ndim == 2 else residual.reshape(-1, 3)
