"""Two survivors of the measuring sample drawn with seed 712770, each on a path only whole diagnoses ran
within the mutation budget, checked here directly against numpy written out in the test.

- The fold store's total made again when effects join later (``FoldGrams.extend``) on fold assignments
  whose first one does not hold out every row (the total then cannot be the sum of its folds): the
  blocks against J^T W J of the whitened columns written out whole.
- A penalised block fit whose box holds the anchor reuses the penalty search's free fold steps (no
  second solve), and solves every fold again when the box leaves the anchor out: the fold steps against
  the normal equations of each fold's training rows, and the solves counted.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis import block_fit
from tcr_accuracy.diagnosis.gram import FoldGrams, Quadratic


def _dense_case(rng, n=90):
    """Three dense effects' whitened columns on one measured frame of n rows, their bases as the store
    reads them, and the whitened Jacobian written out whole."""
    sizes = {"first": 4, "second": 3, "third": 2}
    bases = {}
    for name, k in sizes.items():
        bases[name] = SimpleNamespace(names=[f"{name}{i}" for i in range(k)], scales=rng.uniform(0.5, 2.0, k),
                                      fit_lower=-np.ones(k), fit_upper=np.ones(k), penalty=np.zeros(k),
                                      index=[np.arange(k)], per_part=[SimpleNamespace(g=rng.standard_normal((n, 3, k)))])
    whitening = rng.standard_normal((n, 3, 3)) + 3 * np.eye(3)
    part = SimpleNamespace(q=rng.uniform(-1, 1, (n, 6)), rows_per_pose=3, whitening=whitening)
    columns = [b.per_part[0].g * b.scales for b in bases.values()]
    jacobian = np.einsum("nij,njk->nik", whitening, np.concatenate(columns, axis=2))
    return part, bases, jacobian


def test_the_total_made_again_when_effects_join_and_the_folds_leave_rows_out():
    """A first assignment holding out rows 0-29 and 30-59 only (rows 60-89 in no held-out set), then a
    second one: the store sums the total row by row, not from its folds. Effects joining later
    (``extend``) keep the earlier columns' total block and add the new ones': every block equals the
    dense J^T W J of its rows. Catches the earlier total read from the held-out blocks (``old[-1]``)."""
    rng = np.random.default_rng(71)
    part, bases, jacobian = _dense_case(rng)
    n = part.q.shape[0]
    rows = np.arange(n)
    first = [(np.setdiff1d(rows, t), t) for t in (np.arange(0, 30), np.arange(30, 60))]
    order = rng.permutation(n)
    second = [(np.setdiff1d(rows, t), t) for t in np.array_split(order, 3)]

    def dense(selected):
        j = jacobian[selected].reshape(-1, jacobian.shape[2])
        return j.T @ j

    store = FoldGrams([part], {"first": bases["first"]}, [first, second])
    assert not store._total_from_folds
    store.bases = bases
    store.extend(["second"])
    store.extend(["third"])
    assert store.layout.effects == ["first", "second", "third"]
    scale = np.max(np.abs(dense(rows)))
    np.testing.assert_allclose(store.total, dense(rows), rtol=0, atol=1e-12 * scale)
    for blocks, folds in zip(store.held_blocks(), [first, second]):
        for block, (_, test) in zip(blocks, folds):
            np.testing.assert_allclose(block, dense(test), rtol=0, atol=1e-12 * scale)


def _penalised_problem(rng, n=120, k=5):
    """A weighted sum of squares |r + J d|^2 over n rows, its quadratics over all rows and over each
    fold's held-out rows in two fold assignments, and the penalty's weights and centre."""
    jacobian = rng.standard_normal((n, k))
    residual = jacobian @ rng.normal(0, 0.3, k) + rng.normal(0, 0.05, n)

    def quadratic(selected):
        j, r = jacobian[selected], residual[selected]
        return Quadratic(j.T @ j, j.T @ r, float(r @ r))

    order = rng.permutation(n)
    assignments = [np.array_split(order, 4), np.array_split(order[::-1], 3)]
    held = [[(lambda t=t: quadratic(t)) for t in tests] for tests in assignments]
    weights = np.array([0.0, 1.0, 1.0, 1.0, 0.0])
    center = rng.normal(0, 0.1, k)
    return quadratic(np.arange(n)), held, assignments, weights, center, jacobian, residual


@pytest.mark.parametrize("box", ["unbounded", "around the anchor", "beside the anchor"])
def test_a_penalised_fits_fold_steps_and_how_often_the_box_solver_runs(monkeypatch, box):
    """The fold steps are each fold's training rows' penalised normal equations at the chosen lambda
    (numpy's solve written out here); the box solver runs for the fit to all rows and, when the box
    holds the anchor (d = 0), only for the folds the penalty search did not solve (the second
    assignment's 3), else for every fold (1 + 4 + 3). Catches the anchor's test ``clip(0.0, ...)`` with
    its 0 changed (an unbounded box then seems to leave the anchor out: every fold solved twice)."""
    rng = np.random.default_rng(712770)
    total, held, assignments, weights, center, jacobian, residual = _penalised_problem(rng)
    k = jacobian.shape[1]
    low, high = {"unbounded": (np.full(k, -np.inf), np.full(k, np.inf)),
                 "around the anchor": (np.full(k, -5.0), np.full(k, 5.0)),
                 "beside the anchor": (np.full(k, -5.0), np.r_[np.full(k - 1, 5.0), -1e-9])}[box]
    calls = []
    solver = block_fit.box_step

    def counted(*args, **kwargs):
        calls.append(1)
        return solver(*args, **kwargs)

    monkeypatch.setattr(block_fit, "box_step", counted)
    fit = block_fit.fit_blocks(total, held, low, high, weights, center)
    assert fit.penalty > 0
    n = jacobian.shape[0]
    inside = box != "beside the anchor"
    for tests, steps in zip(assignments, fit.fold_steps):
        for test, step in zip(tests, steps):
            train = np.setdiff1d(np.arange(n), test)
            j, r = jacobian[train], residual[train]
            w = fit.penalty * weights
            expected = np.linalg.solve(j.T @ j + np.diag(w), -(j.T @ r + w * center))
            if inside:
                np.testing.assert_allclose(step, expected, rtol=0, atol=1e-10)
            else:  # the last coordinate held at its upper bound
                assert step[-1] <= high[-1] + 1e-15
    assert len(calls) == (1 + 3 if inside else 1 + 4 + 3)
