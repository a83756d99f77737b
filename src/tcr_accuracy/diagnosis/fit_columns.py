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
        self.sources = sources  # [(g (N, r, P_e) of one effect, the kept columns of it (k_e,)), one or more]
        first = sources[0][0]
        self.shape = (first.shape[0], first.shape[1], sum(c.size for _, c in sources))

    def __getitem__(self, key) -> np.ndarray:
        """The gathered array (N, r, k), indexed (what a caller reading the columns needs)."""
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


class ChainedJacobian:
    """One part's chained Jacobian (N, r, k) of the residual in the scaled parameters phi,
    J = W G S (G: the kept sensitivity columns, S: their scales, W: the part's per-point whitening
    of the position rows, or none), never held whole: its products J^T J, J^T r and J s are taken
    a chunk of poses at a time from the effects' own arrays. Whole, it was (10^4, 3, ~450) floats,
    108 MB per model evaluated with the cyclic effect, 1.1 GB at 10^5 poses.
    """

    def __init__(self, sensitivity: Sensitivity, idx: np.ndarray, scale: np.ndarray, whitening=None):
        """``sensitivity``: the part's kept columns; ``idx`` (k_part,): their positions among the
        model's k parameters; ``scale`` (k,): every parameter's scale; ``whitening``: (N, 3, 3) or None."""
        self.sensitivity, self.idx, self.scale, self.whitening = sensitivity, idx, scale, whitening
        n, r, _ = sensitivity.shape
        self.shape = (n, r, scale.size)

    def block(self, rows) -> np.ndarray:
        """J[rows] (len(rows), r, k) for a slice or an index array of rows (a chunk: this is a copy)."""
        n = len(range(*rows.indices(self.shape[0]))) if isinstance(rows, slice) else len(rows)
        out = np.zeros((n, self.shape[1], self.shape[2]))
        offset = 0
        for g, cols in self.sensitivity.sources:
            where = self.idx[offset:offset + cols.size]
            offset += cols.size
            part = g[rows]
            if not _is_range(cols, part.shape[2]):
                part = part[:, :, cols]
            if where.size and _is_range(where - where[0], where.size):  # a run of columns: written in place
                np.multiply(part, self.scale[where], out=out[:, :, where[0]:where[0] + where.size])
            else:
                out[:, :, where] = part * self.scale[where]
        if self.whitening is not None:  # weighted as the residual rows are
            out[:, :3] = np.einsum("nij,njk->nik", self.whitening[rows], out[:, :3])
        return out

    def chunks(self, rows):
        """The rows (None: all) a chunk at a time: slices, or parts of the index array."""
        if rows is None:
            return [slice(s, s + Sensitivity.CHUNK) for s in range(0, self.shape[0], Sensitivity.CHUNK)]
        return [rows[s:s + Sensitivity.CHUNK] for s in range(0, len(rows), Sensitivity.CHUNK)]

    def transposed_times(self, residual: np.ndarray, rows) -> np.ndarray:
        """J[rows]^T residual (k,) for residual (len(rows) or N, r): the effects' columns times the
        residual (whitened back), gathered and scaled once at the end (no (rows, r, k) copy)."""
        total = np.zeros(self.shape[2])
        if self.whitening is not None:
            residual = residual.copy()
            w = self.whitening if rows is None else self.whitening[rows]
            residual[:, :3] = np.einsum("nji,nj->ni", w, residual[:, :3])
        offset = 0
        for g, cols in self.sensitivity.sources:
            where = self.idx[offset:offset + cols.size]
            offset += cols.size
            if hasattr(g, "transposed_times"):  # held as factors: the product from them
                total[where] += g.transposed_times(residual, rows)[cols] * self.scale[where]
                continue
            product = np.zeros(g.shape[2])
            for start in range(0, residual.shape[0], Sensitivity.CHUNK):
                at = slice(start, start + Sensitivity.CHUNK)
                product += np.tensordot(g[at] if rows is None else g[rows[at]], residual[at], axes=([0, 1], [0, 1]))
            total[where] += product[cols] * self.scale[where]
        return total

    def times(self, step: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """J[rows] @ step (len(rows), r), a chunk of rows at a time."""
        out = np.empty((len(rows), self.shape[1]))
        for start in range(0, len(rows), Sensitivity.CHUNK):
            at = slice(start, start + Sensitivity.CHUNK)
            out[at] = self.block(rows[at]) @ step
        return out


def _is_range(index: np.ndarray, n: int) -> bool:
    """Whether index is 0, 1, .., n - 1."""
    return index.size == n and bool(np.array_equal(index, np.arange(n)))


def gram_matrix(jacs: list[ChainedJacobian], rows) -> np.ndarray:
    """J^T J over the given rows (None: all) of the parts' Jacobians (N, r, k), a chunk of rows at a time."""
    k = jacs[0].shape[2]
    total = np.zeros((k, k))
    for j in jacs:
        for chunk in j.chunks(rows):
            block = j.block(chunk).reshape(-1, k)
            total += block.T @ block
    return total


def gradient_vector(jacs: list[ChainedJacobian], residual: list[np.ndarray], rows, n: int) -> np.ndarray:
    """J^T r for residuals (len(rows), r) on the given rows (None: all N = n rows)."""
    total = np.zeros(jacs[0].shape[2])
    for j, r in zip(jacs, residual):
        total += j.transposed_times(r, rows)
    return total


__all__ = ["ChainedJacobian", "Columns", "Sensitivity", "gradient_vector", "gram_matrix"]
