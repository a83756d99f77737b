"""The linear fit's uncertainty with a smoothness penalty (``FitEngine.evaluate``, ``diagnosis/fitting.py``):
the posterior covariance s^2 (J^T J + lambda W)^-1 written out with numpy from the model's Gram block, the
lambda the fit chose and its weights, s^2 its cost over n - k. The data: joint offsets hidden in a Pinocchio
model (tests/mutd_truth.py), the joint offsets' columns given penalty weights here. Each test names a planted
change it was seen to catch (issue 36)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from mutd_truth import offset_measurements

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.fitting import FitEngine

MODEL = ["frames", "joint_offsets"]
N = 16


@pytest.fixture(scope="module")
def engine():
    """A new engine (four folds) on a diagnosis' rows and columns (16 poses, 30 um noise), the joint offsets'
    columns penalised with weights 0.5 to 2."""
    robot, measured = offset_measurements(N, 4300)
    fitted = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2).fit(measured).engine_
    tests = np.array_split(np.random.default_rng(4301).permutation(N), 4)
    folds = [(np.setdiff1d(np.arange(N), t), np.sort(t)) for t in tests]
    bases = dict(fitted.bases)
    bases["joint_offsets"] = copy.copy(bases["joint_offsets"])
    bases["joint_offsets"].penalty = np.linspace(0.5, 2.0, len(bases["joint_offsets"].names))
    return FitEngine(fitted.parts, bases, folds, rank_tol=fitted.rank_tol, min_motion=fitted.min_motion)


def test_a_penalised_linear_fits_covariance_is_s2_times_the_inverse_penalised_gram(engine):
    """The linear fit of frames + joint offsets with their penalty: its
    covariance cost / (3N - k) x (J^T J + lambda W)^-1, its standard errors that matrix's diagonal's roots.
    lambda is a point of the grid 1e-5 .. 1e3 times the penalised columns' median Gram diagonal, said so in the
    result with each of the four folds' lambda. Seen failing on ``solution.penalty * weights`` turned to
    ``solution.penalty - weights`` and on ``PENALTY_GRID[-1]`` turned to ``PENALTY_GRID[1]``."""
    result = engine.evaluate(MODEL)
    store = engine.grams()
    index = store.layout.indices(MODEL, engine.kept(MODEL))
    weights = store.layout.penalty[index]
    assert np.count_nonzero(weights) == 3 and result["penalty"] is not None  # the joint offsets kept beside frames
    lam = result["penalty"]["full"]
    # lambda on the grid 1e-5 .. 1e3 (nine points a decade apart) times the penalised columns' median Gram diagonal
    gram = store.total[np.ix_(index, index)]
    relative = lam / np.median(np.diag(gram)[weights > 0])
    assert np.min(np.abs(np.log10(relative) - np.arange(-5, 4))) < 1e-9
    assert result["penalty"]["grid_relative"] == [1e-5, 1e3]
    assert result["penalty"]["folds"] == [[lam] * 4]
    k = index.size
    covariance = result["cost"] / (3 * N - k) * np.linalg.inv(store.total[np.ix_(index, index)] + lam * np.diag(weights))
    np.testing.assert_allclose(result["phi_cov"], covariance, rtol=1e-8, atol=1e-12 * np.abs(covariance).max())
    np.testing.assert_allclose(result["phi_std"], np.sqrt(np.diag(covariance)), rtol=1e-8)


def test_a_penalised_exact_fit_takes_the_linear_fits_lambda_into_its_covariance(engine):
    """The exact refit of the same model keeps the linear fit's lambda: its covariance is its own cost over
    3N - k times (J^T J + lambda W)^-1 with that lambda, and it ends where the penalised gradient
    J^T r + lambda W phi (J the Jacobian the fit holds, r the exact residual) is below 1e-6 of the gradient at
    zero. Seen failing on the exact fit's ``lam * cols.penalty`` turned to ``lam - cols.penalty`` and on
    ``_exact``'s ``lam = linear["penalty"]["full"]`` read as ``0.0``."""
    linear = engine.evaluate(MODEL)
    exact = engine.evaluate(MODEL, exact=True)
    store = engine.grams()
    index = store.layout.indices(MODEL, engine.kept(MODEL))
    weights = store.layout.penalty[index]
    lam = linear["penalty"]["full"]
    assert exact["penalty"]["full"] == lam
    k = index.size
    covariance = exact["cost"] / (3 * N - k) * np.linalg.inv(store.total[np.ix_(index, index)] + lam * np.diag(weights))
    np.testing.assert_allclose(exact["phi_cov"], covariance, rtol=1e-8, atol=1e-12 * np.abs(covariance).max())
    cols = engine.columns(MODEL)
    every = np.arange(N)

    def residual(phi):
        return np.concatenate([r.ravel() for r in engine.predict_residual(cols, phi, every)])

    phi = exact["phi"]
    jac = np.concatenate([j.block(slice(None)).reshape(-1, k) for j in engine._jacobians(cols)])
    gradient = jac.T @ residual(phi) + lam * weights * phi
    assert np.abs(gradient).max() < 1e-6 * np.abs(jac.T @ residual(np.zeros(k))).max()
