"""A model's columns of the identification Jacobian (:class:`Columns`, :class:`Sensitivity`) and
the products the fit engine (:mod:`tcr_accuracy.diagnosis.fitting`) takes of them: J^T J, J^T r and
J times a step over a fold's rows, a chunk of poses at a time so that no fold copies the Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class Sensitivity:
    """A model's TCP sensitivity (N, r, k) on one part, left in its effects' own arrays: the kept
    columns of each effect's ``g`` side by side, gathered only where they are used. A model of the
    whole vocabulary with the cyclic effect is (10^4, 3, ~400) floats, 100 MB; gathered, then scaled
    into the Jacobian, it was held three times over at the diagnosis' peak."""

    #: poses gathered at once (a few MB of temporaries at a few hundred columns)
    CHUNK = 2048

    def __init__(self, sources: list):
        self.sources = sources  # [(g (N, r, P_e) of one effect, the kept columns of it (k_e,))]
        first = sources[0][0] if sources else None
        k = sum(c.size for _, c in sources)
        self.shape = (first.shape[0], first.shape[1], k) if first is not None else (0, 0, 0)

    def scaled_into(self, block: np.ndarray, idx: np.ndarray, scale: np.ndarray) -> None:
        """block[:, :, idx] = the gathered columns times scale (k,), a chunk of poses at a time."""
        offset = 0
        for g, cols in self.sources:
            where, factor = idx[offset:offset + cols.size], scale[offset:offset + cols.size]
            offset += cols.size
            for start in range(0, g.shape[0], self.CHUNK):
                stop = start + self.CHUNK
                block[start:stop, :, where] = g[start:stop][:, :, cols] * factor

    def __getitem__(self, key) -> np.ndarray:
        """The gathered array (N, r, k), indexed (what a caller reading the columns needs)."""
        if not self.sources:
            return np.zeros(self.shape)[key]
        return np.concatenate([g[:, :, cols] for g, cols in self.sources], axis=2)[key]


@dataclass(frozen=True)
class Columns:
    """The kept parameters of a model: union names and scales, per part (basis, g, index),
    and the bounds of the scaled parameters phi = theta / scale (the fit range)."""

    names: list
    scale: np.ndarray
    per_part: list
    lower: np.ndarray
    upper: np.ndarray
    penalty: np.ndarray  # (k,) smoothness-penalty weights (0: not penalised), times lambda in a fit

    def clip(self, phi: np.ndarray) -> np.ndarray:
        """phi moved into the bounds."""
        return np.clip(phi, self.lower, self.upper)


def moved_rows(jac: np.ndarray, rows: np.ndarray, step: np.ndarray) -> np.ndarray:
    """jac[rows] @ step, (len(rows), r), a chunk of rows at a time (jac[rows] whole was a copy of a
    fifth of the Jacobian per fold)."""
    out = np.empty((len(rows), jac.shape[1]))
    for start in range(0, len(rows), Sensitivity.CHUNK):
        part = slice(start, start + Sensitivity.CHUNK)
        out[part] = jac[rows[part]] @ step
    return out


def gram_matrix(jacs: list[np.ndarray], rows) -> np.ndarray:
    """J^T J over the given rows (None: all) of the parts' Jacobians (N, r, k)."""
    k = jacs[0].shape[2]
    if rows is None:
        return sum(j.reshape(-1, k).T @ j.reshape(-1, k) for j in jacs)
    total = np.zeros((k, k))
    for j in jacs:  # a fold's rows a chunk at a time: j[rows] whole was a copy of a fifth of the Jacobian
        for start in range(0, len(rows), Sensitivity.CHUNK):
            block = j[rows[start:start + Sensitivity.CHUNK]].reshape(-1, k)
            total += block.T @ block
    return total


def gradient_vector(jacs: list[np.ndarray], residual: list[np.ndarray], rows, n: int) -> np.ndarray:
    """J^T r for residuals on the given rows (None: all): zero-padded to all rows, so the
    Jacobians' rows are never copied."""
    k = jacs[0].shape[2]
    total = np.zeros(k)
    for j, r in zip(jacs, residual):
        if rows is not None:
            padded = np.zeros((n, r.shape[1]))
            padded[rows] = r
            r = padded
        total += j.reshape(-1, k).T @ r.ravel()
    return total


__all__ = ["Columns", "Sensitivity", "gradient_vector", "gram_matrix", "moved_rows"]
