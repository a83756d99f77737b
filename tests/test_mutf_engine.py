"""The fit engine's penalised steps, its uncertainty and its bound flags (``diagnosis/fitting.py``) against
figures written out here: scipy's ``least_squares`` on the exact residual stacked with the penalty's rows
sqrt(lambda w) phi, the penalised normal equations solved with numpy, s^2 (J^T J + lambda W)^-1 with s^2 the
cost over the degrees of freedom, and parameters placed just inside and just outside the documented
tolerance of a bound. The data: joint offsets hidden in a Pinocchio model (tests/mutd_truth.py). Each test
names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from mutd_truth import offset_measurements
from scipy.optimize import least_squares

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.fitting import FitEngine

MODEL = ["frames", "joint_offsets"]
N = 14


@pytest.fixture(scope="module")
def engine():
    """A new engine (three folds) on a diagnosis' rows and columns: 14 poses, 30 um noise."""
    robot, measured = offset_measurements(N, 4200)
    fitted = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2).fit(measured).engine_
    tests = np.array_split(np.random.default_rng(4201).permutation(N), 3)
    folds = [(np.setdiff1d(np.arange(N), t), np.sort(t)) for t in tests]
    return FitEngine(fitted.parts, fitted.bases, folds, rank_tol=fitted.rank_tol, min_motion=fitted.min_motion)


def _model(engine):
    """(columns, their places in the engine's layout, their Gram block, the residual function of phi)."""
    cols = engine.columns(MODEL)
    store = engine.grams()
    index = store.layout.indices(MODEL, engine.kept(MODEL))
    every = np.arange(N)

    def residual(phi):
        return np.concatenate([r.ravel() for r in engine.predict_residual(cols, phi, every)])

    return cols, index, store.total[np.ix_(index, index)], residual


def test_a_penalised_fit_minimises_the_residual_and_the_penalty_as_scipy_does(engine):
    """Levenberg-Marquardt with a smoothness penalty lambda sum(w phi^2) (lambda three times the median Gram
    diagonal, w from 0.5 to 2), started from phi = -1: its optimum is scipy's on the residual stacked with the rows sqrt(lambda w)
    phi, to 1 % of each parameter's posterior standard error; the penalty pulls it well away from the
    unpenalised optimum. Seen failing on the starting cost's ``weights @ phi**2`` and the trial's ``weights @
    trial**2`` turned to ``**1``, on the gradient's ``+ weights * phi`` turned to ``- weights * phi`` and on
    ``DampedSolver(gram + np.diag(weights) ...)`` turned to ``gram - ...``."""
    cols, index, gram, residual = _model(engine)
    k = cols.scale.size
    weights = np.linspace(0.5, 2.0, k)
    lam = 3.0 * float(np.median(np.diag(gram)))
    penalised = dataclasses.replace(cols, penalty=weights)
    free = engine.evaluate(MODEL, exact=True)["phi"]
    start = -np.ones(k)  # away from zero: the penalty's gradient and cost count from the first step
    phi, _ = engine._minimise(penalised, engine._jacobians(penalised), None, gram, start,
                              engine.predict_residual(cols, start, np.arange(N)), penalty=lam)

    def stacked(p):
        return np.concatenate([residual(p), np.sqrt(lam * weights) * p])

    reference = least_squares(stacked, np.zeros(k), method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    jac = np.stack([(residual(reference + e) - residual(reference - e)) / 2e-6 for e in 1e-6 * np.eye(k)], axis=1)
    cost = float(residual(reference) @ residual(reference))
    posterior = np.sqrt(np.diag(cost / (3 * N - k) * np.linalg.inv(jac.T @ jac + lam * np.diag(weights))))
    assert np.all(np.abs(phi - reference) < 1e-2 * posterior)
    assert np.max(np.abs(free - reference) / posterior) > 1.0  # the penalty matters here


def test_a_penalised_fold_step_solves_the_penalised_normal_equations_inside_the_bounds(engine):
    """One fold's step from phi with the penalty: phi + d, d = -(A + lambda W)^-1 (b + lambda W phi) for its
    training Gram matrix A and gradient b (made up here), clipped into the bounds where the free step leaves
    them. Seen failing on ``gradient + weights * phi`` turned to ``gradient - weights * phi`` and on
    ``gram + np.diag(weights)`` turned to ``gram - np.diag(weights)``."""
    cols, _, gram, _ = _model(engine)
    k = cols.scale.size
    rng = np.random.default_rng(4202)
    weights = rng.uniform(0.5, 2.0, k)
    penalised = dataclasses.replace(cols, penalty=weights, lower=np.full(k, -50.0), upper=np.full(k, 50.0))
    a = rng.standard_normal((3 * k, k))
    system, gradient = a.T @ a, rng.standard_normal(k)
    phi = rng.uniform(-1.0, 1.0, k)
    lam = 0.7
    expected = phi - np.linalg.solve(system + lam * np.diag(weights), gradient + lam * weights * phi)
    assert np.all(np.abs(expected) < 50.0)
    np.testing.assert_allclose(engine._fold_step(penalised, system, phi, gradient, lam), expected, rtol=1e-9,
                               atol=1e-12)
    unpenalised = engine._fold_step(penalised, system, phi, gradient, 0.0)
    np.testing.assert_allclose(unpenalised, phi - np.linalg.solve(system, gradient), rtol=1e-9, atol=1e-12)


def test_standard_errors_and_the_posterior_covariance_are_s2_times_the_inverse_penalised_gram(engine):
    """s^2 = cost / (n - k) times (J^T J + lambda W)^-1 (the model's block of the total Gram matrix): the
    covariance with a penalty, the standard errors its diagonal's roots; none without a penalty; with as
    many observations as parameters, s^2 is the cost itself (n - k floored at 1). Seen failing on ``cost /
    max(fields["n_observations"] - k, 1)`` turned to ``max(..., 2)`` and on ``total[np.ix_(index, index)] +
    np.diag(weights)`` turned to ``-``."""
    cols, index, gram, _ = _model(engine)
    k = index.size
    weights = np.linspace(0.1, 1.0, k) * np.median(np.diag(gram))
    cost = 2.5e-8
    for n, dof in ((3 * N, 3 * N - k), (k, 1)):
        lazy = engine._uncertainty(index, weights, cost, {"n_parameters": k, "n_observations": n})
        covariance = cost / dof * np.linalg.inv(gram + np.diag(weights))
        np.testing.assert_allclose(lazy["phi_cov"](), covariance, rtol=1e-8, atol=1e-12 * np.abs(covariance).max())
        np.testing.assert_allclose(lazy["phi_std"](), np.sqrt(np.diag(covariance)), rtol=1e-8)
    plain = engine._uncertainty(index, np.zeros(k), cost, {"n_parameters": k, "n_observations": 3 * N})
    assert plain["phi_cov"]() is None
    np.testing.assert_allclose(plain["phi_std"](), np.sqrt(np.diag(cost / (3 * N - k) * np.linalg.inv(gram))),
                               rtol=1e-8)


def test_a_parameter_is_at_its_bound_within_1e_9_of_the_larger_of_its_size_and_one(engine):
    """``at_bound``: phi within max(|phi|, 1) x 1e-9 of a bound of its fit range. Bounds of -0.5 and 0.7 (the
    tolerance 1e-9) and of -3 and 4 (3e-9 and 4e-9), parameters at 0.9 and 1.1 of the tolerance inside each
    bound: the first flagged, the second not. Seen failing on ``np.maximum(np.abs(phi), 1.0)`` turned to
    ``0.0`` and to ``2.0``, and on ``1e-9`` turned to ``1.000000001``."""
    cols, index, _, _ = _model(engine)
    store = engine.grams()
    layout = store.layout
    k = index.size
    saved = layout.lower.copy(), layout.upper.copy()
    try:
        small = np.arange(k) % 2 == 0
        low, high = np.where(small, -0.5, -3.0), np.where(small, 0.7, 4.0)
        layout.lower[index], layout.upper[index] = low, high
        tolerance = np.maximum(np.abs(np.where(np.arange(k) % 4 < 2, low, high)), 1.0) * 1e-9
        near = np.where(np.arange(k) % 4 < 2, low, high)  # each parameter's bound, lower and upper in turn
        inward = np.where(np.arange(k) % 4 < 2, 1.0, -1.0)
        for factor, flagged in ((0.9, True), (1.1, False)):
            phi = near + inward * factor * tolerance
            fold_steps = [[phi] * len(tests) for tests in store.tests]
            fields, _ = engine._fields(MODEL, engine.kept(MODEL), index, phi, fold_steps, 0.0, None, cols.names,
                                       exact=False)
            assert fields["at_bound"].tolist() == [flagged] * k, factor
    finally:
        layout.lower[:], layout.upper[:] = saved


def test_geometry_without_joint_offsets_is_judged_with_them_borrowed_and_its_condition_number_is_numpys():
    """A set with geometry but not joint_offsets: identifiability takes the joint offsets first (rotations about
    the joint axes are theirs) and leaves them out of the answer, says so in a note, and reports the rank and
    the condition number and smallest singular value of the kept columns (each scaled to its typical size and
    to unit norm), numpy's SVD of the dense columns here; every kept column is one of geometry's or the
    frames'. Seen failing on ``sv[0] / sv[-1]`` turned to ``sv[1] / sv[-1]``, on ``float(sv[-1])`` turned to
    ``sv[-2]``, on the compressed columns' ``g[:, 0, keep[e]]`` turned to ``g[:, 1, ...]`` and on the columns'
    ``mat / np.linalg.norm(mat, axis=0)`` turned to ``axis=1``."""
    robot, measured = offset_measurements(30, 4400)
    engine = GapDiagnosis(robot=robot, effects=["joint_offsets", "geometry"], folds=2,
                          stability_replays=2).fit(measured).engine_
    keep, report = engine.identify(["frames", "geometry"])
    assert set(keep) == {"frames", "geometry"} and set(report["effects"]) == {"frames", "geometry"}
    assert report["note"] == "geometry excludes rotations about the joint axes (the joint_offsets effect)"
    columns = []
    for e in ("frames", "geometry"):
        b = engine.bases[e]
        dense = (np.asarray(b.g) * b.scales).reshape(-1, len(b.names))
        columns.append(dense[:, keep[e]])
    mat = np.concatenate(columns, axis=1)
    mat = mat / np.linalg.norm(mat, axis=0)
    sv = np.linalg.svd(mat, compute_uv=False)
    assert report["rank"] == mat.shape[1] == sum(k.size for k in keep.values())
    assert report["condition_number"] == pytest.approx(sv[0] / sv[-1], rel=1e-6)
    assert report["smallest_singular_value"] == pytest.approx(sv[-1], rel=1e-6)
    assert 0 < keep["geometry"].size < len(engine.bases["geometry"].names)  # some of geometry is the offsets'
