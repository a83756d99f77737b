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
