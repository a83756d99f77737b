"""Reliability: Gaussian tails against chi-square closed forms, importance sampling
against the first-order tail, binomial intervals against the beta-quantile formula."""

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.model.errors import seed_budget
from tcr_accuracy.analysis.montecarlo import run_monte_carlo
from tcr_accuracy.analysis.reliability import (
    binomial_interval,
    first_order,
    gaussian_exceedance,
    importance_exceedance,
)


@pytest.mark.parametrize("sigma, threshold", [(1.0, 3.0), (1.0, 5.5), (2e-4, 1.3e-3), (1.0, 0.2)])
def test_isotropic_gaussian_tail_is_chi_square_with_3_dof(sigma, threshold):
    got = gaussian_exceedance(np.zeros(3), sigma**2 * np.eye(3), threshold)
    expected = stats.chi2.sf((threshold / sigma) ** 2, 3)
    assert got == pytest.approx(expected, rel=1e-9)


def test_offset_isotropic_gaussian_tail_is_noncentral_chi_square():
    mean = np.array([0.3, -0.4, 1.2])
    got = gaussian_exceedance(mean, np.eye(3), 5.0)
    assert got == pytest.approx(stats.ncx2.sf(25.0, 3, mean @ mean), rel=1e-8)
    assert got < 1e-3


def test_anisotropic_and_degenerate_gaussian_tail_against_direct_sampling():
    rng = np.random.default_rng(0)
    cov = np.array([[1.0, 0.3, 0.0], [0.3, 0.5, 0.1], [0.0, 0.1, 0.2]])
    z = rng.multivariate_normal([0.1, 0.0, 0.0], cov, size=1_000_000)
    hits = np.sum(np.linalg.norm(z, axis=1) > 2.5)
    lo, hi = binomial_interval(hits, len(z), confidence=0.999)
    assert lo < gaussian_exceedance(np.array([0.1, 0.0, 0.0]), cov, 2.5) < hi
    # a rank-2 covariance (no spread along z) is a 2-D problem: chi-square with 2 dof
    assert gaussian_exceedance(np.zeros(3), np.diag([1.0, 1.0, 0.0]), 3.0) == pytest.approx(
        stats.chi2.sf(9.0, 2), rel=1e-9)


def test_binomial_interval_is_clopper_pearson():
    k, n = 7, 1000
    lo, hi = binomial_interval(k, n)
    assert lo == pytest.approx(stats.beta.ppf(0.025, k, n - k + 1), rel=1e-9)
    assert hi == pytest.approx(stats.beta.ppf(0.975, k + 1, n - k), rel=1e-9)
    assert binomial_interval(0, 20000)[0] == 0.0


def test_importance_sampling_reaches_one_in_a_million_and_agrees_with_first_order(tool_changer):
    """Small errors make the model nearly linear, so the exact-model IS estimate must
    agree with the first-order Gaussian tail (5 million plain samples gave 32 hits,
    6.4e-6, when this was written; 40 000 importance samples give +-8 %)."""
    budget = seed_budget(tool_changer, "table2").scaled(0.01)
    q = tool_changer.working_pose
    fo = first_order(budget, q)
    threshold = 0.45e-3
    expected = gaussian_exceedance(fo.mean[:3], fo.covariance[:3, :3], threshold)
    assert 1e-6 < expected < 2e-5
    est = importance_exceedance(budget, q, threshold, 40_000, np.random.default_rng(4))
    assert est.ci95[0] < expected < est.ci95[1]
    assert est.standard_error < 0.1 * est.probability


def test_importance_sampling_matches_plain_monte_carlo_where_both_work(tool_changer):
    budget = seed_budget(tool_changer, "table1").scaled(0.01)
    q = tool_changer.working_pose
    threshold = 0.5e-3
    mc = run_monte_carlo(budget, q, 200_000, 9, position_tolerances=(threshold,))
    outside = 200_000 - int(mc.inside_position[0])
    lo, hi = binomial_interval(outside, 200_000, confidence=0.999)
    est = importance_exceedance(budget, q, threshold, 40_000, np.random.default_rng(9))
    assert est.inflation > 1.0
    assert lo < est.probability < hi
