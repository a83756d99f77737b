"""The fit from blocks with repeated fold assignments and the penalised columns' factors kept
(``diagnosis/block_fit.py``), the factor cache's default budget at its edges (``diagnosis/least_squares.py``),
against ridges solved here with numpy and byte counts written out (issue 36). Each test names a planted change
it was seen to catch."""

from __future__ import annotations

import numpy as np

from tcr_accuracy.diagnosis.block_fit import SharedBlock, fit_blocks
from tcr_accuracy.diagnosis.gram import Quadratic
from tcr_accuracy.diagnosis.least_squares import FactorCache


def test_each_fold_assignments_penalised_fits_are_ridges_on_its_own_training_rows():
    """Two fold assignments of 300 rows (five folds each), 16 penalised columns beside 4 free ones, their
    factors kept: lambda is chosen on the first assignment's folds (the grid's held-out argmin, solved here),
    and every fold of BOTH assignments is the ridge on its own training rows at that lambda, to 1e-8. The
    lambda search keeps its factors under the first assignment's labels; under the second's, the second
    assignment's folds would take the first's factors. The grid: the penalised columns' median Gram diagonal
    times the decades 1e-5 to 1e3. Seen failing on the search's key ``("train", 0, f)`` turned to
    ``("train", 1, f)`` and on ``PENALTY_GRID = np.logspace(-5, 3, 9)`` turned to ``logspace(-4, 3, 9)``."""
    rng = np.random.default_rng(3500)
    n, k_p, k_o = 300, 16, 4
    x = rng.standard_normal((n, k_o + k_p)) * np.logspace(0, -2, k_o + k_p)
    k = x.shape[1]
    y = x @ np.concatenate([np.ones(k_o), 1.0 * rng.standard_normal(k_p)]) + 0.3 * rng.standard_normal(n)
    weights = np.concatenate([np.zeros(k_o), np.linspace(0.1, 10.0, k_p)])
    assignments = [np.array_split(rng.permutation(n), 5) for _ in range(2)]

    def quadratic(rows):
        return Quadratic(x[rows].T @ x[rows], -x[rows].T @ y[rows], float(y[rows] @ y[rows]))

    held = [[(lambda rows=rows: quadratic(rows)) for rows in folds] for folds in assignments]
    shared = SharedBlock(FactorCache(), tuple(range(k_o, k)), np.arange(k_o, k))
    total = quadratic(np.arange(n))
    fit = fit_blocks(total, held, -np.full(k, 1e3), np.full(k, 1e3), weights, np.zeros(k), shared=shared)

    def ridge(rows, lam):
        return np.linalg.lstsq(np.vstack([x[rows], np.diag(np.sqrt(lam * weights))]),
                               np.concatenate([y[rows], np.zeros(k)]), rcond=None)[0]

    grid = np.median(np.diag(total.gram)[k_o:]) * 10.0 ** np.arange(-5, 4)  # decades from 1e-5 to 1e3
    train = [[np.setdiff1d(np.arange(n), rows) for rows in folds] for folds in assignments]
    score = [sum(float(np.sum((y[rows] - x[rows] @ ridge(t, lam)) ** 2)) for rows, t in zip(assignments[0], train[0]))
             for lam in grid]
    chosen = int(np.argmin(score))
    assert 0 < chosen < grid.size - 1 and (fit.grid_index, fit.penalty) == (chosen, grid[chosen])
    for r in range(2):
        for f, t in enumerate(train[r]):
            expected = ridge(t, grid[chosen])
            np.testing.assert_allclose(fit.fold_steps[r][f], expected, rtol=0, atol=1e-8 * np.abs(expected).max(),
                                       err_msg=f"assignment {r}, fold {f}")
            held_out = assignments[r][f]
            np.testing.assert_allclose(fit.heldout_ssq[r][f], np.sum((y[held_out] - x[held_out] @ expected) ** 2),
                                       rtol=1e-8)


def test_the_factor_caches_default_budget_is_24_mib_and_640_columns():
    """The default cache keeps factors of up to 640 columns (641: not worth keeping) and up to 24 MiB in
    all: two 12 MiB factors stay (neither made again), a third pushes out the least recently used, and one
    factor a byte over 24 MiB is made but not kept. Seen failing on ``24 * 2**20`` turned to ``24 * 2**19``
    and on ``max_columns: int = 640`` turned to ``641``."""
    cache = FactorCache()
    assert cache.keeps(640) and not cache.keeps(641)
    made = []

    def factor(name, n_bytes):
        def make():
            made.append(name)
            return np.zeros(n_bytes, dtype=np.uint8)
        return make

    half = 12 * 2**20
    cache.get("a", factor("a", half))
    cache.get("b", factor("b", half))
    assert cache.nbytes() == 24 * 2**20
    cache.get("a", factor("a", half))
    cache.get("b", factor("b", half))
    assert made == ["a", "b"]  # both kept at exactly the budget
    cache.get("c", factor("c", half))  # over it: "a", the least recently used, goes
    cache.get("b", factor("b", half))
    cache.get("a", factor("a", half))
    assert made == ["a", "b", "c", "a"] and cache.nbytes() == 24 * 2**20
    cache.clear()
    cache.get("big", factor("big", 24 * 2**20 + 1))
    cache.get("big", factor("big", 24 * 2**20 + 1))
    assert made[-2:] == ["big", "big"] and cache.nbytes() == 0
