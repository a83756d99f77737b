"""What is left after a fit (``diagnosis/residuals.py``): the where-analysis' short-lag semivariance along each
joint against a semivariogram written out here on every pair of poses. Each test names a planted change it was
seen to catch (issue 36)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.residuals import where_analysis


def _standardised(values: np.ndarray) -> np.ndarray:
    std = values.std(axis=0)
    return (values - values.mean(axis=0)) / np.where(std > 0, std, 1.0)


def _short_lag_semivariance(q_joint: np.ndarray, residual: np.ndarray, n_bins: int = 12) -> np.ndarray:
    """The mean of half the squared differences of the standardised residual over the pairs of poses whose
    standardised distance along the joint falls in the equal-width bins (``n_bins`` from the shortest to the
    longest distance) whose mean distance is in the lowest quarter of the bins' mean distances."""
    x = _standardised(q_joint[:, None])[:, 0]
    e = _standardised(residual)
    i, k = np.triu_indices(len(x), 1)
    distance = np.abs(x[i] - x[k])
    half_squares = 0.5 * (e[i] - e[k]) ** 2
    edges = np.linspace(distance.min(), distance.max(), n_bins + 1)
    which = np.minimum(np.searchsorted(edges, distance, side="right") - 1, n_bins - 1)
    used = [b for b in range(n_bins) if np.any(which == b)]
    lags = np.array([distance[which == b].mean() for b in used])
    short = [b for b, lag in zip(used, lags) if lag <= np.quantile(lags, 0.25)]
    in_short = np.isin(which, short)
    return half_squares[in_short].mean(axis=0)


def test_short_lag_semivariance_along_each_joint_is_the_twelve_bin_semivariogram_written_out():
    """60 poses of two revolute joints and a prismatic one, a residual smooth along the first joint plus noise:
    each joint's ``short_lag_semivariance_xyz`` is the semivariogram of 12 equal-width distance bins written out
    here on all 1770 pairs (not the function's own semivariograms). Seen failing on the where-analysis'
    ``per_joint_semivariograms(q, residual, n_bins=12, ...)`` turned to ``n_bins=13`` and ``11``."""
    rng = np.random.default_rng(1012)
    n = 60
    q = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-1, 1, n), rng.uniform(0.0, 0.4, n)])
    nominal = rng.normal(size=(n, 3)) * 0.4 + [0.2, 0.0, 0.8]
    residual = np.column_stack([np.sin(2 * q[:, 0]), np.cos(q[:, 0]), q[:, 2]]) * 1e-4
    residual += rng.normal(0, 2e-5, (n, 3))
    tau = rng.normal(size=(n, 3))
    robot = SimpleNamespace(joint_names=["a", "b", "c"], joint_kinds=["revolute", "revolute", "prismatic"])
    where, _ = where_analysis(robot, q, nominal, residual, tau, {}, rng=np.random.default_rng(0))
    for j, name in enumerate("abc"):
        assert where["along_joints"][name]["short_lag_semivariance_xyz"] == pytest.approx(
            _short_lag_semivariance(q[:, j], residual).tolist(), rel=1e-9)
