"""The k-nearest-neighbour averaging matrix written out by brute-force distances, the independent
reference the structure test's sparse neighbour sums are checked against (shared by its test files)."""

from __future__ import annotations

import numpy as np


def knn_mean(points: np.ndarray, k: int) -> np.ndarray:
    """(N, N) dense matrix averaging each point's k nearest other points, by brute-force distances."""
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    out = np.zeros_like(d)
    for i, row in enumerate(d):
        out[i, np.argsort(row)[:k]] = 1.0 / k
    return out
