"""``diagnosis/bayes_design.py``'s type-II maximum likelihood prior to a tight tolerance (issue 36): the noise
and every tau_e where the log evidence of the errors, a multivariate normal written out here (covariance
sigma^2 I + G Lambda^-1 G^T on the stacked rows), is largest, found here by Nelder-Mead to 1e-7 in log
(its simplex about the fitted point);
three campaigns whose effects are large, typical and small against the noise. Each test names a planted
change it was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from tcr_accuracy.diagnosis.bayes_design import DesignColumns, fit_prior

EFFECTS = ["frames", "compliance", "transmission"]
OWNER = np.array(["frames"] * 2 + ["compliance"] * 8 + ["transmission"] * 8)


def _neg_log_evidence(g, y, tau, sigma):
    """-log N(y; 0, sigma^2 I + G diag(prior variances) G^T), written out; frames' prior variance 1e6."""
    variance = np.array([1e6 if e == "frames" else tau[e] ** 2 for e in OWNER])
    flat = g.reshape(-1, g.shape[2])
    covariance = sigma**2 * np.eye(flat.shape[0]) + (flat * variance) @ flat.T
    y = y.ravel()
    return 0.5 * (y @ np.linalg.solve(covariance, y) + np.linalg.slogdet(covariance)[1] + y.size * np.log(2 * np.pi))


@pytest.mark.parametrize("seed, sizes, tolerance", [(11, (2.0, 0.3), 4e-4), (12, (1.0, 1.0), 4e-4),
                                                    (13, (5.0, 0.05), 1e-3)])
def test_the_fitted_prior_is_the_evidence_maximum_to_a_few_parts_in_ten_thousand(seed, sizes, tolerance):
    """log sigma and each log tau_e within 4e-4 (1e-3 where one effect is 20 times below the noise: a flat
    ridge of the evidence) of the maximum written out here, and the evidence there within 1e-5 of it.
    The earlier test held 1 %: a gradient with ``theta**2 + np.diag(inverse)`` turned to ``-`` still landed
    within it. Seen failing on that change (L-BFGS-B then stops 1.4e-3 off in log tau) (planted by
    hand)."""
    rng = np.random.default_rng(seed)
    g = rng.normal(size=(25, 3, OWNER.size)) * 1e-3
    theta = np.concatenate([rng.normal(0, 30.0, 2), rng.normal(0, sizes[0], 8), rng.normal(0, sizes[1], 8)])
    errors = g @ theta + rng.normal(0, 1e-4, (25, 3))

    def objective(h):
        return _neg_log_evidence(g, errors, dict(zip(EFFECTS[1:], np.exp(h[1:]))), np.exp(h[0]))

    fitted = fit_prior(DesignColumns(g, OWNER, EFFECTS), errors)
    found = np.log([fitted.noise_m, fitted.tau["compliance"], fitted.tau["transmission"]])
    # Nelder-Mead from a simplex of +-0.05 in log about the found point: it walks to the maximum near it
    simplex = found + np.vstack([np.zeros(3), 0.05 * np.eye(3)]) - 0.0125
    best = optimize.minimize(objective, found, method="Nelder-Mead",
                             options={"xatol": 1e-7, "fatol": 1e-11, "maxiter": 3000, "initial_simplex": simplex})
    np.testing.assert_allclose(found, best.x, rtol=0, atol=tolerance)
    assert objective(found) - best.fun < 1e-5
