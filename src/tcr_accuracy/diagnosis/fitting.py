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

import numpy as np
from scipy.spatial.transform import Rotation

from ..model.errors import ErrorModel
from ..model.kinematics import tcp_poses
from .bases import Part, ordered
from .error_map import ErrorMap
from .identifiability import compressed, identifiability
from .least_squares import DampedSolver, cholesky_solve
from .fit_columns import ChainedJacobian, Columns, Sensitivity, gradient_vector, gram_matrix, moved_rows
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
        self._materialised = None  # (a cached fit, its remade per-row arrays): the last ones read
        self._keep_cache: dict = {}
        self._compressed = None  # the bases with the poses folded away, for identify
        self._last: dict = {}  # parameter name -> last fitted scaled value (a warm start)
        self.size_factors: dict = {}  # effect -> fitted size / typical size (>= 1), see resize
        self.n_fits = 0

    def add_bases(self, bases: dict) -> None:
        """Effects joining after the engine was built (an effect of last resort, tried late):
        identifiability is judged again with them (what was fitted stays cached: effects come
        in vocabulary order, and a later one takes nothing from the sets fitted without it)."""
        self.bases.update(bases)
        self._compressed = None
        self._keep_cache.clear()

    def reset(self) -> None:
        """Forget every fit and identifiability judgement (the bases were linearised again); the
        last fitted values stay as warm starts."""
        self._compressed = None
        self._keep_cache.clear()
        self._full_cache.clear()
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
        self._full_cache.clear()
        self._materialised = None
        return True

    # -- identifiability -------------------------------------------------------------
    def identify(self, effects) -> tuple[dict, dict]:
        """Identifiable columns of each effect *within this set* (vocabulary order), and the report.

        Per set, not once for the whole vocabulary: an effect that is not in the model
        must not take columns away from one that is (sin q of transmission against s q of
        encoder_scale, say).
        """
        key = tuple(effects)
        if key not in self._keep_cache:
            # vocabulary convention: geometry is what frames and joint offsets cannot
            # express, so joint-axis rotations stay joint offsets even when joint_offsets
            # is not (yet) in the model
            order = list(effects)
            borrowed = "geometry" in order and "joint_offsets" not in order and "joint_offsets" in self.bases
            if borrowed:
                order = ordered(order + ["joint_offsets"])
            thresholds = {e: self.min_motion / self.size_factors.get(e, 1.0) for e in order}
            if self._compressed is None:
                self._compressed = compressed(self.bases)
            keep, report = identifiability(self._compressed, order, self.rank_tol, thresholds)
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
        keep = keep if keep is not None else self.identify(effects)[0]
        names, scale, lower, upper, penalty = [], [], [], [], []
        for e in effects:
            b = self.bases[e]
            names += [b.names[k] for k in keep[e]]
            scale.append(b.scales[keep[e]])
            penalty.append(b.penalty[keep[e]])
            lower.append(b.fit_lower[keep[e]] / b.scales[keep[e]])
            upper.append(b.fit_upper[keep[e]] / b.scales[keep[e]])
        scale = np.concatenate(scale) if scale else np.zeros(0)
        lower = np.concatenate(lower) if lower else np.zeros(0)
        upper = np.concatenate(upper) if upper else np.zeros(0)
        penalty = np.concatenate(penalty) if penalty else np.zeros(0)
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
            per_part.append((ErrorMap.concatenate(bases), Sensitivity(gs),
                             np.concatenate(idx) if idx else np.zeros(0, dtype=int)))
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

    def _unweighted(self, p: int, rows, moved: np.ndarray) -> np.ndarray:
        """Residual changes (len(rows), r) computed with the weighted Jacobian, back in metres."""
        part = self.parts[p]
        if part.whitening is None:
            return moved
        moved = moved.copy()
        moved[:, :3] = np.linalg.solve(part.whitening[rows], moved[:, :3, None])[:, :, 0]
        return moved

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
        their gradient J^T r at phi), inside the bounds, with the smoothness penalty lambda: a
        Cholesky solve, or the damped solver's pseudo-inverse and box-constrained step where the
        system is near singular or the step would leave the bounds."""
        weights = penalty * cols.penalty
        system = gram + np.diag(weights) if penalty else gram
        rhs = -(gradient + weights * phi)
        try:
            norms = np.sqrt(np.clip(np.diag(system), 1e-300, None))
            step = cholesky_solve(system / np.outer(norms, norms), rhs / norms, strict=True) / norms
            if np.all(np.isfinite(step)) and np.all(phi + step >= cols.lower) and np.all(phi + step <= cols.upper):
                return phi + step
        except np.linalg.LinAlgError:
            pass
        step, _ = DampedSolver(system).step(-rhs, 0.0, cols.lower - phi, cols.upper - phi)
        return cols.clip(phi + step)

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

    #: lambdas tried for a smoothness penalty, times the penalised columns' median Gram diagonal
    PENALTY_GRID = np.logspace(-5, 3, 9)

    def _penalties(self, cols: "Columns", jacs: list, fold_grams: list, residual: list, phi: np.ndarray) -> dict:
        """Smoothness-penalty lambdas chosen by held-out error inside the training rows: for the
        full fit by k-fold over all rows (the first assignment), for each fold's fit by (k-1)-fold
        over its training rows only (never its held-out rows), in every fold assignment.
        ``fold_grams``: per assignment, per fold, the Gram matrix of its held-out rows. The model
        is linearised at phi (residual on all rows): one small solve per lambda and fold."""
        first = fold_grams[0] if fold_grams else []
        penalised = cols.penalty > 0
        base = float(np.median(np.diag(sum(first))[penalised])) if first else 1.0
        grid = base * self.PENALTY_GRID
        ridge = 1e-12 * max(float(np.max(np.diag(sum(first)))) if first else 1.0, 1e-300)

        gradients_of = {}

        def choose(folds, grams, allowed: list[int]) -> float:
            if len(allowed) < 2:
                return float(grid[len(grid) // 2])
            key = id(folds)
            if key not in gradients_of:
                gradients_of[key] = [gradient_vector(jacs, self._weighted([r[test] for r in residual], test), test,
                                               self.n_rows)
                                     for _, test in folds]
            gradients = gradients_of[key]
            total_gram = sum(grams[f] for f in allowed)
            total_gradient = sum(gradients[f] for f in allowed)
            scores = np.zeros(len(grid))
            for h in allowed:
                g_train = total_gram - grams[h]
                b_train = total_gradient - gradients[h]
                for i, lam in enumerate(grid):
                    step = cholesky_solve(g_train + np.diag(lam * cols.penalty + ridge),
                                           -(b_train + lam * cols.penalty * phi))
                    # |r + J s|^2 on the held-out rows, less the constant |r|^2: from their Gram
                    # matrix and gradient, without touching the rows again
                    scores[i] += float(2.0 * gradients[h] @ step + step @ grams[h] @ step)
            return float(grid[int(np.argmin(scores))])

        every = list(range(len(self.folds)))
        first_folds = [choose(self.folds, first, [g for g in every if g != f]) for f in every]
        # the other fold assignments take the first's choice (its median): one scalar, chosen without
        # each of the first assignment's held-out folds; the nested search per assignment was most of
        # a cyclic diagnosis' time and chose the same grid value
        shared = float(np.median(first_folds)) if first_folds else float(grid[len(grid) // 2])
        per_repeat = [first_folds] + [[shared] * len(folds) for folds in self.repeats[1:]]
        return {"full": choose(self.folds, first, every), "folds": per_repeat,
                "grid_relative": [float(self.PENALTY_GRID[0]), float(self.PENALTY_GRID[-1])]}

    def cached(self, effects) -> dict | None:
        """The fit of a set of effects (own identifiability) if it was evaluated already, else None."""
        return self._full_cache.get((tuple(effects), None))

    def _inner(self, effects) -> dict | None:
        """The best-fitting model already evaluated whose effects lie inside ``effects``: its
        optimum (the new parameters at zero) is a point of the larger model, and starting
        there is what keeps a nested model from fitting worse than the one inside it."""
        inside = set(effects)
        best = None
        for result in self._full_cache.values():
            if set(result["effects"]) < inside:
                if best is None or result["cost"] < best["cost"]:
                    best = result
        return best

    def evaluate(self, effects, keep: dict | None = None):
        """Full-data fit and k-fold out-of-fold residuals for a set of effects.

        ``keep``: identifiable columns to use instead of the set's own (the leave-one-out
        of an effect's own share keeps the full model's partition). Parameters stay inside
        their fit range (:meth:`~tcr_accuracy.effects.base.Effect.fit_range`).

        The full fit starts from the best of: zeros, the values last fitted for these
        parameters, and the optimum of the best model evaluated so far that is nested in
        this one, and only accepts steps that lower the cost, so along a ladder of nested
        models the training cost never rises.

        Each fold is refitted from the full optimum by one Gauss-Newton step on the normal
        equations less its held-out rows (the Jacobian is the engine's constant one, the
        residual the exact kinematics at the full optimum; a box-constrained step where the
        bounds stop it). It is exact for a model linear in its parameters and, the effects
        being linearised per pose, within a second-order term of a full refit; it costs one
        small solve instead of a Levenberg-Marquardt run over the training rows, which is
        what makes several fold assignments affordable. The held-out rows' residual is the
        exact one at the full fit moved by the Jacobian times the step (second order in the
        step, which is of the size of the parameters' standard errors).

        Returns a dict: ``phi``, ``scale``, ``names``, ``keep``, ``n_parameters``,
        ``train_residual`` / ``heldout_residual`` (position errors, (N, 3) for one part,
        (n_parts, N, 3) for several; held out: the first fold assignment),
        ``heldout_repeats`` (the held-out position errors of every fold assignment),
        ``heldout_squares`` ((N,) each row's squared held-out error, its parts added up,
        averaged over the assignments: what the paired tests compare),
        ``train_orientation`` / ``heldout_orientation`` (rotation errors [rad], same shapes,
        or None), ``train_stats`` / ``heldout_stats`` (:class:`~tcr_accuracy.diagnosis.records.ErrorStats`
        of the training errors and of the held-out ones pooled over the assignments), ``cost``
        (training sum of squares [m^2]), ``fold_phi`` (each fold's fit, first assignment),
        ``fold_steps`` (each fold's fit, every assignment), ``phi_std`` (standard errors of phi from the Jacobian and the residual),
        ``at_bound`` (which parameters sit on their fit range's bound), ``n_observations``.
        A later call for the same set returns the cached fit, whose per-row residual arrays are made
        again when read (:class:`~tcr_accuracy.diagnosis.fit_result.FitResult`).
        """
        key = (tuple(effects), None if keep is None else tuple((e, tuple(v)) for e, v in keep.items()))
        if key in self._full_cache:
            return self._full_cache[key]
        keep = keep if keep is not None else self.identify(effects)[0]
        cols = self.columns(effects, keep)
        k = cols.scale.size
        every = np.arange(self.n_rows)
        inner = self._inner(effects)

        def mapped(names, values) -> np.ndarray:
            known = dict(zip(names, values))
            return np.array([known.get(n, 0.0) for n in cols.names])

        # the nested model's optimum costs no more than zeros (its fit only descended from there)
        starts = [mapped(inner["names"], inner["phi"])] if inner is not None else \
            [np.zeros(k), mapped(list(self._last), list(self._last.values()))]
        phi, train = self._best_start(cols, starts, every)
        jacs = self._jacobians(cols) if k else []
        fold_grams = [[gram_matrix(jacs, test) for _, test in folds] for folds in self.repeats] if k else []
        gram = None
        if k:  # the first assignment's held-out rows cover every row once: the full Gram matrix is their sum
            held = np.sort(np.concatenate([test for _, test in self.folds])) if self.folds else None
            gram = sum(fold_grams[0]) if held is not None and np.array_equal(held, every) else \
                gram_matrix(jacs, None)
        penalties = self._penalties(cols, jacs, fold_grams, train, phi) if k and cols.penalty.any() else None
        if k:
            phi, train = self._minimise(cols, jacs, None, gram, phi, train,
                                        penalties["full"] if penalties else 0.0)
        else:
            self.n_fits += 1
        self._last.update(zip(cols.names, phi))
        total_gradient = gradient_vector(jacs, self._weighted(train, None), None, self.n_rows) if k else None
        fold_steps = []  # per assignment, per fold: the fold's fit (phi where nothing is fitted)
        for r, folds in enumerate(self.repeats):
            steps = []
            for f, (_, test) in enumerate(folds):
                phi_k = phi
                if k:  # one step from the full fit, on the normal equations less the held-out rows
                    lam = penalties["folds"][r][f] if penalties else 0.0
                    held_gradient = gradient_vector(jacs, self._weighted([res[test] for res in train], test), test,
                                              self.n_rows)
                    phi_k = self._fold_step(cols, gram - fold_grams[r][f], phi, total_gradient - held_gradient, lam)
                steps.append(phi_k)
            fold_steps.append(steps)
        arrays = self._residual_arrays(train, jacs, phi, fold_steps)
        heldout_repeats = arrays["heldout_repeats"]
        squares = np.mean([row_squares(h) for h in heldout_repeats], axis=0) if heldout_repeats else \
            np.zeros(self.n_rows)
        flat = _flat(self._weighted(train, None))
        cost = float(flat @ flat)
        n_obs = flat.size
        lam = penalties["full"] if penalties else 0.0
        # with a smoothness penalty, the posterior covariance of the penalised fit (as for penalised splines)
        solver = DampedSolver(gram + np.diag(lam * cols.penalty)) if k else None
        phi_std = solver.standard_errors(cost / max(n_obs - k, 1)) if k else np.zeros(0)
        phi_cov = solver.covariance(cost / max(n_obs - k, 1)) if k and cols.penalty.any() else None
        span = np.maximum(np.abs(phi), 1.0) * 1e-9
        at_bound = (phi <= cols.lower + span) | (phi >= cols.upper - span)
        result = {"effects": tuple(effects), "phi": phi, "scale": cols.scale,
                  "names": cols.names, "keep": keep, "n_parameters": int(k),
                  "lower": cols.lower, "upper": cols.upper, **arrays, "heldout_squares": squares,
                  "train_stats": ErrorStats.of(arrays["train_residual"]), "heldout_stats": ErrorStats.pooled(
                      heldout_repeats) if heldout_repeats else None,
                  "cost": cost, "fold_phi": fold_steps[0] if fold_steps else [], "fold_steps": fold_steps,
                  "phi_std": phi_std, "at_bound": at_bound, "n_observations": int(n_obs), "phi_cov": phi_cov,
                  "penalty": penalties, "penalty_weights": cols.penalty}
        # cached without its per-row arrays (remade when read: :mod:`.fit_result`); the caller's copy has them
        self._full_cache[key] = FitResult(result, self._remade)
        return result

    def _residual_arrays(self, train: list[np.ndarray], jacs: list, phi: np.ndarray, fold_steps: list) -> dict:
        """The per-row arrays of a fit (:data:`~tcr_accuracy.diagnosis.fit_result.RESIDUAL_KEYS`): its
        training residual per part (the exact one at phi), and each fold assignment's held-out rows at its
        folds' fits ``fold_steps`` (per assignment, per fold: scaled parameters)."""
        repeats = []
        for folds, steps in zip(self.repeats, fold_steps):
            oof = [np.empty((self.n_rows, p.rows_per_pose)) for p in self.parts]
            for (_, test), phi_k in zip(folds, steps):
                for p, (res, jac) in enumerate(zip(train, jacs or [None] * len(train))):
                    # the held-out rows at the fold's fit: the exact residual at the full fit moved by
                    # the Jacobian (the fold's fit is within a step of it; second order is below noise)
                    oof[p][test] = res[test] if jac is None else res[test] + self._unweighted(
                        p, test, moved_rows(jac, test, phi_k - phi))
            repeats.append(oof)
        oof = repeats[0] if repeats else [np.zeros((self.n_rows, p.rows_per_pose)) for p in self.parts]
        return {"train_residual": self._positions(train), "heldout_residual": self._positions(oof),
                "train_orientation": self._rotations(train), "heldout_orientation": self._rotations(oof),
                "heldout_repeats": [self._positions(o) for o in repeats]}

    def _remade(self, result: FitResult) -> dict:
        """The per-row arrays of a cached fit, made again as :meth:`evaluate` made them (the same
        columns, Jacobians, parameters and fold steps: the same floats); the last ones are kept."""
        if self._materialised is not None and self._materialised[0] is result:
            return self._materialised[1]
        cols = self.columns(result["effects"], result["keep"])
        train = self.predict_residual(cols, result["phi"], np.arange(self.n_rows))
        arrays = self._residual_arrays(train, self._jacobians(cols) if cols.scale.size else [], result["phi"],
                                       result["fold_steps"])
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


def _flat(per_part: list[np.ndarray]) -> np.ndarray:
    return np.concatenate([r.ravel() for r in per_part])


def _rows(rows, n: int) -> np.ndarray:
    return np.arange(n) if rows is None else rows
