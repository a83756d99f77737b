"""The fit engine of the diagnosis: effects linearised per pose, fitted on exact kinematics.

A measurement row may carry several measured frames (both hands of a humanoid, a target
on the TCP and one on the base); each frame is a *part* with its own kinematic chain
(:class:`~tcr_accuracy.model.robot.RobotModel`) and effect instances. Parameters are shared by
name across parts: ``compliance.torso_1`` or ``geometry.torso_2.dx`` is one number
whichever hand sees it, the tracker frame (``frames.base.*``) is one, and each measured
frame has its own TCP offset (``frames.tool.*``, renamed ``frames.<frame>.*`` when there
are several).

Each effect is linearised per part (:mod:`tcr_accuracy.diagnosis.bases`: each parameter's
column of the identification Jacobian). :class:`FitEngine` fits sets of effects by nonlinear least
squares (Gauss-Newton: exact batched forward kinematics as the residual, the chained
Jacobian as the constant Jacobian) and scores them by k-fold held-out error.

Residual rows per measured frame: the three position components [m], and with measured
orientation three rotation-vector components [rad] multiplied by the part's
``orientation_weight`` [m/rad] (an angle counts as the position error it makes at that
distance).

One concept, the fit engine (one class: fit, fold scores and the cyclic penalty share its state), and so
one module above 500 lines; the columns and their chunked products are in
:mod:`tcr_accuracy.diagnosis.fit_columns`.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np
from scipy.spatial.transform import Rotation

from ..model.errors import ErrorModel
from ..model.kinematics import tcp_poses
from .bases import Part, ordered
from .error_map import JoinedMaps
from .identifiability import compressed, gram_factor, identifiability
from .least_squares import DampedSolver
from .block_fit import PENALTY_GRID, SharedBlock, box_step, fit_blocks, penalty_grid
from .fit_columns import ChainedJacobian, Columns, Sensitivity, gradient_vector, gram_matrix
from .gram import Anchor, FoldGrams, moved_rows
from .fit_result import FitResult
from .paired import row_squares
from .records import ErrorStats


class FitEngine:
    """Linearised effects over one data set; fits and k-fold held-out errors.

    Parameters
    ----------
    parts : list of Part
        The measured frames (one for a single TCP), all with the same N rows.
    bases : dict of str to UnionBasis
        Every effect that may enter, linearised on every part.
    folds : list of (train, test) row index arrays, or a list of such lists
        One fold assignment, or several (repeated k-fold): each model's held-out error is then
        the mean over the assignments, so that no answer hangs on one way of splitting the rows.
    rank_tol, min_motion : identifiability thresholds (see
        :func:`~tcr_accuracy.diagnosis.identifiability.identifiability`)
    """

    def __init__(self, parts: list[Part], bases: dict, folds, rank_tol=1e-6, min_motion=0.0):
        self.parts = parts
        self.ems = [ErrorModel(p.robot) for p in parts]
        self.bases = bases
        folds = list(folds)
        #: the fold assignments (repeated k-fold); ``folds`` is the first one
        self.repeats = folds if folds and isinstance(folds[0], list) else ([folds] if folds else [])
        self.folds = self.repeats[0] if self.repeats else []
        self.rank_tol, self.min_motion = rank_tol, min_motion
        self.n_rows = parts[0].q.shape[0]
        self._full_cache: dict = {}
        #: the fits made before identifiability was last re-judged (:meth:`resize`), for :meth:`_still_valid`
        self._judged_before: dict = {}
        self._materialised = None  # (a cached fit, its remade per-row arrays): the last ones read
        self._keep_cache: dict = {}
        self._kept_cache: dict = {}  # the kept columns alone, without identifiability's report
        self._prefixes: dict = {}  # identifiability's leading effects' work, for the compressed bases
        self._compressed = None  # the bases with the poses folded away, for identify
        self._last: dict = {}  # parameter name -> last fitted scaled value (a warm start)
        self.size_factors: dict = {}  # effect -> fitted size / typical size (>= 1), see resize
        self.n_fits = 0
        #: the model whose exact fit anchors the linear model (see :meth:`grams`)
        self.anchor_effects: tuple = ("frames",)
        self._grams: FoldGrams | None = None
        self._penalty_start: dict = {}  # penalised effects -> where the last lambda search ended
        self._last_penalty_index: int | None = None  # where the last lambda search of any penalised effects ended

    def add_bases(self, bases: dict) -> None:
        """Effects joining after the engine was built (an effect of last resort, tried late):
        identifiability is judged again with them (what was fitted stays cached: effects come
        in vocabulary order, and a later one takes nothing from the sets fitted without it)."""
        self.bases.update(bases)
        self._compressed = None
        self._keep_cache.clear()
        self._kept_cache.clear()
        if self._grams is not None:
            self._grams.extend(list(bases))

    def reset(self, anchor=None) -> None:
        """Forget every fit, identifiability judgement and Gram block (the bases were linearised
        again); the last fitted values stay as warm starts. ``anchor``: the effects whose exact fit
        anchors the linear model from now on (default: as before)."""
        self._compressed = None
        self._keep_cache.clear()
        self._kept_cache.clear()
        self._full_cache.clear()
        self._judged_before.clear()
        self._materialised = None
        self._grams = None
        if anchor is not None:
            self.anchor_effects = tuple(anchor)

    def checkpoint(self) -> tuple:
        """What the fits so far rest on (their cache, identifiability's judgements, the Gram blocks and
        their anchor), for :meth:`restore` after a trial linearisation the selection does not keep
        (:meth:`reset` forgets them). The held-out rows' blocks are let go meanwhile (the trial makes
        its own; a fit after :meth:`restore` makes them again)."""
        if self._grams is not None:
            self._grams.release()
        return (self._grams, self.anchor_effects, dict(self._full_cache), dict(self._judged_before),
                dict(self._keep_cache), dict(self._kept_cache), self._compressed)

    def restore(self, state: tuple) -> None:
        """Back to a :meth:`checkpoint`, the bases linearised again as they were then: its fits stand
        (refitted on Gram blocks made again about an anchor fitted again, they came out the same to
        within the fits' tolerance, at a sixth of the diagnosis of Justin's 500 poses)."""
        grams, self.anchor_effects, full, before, keep, kept, self._compressed = state
        self._grams = grams
        self._full_cache, self._judged_before = full, before
        self._keep_cache, self._kept_cache = keep, kept
        self._materialised = None

    def resize(self, factors: dict) -> bool:
        """Judge identifiability at fitted sizes: an effect fitted at f times its typical size
        resolves columns f times smaller (min_motion / f). Returns whether anything changed
        (the caches are then cleared: every set is re-identified and refitted)."""
        factors = {e: float(f) for e, f in factors.items() if f > 1.0}
        if factors == self.size_factors:
            return False
        self.size_factors = factors
        self._keep_cache.clear()
        self._kept_cache.clear()
        self._judged_before.update(self._full_cache)
        self._full_cache.clear()
        self._materialised = None
        return True

    def _judged(self, effects, keep: dict) -> bool:
        """Whether ``keep`` is the set's own identifiable columns, as judged already (not judged yet: False)."""
        key = tuple(effects)
        own = self._keep_cache[key][0] if key in self._keep_cache else self._kept_cache.get(key)
        return own is not None and _same_columns(own, keep)

    def _still_valid(self, key: tuple) -> FitResult | None:
        """The fit of ``key`` made before identifiability was re-judged, if its columns are still the set's
        and refitting it would give the same floats: a linear fit without a smoothness penalty (a function
        of its columns and the Gram blocks alone; a penalised fit's lambda search starts where the last one
        ended, an exact fit from the nested exact fits made so far). Sets whose effects were not resized,
        or whose columns the new thresholds leave as they were, are not fitted again."""
        old = self._judged_before.pop(key, None)
        if old is None or key[0] or old["penalty"] is not None:
            return None
        if key[2] is None and not _same_columns(self.kept(key[1]), old["keep"]):  # its own columns, judged again
            return None
        return old

    # -- identifiability -------------------------------------------------------------
    def kept(self, effects) -> dict:
        """The identifiable columns of :meth:`identify`, without its report (most of its cost)."""
        key = tuple(effects)
        if key in self._keep_cache:
            return self._keep_cache[key][0]
        if key not in self._kept_cache:
            order, borrowed = self._identify_order(effects)
            keep, _ = identifiability(self._compressed_bases(), order, self.rank_tol, self._thresholds(order),
                                      report=False, prefixes=self._prefixes)
            if borrowed:
                keep.pop("joint_offsets")
            self._kept_cache[key] = keep
        return self._kept_cache[key]

    def _identify_order(self, effects) -> tuple[list, bool]:
        """The order identifiability takes a set in: vocabulary convention, geometry is what frames and
        joint offsets cannot express, so joint-axis rotations stay joint offsets even when
        joint_offsets is not (yet) in the model (then it is borrowed)."""
        order = list(effects)
        borrowed = "geometry" in order and "joint_offsets" not in order and "joint_offsets" in self.bases
        return (ordered(order + ["joint_offsets"]) if borrowed else order), borrowed

    def _thresholds(self, order) -> dict:
        return {e: self.min_motion / self.size_factors.get(e, 1.0) for e in order}

    def _compressed_bases(self) -> dict:
        """The bases with the poses folded away (what identifiability reads): a factor F of the total
        Gram matrix (F^T F = J^T J, :func:`~tcr_accuracy.diagnosis.identifiability.gram_factor`) when the
        fit weighs every point alike (then the Gram matrix is that of the unweighted columns identifiability
        judges), else one tall-skinny QR of the columns."""
        if self._compressed is None:
            if any(part.whitening is not None for part in self.parts):
                self._compressed = compressed(self.bases)
            else:
                store = self._fold_grams()
                n_poses = self.n_rows * len(self.parts)
                self._compressed = gram_factor(store.total, {e: (self.bases[e].names, store.layout.columns_of([e]))
                                                             for e in self.bases}, n_poses)
        return self._compressed

    def identify(self, effects) -> tuple[dict, dict]:
        """Identifiable columns of each effect *within this set* (vocabulary order), and the report.

        Per set, not once for the whole vocabulary: an effect that is not in the model
        must not take columns away from one that is (sin q of transmission against s q of
        encoder_scale, say).
        """
        key = tuple(effects)
        if key not in self._keep_cache:
            order, borrowed = self._identify_order(effects)
            keep, report = identifiability(self._compressed_bases(), order, self.rank_tol, self._thresholds(order),
                                           prefixes=self._prefixes)
            if self.size_factors:
                report["fitted_size_factors"] = dict(self.size_factors)
            if borrowed:
                keep.pop("joint_offsets")
                report["effects"].pop("joint_offsets")
                report["note"] = "geometry excludes rotations about the joint axes (the joint_offsets effect)"
                cols = [self._compressed[e].g[:, 0, keep[e]] for e in effects if keep[e].size]  # may keep none
                report["rank"] = int(sum(c.shape[1] for c in cols))
                if cols:
                    mat = np.concatenate(cols, axis=1)
                    mat = mat / np.linalg.norm(mat, axis=0)
                    sv = np.linalg.svd(mat, compute_uv=False)
                    report["condition_number"] = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
                    report["smallest_singular_value"] = float(sv[-1])
            self._keep_cache[key] = (keep, report)
        return self._keep_cache[key]

    # -- columns of a model ------------------------------------------------------------
    def columns(self, effects, keep: dict | None = None) -> "Columns":
        """The kept parameters of a set of effects: per-part bases and their union layout,
        bounded by each parameter's fit range (what keeps a fit sane, any sign)."""
        keep = keep if keep is not None else self.kept(effects)
        names, scale, lower, upper, penalty = [], [], [], [], []
        for e in effects:
            b = self.bases[e]
            names += [b.names[k] for k in keep[e]]
            scale.append(b.scales[keep[e]])
            penalty.append(b.penalty[keep[e]])
            lower.append(b.fit_lower[keep[e]] / b.scales[keep[e]])
            upper.append(b.fit_upper[keep[e]] / b.scales[keep[e]])
        # (no effect at all has no columns to join: JoinedMaps below needs one map per effect)
        scale, lower, upper, penalty = (np.concatenate(v) for v in (scale, lower, upper, penalty))
        per_part = []
        for p in range(len(self.parts)):
            bases, gs, idx = [], [], []
            offset = 0
            for e in effects:
                ub = self.bases[e]
                local = ub.per_part[p]
                position = {u: i for i, u in enumerate(keep[e])}  # union column -> kept position
                cols = [c for c, u in enumerate(ub.index[p]) if u in position]
                bases.append(local.basis.take(cols))
                gs.append((local.g, np.array(cols, dtype=int)))
                idx.append(offset + np.array([position[ub.index[p][c]] for c in cols], dtype=int))
                offset += keep[e].size
            per_part.append((JoinedMaps(bases), Sensitivity(gs),
                             np.concatenate(idx)))
        return Columns(names=names, scale=scale, per_part=per_part, lower=lower, upper=upper, penalty=penalty)

    # -- fits --------------------------------------------------------------------------
    def _pose_residual(self, p: int, rows, x: np.ndarray) -> np.ndarray:
        """(len(rows), r) residual rows of part p for error vectors x (len(rows), p_em)."""
        part = self.parts[p]
        poses = tcp_poses(part.robot, part.q[rows], x, self.ems[p])
        res = poses.position - part.target[rows]
        if part.target_rotation is None:
            return res
        # rotation vector of R_model R_target^T, base-frame axes (the Jacobian's rows)
        rel = np.einsum("nij,nkj->nik", poses.rotation, part.target_rotation[rows])
        rot = Rotation.from_matrix(rel).as_rotvec() * part.orientation_weight
        return np.concatenate([res, rot], axis=1)

    def _weighted(self, residual: list[np.ndarray], rows) -> list[np.ndarray]:
        """The residual rows as the fit weighs them: each measured point's position rows through its
        part's whitening (the instrument's per-point noise, :attr:`Part.whitening`); as they are
        without one."""
        out = []
        for part, res in zip(self.parts, residual):
            if part.whitening is None:
                out.append(res)
                continue
            w = part.whitening if rows is None else part.whitening[rows]
            res = res.copy()
            res[:, :3] = np.einsum("nij,nj->ni", w, res[:, :3])
            out.append(res)
        return out

    def predict_residual(self, cols: "Columns", phi: np.ndarray, rows) -> list[np.ndarray]:
        """Residual rows of every part at scaled parameters phi (theta = phi * scale)."""
        theta = phi * cols.scale
        return [self._pose_residual(p, rows, basis.errors(theta[idx], rows))
                for p, (basis, _, idx) in enumerate(cols.per_part)]

    def _jacobians(self, cols: "Columns") -> list[ChainedJacobian]:
        """Per part, the chained Jacobian (N, r, k) of the residual in phi, over all rows (held as
        its effects' columns: :class:`~tcr_accuracy.diagnosis.fit_columns.ChainedJacobian`)."""
        return [ChainedJacobian(g, idx, cols.scale, part.whitening)
                for part, (_, g, idx) in zip(self.parts, cols.per_part)]

    def fit(self, cols: "Columns", rows, start=None, jacobians=None, gram=None):
        """Scaled parameters phi minimising the residual on rows, and the residual per part.
        ``jacobians``, ``gram``: :meth:`_jacobians` of cols and their Gram matrix on the rows,
        when the caller has them already."""
        rows = None if rows is None or len(rows) == self.n_rows else np.asarray(rows)
        k = cols.scale.size
        phi = cols.clip(np.zeros(k) if start is None else np.asarray(start, dtype=float))
        residual = self.predict_residual(cols, phi, _rows(rows, self.n_rows))
        if k == 0:  # nothing identifiable at this noise: the residual is the data's own
            self.n_fits += 1
            return phi, residual
        jacs = self._jacobians(cols) if jacobians is None else jacobians
        return self._minimise(cols, jacs, rows, gram_matrix(jacs, rows) if gram is None else gram, phi, residual)

    def _minimise(self, cols: "Columns", jacs: list, rows, gram: np.ndarray, phi: np.ndarray,
                  residual: list[np.ndarray], penalty: float = 0.0):
        """Levenberg-Marquardt from phi (with its residual on rows) to the least squares
        optimum on rows inside the parameters' physical bounds, the chained Jacobian held
        constant (the effects are linearised per pose; the residual is the exact kinematics),
        columns scaled to unit norm as MINPACK's ``x_scale='jac'``.

        A step is taken only when the exact residual's cost falls (else the damping grows),
        so a fit never ends above its start: started from the model nested inside it, a
        larger model cannot fit worse. Near-null directions of the Gram matrix are left
        where the start put them (pseudo-inverse), and every damped step is a box-constrained
        quadratic (scipy's BVLS) when the free step would leave the bounds.

        Hand-written on the normal equations: one eigendecomposition of the small Gram
        matrix serves every iteration and damping, and a k-fold split's Gram matrices are
        the full one less each fold's held-out rows'. scipy's least_squares refactorises
        the tall constant matrix at each iteration, which at 10^5 poses was most of the
        diagnosis' time.

        ``penalty``: lambda of the columns' smoothness penalty, lambda * sum(w phi^2) added to
        the cost (its Gram matrix and gradient with it).
        """
        self.n_fits += 1
        every = _rows(rows, self.n_rows)
        weights = penalty * cols.penalty
        damped = DampedSolver(gram + np.diag(weights) if penalty else gram)
        flat = _flat(self._weighted(residual, rows))
        cost = float(flat @ flat) + float(weights @ phi**2)
        # first an undamped step: the model is nearly linear, so it usually lands on the optimum
        damping, growth = 0.0, 2.0
        for _ in range(self.MAX_EVALUATIONS):
            step, predicted = damped.step(gradient_vector(jacs, self._weighted(residual, rows), rows, self.n_rows)
                                          + weights * phi, damping, cols.lower - phi, cols.upper - phi)
            if predicted <= self.COST_TOLERANCE * cost:
                break  # the linear model cannot lower the cost any further
            trial = cols.clip(phi + step)
            trial_residual = self.predict_residual(cols, trial, every)
            trial_flat = _flat(self._weighted(trial_residual, rows))
            trial_cost = float(trial_flat @ trial_flat) + float(weights @ trial**2)
            if trial_cost < cost:
                gain = cost - trial_cost
                phi, residual, cost = trial, trial_residual, trial_cost
                damping *= max(1.0 / 3.0, 1.0 - (2.0 * gain / predicted - 1.0) ** 3)  # Nielsen's rule
                growth = 2.0
                if gain <= self.COST_TOLERANCE * cost:
                    break
            else:
                damping = damped.first_damping if damping == 0.0 else damping * growth
                growth *= 2.0
        return phi, residual

    def _fold_step(self, cols: "Columns", gram: np.ndarray, phi: np.ndarray, gradient: np.ndarray,
                   penalty: float) -> np.ndarray:
        """phi moved by one Gauss-Newton step on a fold's training rows (their Gram matrix and
        their gradient J^T r at phi), inside the bounds, with the smoothness penalty lambda
        (:func:`~tcr_accuracy.diagnosis.block_fit.box_step`)."""
        weights = penalty * cols.penalty
        system = gram + np.diag(weights) if penalty else gram
        return cols.clip(phi + box_step(system, gradient + weights * phi, cols.lower - phi, cols.upper - phi))

    #: the fit stops when a step lowers the cost (or could lower it) by less than this share of it
    COST_TOLERANCE = 1e-7
    #: residual evaluations per fit at most (scipy's ``max_nfev`` before)
    MAX_EVALUATIONS = 40

    def _best_start(self, cols: "Columns", candidates: list[np.ndarray], rows) -> tuple[np.ndarray, list]:
        """Of several feasible starting points, the one with the lowest cost on rows, and its residual."""
        best, best_cost, best_residual, seen = None, math.inf, None, []
        for phi in candidates:
            phi = cols.clip(phi)
            if any(np.array_equal(phi, s) for s in seen):
                continue
            seen.append(phi)
            residual = self.predict_residual(cols, phi, rows)
            flat = _flat(self._weighted(residual, None if len(rows) == self.n_rows else rows))
            cost = float(flat @ flat)
            if cost < best_cost:
                best, best_cost, best_residual = phi, cost, residual
        return best, best_residual

    # -- the fold Gram matrices ----------------------------------------------------------
    def grams(self) -> FoldGrams:
        """The whole vocabulary's Gram blocks per fold (:class:`~tcr_accuracy.diagnosis.gram.FoldGrams`),
        made when first asked for and anchored at the exact fit of :attr:`anchor_effects`."""
        store = self._fold_grams()
        if store.anchor is None:
            effects = [e for e in self.anchor_effects if e in self.bases]
            phi = np.zeros(store.layout.n_columns)
            if effects:
                keep = self.kept(tuple(effects))
                cols = self.columns(effects, keep)
                index = store.layout.indices(effects, keep)
                start = cols.clip(np.array([self._last.get(n, 0.0) for n in cols.names]))
                fitted, residual = self.fit(cols, None, start=start, gram=store.total[np.ix_(index, index)])
                phi[index] = fitted
            else:  # nothing anchors it: the nominal model's residual
                every = np.arange(self.n_rows)
                residual = [self._pose_residual(p, every, np.zeros((self.n_rows, em.size)))
                            for p, em in enumerate(self.ems)]
            store.set_anchor(Anchor(tuple(effects), phi, residual))
        return store

    def release_fold_blocks(self) -> None:
        """Let the held-out rows' Gram blocks go once the models are fitted
        (:meth:`~tcr_accuracy.diagnosis.gram.FoldGrams.release`); a later new fit makes them again."""
        if self._grams is not None:
            self._grams.release()
        self._judged_before.clear()

    def _fold_grams(self) -> FoldGrams:
        """The Gram blocks, made when first asked for (not yet anchored)."""
        if self._grams is None:
            self._grams = FoldGrams(self.parts, self.bases, self.repeats)
        return self._grams

    def cached(self, effects) -> dict | None:
        """The fit of a set of effects (own identifiability) if it was evaluated already, else None."""
        return self._full_cache.get((False, tuple(effects), None))

    def _inner(self, effects) -> dict | None:
        """The best-fitting exact model already evaluated whose effects lie inside ``effects``: its
        optimum (the new parameters at zero) is a point of the larger model, and starting
        there is what keeps a nested model from fitting worse than the one inside it."""
        inside = set(effects)
        best = None
        for (exact, _, _), result in self._full_cache.items():
            if exact and set(result["effects"]) < inside:
                if best is None or result["cost"] < best["cost"]:
                    best = result
        return best

    def evaluate(self, effects, keep: dict | None = None, exact: bool = False):
        """Full-data fit and k-fold out-of-fold residuals for a set of effects.

        ``keep``: identifiable columns to use instead of the set's own (the leave-one-out
        of an effect's own share keeps the full model's partition). Parameters stay inside
        their fit range (:meth:`~tcr_accuracy.effects.base.Effect.fit_range`).

        Two ways, on the same columns and folds:

        * the **linear** model (default; every candidate the selection compares): the residual
          at phi is the exact one at the engine's anchor moved by the constant Jacobian,
          r_a + J (phi - phi_a), and every fit, fold fit and held-out sum of squares comes from
          the model's sub-blocks of the fold Gram matrices (:meth:`grams`,
          :func:`~tcr_accuracy.diagnosis.block_fit.fit_blocks`); its fits are exact least
          squares of that model, so a model never fits worse than one nested in it;
        * ``exact=True`` (the models of the final ladder, the final model's parameters and
          residual): the residual is the exact kinematics. The full fit is Levenberg-Marquardt
          from the linear model's optimum (or the best nested exact fit), the Jacobian held
          constant, accepting only steps that lower the cost; each fold is refitted from the
          full optimum by one Gauss-Newton step on the normal equations less its held-out rows
          (a box-constrained step where the bounds stop it), exact for a model linear in its
          parameters and within a second-order term of a full refit, and its held-out rows'
          residual is the exact one at the full fit moved by the Jacobian times the step. The
          smoothness penalty's lambda is the linear model's.

        Returns a dict: ``phi``, ``scale``, ``names``, ``keep``, ``n_parameters``,
        ``train_residual`` / ``heldout_residual`` (position errors, (N, 3) for one part,
        (n_parts, N, 3) for several; held out: the first fold assignment),
        ``heldout_repeats`` (the held-out position errors of every fold assignment),
        ``heldout_squares`` ((N,) each row's squared held-out error, its parts added up,
        averaged over the assignments: what the paired tests compare),
        ``train_orientation`` / ``heldout_orientation`` (rotation errors [rad], same shapes,
        or None), ``train_stats`` / ``heldout_stats`` (:class:`~tcr_accuracy.diagnosis.records.ErrorStats`
        of the training errors and of the held-out ones pooled over the assignments), ``cost``
        (training sum of squares [m^2], weighted as fitted), ``fold_phi`` (each fold's fit, first
        assignment), ``fold_steps`` (each fold's fit, every assignment), ``heldout_ssq`` (per
        assignment, per fold, the weighted held-out sum of squares [m^2]), ``phi_std`` (standard
        errors of phi from the Jacobian and the residual), ``phi_cov`` (with a penalty: the penalised
        fit's posterior covariance), ``at_bound`` (which parameters sit on their fit range's bound),
        ``n_observations``, ``exact``. The fit is cached (per set, ``keep`` and way) without its
        per-row residual arrays, which are made again when read
        (:class:`~tcr_accuracy.diagnosis.fit_result.FitResult`).
        """
        if keep is not None and self._judged(effects, keep):
            keep = None  # the set's own columns: its own fit (a leave-one-out's own share often asks for them)
        keep_key = None if keep is None else tuple((e, tuple(v)) for e, v in keep.items())
        key = (bool(exact), tuple(effects), keep_key)
        if key not in self._full_cache and (valid := self._still_valid(key)) is not None:
            self._full_cache[key] = valid
        if key not in self._full_cache:
            keep = keep if keep is not None else self.kept(effects)
            fields, arrays, lazy = self._exact(effects, keep) if exact else self._linear(effects, keep)
            result = FitResult(fields, self._remade, lazy)
            self._full_cache[key] = result
            self._materialised = (result, arrays)
        return self._full_cache[key]

    def _linear(self, effects, keep: dict) -> tuple[dict, dict]:
        """The fit of :meth:`evaluate` on the linear model, from the Gram blocks."""
        self.n_fits += 1
        store = self.grams()
        layout = store.layout
        index = layout.indices(effects, keep)
        anchor = store.anchor.phi
        center = anchor[index]
        fixed = -anchor
        fixed[index] = 0.0
        fixed = fixed if np.any(fixed) else None
        total = store.quadratic(index, fixed)
        held = [[partial(store.quadratic, index, fixed, r, f) for f in range(len(tests))]
                for r, tests in enumerate(store.tests)]
        weights = layout.penalty[index]
        penalised = tuple(e for e in effects if np.any(layout.penalty[layout.columns_of([e])] > 0))
        low, high = layout.lower[index] - center, layout.upper[index] - center
        reuse = index.size > self.LARGE_MODEL and penalised in self._penalty_start
        positions = np.flatnonzero(weights > 0)
        shared = SharedBlock(store.factors, tuple(index[positions].tolist()), positions) \
            if positions.size and store.factors.keeps(positions.size) else None
        # the walk to the nearest minimum of the held-out score starts where it ended last for these penalised
        # effects, else where it ended last for any (the score has one minimum: the start sets the cost, not
        # the answer; a fine angle table's search from the grid's middle was 6 lambdas of 11 solves each, and
        # its lambda sits at the grid's end with the cyclic effect's)
        start = self._penalty_start.get(penalised, self._last_penalty_index)
        solution = fit_blocks(total, held, low, high, weights, center, start,
                              chosen_index=self._penalty_start[penalised] if reuse else None, shared=shared)
        if solution.grid_index is not None:
            self._penalty_start[penalised] = self._last_penalty_index = solution.grid_index
        second_order = corrected = None
        if self._curved():
            # one Gauss-Newton step on the exact kinematics: the anchor's residual replaced by the exact
            # residual at the linear fit less J times the fit's step (what the linear model misses there)
            second_order = center + solution.step
            corrected = self._corrected_residual(effects, keep, index, second_order)
            products = store.residual_products(corrected, ordered(set(effects) | set(store.anchor.effects)))
            total = store.quadratic(index, fixed, products=products)
            held = [[partial(store.quadratic, index, fixed, r, f, products=products) for f in range(len(tests))]
                    for r, tests in enumerate(store.tests)]
            solution = fit_blocks(total, held, low, high, weights, center, chosen_index=solution.grid_index,
                                  shared=shared)
        phi = center + solution.step
        fold_steps = [[center + d for d in steps] for steps in solution.fold_steps]
        penalty = None if solution.grid_index is None else {
            "full": solution.penalty, "folds": [[solution.penalty] * len(steps) for steps in fold_steps],
            "grid_relative": [float(PENALTY_GRID[0]), float(PENALTY_GRID[-1])],
            "chosen_on": "k-fold held-out error of the first fold assignment; every fold's fit takes it"}
        names = [layout.names[i] for i in index]
        fields, arrays = self._fields(effects, keep, index, phi, fold_steps, solution.cost, penalty, names,
                                      exact=False, base=corrected, second_order=second_order)
        fields["heldout_ssq"] = solution.heldout_ssq
        return fields, arrays, self._uncertainty(index, solution.penalty * weights, solution.cost, fields)

    #: a model of more parameters than this (a fine angle table) takes the smoothness penalty's lambda
    #: chosen last for the same penalised effects, without searching again: each lambda tried costs a
    #: solve per fold of the model's size, and the choice follows the penalised effects' own roughness
    #: and the noise, not the few other effects around them
    LARGE_MODEL = 800

    #: the linear model's fits get one Gauss-Newton step on the exact kinematics when the whole
    #: vocabulary's linear fit misses its exact residual's sum of squares by more than this share
    CURVATURE_TOLERANCE = 1e-4

    def _corrected_residual(self, effects, keep: dict, index: np.ndarray, phi: np.ndarray) -> list:
        """Per part, the exact residual at phi (the model's columns ``index``, the anchor's others at
        zero) less J times phi's step from the anchor: the residual of a linear model taken at phi."""
        store = self.grams()
        step = -store.anchor.phi
        step[index] = phi - store.anchor.phi[index]
        exact = self.predict_residual(self.columns(effects, keep), phi, np.arange(self.n_rows))
        return [res - moved_rows(self.bases, store.layout, p, step[:, None], self.n_rows, part.rows_per_pose)[:, :, 0]
                for p, (res, part) in enumerate(zip(exact, self.parts))]

    def _curved(self) -> bool:
        """Whether the linear model misses the exact kinematics enough to take the Gauss-Newton step
        (:data:`CURVATURE_TOLERANCE`): judged once per Gram blocks on the linear fit of every effect
        built (all rows, the penalised effects at the middle of the lambda grid)."""
        store = self.grams()
        if store.curvature is None:
            effects = [e for e in store.layout.effects]
            keep = self.kept(tuple(effects))
            index = store.layout.indices(effects, keep)
            anchor = store.anchor.phi
            center = anchor[index]
            total = store.quadratic(index)
            weights = store.layout.penalty[index]
            lam = float(penalty_grid(total, weights)[len(PENALTY_GRID) // 2]) if np.any(weights > 0) else 0.0
            step = box_step(total.gram + np.diag(lam * weights), total.gradient + lam * weights * center,
                            store.layout.lower[index] - center, store.layout.upper[index] - center)
            corrected = self._corrected_residual(effects, keep, index, center + step)
            missed = sum(float(np.sum(_whitened(part, c - a) ** 2))
                         for part, c, a in zip(self.parts, corrected, store.anchor.residual))
            store.curvature = missed / max(total.value(step), 1e-300)
        return store.curvature > self.CURVATURE_TOLERANCE

    def _exact(self, effects, keep: dict) -> tuple[dict, dict]:
        """The fit of :meth:`evaluate` on the exact kinematics."""
        linear = self.evaluate(effects, keep)
        store = self.grams()
        index = store.layout.indices(effects, keep)
        cols = self.columns(effects, keep)
        k = cols.scale.size
        every = np.arange(self.n_rows)
        inner = self._inner(effects)
        starts = [linear["phi"]]
        if inner is not None:
            known = dict(zip(inner["names"], inner["phi"]))
            starts.append(np.array([known.get(n, 0.0) for n in cols.names]))
        phi, train = self._best_start(cols, starts, every)
        lam = linear["penalty"]["full"] if linear["penalty"] else 0.0
        gram = store.total[np.ix_(index, index)]
        jacs = self._jacobians(cols) if k else []
        if k:
            phi, train = self._minimise(cols, jacs, None, gram, phi, train, lam)
        else:
            self.n_fits += 1
        self._last.update(zip(cols.names, phi))
        fold_steps = []  # per assignment, per fold: the fold's fit (phi where nothing is fitted)
        if k:
            total_gradient = gradient_vector(jacs, self._weighted(train, None), None, self.n_rows)
        for r, tests in enumerate(store.tests):
            steps = []
            for f, test in enumerate(tests):
                phi_k = phi
                if k:  # one step from the full fit, on the normal equations less the held-out rows
                    held_gradient = gradient_vector(jacs, self._weighted([res[test] for res in train], test), test,
                                                    self.n_rows)
                    phi_k = self._fold_step(cols, gram - store.held_blocks()[r][f][np.ix_(index, index)], phi,
                                            total_gradient - held_gradient, lam)
                steps.append(phi_k)
            fold_steps.append(steps)
        flat = _flat(self._weighted(train, None))
        fields, arrays = self._fields(effects, keep, index, phi, fold_steps, float(flat @ flat), linear["penalty"],
                                      cols.names, exact=True, base=train)
        return fields, arrays, self._uncertainty(index, lam * cols.penalty, fields["cost"], fields)

    def _fields(self, effects, keep, index, phi, fold_steps, cost, penalty, names, exact, base=None,
                second_order=None) -> tuple:
        """A fit's figures (the dict :meth:`evaluate` returns) and its per-row arrays (``base``: see
        :meth:`_arrays`)."""
        layout = self.grams().layout
        lower, upper, scale = layout.lower[index], layout.upper[index], layout.scale[index]
        fields = {"effects": tuple(effects), "phi": phi, "scale": scale, "names": names, "keep": keep,
                  "n_parameters": int(index.size), "lower": lower, "upper": upper, "cost": cost,
                  "fold_phi": fold_steps[0] if fold_steps else [], "fold_steps": fold_steps,
                  "n_observations": int(sum(self.n_rows * p.rows_per_pose for p in self.parts)),
                  "penalty": penalty, "penalty_weights": layout.penalty[index], "exact": exact, "index": index,
                  "second_order_at": second_order}
        span = np.maximum(np.abs(phi), 1.0) * 1e-9
        fields["at_bound"] = (phi <= lower + span) | (phi >= upper - span)
        arrays = self._arrays(fields, base)
        heldout_repeats = arrays["heldout_repeats"]
        fields["heldout_squares"] = np.mean([row_squares(h) for h in heldout_repeats], axis=0) if heldout_repeats \
            else np.zeros(self.n_rows)
        fields["train_stats"] = ErrorStats.of(arrays["train_residual"])
        fields["heldout_stats"] = ErrorStats.pooled(heldout_repeats) if heldout_repeats else None
        return fields, arrays

    def _uncertainty(self, index: np.ndarray, weights: np.ndarray, cost: float, fields: dict) -> dict:
        """The standard errors (and with a penalty, the posterior covariance) of a fit, made when read:
        s^2 (J^T J + lambda W)^+ with s^2 the training cost per degree of freedom, J^T J the model's
        block of the total Gram matrix (taken then: a cached fit holds no k x k matrix)."""
        k = fields["n_parameters"]
        variance = cost / max(fields["n_observations"] - k, 1)
        solver = []
        store = self._grams

        def damped():
            if not solver:
                solver.append(DampedSolver(store.total[np.ix_(index, index)] + np.diag(weights)))
            return solver[0]

        lazy = {"phi_std": (lambda: damped().standard_errors(variance)) if k else (lambda: np.zeros(0)),
                "phi_cov": (lambda: damped().covariance(variance)) if k and np.any(weights) else (lambda: None)}
        return lazy

    def _arrays(self, result, base=None) -> dict:
        """The per-row arrays of a fit (:data:`~tcr_accuracy.diagnosis.fit_result.RESIDUAL_KEYS`): its
        training residual per part and each fold assignment's held-out rows at its folds' fits. On
        the linear model, the anchor's residual (or with the Gauss-Newton step, the corrected residual
        at it) moved by J times each fit's step from the anchor; on the exact kinematics, the exact
        residual at phi moved by J times each fold's step from phi. ``base``: that residual per part
        when the fit has it (made again when not: the exact kinematics at 500 poses cost as much as
        the rest of a fit)."""
        store = self.grams()
        layout = store.layout
        index, phi = result["index"], result["phi"]
        columns = [np.zeros(layout.n_columns)]
        if result["exact"]:
            base = base if base is not None else self.predict_residual(
                self.columns(list(result["effects"]), result["keep"]), phi, np.arange(self.n_rows))
            origin = phi
        else:
            if result["second_order_at"] is None:
                base = store.anchor.residual
            elif base is None:
                base = self._corrected_residual(result["effects"], result["keep"], index, result["second_order_at"])
            origin = store.anchor.phi[index]
            columns[0] = -store.anchor.phi
            columns[0][index] = phi - origin
        for steps in result["fold_steps"]:
            for phi_k in steps:
                column = columns[0].copy()
                column[index] = phi_k - origin
                columns.append(column)
        steps = np.stack(columns, axis=1)
        # which column each row's held-out error takes, per assignment (its fold's; the full fit's if in none)
        picks, at = [], 1
        for r, tests in enumerate(store.tests):
            label = store.fold_of[r]
            picks.append(np.where(label >= 0, at + label, 0))
            at += len(tests)
        train_rows, repeats = [], [[] for _ in store.tests]
        for p, part in enumerate(self.parts):
            moved = moved_rows(self.bases, layout, p, steps, self.n_rows, part.rows_per_pose) if np.any(steps) \
                else np.zeros((self.n_rows, part.rows_per_pose, steps.shape[1]))
            train_rows.append(base[p] + moved[:, :, 0])
            for r, pick in enumerate(picks):
                repeats[r].append(base[p] + np.take_along_axis(moved, pick[:, None, None], axis=2)[:, :, 0])
        oof = repeats[0] if repeats else [np.zeros((self.n_rows, p.rows_per_pose)) for p in self.parts]
        return {"train_residual": self._positions(train_rows), "heldout_residual": self._positions(oof),
                "train_orientation": self._rotations(train_rows), "heldout_orientation": self._rotations(oof),
                "heldout_repeats": [self._positions(o) for o in repeats]}

    def _remade(self, result: FitResult) -> dict:
        """The per-row arrays of a cached fit, made again as :meth:`evaluate` made them (the same
        parameters and fold steps: the same floats); the last ones are kept."""
        if self._materialised is not None and self._materialised[0] is result:
            return self._materialised[1]
        arrays = self._arrays(result)
        self._materialised = (result, arrays)
        return arrays

    def _positions(self, per_part: list[np.ndarray]) -> np.ndarray:
        pos = [r[:, :3] for r in per_part]
        return pos[0] if len(pos) == 1 else np.stack(pos)

    def _rotations(self, per_part: list[np.ndarray]):
        rot = [r[:, 3:] / part.orientation_weight for r, part in zip(per_part, self.parts)
               if part.target_rotation is not None]
        if not rot:
            return None
        return rot[0] if len(rot) == 1 else np.concatenate(rot)


def _same_columns(keep: dict, other: dict) -> bool:
    """Whether two partitions of kept columns (effect -> (k_e,) column positions) are the same."""
    return set(keep) == set(other) and all(np.array_equal(keep[e], other[e]) for e in keep)


def _whitened(part: Part, residual: np.ndarray) -> np.ndarray:
    """A part's residual rows (N, r) as the fit weighs them (the position rows through its whitening)."""
    if part.whitening is None:
        return residual
    out = residual.copy()
    out[:, :3] = np.einsum("nij,nj->ni", part.whitening, residual[:, :3])
    return out


def _flat(per_part: list[np.ndarray]) -> np.ndarray:
    return np.concatenate([r.ravel() for r in per_part])


def _rows(rows, n: int) -> np.ndarray:
    return np.arange(n) if rows is None else rows
