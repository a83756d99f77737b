"""The per-pose part of an effect's parameter Jacobian held as its nonzero entries (:class:`PoseEntries`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PoseEntries:
    """The part of a parameter Jacobian d(x)/d(params) that changes with the pose, held as its nonzero
    (error-vector entry, parameter) pairs: x[n, entry[i], column[i]] = values[n, i]. An effect whose
    every parameter moves a few entries of the error vector (a joint's tilt, the base's drift) is
    then (N, m) floats instead of (N, n_error_params, k): for lateral compliance and drift at 10^5
    poses 10 MB instead of 0.5 and 0.8 GB.

    values : ndarray of shape (N, m)
    entry, column : ndarray of shape (m,) int, distinct (entry, column) pairs
    """

    values: np.ndarray
    entry: np.ndarray
    column: np.ndarray

    @staticmethod
    def of(blocks, n: int) -> "PoseEntries":
        """From (first entry, (N, b) block, column) triples: the block's columns that are nonzero
        at some pose, as entries first, first + 1, ... of that parameter's column."""
        values, entry, column = [], [], []
        for first, block, c in blocks:
            for a in range(block.shape[1]):
                if np.any(block[:, a] != 0):
                    values.append(block[:, a])
                    entry.append(first + a)
                    column.append(c)
        return PoseEntries(np.stack(values, axis=1) if values else np.zeros((n, 0)), np.array(entry, dtype=int),
                           np.array(column, dtype=int))

    def dense(self, size: int, k: int) -> np.ndarray:
        """(N, size, k) the Jacobian written out."""
        out = np.zeros((self.values.shape[0], size, k))
        out[:, self.entry, self.column] = self.values
        return out
