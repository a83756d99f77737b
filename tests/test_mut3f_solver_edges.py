"""The fit core's standard errors where the Gram matrix has a null direction, and its walk along the penalty
grid to a minimum away from the grid's middle (``diagnosis/least_squares.py``, ``block_fit.py``), against
numpy: the pseudo-inverse of the column-scaled Gram matrix (SVD), ridge fits of every fold's training rows
(``lstsq`` on the rows stacked with sqrt(lambda w) rows) and their held-out sums of squares. Each test names
a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import contextlib
import signal

import numpy as np
import pytest

from tcr_accuracy.diagnosis.block_fit import PENALTY_GRID, choose_penalty
from tcr_accuracy.diagnosis.gram import Quadratic
from tcr_accuracy.diagnosis.least_squares import DampedSolver


def test_a_parameter_clear_of_a_null_direction_keeps_its_pseudo_inverse_standard_error():
    """Columns c0, c1 and c2 = c1 + 1e-4 c0 (dependent; c3 independent): the column-scaled Gram matrix has one
    null direction, (1e-4 |c0| / |c2|, |c1| / |c2|, -1, 0) up to its length, which c0 touches by 5e-9 of its
    square (below the 1e-6 that makes a parameter unseen). c0 and c3: sqrt(s^2 diag(D^-1 (D^-1 G D^-1)^+ D^-1))
    with numpy's SVD pseudo-inverse, to 1e-10; c1 and c2: inf. Seen failing on the null direction's inverse
    ``np.where(self.kept, ..., 0.0)`` turned to ``1.0`` (c0's error grown by 5e-9 of itself... and more)."""
    rng = np.random.default_rng(3006)
    x = rng.standard_normal((40, 4)) * np.array([2e-3, 1e-3, 1.0, 5e-4])
    x[:, 2] = x[:, 1] + 1e-4 * x[:, 0]
    gram = x.T @ x
    solver = DampedSolver(gram)
    norms = np.sqrt(np.diag(gram))
    unit = gram / np.outer(norms, norms)
    null = np.linalg.svd(unit)[2][-1]
    assert 1e-10 < null[0] ** 2 < 1e-6 and null[3] ** 2 < 1e-20  # c0 barely touches it, c3 not at all
    variance = 2.5e-9
    expected = np.sqrt(variance * np.diag(np.linalg.pinv(unit, rcond=1e-10, hermitian=False)) / norms**2)
    std = solver.standard_errors(variance)
    assert np.all(np.isinf(std[[1, 2]]))
    np.testing.assert_allclose(std[[0, 3]], expected[[0, 3]], rtol=1e-10)
    covariance = variance * np.linalg.pinv(unit, rcond=1e-10) / np.outer(norms, norms)
    np.testing.assert_allclose(solver.covariance(variance), covariance, rtol=1e-8, atol=1e-12 * np.abs(covariance).max())


@contextlib.contextmanager
def _ends_within(seconds: float):
    """Fails (AssertionError) instead of hanging when the block runs on past ``seconds`` (an endless walk:
    a planted change can make it one, and a hang would read as a pass to a mutation run's time budget)."""
    def stop(signum, frame):
        raise AssertionError(f"the penalty walk did not end within {seconds} s")

    old = signal.signal(signal.SIGALRM, stop)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)


def _ridge_case(rng, truth_size: float, noise: float):
    """(rows x (n, k), targets y (n,), penalty weights (k,), five folds of rows)."""
    n, k = 120, 6
    x = rng.standard_normal((n, k))
    y = x @ (truth_size * rng.standard_normal(k)) + noise * rng.standard_normal(n)
    return x, y, np.linspace(0.5, 2.0, k), np.array_split(rng.permutation(n), 5)


def _quadratic(x, y, rows) -> Quadratic:
    return Quadratic(x[rows].T @ x[rows], -x[rows].T @ y[rows], float(y[rows] @ y[rows]))


@pytest.mark.parametrize("truth_size,noise,side", [(1.0, 0.05, "low"), (0.003, 1.0, "high")])
def test_the_penalty_walk_reaches_a_minimum_on_either_side_of_the_grids_middle(truth_size, noise, side):
    """A large truth in little noise (the best lambda is small) and a tiny one in much noise (large): the
    held-out score of each lambda on the grid, ridge fits of each fold's training rows by numpy's lstsq on
    the rows stacked with sqrt(lambda w) rows, has its minimum below or above the grid's middle, and the walk
    from the middle (and from either end) ends on it; with one fold, nothing to score, lambda is the grid's middle. Seen failing on the walk's ``scores[i - 1] <=
    scores[i]`` turned to ``scores[i + 1]`` and on the step ``i -= 1`` turned to ``i -= 0`` (endless walks, failed
    after 20 s rather than hung), on ``len(grid) - 1`` turned to ``- 2`` and on the middle ``len(grid) // 2`` turned to ``// 3``."""
    rng = np.random.default_rng(3007)
    x, y, weights, folds = _ridge_case(rng, truth_size, noise)
    n, k = x.shape
    total = _quadratic(x, y, np.arange(n))
    held = [(lambda rows=rows: _quadratic(x, y, rows)) for rows in folds]
    grid = np.median(np.diag(total.gram)) * PENALTY_GRID
    scores = []
    for lam in grid:
        score = 0.0
        for rows in folds:
            train = np.setdiff1d(np.arange(n), rows)
            d = np.linalg.lstsq(np.vstack([x[train], np.diag(np.sqrt(lam * weights))]),
                                np.concatenate([y[train], np.zeros(k)]), rcond=None)[0]
            score += float(np.sum((y[rows] - x[rows] @ d) ** 2))
        scores.append(score)
    best = int(np.argmin(scores))
    assert (best < 4) if side == "low" else (best > 4)
    assert np.all(np.diff(scores[:best + 1]) < 0) and np.all(np.diff(scores[best:]) > 0)  # one minimum
    for start in (None, 0, len(grid) - 1):
        with _ends_within(20.0):  # milliseconds when it ends
            index, lam = choose_penalty(total, held, weights, np.zeros(k), start)
        assert (index, lam) == (best, pytest.approx(grid[best], rel=1e-12))
    # one fold scores nothing: the grid's middle, 1e-1 of the median diagonal
    assert choose_penalty(total, held[:1], weights, np.zeros(k), None) == (4, pytest.approx(grid[4], rel=1e-12))
