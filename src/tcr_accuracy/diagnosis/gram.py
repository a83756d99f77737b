"""One Gram matrix per fold: the products every candidate model of the diagnosis is fitted and
scored from.

The fit engine's identification Jacobian J holds one column per parameter of every effect built
so far (the whole identifiable vocabulary, a few hundred columns), in the scaled parameters
phi = theta / scale, each measured frame's position rows whitened as the fit weighs them
(:class:`~tcr_accuracy.diagnosis.bases.Part`). A candidate model is a set of those columns. They
were gathered and multiplied again for every model of every fold; here they are multiplied once
per fold assignment, over each fold's held-out rows (every row once per assignment),

    H_f = J_f^T J_f  (K, K),    g_f = J_f^T r_f  (K,),    c_f = r_f^T r_f,

where r is the residual at the engine's *anchor* (an exact fit, :class:`Anchor`), a chunk of poses
at a time, so that memory is bounded by the chunk and the K x K blocks, not by the poses. The
total over all rows is the sum of an assignment's folds; a fold's training blocks are the total
less its own. For a step d from the anchor (zero outside a model's columns, except where the
anchor has parameters the model lacks: there d takes them back to zero) the sum of squares over a
fold's rows is

    SSQ_f(d) = c_f + 2 g_f^T d + d^T H_f d,

from the sub-blocks of the model's columns alone (:meth:`FoldGrams.quadratic`). Each row's own
residual r + J d, which the paired tests read, is its effects' columns times their part of d
(:func:`moved_rows`), without gathering the columns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .error_map import JointColumnsSensitivity

#: poses whose Jacobian rows are gathered at once (n x r x K floats: ~12 MB at 500 columns)
CHUNK = 512


class ColumnLayout:
    """Where each effect's parameters (its union columns, :class:`~tcr_accuracy.diagnosis.bases.UnionBasis`)
    sit among the K columns of the whole vocabulary, and their scales, bounds and penalty weights
    in the scaled parameters phi."""

    def __init__(self, bases: dict, effects=None):
        self.effects = list(bases if effects is None else effects)
        self.offset, self.size = {}, {}
        at = 0
        for e in self.effects:
            self.offset[e], self.size[e] = at, len(bases[e].names)
            at += self.size[e]
        self.n_columns = at

        def joined(field):
            arrays = [np.asarray(getattr(bases[e], field), dtype=float) for e in self.effects]
            return np.concatenate(arrays) if arrays else np.zeros(0)

        #: (K,) each column's scale [its SI unit per unit of phi], fit range in phi, penalty weight
        self.scale = joined("scales")
        self.lower = joined("fit_lower") / np.where(self.scale > 0, self.scale, 1.0)
        self.upper = joined("fit_upper") / np.where(self.scale > 0, self.scale, 1.0)
        self.penalty = joined("penalty")
        self.names = [n for e in self.effects for n in bases[e].names]

    def indices(self, effects, keep: dict) -> np.ndarray:
        """(k,) the global columns of a model: each effect's kept union columns, in the given order."""
        parts = [self.offset[e] + np.asarray(keep[e], dtype=int) for e in effects]
        return np.concatenate(parts) if parts else np.zeros(0, dtype=int)

    def columns_of(self, effects) -> np.ndarray:
        """(K_e,) every column of the given effects."""
        parts = [np.arange(self.offset[e], self.offset[e] + self.size[e]) for e in effects]
        return np.concatenate(parts) if parts else np.zeros(0, dtype=int)


@dataclass(frozen=True)
class Anchor:
    """Where the engine's linear model is taken: parameters phi (K,) of the whole layout (zero outside
    the anchor's model) and the exact residual there, per part (N, r) [m, and weighted rad]. A model's
    residual at phi is r + J (phi - anchor.phi), exact at the anchor and to first order around it."""

    effects: tuple
    phi: np.ndarray
    residual: list


@dataclass(frozen=True)
class Quadratic:
    """A sum of squares c + 2 g^T d + d^T H d over some rows, in a model's columns (step d)."""

    gram: np.ndarray
    gradient: np.ndarray
    constant: float

    def __sub__(self, other: "Quadratic") -> "Quadratic":
        return Quadratic(self.gram - other.gram, self.gradient - other.gradient, self.constant - other.constant)

    def value(self, step: np.ndarray) -> float:
        return float(self.constant + 2.0 * self.gradient @ step + step @ self.gram @ step)


class FoldGrams:
    """J^T W J, J^T W r and r^T W r of the whole vocabulary's columns, over all rows and over each
    fold's held-out rows in every fold assignment (see the module's docstring).

    Parameters
    ----------
    parts : list of Part
        The measured frames (their whitening weighs the position rows).
    bases : dict of str to UnionBasis
        Every effect built so far, linearised on every part.
    repeats : list of list of (train, test)
        The fold assignments.
    """

    def __init__(self, parts: list, bases: dict, repeats: list):
        self.parts, self.bases = parts, bases
        self.n_rows = parts[0].q.shape[0]
        self.tests = [[np.sort(np.asarray(test, dtype=int)) for _, test in folds] for folds in repeats]
        #: per assignment, (N,) the fold whose held-out rows hold each row (-1: none)
        self.fold_of = []
        for tests in self.tests:
            label = np.full(self.n_rows, -1, dtype=int)
            for f, test in enumerate(tests):
                label[test] = f
            self.fold_of.append(label)
        first = self.tests[0] if self.tests else []
        # the first assignment's held-out rows cover every row once: the total is the sum of its folds
        self._total_from_folds = bool(first) and sum(t.size for t in first) == self.n_rows and \
            np.array_equal(np.sort(np.concatenate(first)), np.arange(self.n_rows))
        self.layout = ColumnLayout(bases)
        self.total, self.held = self._grams(self.layout.effects)
        self.anchor: Anchor | None = None
        #: how far the linear model misses the exact kinematics (set by the engine; None: not judged)
        self.curvature: float | None = None
        self.gradients = None  # (total (K,), per assignment per fold (K,)) at the anchor
        self.constants = None  # (total, per assignment per fold)

    # -- the products, a chunk of poses at a time -----------------------------------------
    def _block(self, p: int, rows: slice, effects) -> np.ndarray:
        """(n, r, K_e) the whitened Jacobian rows of part p for the given effects' columns (scaled), the
        effects side by side in the given order, each with all its columns."""
        part = self.parts[p]
        n = len(range(*rows.indices(self.n_rows)))
        out = np.zeros((n, part.rows_per_pose, sum(self.layout.size[e] for e in effects)))
        start = 0
        for e in effects:
            basis = self.bases[e]
            index = basis.index[p]
            at, start = start, start + self.layout.size[e]
            if not index.size:
                continue
            values = basis.per_part[p].g[rows]
            scale = basis.scales[index]
            if np.array_equal(index, np.arange(index.size)):  # the part holds the effect's columns in order
                np.multiply(values, scale, out=out[:, :values.shape[1], at:at + index.size])
            else:
                out[:, :values.shape[1], at + index] = values * scale
        if part.whitening is not None:
            out[:, :3] = np.einsum("nij,njk->nik", part.whitening[rows], out[:, :3])
        return out

    def _chunks(self):
        for start in range(0, self.n_rows, CHUNK):
            yield slice(start, min(start + CHUNK, self.n_rows))

    def _fold_rows(self, rows: slice):
        """Per assignment, per fold: the positions within the chunk of its held-out rows."""
        out = []
        for tests in self.tests:
            per_fold = []
            for test in tests:
                lo, hi = np.searchsorted(test, [rows.start, rows.stop])
                per_fold.append(test[lo:hi] - rows.start)
            out.append(per_fold)
        return out

    def _accumulate(self, effects, old_effects, targets: list) -> None:
        """Add the Gram blocks of the given effects' columns into ``targets`` (each (K, K), its last
        K_e rows and columns theirs), and with ``old_effects`` (the columns before them) the blocks
        of those against the new ones: a chunk of poses at a time, straight into the final arrays.
        ``targets``: the total (or None, when it is the sum of the first assignment's folds), then per
        assignment per fold."""
        width = sum(self.layout.size[e] for e in effects)
        old_width = sum(self.layout.size[e] for e in old_effects) if old_effects else 0
        total, held = targets

        def add(target, block, old):
            own = target[old_width:, old_width:]
            own += block.T @ block
            if old is not None:
                cross = old.T @ block
                target[:old_width, old_width:] += cross
                target[old_width:, :old_width] += cross.T

        for rows in self._chunks():
            fold_rows = self._fold_rows(rows)
            for p in range(len(self.parts)):
                block = self._block(p, rows, effects)
                old = self._block(p, rows, old_effects) if old_effects else None
                if total is not None:
                    add(total, block.reshape(-1, width), None if old is None else old.reshape(-1, old_width))
                for r, per_fold in enumerate(fold_rows):
                    for f, at in enumerate(per_fold):
                        if at.size:
                            add(held[r][f], block[at].reshape(-1, width),
                                None if old is None else old[at].reshape(-1, old_width))

    def _grams(self, effects, old: tuple | None = None) -> tuple:
        """(total, held) Gram blocks over the layout's K columns: the given effects' (the last ones)
        multiplied out, the blocks of ``old`` (total, held) of the columns before them copied in."""
        k = self.layout.n_columns
        k_old = 0 if old is None else old[0].shape[0]

        def made(previous):
            out = np.zeros((k, k))
            if previous is not None:
                out[:k_old, :k_old] = previous
            return out

        held = [[made(None if old is None else old[1][r][f]) for f in range(len(tests))]
                for r, tests in enumerate(self.tests)]
        total = None if self._total_from_folds else made(None if old is None else old[0])
        self._accumulate(effects, self.layout.effects[:len(self.layout.effects) - len(effects)] or None,
                         (total, held))
        if total is None:
            total = held[0][0].copy()
            for block in held[0][1:]:
                total += block
        return total, held

    def extend(self, effects) -> None:
        """New effects joined the engine's bases (effects of last resort): their columns are added to
        every block (their products with the columns already held, and their own)."""
        effects = [e for e in effects if e not in self.layout.offset]
        if not effects:
            return
        old = (self.total, self.held_blocks())
        self.total, self.held = None, None  # the old blocks are copied into the new ones as they are made
        self.layout = ColumnLayout(self.bases, list(self.layout.effects) + effects)
        self.total, self.held = self._grams(effects, old)
        del old
        self.curvature = None
        if self.anchor is not None:  # the anchor's products, for the new columns only
            k_old = self.anchor.phi.size
            phi = np.concatenate([self.anchor.phi, np.zeros(self.layout.n_columns - k_old)])
            self.anchor = Anchor(self.anchor.effects, phi, self.anchor.residual)
            (total, held), constants = self.residual_products(self.anchor.residual, effects)
            old_total, old_held = self.gradients
            self.gradients = (np.concatenate([old_total, total[k_old:]]),
                              [[np.concatenate([o, n[k_old:]]) for o, n in zip(os, ns)] for os, ns in zip(old_held, held)])

    def set_anchor(self, anchor: Anchor) -> None:
        """The residual the linear model is taken at: J^T W r and r^T W r over all rows and each fold."""
        self.anchor = anchor
        self.gradients, self.constants = self.residual_products(anchor.residual, self.layout.effects)

    def residual_products(self, residual: list, effects) -> tuple:
        """J^T W r (K,) over the given effects' columns (zero elsewhere) and r^T W r, over all rows and
        over each fold's held-out rows, for a residual r per part (N, r) [m]: ((total, per assignment
        per fold), (total, per assignment per fold))."""
        k = self.layout.n_columns
        columns = self.layout.columns_of(effects)
        total = np.zeros(columns.size)
        held = [[np.zeros(columns.size) for _ in tests] for tests in self.tests]
        c_total, c_held = 0.0, [[0.0 for _ in tests] for tests in self.tests]
        for rows in self._chunks():
            fold_rows = self._fold_rows(rows)
            for p, part in enumerate(self.parts):
                block = self._block(p, rows, effects)
                r = residual[p][rows]
                if part.whitening is not None:
                    r = r.copy()
                    r[:, :3] = np.einsum("nij,nj->ni", part.whitening[rows], r[:, :3])
                total += block.reshape(-1, columns.size).T @ r.ravel()
                c_total += float(np.sum(r**2))
                for a, per_fold in enumerate(fold_rows):
                    for f, at in enumerate(per_fold):
                        if at.size:
                            w = r[at]
                            held[a][f] += block[at].reshape(-1, columns.size).T @ w.ravel()
                            c_held[a][f] += float(np.sum(w**2))

        def spread(values):
            out = np.zeros(k)
            out[columns] = values
            return out

        return (spread(total), [[spread(h) for h in hs] for hs in held]), (c_total, c_held)

    # -- a model's sub-blocks ---------------------------------------------------------------
    def quadratic(self, index: np.ndarray, fixed: np.ndarray | None = None, repeat=None, fold=None,
                  products=None) -> Quadratic:
        """The sum of squares over all rows (or fold ``fold`` of assignment ``repeat``'s held-out
        rows) as a function of the step d on the columns ``index``, the other columns stepped by
        ``fixed`` (K,) (zero on ``index``; None: not stepped). ``products``: the residual's
        (:meth:`residual_products`) when it is not the anchor's."""
        gradients, constants = products if products is not None else (self.gradients, self.constants)
        if repeat is None:
            gram, gradient, constant = self.total, gradients[0], constants[0]
        else:
            gram, gradient, constant = self.held_blocks()[repeat][fold], gradients[1][repeat][fold], \
                constants[1][repeat][fold]
        sub = gram[np.ix_(index, index)]
        b = gradient[index]
        c = float(constant)
        if fixed is not None and np.any(fixed):
            moved = np.flatnonzero(fixed)
            step = fixed[moved]
            b = b + gram[np.ix_(index, moved)] @ step
            c += float(2.0 * gradient[moved] @ step + step @ gram[np.ix_(moved, moved)] @ step)
        return Quadratic(sub, b, c)

    def held_blocks(self) -> list:
        """Per assignment, per fold, the held-out rows' Gram block (K, K), made again if released."""
        if self.held is None:
            k = self.layout.n_columns
            held = [[np.zeros((k, k)) for _ in tests] for tests in self.tests]
            self._accumulate(self.layout.effects, None, (None, held))
            self.held = held
        return self.held

    def release(self) -> None:
        """Let the held-out rows' Gram blocks go (the total, the anchor and its products stay: a fit's
        standard errors and every cached fit's rows are read from those); a new model's fit makes
        them again. The diagnosis calls it once its models are fitted, before its residual tests
        (5 blocks of 25 MB with a fine angle table at 10^4 poses)."""
        self.held = None

    def nbytes(self) -> int:
        held = self.held or []
        return int(self.total.nbytes + sum(h.nbytes for hs in held for h in hs))


def sensitivity_times(g, theta: np.ndarray) -> np.ndarray:
    """(N, r, m) g (N, r, P) times the parameter vectors theta (P, m), a chunk of poses at a time; g
    may be held as its factors (:class:`~tcr_accuracy.diagnosis.error_map.JointColumnsSensitivity`)."""
    if isinstance(g, JointColumnsSensitivity):
        return g.times(theta)
    n, r, k = g.shape
    out = np.empty((n, r, theta.shape[1]))
    for start in range(0, n, 4 * CHUNK):
        at = slice(start, start + 4 * CHUNK)
        block = np.asarray(g[at])
        out[at] = (block.reshape(-1, k) @ theta).reshape(block.shape[0], r, theta.shape[1])
    return out


def moved_rows(bases: dict, layout: ColumnLayout, p: int, steps: np.ndarray, n_rows: int, rows_per_pose: int) \
        -> np.ndarray:
    """(N, r, m) J d of part p, unweighted (metres, and weighted rad for orientation rows), for the
    steps d (K, m) of the whole layout (phi units): each effect's columns times its part of the
    steps, never gathered."""
    out = np.zeros((n_rows, rows_per_pose, steps.shape[1]))
    for e in layout.effects:
        block = steps[layout.offset[e]:layout.offset[e] + layout.size[e]]
        if not np.any(block):
            continue
        basis = bases[e]
        index = basis.index[p]
        theta = block[index] * basis.scales[index][:, None]
        if np.any(theta):
            moved = sensitivity_times(basis.per_part[p].g, theta)
            out[:, :moved.shape[1]] += moved
    return out


__all__ = ["Anchor", "ColumnLayout", "FoldGrams", "Quadratic", "moved_rows", "sensitivity_times"]
