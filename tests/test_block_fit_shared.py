"""The fit from blocks with the penalised columns' factors kept across models (the Schur complement on
the other columns) against the normal equations solved here with numpy, model after model."""

import numpy as np

from tcr_accuracy.diagnosis.block_fit import PENALTY_GRID, SharedBlock, fit_blocks, free_step
from tcr_accuracy.diagnosis.gram import Quadratic
from tcr_accuracy.diagnosis.least_squares import FactorCache


def _rows(rng, n: int, k: int) -> np.ndarray:
    return rng.standard_normal((n, k)) * np.logspace(0, -2, k)  # columns a hundredfold apart


def test_a_step_through_a_kept_factor_solves_each_models_system():
    rng = np.random.default_rng(21)
    n, k_p = 500, 40
    penalised = _rows(rng, n, k_p)
    cache = FactorCache()
    lam_w = np.linspace(0.1, 3.0, k_p)
    for model in range(4):  # the same penalised columns beside other columns each time
        others = _rows(rng, n, 3 + model)
        # the penalised columns in the middle of the model's, as the vocabulary orders them
        x = np.hstack([others[:, :2], penalised, others[:, 2:]])
        positions = np.arange(2, 2 + k_p)
        system = x.T @ x
        system[positions, positions] += lam_w
        gradient = rng.standard_normal(x.shape[1])
        shared = SharedBlock(cache, tuple(range(100, 100 + k_p)), positions)
        step = free_step(system, gradient, shared, shared.key("all", 1.0))
        expected = np.linalg.solve(system, -gradient)
        np.testing.assert_allclose(step, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    assert cache.nbytes() == 8 * k_p * k_p  # one factor, made once, taken by every model


def test_a_step_through_a_kept_factor_is_refused_where_the_system_is_singular():
    rng = np.random.default_rng(22)
    x = _rows(rng, 300, 12)
    x = np.hstack([x, x[:, [3]]])  # a column that repeats a penalised one
    positions = np.arange(2, 10)
    shared = SharedBlock(FactorCache(), tuple(positions.tolist()), positions)
    system = x.T @ x
    assert free_step(system, rng.standard_normal(13)) is None
    assert free_step(system, rng.standard_normal(13), shared, shared.key("all", 1.0)) is None


def test_penalised_fits_of_several_models_with_their_factors_kept_are_the_ridges_solved_here():
    rng = np.random.default_rng(23)
    n, k_p = 400, 24
    penalised = _rows(rng, n, k_p)
    folds = np.array_split(rng.permutation(n), 5)
    cache = FactorCache()
    for model in range(3):
        others = _rows(rng, n, 4 + model)
        x = np.hstack([others, penalised])
        k = x.shape[1]
        truth = np.concatenate([np.ones(others.shape[1]), 0.05 * rng.standard_normal(k_p)])
        y = x @ truth + 0.3 * rng.standard_normal(n)
        weights = np.concatenate([np.zeros(others.shape[1]), np.linspace(0.1, 10.0, k_p)])
        positions = np.flatnonzero(weights > 0)

        def quadratic(rows):
            return Quadratic(x[rows].T @ x[rows], -x[rows].T @ y[rows], float(y[rows] @ y[rows]))

        total = quadratic(np.arange(n))
        held = [[(lambda rows=rows: quadratic(rows)) for rows in folds]]
        shared = SharedBlock(cache, tuple(range(1000, 1000 + k_p)), positions)
        fit = fit_blocks(total, held, -np.full(k, 1e3), np.full(k, 1e3), weights, np.zeros(k), shared=shared)
        grid = np.median(np.diag(total.gram)[positions]) * PENALTY_GRID
        # each fold's ridge as least squares on its training rows and sqrt(lambda w) rows below them
        train = [np.setdiff1d(np.arange(n), rows) for rows in folds]
        steps = {(i, f): np.linalg.lstsq(np.vstack([x[t], np.diag(np.sqrt(lam * weights))]),
                                         np.concatenate([y[t], np.zeros(k)]), rcond=None)[0]
                 for i, lam in enumerate(grid) for f, t in enumerate(train)}
        score = [sum(float(np.sum((y[rows] - x[rows] @ steps[i, f]) ** 2)) for f, rows in enumerate(folds))
                 for i in range(grid.size)]
        chosen = int(np.argmin(score))
        assert (fit.grid_index, fit.penalty) == (chosen, grid[chosen])
        for f, d in enumerate(fit.fold_steps[0]):
            np.testing.assert_allclose(d, steps[chosen, f], rtol=0, atol=1e-8 * np.abs(steps[chosen, f]).max())
        whole = np.linalg.lstsq(np.vstack([x, np.diag(np.sqrt(grid[chosen] * weights))]),
                                np.concatenate([y, np.zeros(k)]), rcond=None)[0]
        np.testing.assert_allclose(fit.step, whole, rtol=0, atol=1e-8 * np.abs(whole).max())


def test_the_factor_cache_keeps_the_most_recently_used_within_its_bytes():
    cache = FactorCache(max_bytes=3 * 800)  # three 10 x 10 factors
    made = []

    def maker(i):
        return lambda: made.append(i) or np.full((10, 10), float(i))

    for i in range(4):
        cache.get(i, maker(i))
    assert made == [0, 1, 2, 3] and cache.nbytes() == 2400
    assert cache.get(1, maker(-1))[0, 0] == 1.0 and made[-1] == 3  # kept: not made again
    cache.get(4, maker(4))  # pushes out 2, the least recently used (1 was just asked for)
    cache.get(2, maker(2))
    assert made[-2:] == [4, 2]
    cache.get(1, maker(-1))
    assert made[-1] == 2
