"""Where the fit engine's Levenberg-Marquardt (``FitEngine._minimise``, ``diagnosis/fitting.py``) STOPS: a
residual in metres (costs of 1e-8 m^2, far from 1) that is nonlinear in its three parameters, the Jacobian
held at the start, against the same iteration written out here on numpy with its two stopping rules
(the predicted cut, then the kept step's gain, each below 1e-7 of the cost). The engine is given the
residual as a function (no robot): the count of its residual evaluations and its final parameters are the
written-out ones. Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.fit_columns import ChainedJacobian, Columns, Sensitivity, gram_matrix
from tcr_accuracy.diagnosis.fitting import FitEngine

N, K = 30, 3


#: h(phi) and the truth of each problem: all with h'(0) = 1 (the Jacobian held, -M, is the start's)
SHAPES = {"sin": (np.sin, [1.2, -0.9, 0.4]), "cubic": (lambda phi: phi + 0.3 * phi**3, [0.8, -0.5, 0.3]),
          "steep": (lambda phi: phi + phi**3, [1.0, -0.7, 0.35])}


def _problem(shape: str):
    """(M (3N, K) [m per unit], residual(phi) (3N,) [m]): targets M h(truth) + 10 um noise, model M h(phi)."""
    h, truth = SHAPES[shape]
    rng = np.random.default_rng(0)
    m = rng.standard_normal((3 * N, K)) * 1e-3
    y = m @ h(np.array(truth)) + 1e-5 * rng.standard_normal(3 * N)
    return m, (lambda phi: y - m @ h(phi))


def _written_out(residual, jacobian, tolerance: float = 1e-7, cap: int = 40):
    """Levenberg-Marquardt with J held: d = -(J^T J + mu diag(J^T J))^-1 J^T r, predicted cut -(2 g.d + d J^T J d);
    stop when it is <= tolerance x cost; a step kept when the cost falls, mu then times
    max(1/3, 1 - (2 gain / predicted - 1)^3), and stop when that gain is <= tolerance x the new cost; a failed
    step sets mu to 1e-3 of the column-scaled J^T J's largest eigenvalue (mu was 0) or multiplies it by nu,
    nu doubling. (parameters, residual evaluations, the rule that stopped it, failed steps)."""
    gram = jacobian.T @ jacobian
    norms = np.sqrt(np.diag(gram))
    first = 1e-3 * np.linalg.eigvalsh(gram / np.outer(norms, norms))[-1]
    phi = np.zeros(K)
    r = residual(phi)
    cost, mu, nu, evaluations, failed = r @ r, 0.0, 2.0, 0, 0
    for _ in range(cap):
        g = jacobian.T @ r
        d = np.linalg.solve(gram + mu * np.diag(np.diag(gram)), -g)
        predicted = -(2.0 * g @ d + d @ gram @ d)
        if predicted <= tolerance * cost:
            return phi, evaluations, "predicted", failed
        trial = residual(phi + d)
        evaluations += 1
        if trial @ trial < cost:
            gain = cost - trial @ trial
            phi, r, cost = phi + d, trial, trial @ trial
            mu, nu = mu * max(1.0 / 3.0, 1.0 - (2.0 * gain / predicted - 1.0) ** 3), 2.0
            if gain <= tolerance * cost:
                return phi, evaluations, "gain", failed
        else:
            mu, nu = (first if mu == 0.0 else mu * nu), 2.0 * nu
            failed += 1
    return phi, evaluations, "cap", failed


def _engine_fit(m, residual):
    """The engine's fit of the residual from phi = 0: (parameters, residual evaluations)."""
    engine = FitEngine.__new__(FitEngine)  # only what _minimise reads: one unweighted part, the rows, a counter
    engine.parts, engine.n_rows, engine.n_fits = [SimpleNamespace(whitening=None)], N, 0
    seen = []

    def predict_residual(cols, phi, rows):
        seen.append(phi.copy())
        return [residual(phi).reshape(N, 3)]

    engine.predict_residual = predict_residual
    jacobian = ChainedJacobian(Sensitivity([((-m).reshape(N, 3, K), np.arange(K))]), np.arange(K), np.ones(K))
    # penalty weights carried, lambda left at its default: no penalty enters
    cols = Columns([f"p{i}" for i in range(K)], np.ones(K), [], np.full(K, -np.inf), np.full(K, np.inf), np.ones(K))
    start = np.zeros(K)
    phi, _ = engine._minimise(cols, [jacobian], None, gram_matrix([jacobian], None), start,
                              [residual(start).reshape(N, 3)])
    return phi, len(seen)


@pytest.mark.parametrize("shape,rule,count,failed", [("sin", "gain", 24, 0), ("cubic", "predicted", 22, 0),
                                                      ("steep", "cap", 40, 7)])
def test_the_fit_stops_where_the_written_out_iteration_stops(shape, rule, count, failed):
    """sin: the fit ends on a kept step whose gain is below 1e-7 of the cost, after 24 evaluations; cubic:
    on a predicted cut below it, after 22 (costs ~1e-8 m^2); steep (h = phi + phi^3: the held Jacobian's
    steps overshoot, 7 of them fail and the damping follows Nielsen's rule) at the cap of 40 evaluations.
    The engine makes the same evaluations and ends on the same parameters (to 1e-12); where a stopping
    rule ends it, the written-out iteration with a tolerance ten times larger or smaller stops elsewhere.
    Seen failing on the gain ``cost - trial_cost`` turned to ``cost ** trial_cost`` (steep: Nielsen's
    factor always its floor), on ``gain <= self.COST_TOLERANCE * cost`` and on ``predicted <= ...`` turned
    to ``%`` or ``/`` (a tolerance 1e-7 m^2 absolute), on ``COST_TOLERANCE = 1e-7`` turned to ``1.0000001`` and
    on ``_minimise``'s default ``penalty: float = 0.0`` turned to ``-1.0`` (the columns carry penalty weights)."""
    assert FitEngine.COST_TOLERANCE == 1e-7 and FitEngine.MAX_EVALUATIONS == 40
    m, residual = _problem(shape)
    expected, evaluations, stopped, failures = _written_out(residual, -m)
    assert (stopped, evaluations, failures) == (rule, count, failed)
    if rule != "cap":
        assert _written_out(residual, -m, 1e-6)[1] != count != _written_out(residual, -m, 1e-8)[1]
    r = residual(expected)
    assert 1e-9 < r @ r < 1e-7  # far from 1: an absolute tolerance is not a relative one
    phi, made = _engine_fit(m, residual)
    assert made == count
    np.testing.assert_allclose(phi, expected, rtol=0, atol=1e-12)
