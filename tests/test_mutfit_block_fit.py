"""A model's fits from its Gram blocks (``diagnosis/block_fit.py``, ``diagnosis/gram.py``'s ``Quadratic``)
against least squares solved here on the rows: scipy's bounded ``lsq_linear`` on the stacked system
[J; sqrt(lambda w)] for every fit inside a box, each lambda's k-fold held-out error summed on the rows,
the penalty grid written out as powers of ten times the penalised columns' median Gram diagonal. Each
test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from tcr_accuracy.diagnosis.block_fit import box_step, fit_blocks, free_step, penalty_grid
from tcr_accuracy.diagnosis.gram import Quadratic


def _rows(seed: int, n: int = 120, k: int = 6):
    """(n, k) columns of different sizes and a residual r (n,) at the anchor (the step d fits r + J d)."""
    rng = np.random.default_rng(seed)
    jac = rng.standard_normal((n, k)) * np.logspace(0, -1.5, k)
    truth = rng.standard_normal(k)
    residual = -(jac @ truth) + 0.2 * rng.standard_normal(n)
    return jac, residual


def _quadratic(jac, residual, rows=slice(None)) -> Quadratic:
    return Quadratic(jac[rows].T @ jac[rows], jac[rows].T @ residual[rows], float(residual[rows] @ residual[rows]))


def _bounded(jac, residual, low, high, weights=None, center=None):
    """argmin |r + J d|^2 + sum(w (center + d)^2) over low <= d <= high, by scipy on the stacked rows."""
    k = jac.shape[1]
    weights = np.zeros(k) if weights is None else weights
    center = np.zeros(k) if center is None else center
    stacked = np.vstack([jac, np.diag(np.sqrt(weights))])
    target = np.r_[-residual, -np.sqrt(weights) * center]
    return lsq_linear(stacked, target, bounds=(low, high), method="bvls", tol=1e-14).x


def test_a_quadratic_is_the_sum_of_squares_of_its_rows_and_subtracts_row_sets():
    """value(d) = |r + J d|^2 on its rows; a quadratic less another is the sum over the rows left. Seen
    failing on ``self.constant - other.constant`` turned to ``** other.constant`` and on ``2.0 *
    self.gradient @ step`` turned to ``3.0``."""
    jac, residual = _rows(1)
    d = np.random.default_rng(2).standard_normal(jac.shape[1])
    total, held = _quadratic(jac, residual), _quadratic(jac, residual, slice(0, 40))
    assert total.value(d) == pytest.approx(np.sum((residual + jac @ d) ** 2), rel=1e-12)
    rest = total - held
    assert rest.value(d) == pytest.approx(np.sum((residual[40:] + jac[40:] @ d) ** 2), rel=1e-10)
    assert rest.constant == pytest.approx(residual[40:] @ residual[40:], rel=1e-12)


@pytest.mark.parametrize("box", ["wide", "tight", "away from zero"])
def test_box_step_is_scipys_bounded_least_squares(box):
    """d^T A d + 2 b^T d minimised over a box: a box that holds the free step (the Cholesky solve), one
    that stops it, one that does not hold zero (the step starts from zero clipped into it): each
    against ``lsq_linear``. Seen failing on ``gradient + system @ origin`` turned to ``-`` and on
    ``low - origin`` turned to ``low + origin``."""
    jac, residual = _rows(3)
    quad = _quadratic(jac, residual)
    free = np.linalg.solve(quad.gram, -quad.gradient)
    low, high = {"wide": (-10 * np.abs(free) - 1, 10 * np.abs(free) + 1),
                 "tight": (-0.5 * np.abs(free), 0.5 * np.abs(free)),
                 "away from zero": (np.abs(free) * 0.2 + 0.3, np.abs(free) * 0.2 + 2.0)}[box]
    got = box_step(quad.gram, quad.gradient, low, high)
    expected = _bounded(jac, residual, low, high)
    np.testing.assert_allclose(got, expected, rtol=1e-7, atol=1e-9)
    if box == "wide":
        np.testing.assert_allclose(got, free, rtol=1e-10)
    else:
        assert np.any(np.isclose(got, low, rtol=1e-12) | np.isclose(got, high, rtol=1e-12))
    assert np.all(got >= low) and np.all(got <= high)


def test_free_step_solves_the_normal_equations_and_declines_a_singular_system():
    """The unbounded minimiser -A^-1 b at any column scale; None for a rank-deficient or indefinite A.
    Seen failing on ``-gradient / norms`` turned to ``gradient / norms`` and on ``/ norms`` at the end
    turned to ``* norms``."""
    jac, residual = _rows(4)
    jac = jac * np.array([1e3, 1.0, 1e-3, 1.0, 10.0, 0.1])
    quad = _quadratic(jac, residual)
    np.testing.assert_allclose(free_step(quad.gram, quad.gradient), np.linalg.solve(quad.gram, -quad.gradient),
                               rtol=1e-8)
    twin = np.hstack([jac, jac[:, :1]])
    assert free_step(twin.T @ twin, twin.T @ residual) is None
    assert free_step(-quad.gram, quad.gradient) is None


def test_penalty_grid_is_powers_of_ten_times_the_median_penalised_diagonal():
    """lambda in {1e-5 ... 1e3} times the median of the penalised columns' Gram diagonal (the
    unpenalised ones not counted). Seen failing on ``np.logspace(-5, 3, 9)`` turned to ``(-5, 4, 9)``
    and on ``[penalised]`` dropped."""
    jac, residual = _rows(5)
    quad = _quadratic(jac, residual)
    weights = np.array([0.0, 0.0, 1.0, 2.0, 0.5, 0.0])
    diagonal = np.sum(jac**2, axis=0)
    expected = np.median(diagonal[[2, 3, 4]]) * 10.0 ** np.arange(-5, 4)
    np.testing.assert_allclose(penalty_grid(quad, weights), expected, rtol=1e-12)


def test_penalised_fits_with_bounds_are_the_stacked_least_squares_and_lambda_the_grids_argmin():
    """A penalised model (center not zero) whose bounds stop some fits, 4 folds: lambda is the grid's
    argmin of the summed held-out squares of the free fold fits (computed here), whichever end the
    walk starts from; the fit to all rows and each fold's fit are ``lsq_linear`` on the stacked rows
    at that lambda within the box; its cost the rows' sum of squares (the penalty not added); each
    held-out sum of squares the held rows' at the fold's fit. With one fold, the grid's middle. Seen
    failing on ``gradient + weights * center`` turned to ``-`` and on ``len(grid) // 2`` turned to
    ``// 3``."""
    rng = np.random.default_rng(6)
    n, k = 160, 8
    jac = rng.standard_normal((n, k)) * np.logspace(0, -1, k)
    truth = np.where(np.arange(k) < 3, 1.0, 0.1 * rng.standard_normal(k))
    residual = -(jac @ truth) + 0.4 * rng.standard_normal(n)
    weights = np.where(np.arange(k) < 3, 0.0, np.linspace(0.5, 4.0, k))
    center = 0.05 * rng.standard_normal(k)
    folds = np.array_split(rng.permutation(n), 4)
    total = _quadratic(jac, residual)
    held = [[(lambda rows=rows: _quadratic(jac, residual, rows)) for rows in folds]]
    grid = np.median(np.sum(jac[:, weights > 0] ** 2, axis=0)) * 10.0 ** np.arange(-5, 4)

    def free_fold_fit(rows, lam):
        train = np.setdiff1d(np.arange(n), rows)
        system = jac[train].T @ jac[train] + lam * np.diag(weights)
        return np.linalg.solve(system, -(jac[train].T @ residual[train]) - lam * weights * center)

    scores = [sum(np.sum((residual[rows] + jac[rows] @ free_fold_fit(rows, lam)) ** 2) for rows in folds)
              for lam in grid]
    best = int(np.argmin(scores))
    assert 0 < best < len(grid) - 1  # an inner minimum: the walk has somewhere to go from either end
    free_all = np.linalg.solve(total.gram + grid[best] * np.diag(weights),
                               -total.gradient - grid[best] * weights * center)
    low, high = -np.full(k, 10.0), np.full(k, 10.0)
    low[0] = free_all[0] + 0.3 * abs(free_all[0])  # the first column's bound stops the fits
    for start in (0, len(grid) - 1, None):
        fit = fit_blocks(total, held, low, high, weights, center, start_index=start)
        assert fit.grid_index == best and fit.penalty == pytest.approx(grid[best], rel=1e-12)
    np.testing.assert_allclose(fit.step, _bounded(jac, residual, low, high, grid[best] * weights, center),
                               rtol=1e-7, atol=1e-9)
    assert fit.step[0] == pytest.approx(low[0], rel=1e-12)
    assert fit.cost == pytest.approx(np.sum((residual + jac @ fit.step) ** 2), rel=1e-10)
    for rows, d, ssq in zip(folds, fit.fold_steps[0], fit.heldout_ssq[0]):
        train = np.setdiff1d(np.arange(n), rows)
        np.testing.assert_allclose(d, _bounded(jac[train], residual[train], low, high, grid[best] * weights, center),
                                   rtol=1e-7, atol=1e-9)
        assert ssq == pytest.approx(np.sum((residual[rows] + jac[rows] @ d) ** 2), rel=1e-10)
    one = fit_blocks(total, [held[0][:1]], low, high, weights, center)
    assert one.grid_index == 4 and one.penalty == pytest.approx(grid[4], rel=1e-12)
    chosen = fit_blocks(total, held, low, high, weights, center, chosen_index=2)
    assert chosen.grid_index == 2 and chosen.penalty == pytest.approx(grid[2], rel=1e-12)
    np.testing.assert_allclose(chosen.step, _bounded(jac, residual, low, high, grid[2] * weights, center),
                               rtol=1e-7, atol=1e-9)


def test_a_small_models_fold_blocks_are_made_once_per_fit_and_a_large_ones_when_needed(monkeypatch):
    """A penalised model's lambda search walks several lambdas and then fits each fold: its folds' held-out
    blocks are asked for once per fit (the search's steps and the fold fits share them) up to
    ``KEEP_FOLD_BLOCKS`` columns; above, each time they are needed (a fine angle table's are let go). The
    fits are the stacked least squares solved here either way."""
    from tcr_accuracy.diagnosis import block_fit

    rng = np.random.default_rng(8)
    n, k = 150, 7
    jac = rng.standard_normal((n, k)) * np.logspace(0, -1, k)
    residual = -(jac @ rng.standard_normal(k)) + 0.3 * rng.standard_normal(n)
    weights = np.where(np.arange(k) < 2, 0.0, 1.0)
    center = np.zeros(k)
    folds = np.array_split(rng.permutation(n), 5)
    low, high = -np.full(k, 50.0), np.full(k, 50.0)
    for limit, once in ((k, True), (k - 1, False)):
        monkeypatch.setattr(block_fit, "KEEP_FOLD_BLOCKS", limit)
        asked = [0] * len(folds)

        def getter(f):
            def get():
                asked[f] += 1
                return _quadratic(jac, residual, folds[f])
            return get

        fit = fit_blocks(_quadratic(jac, residual), [[getter(f) for f in range(len(folds))]], low, high, weights,
                         center, start_index=0)
        assert (asked == [1] * len(folds)) == once and min(asked) >= 1
        lam = fit.penalty * weights
        for rows, d in zip(folds, fit.fold_steps[0]):
            train = np.setdiff1d(np.arange(n), rows)
            np.testing.assert_allclose(d, _bounded(jac[train], residual[train], low, high, lam, center),
                                       rtol=1e-7, atol=1e-9)
