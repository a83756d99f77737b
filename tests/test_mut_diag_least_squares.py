"""The fit engine's small linear algebra (``diagnosis/least_squares.py``) against numpy and scipy: the damped
Gauss-Newton step against the normal equations solved here, the box-constrained step against scipy's
``lsq_linear``, the covariance and standard errors against a pseudo-inverse. Each test names a planted
change it was seen to catch (issue 36)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from tcr_accuracy.diagnosis.least_squares import DampedSolver, box_quadratic, cholesky_solve


def _problem(seed=0, rows=40, k=6):
    rng = np.random.default_rng(seed)
    jac = rng.normal(size=(rows, k)) * rng.uniform(0.01, 100.0, k)  # columns of very different sizes
    residual = rng.normal(size=rows)
    return jac, residual


def test_damped_step_and_its_predicted_cut_are_the_normal_equations():
    """d = -(J^T J + mu D^2)^-1 J^T r with D the column norms, solved here; the cut the linear model predicts
    |r|^2 - |r + J d|^2 (the damping's own term left out: -2 g.d - d^T J^T J d); the first damping 1e-3 x
    the largest eigenvalue of the scaled Gram matrix. Seen failing on ``coefficient = -c / (values +
    damping)`` turned to ``values - damping``, on ``predicted = -(2.0 * g.d + ...)`` turned to ``3.0`` and
    on ``first_damping = 1e-3 * top`` turned to ``2e-3``."""
    jac, residual = _problem()
    gram, gradient = jac.T @ jac, jac.T @ residual
    solver = DampedSolver(gram)
    norms = np.sqrt(np.diag(gram))
    assert solver.first_damping == pytest.approx(1e-3 * np.linalg.eigvalsh(gram / np.outer(norms, norms))[-1],
                                                 rel=1e-12)
    for damping in (0.0, 1e-3, 0.7):
        d, predicted = solver.step(gradient, damping)
        expected = np.linalg.solve(gram + damping * np.diag(norms**2), -gradient)
        np.testing.assert_allclose(d, expected, rtol=1e-8)
        assert predicted == pytest.approx(residual @ residual - np.sum((residual + jac @ d) ** 2), rel=1e-8)


def test_boxed_step_is_scipys_bounded_least_squares():
    """Bounds that stop the free step: the step minimises |r + J d|^2 + mu |D d|^2 within them, as scipy's
    ``lsq_linear`` on the stacked system [J; sqrt(mu) D] finds it; the predicted cut is the linear model's
    at that step. ``box_quadratic`` alone against ``lsq_linear`` on H = L L^T. Seen failing on the
    multiplier's ``hessian[fixed] @ d + gradient[fixed]`` turned to ``- gradient[fixed]`` and the boxed
    curvature's ``1e-10 * self.top`` turned to ``1e-1``."""
    jac, residual = _problem(seed=1)
    gram, gradient = jac.T @ jac, jac.T @ residual
    solver = DampedSolver(gram)
    norms = np.sqrt(np.diag(gram))
    free, _ = solver.step(gradient, 0.01)
    room = np.abs(free) * 0.4
    room_low, room_high = -room, room
    for damping in (0.0, 0.01):
        d, predicted = solver.step(gradient, damping, room_low, room_high)
        stacked = np.vstack([jac, np.sqrt(damping) * np.diag(norms)])
        target = np.r_[-residual, np.zeros(jac.shape[1])]
        expected = lsq_linear(stacked, target, bounds=(room_low, room_high), tol=1e-14, method="bvls").x
        np.testing.assert_allclose(d, expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())
        assert np.any(np.isclose(np.abs(d), room, rtol=1e-12))  # some bound holds the step
        assert predicted == pytest.approx(residual @ residual - np.sum((residual + jac @ d) ** 2), rel=1e-6)
    rng = np.random.default_rng(2)
    lower_factor = np.tril(rng.normal(size=(8, 8))) + 3 * np.eye(8)
    hessian = lower_factor @ lower_factor.T
    g = rng.normal(size=8) * 10
    low, high = -np.full(8, 0.3), np.full(8, 0.2)
    d = box_quadratic(hessian, g, low, high)
    # 1/2 d^T H d + g^T d = 1/2 |L^T d + L^-1 g|^2 + const
    expected = lsq_linear(lower_factor.T, -np.linalg.solve(lower_factor, g), bounds=(low, high), tol=1e-14,
                          method="bvls").x
    np.testing.assert_allclose(d, expected, rtol=1e-8, atol=1e-12)


def test_covariance_and_standard_errors_are_the_pseudo_inverse():
    """s^2 (J^T J)^+ for a full-rank J (numpy's pinv) and its diagonal's root; a column that duplicates
    another leaves directions the data do not see: their standard errors infinite, the others' the
    pseudo-inverse's; a column close to another (not a twin) still seen. Seen failing on the kept
    eigenvalues' ``* 10`` turned to ``* 1e11`` and the unseen test's ``> 1e-6`` turned to ``> 1.000001``."""
    jac, _ = _problem(seed=3)
    gram = jac.T @ jac
    solver = DampedSolver(gram)
    np.testing.assert_allclose(solver.covariance(2.5), 2.5 * np.linalg.inv(gram), rtol=1e-7)
    np.testing.assert_allclose(solver.standard_errors(2.5), np.sqrt(2.5 * np.diag(np.linalg.inv(gram))), rtol=1e-7)
    # a column close to another (its scaled Gram matrix's smallest eigenvalue some 1e-4 of the largest) is
    # still seen: its standard errors those of the inverse
    wobble = np.random.default_rng(9).normal(size=jac.shape[0])
    near = np.column_stack([jac, jac[:, 0] + 0.02 * np.linalg.norm(jac[:, 0]) * wobble / np.linalg.norm(wobble)])
    np.testing.assert_allclose(DampedSolver(near.T @ near).standard_errors(1.0),
                               np.sqrt(np.diag(np.linalg.inv(near.T @ near))), rtol=1e-5)
    twin = np.column_stack([jac, jac[:, 0] * 2.0])
    solver = DampedSolver(twin.T @ twin)
    errors = solver.standard_errors(1.0)
    assert np.isinf(errors[0]) and np.isinf(errors[-1])
    pinv = np.linalg.pinv(twin.T @ twin)
    np.testing.assert_allclose(errors[1:-1], np.sqrt(np.diag(pinv))[1:-1], rtol=1e-6)
    assert not solver.kept.all() and solver.kept.sum() == 6


def test_cholesky_solve_and_its_strict_refusals():
    """A positive definite system solved as numpy solves it; with ``strict``, a factor whose smallest
    diagonal is 1e-7 of its largest or less is refused (a diagonal of 1 and 1e-15: refused; 1 and 1e-12,
    i.e. factor 1e-6: solved), and a matrix that is not positive definite is refused, where without
    ``strict`` LU solves it. Catches ``1e-7 * diagonal.max()`` turned to ``1e-5``."""
    rng = np.random.default_rng(4)
    a = rng.normal(size=(5, 5))
    spd = a @ a.T + 5 * np.eye(5)
    rhs = rng.normal(size=5)
    np.testing.assert_allclose(cholesky_solve(spd, rhs, strict=True), np.linalg.solve(spd, rhs), rtol=1e-10)
    with pytest.raises(np.linalg.LinAlgError):
        cholesky_solve(np.diag([1.0, 1e-15]), np.ones(2), strict=True)
    np.testing.assert_allclose(cholesky_solve(np.diag([1.0, 1e-12]), np.ones(2), strict=True), [1.0, 1e12])
    indefinite = np.array([[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(np.linalg.LinAlgError):
        cholesky_solve(indefinite, np.ones(2), strict=True)
    np.testing.assert_allclose(cholesky_solve(indefinite, np.array([3.0, 3.0])), [1.0, 1.0])
