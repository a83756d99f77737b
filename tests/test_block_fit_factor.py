"""The block fits' Cholesky factor taken in place (``least_squares.cholesky_factor``), the near-singular
judgement on the unit-diagonal system, the box step on a system it may overwrite, and the lambda walk
from any start: each against numpy or scipy on explicit matrices written here. Each test names the
planted bug it was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from tcr_accuracy.diagnosis.block_fit import PENALTY_GRID, box_step, choose_penalty, free_step
from tcr_accuracy.diagnosis.gram import Quadratic
from tcr_accuracy.diagnosis.least_squares import cholesky_factor


def _spd(rng, k: int, spread: float = 2.0) -> np.ndarray:
    """A (k, k) positive definite Gram matrix of columns whose norms span 10^spread."""
    x = rng.standard_normal((3 * k, k)) * np.logspace(0, spread, k)
    return x.T @ x


@pytest.mark.parametrize("order", ["C", "F"])
def test_the_factor_is_numpys_cholesky_in_place_or_in_a_copy(order):
    """U^T U = A with U numpy's lower factor transposed; the copy leaves A as it was, in place A's lower
    triangle holds the factor and its upper one is A's; an indefinite matrix gives None. Seen failing on
    ``lower=False`` turned to ``lower=True`` in the potrf call (the factor in the wrong triangle) and on
    ``info == 0`` turned to ``info >= 0`` (an indefinite matrix factored)."""
    rng = np.random.default_rng(1)
    a = np.asarray(_spd(rng, 40), order=order)
    expected = np.linalg.cholesky(a).T  # upper: A = U^T U
    kept = a.copy()
    factor = cholesky_factor(a)
    np.testing.assert_array_equal(a, kept)
    np.testing.assert_allclose(np.triu(factor), expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    c_order = np.ascontiguousarray(kept)
    factor = cholesky_factor(c_order, overwrite=True)
    assert np.shares_memory(factor, c_order)
    np.testing.assert_allclose(np.tril(c_order), expected.T, rtol=0, atol=1e-12 * np.abs(expected).max())
    np.testing.assert_array_equal(np.triu(c_order, 1), np.triu(kept, 1))
    indefinite = kept.copy()
    indefinite[5, 5] = -1.0
    assert cholesky_factor(indefinite) is None


def test_a_badly_scaled_system_is_solved_and_a_near_singular_one_refused():
    """Columns a hundred million times apart in norm are a well-posed system (the unit-diagonal system's
    pivots judge it): its step is numpy's solve; a positive definite system whose unit-diagonal pivots
    (numpy's) fall below 1e-7 of the largest is refused (None), and taken once a ridge lifts them. Seen
    failing on the pivots taken from the unscaled factor (``np.diagonal(factor)`` without ``/ norms``:
    the scaled system refused) and on ``PIVOT_FLOOR * pivots.max()`` turned to ``0.0 * pivots.max()``
    (the near-singular one solved)."""
    rng = np.random.default_rng(2)

    def unit_singular_values(rows):  # of the columns scaled to unit norm, from the rows (LAPACK's SVD)
        return np.linalg.svd(rows / np.linalg.norm(rows, axis=0), compute_uv=False)

    x = rng.standard_normal((200, 8)) * np.logspace(-4, 4, 8)
    system, gradient = x.T @ x, rng.standard_normal(8)
    sv = unit_singular_values(x)
    assert sv[-1] > 1e-2 * sv[0]
    raw = np.diag(np.linalg.cholesky(system))
    assert raw.min() < 1e-7 * raw.max()  # the raw factor's pivots alone would call it singular
    expected = np.linalg.solve(system, -gradient)
    for overwrite in (False, True):
        step = free_step(system.copy(), gradient, overwrite=overwrite)
        np.testing.assert_allclose(step, expected, rtol=1e-8)
    # a positive definite system whose unit-diagonal form's last pivot is 3e-8: L L^T scaled apart
    lower = np.tril(rng.uniform(-0.5, 0.5, (8, 8)), -1) + np.diag(np.r_[np.ones(7), 3e-8])
    near = lower @ lower.T
    scales = np.logspace(-3, 3, 8)
    near = near / np.sqrt(np.outer(np.diag(near), np.diag(near))) * np.outer(scales, scales)
    unit = near / np.outer(scales, scales)
    numpy_pivots = np.diag(np.linalg.cholesky(unit))  # positive definite to numpy, and near singular
    assert numpy_pivots.min() < 1e-7 * numpy_pivots.max()
    assert free_step(near, rng.standard_normal(8)) is None
    assert free_step(near + np.diag(1e-6 * scales**2), rng.standard_normal(8)) is not None  # a ridge mends it


@pytest.mark.parametrize("case", ["bound stops the step", "singular"])
def test_a_box_step_on_a_system_it_may_overwrite_is_scipys_bounded_least_squares(case):
    """The box step told it may overwrite its system, where the free step leaves the box (the damped
    solver then reads the system again) and where the system is singular (two equal columns: the free
    step refused after the factorisation has run): scipy's ``lsq_linear`` on the rows. Seen failing on
    the system not put back from its untouched triangle (the damped solver reading the factor)."""
    rng = np.random.default_rng(3)
    jac = rng.standard_normal((80, 6)) * np.logspace(0, -1, 6)
    if case == "singular":
        jac[:, 4] = jac[:, 1]
    residual = -jac @ np.array([2.0, -1.5, 0.5, 1.0, -0.3, 0.2]) + 0.1 * rng.standard_normal(80)
    low, high = np.full(6, -1.0), np.full(6, 1.0)
    system, gradient = jac.T @ jac, jac.T @ residual
    kept = system.copy()
    step = box_step(system, gradient, low, high, overwrite=True)
    expected = lsq_linear(jac, -residual, bounds=(low, high), method="bvls", tol=1e-14).x
    np.testing.assert_allclose(jac @ step, jac @ expected, rtol=0, atol=1e-8)
    assert np.sum((residual + jac @ step) ** 2) <= np.sum((residual + jac @ expected) ** 2) * (1 + 1e-10)
    np.testing.assert_array_equal(box_step(kept.copy(), gradient, low, high), step)  # a copy, the same step
    assert np.all(step >= low) and np.all(step <= high)


def test_the_lambda_walk_reaches_the_grids_best_from_every_start():
    """A ridge whose k-fold score over the lambda grid has its minimum inside the grid: the walk from
    every start ends on the argmin of the scores computed here on the rows, and from the argmin itself
    scores only it and its neighbours (each fold's blocks asked for once). Seen failing on the walk up
    the grid taken out (``i += 1`` turned to ``break``) and on the start index ignored (every walk from
    the middle: the folds asked for more than once)."""
    rng = np.random.default_rng(4)
    n, k = 300, 24
    x = rng.standard_normal((n, k))
    y = x @ rng.standard_normal(k) + rng.standard_normal(n)
    weights = np.ones(k)
    folds = np.array_split(rng.permutation(n), 5)
    asked = []

    def quadratic(rows):
        return Quadratic(x[rows].T @ x[rows], -x[rows].T @ y[rows], float(y[rows] @ y[rows]))

    def getter(f, rows):
        def get():
            asked.append(f)
            return quadratic(rows)
        return get

    total = quadratic(np.arange(n))
    grid = np.median(np.diag(total.gram)) * PENALTY_GRID

    def score(lam):
        out = 0.0
        for rows in folds:
            train = np.setdiff1d(np.arange(n), rows)
            d = np.linalg.solve(x[train].T @ x[train] + lam * np.diag(weights), x[train].T @ y[train])
            out += np.sum((y[rows] - x[rows] @ d) ** 2)
        return out

    scores = np.array([score(lam) for lam in grid])
    best = int(np.argmin(scores))
    # one minimum, below the grid's middle (where a walk without a start begins)
    assert 0 < best < len(grid) // 2
    assert np.all(np.diff(scores[:best + 1]) < 0) and np.all(np.diff(scores[best:]) > 0)
    for start in range(len(grid)):
        asked.clear()
        index, lam = choose_penalty(total, [getter(f, rows) for f, rows in enumerate(folds)], weights, np.zeros(k),
                                    start)
        assert (index, lam) == (best, grid[best])
        if start == best:
            assert sorted(asked) == list(range(5))
