"""Semivariograms against closed forms."""

import numpy as np
import pytest

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.analysis.semivariogram import (
    GaussianVariogram,
    empirical_semivariogram,
    fit_gaussian_variogram,
    per_joint_semivariograms,
)


def test_linear_error_along_one_joint_gives_half_slope_squared_times_h_squared():
    """e = a q0 with only q0 varying: gamma(h) = a^2 <h^2> / 2 in each bin, exactly."""
    rng = np.random.default_rng(0)
    q = np.zeros((60, 3))
    q[:, 0] = rng.uniform(-1, 1, 60)
    a = 2.5
    e = a * q[:, [0]]
    emp = empirical_semivariogram(q, e, n_bins=10, standardise=False)
    # independent: pair distances and bins by brute force
    i, k = np.triu_indices(60, 1)
    h = np.abs(q[i, 0] - q[k, 0])
    edges = np.linspace(h.min(), h.max(), 11)
    expected = []
    for b, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        inside = (h >= lo) & ((h < hi) if b < 9 else (h <= hi))
        if inside.any():
            expected.append(a**2 * np.mean(h[inside] ** 2) / 2)
    np.testing.assert_allclose(emp.semivariance[:, 0], expected, rtol=1e-12)


def test_white_noise_is_flat_at_unit_variance():
    rng = np.random.default_rng(1)
    q = rng.uniform(-1, 1, (400, 6))
    e = rng.normal(size=(400, 3))
    emp = empirical_semivariogram(q, e, n_bins=8)
    busy = emp.counts > 4000  # far bins hold pairs of few points: correlated, noisy
    assert busy.sum() >= 4
    np.testing.assert_allclose(emp.semivariance[busy], 1.0, atol=0.1)


def test_per_joint_semivariogram_finds_the_joint_the_error_depends_on():
    rng = np.random.default_rng(2)
    q = rng.uniform(-1.5, 1.5, (300, 4))
    e = np.sin(q[:, [2]]) + 0.05 * rng.normal(size=(300, 1))
    grams = per_joint_semivariograms(q, e, n_bins=10)
    first_bin = [g.semivariance[0, 0] for g in grams]
    assert int(np.argmin(first_bin)) == 2
    assert first_bin[2] < 0.05 and min(first_bin[:2] + first_bin[3:]) > 0.5


def test_gaussian_fit_recovers_known_parameters():
    truth = GaussianVariogram(nugget=0.1, sill=0.8, range_=1.3)
    h = np.linspace(0.05, 3.0, 20)
    from tcr_accuracy.analysis.semivariogram import EmpiricalSemivariogram

    emp = EmpiricalSemivariogram(lags=h, semivariance=truth(h)[:, None], counts=np.full(20, 50), joint=None)
    fit = fit_gaussian_variogram(emp)
    assert fit.nugget == pytest.approx(0.1, abs=1e-6)
    assert fit.sill == pytest.approx(0.8, abs=1e-6)
    assert fit.range_ == pytest.approx(1.3, abs=1e-5)
    assert fit.nugget_ratio == pytest.approx(0.1 / 0.9, abs=1e-6)


def test_too_few_points_is_an_input_error():
    with pytest.raises(InputError, match="at least 3"):
        empirical_semivariogram(np.zeros((2, 3)), np.zeros((2, 1)))


@pytest.mark.parametrize("joint", [None, 1])
def test_sampled_pairs_give_the_brute_force_semivariogram_of_those_pairs(joint):
    """Above ``max_pairs`` pairs the semivariogram is taken over pairs drawn at random (i uniform over
    the points, then k uniform over the others, from the generator in that order): against the same
    pairs' distances (np.linalg.norm of the standardised rows' differences), bins and half squared
    differences written out here. Seen failing when the distance kept only the last coordinate
    (``distance = difference`` for every column instead of summing them)."""
    rng = np.random.default_rng(5)
    n, pairs, n_bins = 400, 5000, 9
    q = rng.uniform(-1, 1, (n, 4)) * np.array([0.3, 2.0, 40.0, 1e-3]) + np.array([1.0, -2.0, 0.0, 5.0])
    e = np.column_stack([np.sin(3 * q[:, 0]), q[:, 1] ** 2, rng.normal(size=n)]) * np.array([1e-4, 2e-3, 1.0])
    emp = empirical_semivariogram(q, e, n_bins=n_bins, joint=joint, max_pairs=pairs, rng=np.random.default_rng(9))
    draw = np.random.default_rng(9)
    i = draw.integers(0, n, pairs)
    k = draw.integers(0, n - 1, pairs)
    k = np.where(k >= i, k + 1, k)
    qs = (q - q.mean(axis=0)) / q.std(axis=0)
    es = (e - e.mean(axis=0)) / e.std(axis=0)
    if joint is not None:
        qs = qs[:, [joint]]
    h = np.linalg.norm(qs[i] - qs[k], axis=1)
    half = 0.5 * (es[i] - es[k]) ** 2
    edges = np.linspace(h.min(), h.max(), n_bins + 1)
    lags, gamma, counts = [], [], []
    for b in range(n_bins):
        inside = (h >= edges[b]) & ((h < edges[b + 1]) if b < n_bins - 1 else (h <= edges[b + 1]))
        if inside.any():
            lags.append(h[inside].mean())
            gamma.append(half[inside].mean(axis=0))
            counts.append(inside.sum())
    assert emp.counts.sum() == pairs
    np.testing.assert_array_equal(emp.counts, counts)
    np.testing.assert_allclose(emp.lags, lags, rtol=1e-12)
    np.testing.assert_allclose(emp.semivariance, gamma, rtol=1e-12)
