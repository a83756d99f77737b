"""A candidate model fitted from its sub-blocks of the fold Gram matrices (:mod:`.gram`): the fit to
all rows, each fold's fit to its training rows, their held-out sums of squares, inside the
parameters' fit ranges and with the smoothness penalty of the effects that carry one.

Each fit minimises a quadratic d^T A d + 2 b^T d (A, b: the model's sub-blocks, plus lambda W for
the penalty) over the box lower <= d <= upper. The free minimiser is one Cholesky solve of the
model's k x k system; where it leaves the box, the box-constrained quadratic is solved on the same
normal equations by the primal active-set method (:func:`~.least_squares.box_quadratic`, started
from the anchor, which lies in the box): a fit reaches a bound for a handful of parameters at most,
and each change of the active set costs one solve of the free block, where a bounded least
squares on the rows (scipy's ``lsq_linear``) would go back to the tall Jacobian. Near-singular
systems (a direction the rows do not see) take the damped solver's pseudo-inverse, as the exact
fits do.

The penalty's lambda is chosen per model on the grid :data:`PENALTY_GRID` (times the penalised
columns' median Gram diagonal) by the first fold assignment's k-fold held-out error: for each
lambda and fold, the fit to the fold's training rows scored on its held-out rows, from the blocks.
The search walks the grid from where the last model with the same penalised effects ended, to the
nearest minimum (the grid's argmin where the score has one minimum, as it has: too little penalty
overfits, too much underfits); every fold's fit then takes the chosen lambda.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from scipy import linalg

from .gram import Quadratic
from .least_squares import DampedSolver, FactorCache, cholesky_factor, cholesky_solve

#: lambdas tried for a smoothness penalty, times the penalised columns' median Gram diagonal: the decades
#: 1e-5 .. 1e3 written out (np.logspace's ends moved by an ulp between numpy releases: 9.999999999999999e-06)
PENALTY_GRID = np.array([1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3])


class SharedBlock:
    """The penalised columns of the models fitted from one store of Gram blocks, and the Cholesky
    factors of their systems (their Gram block on some rows plus lambda W), kept for the next model
    with the same penalised columns: models that differ in a few other columns (every candidate added
    to a model with a fine angle table or the cyclic effect) reach their fit through the Schur
    complement on those few (:func:`free_step`), where each was one Cholesky factorisation of the
    whole system (a thousand columns and more with an angle table).

    Parameters
    ----------
    factors : FactorCache
        Where the factors are kept (one per store of Gram blocks: they hold its numbers).
    columns : tuple of int
        The penalised columns' places in the store's layout (what the factors are of).
    positions : (p,) int array
        Their places among the model's columns.
    """

    def __init__(self, factors: FactorCache, columns: tuple, positions: np.ndarray):
        self.factors, self.columns, self.positions = factors, columns, positions
        self._others: dict = {}

    def key(self, rows, lam: float) -> tuple:
        """The cache key of the factor on ``rows`` (a label: all rows, or a fold's training rows) at lambda."""
        return (rows, float(lam), self.columns)

    def others(self, k: int) -> np.ndarray:
        """The model's other columns (not penalised), among its k."""
        if k not in self._others:
            mask = np.ones(k, dtype=bool)
            mask[self.positions] = False
            self._others[k] = np.flatnonzero(mask)
        return self._others[k]


def box_step(system: np.ndarray, gradient: np.ndarray, low: np.ndarray, high: np.ndarray,
             shared: SharedBlock | None = None, key=None, overwrite: bool = False) -> np.ndarray:
    """argmin d^T A d + 2 b^T d over low <= d <= high, for A = ``system`` (k, k) positive
    semi-definite and b = ``gradient``: a Cholesky solve where it is well posed and its step inside
    the box, else the damped solver's pseudo-inverse with the box-constrained active-set step.
    ``shared``, ``key``: see :func:`free_step`; ``overwrite``: the system is the caller's to lose (the
    Cholesky factor is made in its memory)."""
    if not gradient.size:
        return np.zeros(0)
    origin = np.clip(0.0, low, high)  # a feasible point to start the box-constrained step from
    if np.any(origin):
        gradient = gradient + system @ origin
        low, high = low - origin, high - origin
    diagonal = np.diag(system).copy() if overwrite else None
    step = free_step(system, gradient, shared, key, overwrite)
    if step is not None and np.all(step >= low) and np.all(step <= high):
        return origin + step
    if overwrite:  # the factor took the lower triangle and the diagonal; the upper triangle is the system's
        np.copyto(system, system.T, where=np.tri(*system.shape, k=-1, dtype=bool))
        system[np.diag_indices_from(system)] = diagonal
    step, _ = DampedSolver(system).step(gradient, 0.0, low, high)
    return origin + np.clip(step, low, high)


#: a system is near singular where a pivot of its unit-diagonal form's Cholesky factor is below this
#: share of the largest
PIVOT_FLOOR = 1e-7


def free_step(system: np.ndarray, gradient: np.ndarray, shared: SharedBlock | None = None, key=None,
              overwrite: bool = False) -> np.ndarray | None:
    """argmin d^T A d + 2 b^T d without bounds: a Cholesky solve, or None where it is not well posed
    (not positive definite, or near singular: a pivot of the factor of the unit-diagonal system
    D^-1 A D^-1, D = sqrt(diag A), below :data:`PIVOT_FLOOR` of the largest). The factor is taken of A
    itself (Cholesky's rounding does not depend on a diagonal scaling; its pivots are the unit system's
    times D), ``system``'s memory overwritten with ``overwrite``.

    With ``shared`` (and its ``key``, the factor's rows and lambda), the same solve with the shared
    penalised columns P first: their block's factor L_P is the one kept under ``key`` (made once), the
    other columns O take the Schur complement S = A_OO - Y^T Y, Y = L_P^-1 A_PO, and the step is the
    two triangular solves of the block factor [[L_P, 0], [Y^T, L_S]]: the Cholesky factor of the
    system with its columns in that order."""
    norms = np.sqrt(np.clip(np.diag(system), 1e-300, None))
    if shared is None or not 0 < shared.positions.size < system.shape[0]:
        factor = cholesky_factor(system, overwrite)
        if factor is None or not _well_posed(np.diagonal(factor) / norms):
            return None
        step = linalg.cho_solve((factor, False), -gradient, check_finite=False)
        return step if np.all(np.isfinite(step)) else None
    p = shared.positions
    o = shared.others(system.shape[0])
    factor_p = shared.factors.get(key, lambda: cholesky_factor(system[np.ix_(p, p)], overwrite=True))
    if factor_p is None:
        return None
    # Y = L_P^-1 A_PO = U_P^-T A_PO
    y = linalg.solve_triangular(factor_p, system[np.ix_(p, o)], trans="T", check_finite=False)
    factor_s = cholesky_factor(system[np.ix_(o, o)] - y.T @ y, overwrite=True)
    if factor_s is None or not _well_posed(np.concatenate([np.diagonal(factor_p) / norms[p],
                                                           np.diagonal(factor_s) / norms[o]])):
        return None
    rhs = -gradient
    z_p = linalg.solve_triangular(factor_p, rhs[p], trans="T", check_finite=False)
    x_o = linalg.cho_solve((factor_s, False), rhs[o] - y.T @ z_p, check_finite=False)
    x_p = linalg.solve_triangular(factor_p, z_p - y @ x_o, check_finite=False)
    step = np.empty_like(rhs)
    step[p], step[o] = x_p, x_o
    return step if np.all(np.isfinite(step)) else None


def _well_posed(pivots: np.ndarray) -> bool:
    """Whether the unit-diagonal system's Cholesky pivots (all positive) are none near zero."""
    return bool(pivots.min() > PIVOT_FLOOR * pivots.max())


def _system(total: Quadratic, fold: Quadratic | None, weights: np.ndarray, center: np.ndarray,
            training: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(A + diag(w), b + w * center) of the training rows' quadratic (``total`` less the held-out
    ``fold``, or all rows): the penalty sum w (center + d)^2 added, in one new matrix (``total`` itself
    when all rows are taken without a penalty). ``training``: the training rows' Gram block when made
    already (total less fold), copied."""
    if fold is None:
        system = total.gram.copy() if np.any(weights) else total.gram
        gradient = total.gradient
    else:
        system = training.copy() if training is not None else np.subtract(total.gram, fold.gram)
        gradient = total.gradient - fold.gradient
    if np.any(weights):
        system[np.diag_indices_from(system)] += weights
        gradient = gradient + weights * center
    return system, gradient


@dataclass(frozen=True)
class BlockFit:
    """A model fitted from its blocks: steps d from the anchor (phi = anchor + d on its columns).

    step : (k,) the fit to all rows
    fold_steps : per assignment, per fold, (k,) the fit to the fold's training rows
    penalty : lambda of the smoothness penalty (0: none)
    cost : the weighted sum of squares of the fit to all rows (the penalty not added) [m^2]
    heldout_ssq : per assignment, per fold, the weighted held-out sum of squares of its fit [m^2]
    grid_index : where on :data:`PENALTY_GRID` lambda was chosen (None: no penalty)
    """

    step: np.ndarray
    fold_steps: list
    penalty: float
    cost: float
    heldout_ssq: list
    grid_index: int | None


def fit_blocks(total: Quadratic, held: list, low: np.ndarray, high: np.ndarray, weights: np.ndarray,
               center: np.ndarray, start_index: int | None = None, chosen_index: int | None = None,
               shared: SharedBlock | None = None) -> BlockFit:
    """Fit a model from its quadratics.

    Parameters
    ----------
    total : Quadratic
        The sum of squares over all rows, as a function of the step d (k,).
    held : list of list of callables
        Per fold assignment, per fold, a function giving the sum of squares over its held-out rows as
        a Quadratic (made when needed and let go: a fine angle table's blocks are 20 MB each).
    low, high : (k,)
        The box of the step (the fit range less the anchor).
    weights : (k,)
        The penalty's weight of each column (0: not penalised); the penalty is
        lambda * sum(weights * (center + d)^2).
    center : (k,)
        The anchor's values on the model's columns.
    start_index : int or None
        Where on the lambda grid to start the search (the last choice for these penalised effects).
    chosen_index : int or None
        Lambda's place on the grid when it is chosen already (no search).
    shared : SharedBlock or None
        The penalised columns, whose systems' factors are kept for the next model with them
        (:func:`free_step`): the same fits, fewer factorisations.
    """
    penalised = np.any(weights > 0)
    if total.gram.shape[0] <= KEEP_FOLD_BLOCKS:
        # each fold's blocks made once for the whole fit: the penalty search's steps and the fold fits after
        # it each gathered them again from the store (a model with the cyclic effect: 350 columns, 1 MB a fold)
        held = [[cache(get) for get in folds] for folds in held]
    lam, index, searched = 0.0, None, {}
    if penalised and chosen_index is not None:
        index, lam = chosen_index, float(penalty_grid(total, weights)[chosen_index])
    elif penalised:
        index, lam, searched = choose_penalty(total, held[0] if held else [], weights, center, start_index,
                                              steps=True, shared=shared)
    w = lam * weights
    shared = shared if penalised else None
    system, gradient = _system(total, None, w, center)
    step = box_step(system, gradient, low, high, shared, shared and shared.key("all", lam),
                    overwrite=system is not total.gram)
    inside = not np.any(np.clip(0.0, low, high))  # the box holds the anchor: a free step is box_step's own
    fold_steps, ssq = [], []
    for r, folds in enumerate(held):
        steps, scores = [], []
        for f, get in enumerate(folds):
            fold = get()
            free = searched.get(f) if r == 0 and inside else None
            if free is not None and np.all(free >= low) and np.all(free <= high):
                d = free  # the search's solve at the chosen lambda: what box_step would solve again
            else:
                d = box_step(*_system(total, fold, w, center), low, high, shared,
                             shared and shared.key(("train", r, f), lam), overwrite=True)
            steps.append(d)
            scores.append(fold.value(d))
        fold_steps.append(steps)
        ssq.append(scores)
    return BlockFit(step, fold_steps, lam, total.value(step), ssq, index)


#: a model of at most this many columns keeps its folds' held-out blocks through its fit (5 x 3 MB at most);
#: a fine angle table's (1,231 columns at 10^4 poses, 12 MB a fold) are made when needed and let go
KEEP_FOLD_BLOCKS = 640


def penalty_grid(total: Quadratic, weights: np.ndarray) -> np.ndarray:
    """The lambdas tried: :data:`PENALTY_GRID` times the penalised columns' median Gram diagonal."""
    penalised = weights > 0
    return float(np.median(np.diag(total.gram)[penalised])) * PENALTY_GRID if penalised.any() else PENALTY_GRID


def choose_penalty(total: Quadratic, folds: list, weights: np.ndarray, center: np.ndarray,
                   start_index: int | None, steps: bool = False, shared: SharedBlock | None = None) -> tuple:
    """(grid index, lambda): the penalty whose fits to each fold's training rows predict its held-out
    rows best (summed over ``folds``, one assignment: functions giving each fold's held-out
    Quadratic), walking :data:`PENALTY_GRID` from ``start_index`` (default its middle) to the nearest
    minimum, a lambda and its neighbours at a time (each fold's blocks made once for them). The fits
    are the free minimisers (:func:`free_step`, as :func:`box_step` solves them; where that is not well
    posed, with a ridge of 1e-12 times the largest diagonal), as the bounds rarely act at the
    penalty's scale. With fewer than two folds, the grid's middle. With ``steps``, also each fold's
    free step at the chosen lambda ({fold: (k,) or None where the ridge was needed}): the fold fits
    at that lambda are those steps where they lie in the box, no second solve. ``shared``: the
    penalised columns' factors kept (:func:`free_step`)."""
    diagonal = np.diag(total.gram)
    grid = penalty_grid(total, weights)
    middle = len(grid) // 2
    if len(folds) < 2:
        return (middle, float(grid[middle])) + (({},) if steps else ())
    ridge = 1e-12 * max(float(diagonal.max()) if diagonal.size else 1.0, 1e-300)
    scores: dict = {}
    solved: dict = {}  # (lambda's index, fold) -> its free step (None: ridge needed)

    def scored(indices) -> None:
        todo = [i for i in indices if 0 <= i < len(grid) and i not in scores]
        if not todo:
            return
        partial = dict.fromkeys(todo, 0.0)
        for f, get in enumerate(folds):
            fold = get()
            training = np.subtract(total.gram, fold.gram) if len(todo) > 1 else None  # made once for them
            for i in todo:
                system, gradient = _system(total, fold, grid[i] * weights, center, training)
                d = free_step(system, gradient, shared, shared and shared.key(("train", 0, f), grid[i]),
                              overwrite=True)
                solved[i, f] = d
                if d is None:
                    system, gradient = _system(total, fold, grid[i] * weights, center, training)
                    system[np.diag_indices_from(system)] += ridge
                    d = cholesky_solve(system, -gradient)
                partial[i] += float(2.0 * fold.gradient @ d + d @ fold.gram @ d)  # less the constant
        scores.update(partial)

    i = middle if start_index is None else int(np.clip(start_index, 0, len(grid) - 1))
    while True:
        scored([i - 1, i, i + 1])
        if i > 0 and scores[i - 1] <= scores[i]:
            i -= 1
        elif i < len(grid) - 1 and scores[i + 1] < scores[i]:
            i += 1
        else:
            break
    if steps:
        return i, float(grid[i]), {f: solved.get((i, f)) for f in range(len(folds))}
    return i, float(grid[i])


__all__ = ["BlockFit", "FactorCache", "KEEP_FOLD_BLOCKS", "PENALTY_GRID", "SharedBlock", "box_step", "choose_penalty", "fit_blocks",
           "free_step", "penalty_grid"]
