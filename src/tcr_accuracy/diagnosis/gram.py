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
from .least_squares import FactorCache

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
class TableGroup:
    """One joint's columns of an angle table on one part: the sensitivity they come from, the joint,
    its sparse B-spline design (N, nb) and modes (nb, m), their global columns (m,) and scales (m,):
    column c's whitened Jacobian rows are W J_q[:, :, joint] (design @ modes)[:, c] scales[c]."""

    sensitivity: object
    joint: int
    design: object
    modes: np.ndarray
    columns: np.ndarray
    scales: np.ndarray


def _run(index: np.ndarray):
    """index as a slice when it is a run of consecutive integers, else itself."""
    if index.size and np.all(np.diff(index) == 1):
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


def _add_at(target: np.ndarray, rows: np.ndarray, columns: np.ndarray, values: np.ndarray) -> None:
    """target[rows, columns] += values, in place through slices where the indices are runs."""
    if not rows.size or not columns.size:
        return
    r, c = _run(rows), _run(columns)
    if isinstance(r, slice) and isinstance(c, slice):
        target[r, c] += values
    else:
        target[np.ix_(np.arange(target.shape[0])[r], np.arange(target.shape[1])[c])] += values


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
        # every frame is measured on the campaign's rows: a fold holds out the same rows of each
        counts = {part.q.shape[0] for part in parts}
        if len(counts) != 1:
            raise ValueError(f"the measured frames hold different numbers of rows: {sorted(counts)}")
        (self.n_rows,) = counts
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
        #: the penalised columns' factors the fits keep (:class:`~tcr_accuracy.diagnosis.least_squares.FactorCache`):
        #: they hold these blocks' numbers, and go when the blocks change
        self.factors = FactorCache()

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
        """Add the Gram blocks of the given effects' columns into ``targets`` (each (K, K) over the
        layout's columns), and with ``old_effects`` (other columns already held) the blocks of those
        against the new ones, straight into the final arrays. ``targets``: the total (or None, when it
        is the sum of the first assignment's folds), then per assignment per fold.

        Columns held as dense rows are multiplied a chunk of poses at a time. An angle table's columns
        (:meth:`_structured`) are not made: their blocks come from the table's B-spline designs
        (:meth:`_table_blocks`)."""
        old_effects = list(old_effects or [])
        for p in range(len(self.parts)):
            structured = {e: g for e in list(effects) + old_effects if (g := self._structured(p, e)) is not None}
            dense_new = [e for e in effects if e not in structured]
            dense_old = [e for e in old_effects if e not in structured]
            new_groups = [grp for e in effects if e in structured for grp in self._groups(p, e, structured[e])]
            old_groups = [grp for e in old_effects if e in structured for grp in self._groups(p, e, structured[e])]
            self._dense_blocks(p, dense_new, dense_old, new_groups, old_groups if dense_new else [], targets)
            if new_groups:
                self._table_blocks(p, new_groups, old_groups, targets)

    def _dense_blocks(self, p: int, dense_new, dense_old, new_groups, old_groups, targets) -> None:
        """The dense columns' blocks (new against new and old), and, from the same chunks of dense rows,
        the blocks of the table groups against them: ``new_groups`` against every dense column given,
        ``old_groups`` against the new dense columns only."""
        total, held = targets
        new_cols, old_cols = self.layout.columns_of(dense_new), self.layout.columns_of(dense_old)
        if not new_cols.size and not new_groups:
            return
        both_cols = np.concatenate([old_cols, new_cols])
        # per group: (its dense columns, accumulators (nb, width) for the total and per assignment per fold)
        crossing = [(grp, both_cols, len(dense_old)) for grp in new_groups] + \
            [(grp, new_cols, None) for grp in old_groups]
        crossing = [(grp, cols, which) for grp, cols, which in crossing if cols.size]
        sums = [(None if total is None else np.zeros((grp.design.shape[1], cols.size)),
                 [[np.zeros((grp.design.shape[1], cols.size)) for _ in tests] for tests in self.tests])
                for grp, cols, _ in crossing]
        jacobians = {}

        def add(target, block, old):
            _add_at(target, new_cols, new_cols, block.T @ block)
            if old is not None:
                cross = old.T @ block
                _add_at(target, old_cols, new_cols, cross)
                _add_at(target, new_cols, old_cols, cross.T)

        for rows in self._chunks():
            fold_rows = self._fold_rows(rows)
            block = self._block(p, rows, dense_new) if new_cols.size else None
            old = self._block(p, rows, dense_old) if old_cols.size and (block is not None or new_groups) else None
            if block is not None:
                if total is not None:
                    add(total, block.reshape(-1, new_cols.size), None if old is None else old.reshape(-1, old_cols.size))
                for r, per_fold in enumerate(fold_rows):
                    for f, at in enumerate(per_fold):
                        if at.size:
                            add(held[r][f], block[at].reshape(-1, new_cols.size),
                                None if old is None else old[at].reshape(-1, old_cols.size))
            for (grp, cols, split), (sum_total, sum_held) in zip(crossing, sums):
                key = id(grp.sensitivity)
                if key not in jacobians:
                    jacobians[key] = self._whitened_joint_jacobian(p, grp.sensitivity, rows)
                jac = jacobians[key][:, :, grp.joint]  # (n, r_g)
                if split is None:
                    dense = block
                elif block is None or old is None:
                    dense = old if block is None else block
                else:
                    dense = np.concatenate([old, block], axis=2)
                z = np.einsum("nr,nrc->nc", jac, dense[:, :jac.shape[1]])  # (n, width): J_joint^T W^2 J_dense
                design = grp.design[rows]
                if sum_total is not None:
                    sum_total += design.T @ z
                for r, per_fold in enumerate(fold_rows):
                    for f, at in enumerate(per_fold):
                        if at.size:
                            sum_held[r][f] += design[at].T @ z[at]
            jacobians.clear()
        for (grp, cols, _), (sum_total, sum_held) in zip(crossing, sums):
            for target, value in ([(total, sum_total)] if total is not None else []) + \
                    [(held[r][f], sum_held[r][f]) for r in range(len(self.tests)) for f in range(len(self.tests[r]))]:
                cross = (grp.modes.T @ value) * grp.scales[:, None]
                _add_at(target, grp.columns, cols, cross)
                _add_at(target, cols, grp.columns, cross.T)

    def _table_blocks(self, p: int, new_groups, old_groups, targets) -> None:
        """The blocks of the table groups ``new_groups`` against themselves and ``old_groups``, per fold:
        M_a^T (B_a^T D_ab B_b) M_b, D_ab the diagonal of the whitened joint Jacobians' products
        (J_a^T W^2 J_b per pose) on the fold's rows, B the groups' sparse B-spline designs."""
        total, held = targets
        jacobians = {}
        for grp in new_groups + old_groups:
            key = id(grp.sensitivity)
            if key not in jacobians:
                jacobians[key] = self._whitened_joint_jacobian(p, grp.sensitivity, slice(None))
        pairs = [(a, b) for i, a in enumerate(new_groups) for b in new_groups[i:]] + \
            [(a, b) for a in new_groups for b in old_groups]
        row_sets = ([(total, None)] if total is not None else []) + \
            [(held[r][f], test) for r, tests in enumerate(self.tests) for f, test in enumerate(tests)]
        for a, b in pairs:
            ja, jb = jacobians[id(a.sensitivity)], jacobians[id(b.sensitivity)]
            rows = min(ja.shape[1], jb.shape[1])
            weight = np.einsum("nr,nr->n", ja[:, :rows, a.joint], jb[:, :rows, b.joint])  # (N,)
            for target, test in row_sets:
                da, db, w = (a.design, b.design, weight) if test is None else \
                    (a.design[test], b.design[test], weight[test])
                inner = (da.multiply(w[:, None]).tocsr().T @ db).toarray()  # (nb_a, nb_b)
                value = (a.modes.T @ inner @ b.modes) * np.outer(a.scales, b.scales)
                _add_at(target, a.columns, b.columns, value)
                if a is not b:
                    _add_at(target, b.columns, a.columns, value.T)

    def _structured(self, p: int, e: str):
        """Effect e's sensitivity on part p when its Gram blocks are taken from its factors: a
        joint-columns product (:class:`~tcr_accuracy.diagnosis.error_map.JointColumnsSensitivity`)
        whose values are sparse B-spline designs times modes (an angle table's,
        :meth:`~tcr_accuracy.effects.angle_table.TableValues.sparse_factors`); else None."""
        g = self.bases[e].per_part[p].g
        if isinstance(g, JointColumnsSensitivity) and hasattr(g.values, "sparse_factors") and \
                (self.parts[p].whitening is None or g.shape[1] >= 3):
            return g
        return None

    def _groups(self, p: int, e: str, g) -> list:
        """Effect e's columns on part p, one :class:`TableGroup` per joint of its table."""
        basis = self.bases[e]
        index = basis.index[p]
        out = []
        for _, design, modes, positions in g.values.sparse_factors():
            union = index[g.columns[positions]]
            out.append(TableGroup(g, int(g.joint[positions[0]]), design, modes, self.layout.offset[e] + union,
                                  basis.scales[union]))
        return out

    def _whitened_joint_jacobian(self, p: int, g, rows) -> np.ndarray:
        """(n, r_g, n_joints) the sensitivity's joint Jacobian on the rows, its position rows whitened."""
        jac = np.array(g.jac_q[rows], dtype=float)
        whitening = self.parts[p].whitening
        if whitening is not None:
            jac[:, :3] = np.einsum("nij,njk->nik", whitening[rows], jac[:, :3])
        return jac

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
        self.factors.clear()
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
        per fold), (total, per assignment per fold)). An angle table's columns from its designs:
        M^T B^T (J_joint^T W^2 r per pose)."""
        k = self.layout.n_columns
        total = np.zeros(k)
        held = [[np.zeros(k) for _ in tests] for tests in self.tests]
        c_total, c_held = 0.0, [[0.0 for _ in tests] for tests in self.tests]
        for p, part in enumerate(self.parts):
            structured = {e: g for e in effects if (g := self._structured(p, e)) is not None}
            dense = [e for e in effects if e not in structured]
            columns = self.layout.columns_of(dense)
            groups = [grp for e in effects if e in structured for grp in self._groups(p, e, structured[e])]
            sums = [(np.zeros(grp.design.shape[1]), [[np.zeros(grp.design.shape[1]) for _ in tests]
                                                     for tests in self.tests]) for grp in groups]
            for rows in self._chunks():
                fold_rows = self._fold_rows(rows)
                r = residual[p][rows]
                if part.whitening is not None:
                    r = r.copy()
                    r[:, :3] = np.einsum("nij,nj->ni", part.whitening[rows], r[:, :3])
                c_total += float(np.sum(r**2))
                for a, per_fold in enumerate(fold_rows):
                    for f, at in enumerate(per_fold):
                        c_held[a][f] += float(np.sum(r[at] ** 2))
                if columns.size:
                    block = self._block(p, rows, dense)
                    total[columns] += block.reshape(-1, columns.size).T @ r.ravel()
                    for a, per_fold in enumerate(fold_rows):
                        for f, at in enumerate(per_fold):
                            if at.size:
                                held[a][f][columns] += block[at].reshape(-1, columns.size).T @ r[at].ravel()
                jacobians = {}
                for grp, (sum_total, sum_held) in zip(groups, sums):
                    key = id(grp.sensitivity)
                    if key not in jacobians:
                        jacobians[key] = self._whitened_joint_jacobian(p, grp.sensitivity, rows)
                    jac = jacobians[key][:, :, grp.joint]
                    u = np.einsum("nr,nr->n", jac, r[:, :jac.shape[1]])
                    design = grp.design[rows]
                    sum_total += design.T @ u
                    for a, per_fold in enumerate(fold_rows):
                        for f, at in enumerate(per_fold):
                            if at.size:
                                sum_held[a][f] += design[at].T @ u[at]
            for grp, (sum_total, sum_held) in zip(groups, sums):
                total[grp.columns] += (grp.modes.T @ sum_total) * grp.scales
                for a, tests in enumerate(self.tests):
                    for f in range(len(tests)):
                        held[a][f][grp.columns] += (grp.modes.T @ sum_held[a][f]) * grp.scales
        return (total, held), (c_total, c_held)

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
        self.factors.clear()  # the blocks made again may differ in round-off


def sensitivity_times(g, theta: np.ndarray) -> np.ndarray:
    """(N, r, m) g (N, r, P) times the parameter vectors theta (P, m), a chunk of poses at a time; g
    may be held as its factors (:class:`~tcr_accuracy.diagnosis.error_map.JointColumnsSensitivity`)."""
    if isinstance(g, JointColumnsSensitivity) and hasattr(g.values, "sparse_factors"):
        return _table_times(g, theta)
    if isinstance(g, JointColumnsSensitivity):
        return g.times(theta)
    n, r, k = g.shape
    out = np.empty((n, r, theta.shape[1]))
    for start in range(0, n, 4 * CHUNK):
        at = slice(start, start + 4 * CHUNK)
        block = np.asarray(g[at])
        out[at] = (block.reshape(-1, k) @ theta).reshape(block.shape[0], r, theta.shape[1])
    return out


def _table_times(g, theta: np.ndarray) -> np.ndarray:
    """:func:`sensitivity_times` of an angle table's sensitivity: per joint, its B-spline design times
    (modes times the joint's parameters), times the joint's column of the error Jacobian; the
    table's (N, k) values are never made."""
    n, r, _ = g.shape
    theta = np.asarray(theta)[g.columns]
    out = np.zeros((n, r, theta.shape[1]))
    for _, design, modes, positions in g.values.sparse_factors():
        weights = theta[positions]
        if not np.any(weights):
            continue
        joint = int(g.joint[positions[0]])
        out += g.jac_q[:, :, joint, None] * np.asarray(design @ (modes @ weights))[:, None, :]
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
