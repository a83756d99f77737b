"""Where a residual lies and how noisy the measurements are (``diagnosis/residuals.py``): the boundaries the
earlier tests did not reach, each against a figure written out here (issue 36): correlations of a variable or
an axis whose spread is exactly 0 or exactly 1, the bins of 1, 2, 5 and 6 distinct values, a torque's
loading judged relative to its size, the joints a residual varies along (three of four), the neighbour share
of few poses in closed form, the first copy named in the repeated poses' error, and the structured residual's
nugget from a semivariogram written out on every pair of poses. Each test names a planted change it was seen
to catch."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.analysis.semivariogram import EmpiricalSemivariogram, fit_gaussian_variogram
from tcr_accuracy.diagnosis.residuals import noise_from_repeats, noise_from_residual, where_analysis
from tcr_accuracy.exceptions import InputError


def _robot(names, kinds=None):
    return SimpleNamespace(joint_names=list(names), joint_kinds=kinds or ["revolute"] * len(names))


def _knn_share(points, centred, k):
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    neighbours = np.argsort(d, axis=1)[:, :k]
    return 1.0 - np.sum((centred - centred[neighbours].mean(axis=1)) ** 2) / np.sum(centred**2)


@pytest.fixture(scope="module")
def boundary_case():
    """40 poses: joint a at +-1 alternately (spread exactly 1, two levels), b fixed, c at five levels, d at six,
    e continuous; the residual's y at +-1 in pairs (spread exactly 1), its z constant."""
    rng = np.random.default_rng(7)
    n = 40
    q = np.column_stack([np.where(np.arange(n) % 2, 1.0, -1.0), np.full(n, 0.3), np.arange(n) % 5 * 0.2,
                         np.arange(n) % 6 * 0.1 - 0.2, rng.uniform(-2, 2, n)])
    residual = np.column_stack([np.sin(q[:, 4]) + rng.normal(0, 0.3, n), np.where(np.arange(n) // 2 % 2, 1.0, -1.0),
                                np.full(n, 0.5)])
    tau = np.column_stack([rng.normal(size=n) * 20, np.full(n, 5.0), rng.normal(size=n), rng.normal(size=n) * 3,
                           rng.normal(size=n)])
    nominal = rng.normal(size=(n, 3))
    return q, residual, tau, nominal


def test_correlations_where_a_spread_is_exactly_zero_or_one(boundary_case):
    """Pearson's r (scipy) of each joint with each axis; 0 where the joint is fixed or the axis constant, and
    computed where a spread is exactly 1 (a joint at +-1, an axis at +-1). Seen failing on ``np.std(values)
    == 0`` turned to ``== 1`` and ``np.std(residual[:, c]) == 0`` turned to ``== 1`` (either a NaN or a 0
    where r is 0.5)."""
    q, residual, tau, nominal = boundary_case
    assert np.std(q[:, 0]) == 1.0 and np.std(residual[:, 1]) == 1.0
    where, _ = where_analysis(_robot("abcde"), q, nominal, residual, tau, {}, rng=np.random.default_rng(0))
    for j, name in enumerate("abcde"):
        expected = [0.0 if np.std(q[:, j]) == 0 or c == 2 else stats.pearsonr(q[:, j], residual[:, c])[0]
                    for c in range(3)]
        assert where["joints"][name]["correlation_xyz"] == pytest.approx(expected, rel=1e-9, abs=1e-15)
    assert where["joints"]["b"]["correlation_xyz"] == [0.0, 0.0, 0.0]
    assert where["joints"]["a"]["correlation_xyz"][1] == pytest.approx(stats.pearsonr(q[:, 0], residual[:, 1])[0])


def test_bins_of_one_two_five_and_six_distinct_values(boundary_case):
    """A fixed joint: no bins and no spread; two levels and five levels: one bin per level (five is the bin
    count, still one each); six levels: five quantile bins. Each bin's count and mean in mm by hand. Seen
    failing on ``levels.size <= n_bins`` turned to ``< n_bins`` (five levels in quantile bins) and on
    ``levels.size < 2`` turned to ``< 1`` (a fixed joint given one bin) and to ``< 3`` (two levels none)."""
    q, residual, tau, nominal = boundary_case
    where, _ = where_analysis(_robot("abcde"), q, nominal, residual, tau, {}, rng=np.random.default_rng(0))
    joints = where["joints"]
    assert joints["b"]["bins"] == [] and joints["b"]["spread_mm"] == 0.0
    for name, j in (("a", 0), ("c", 2)):
        levels = np.unique(q[:, j])
        bins = joints[name]["bins"]
        assert [(b["low"], b["high"], b["count"]) for b in bins] == [(v, v, int(np.sum(q[:, j] == v))) for v in levels]
        for b, v in zip(bins, levels):
            assert b["mean_mm"] == pytest.approx((residual[q[:, j] == v].mean(axis=0) * 1e3).tolist(), rel=1e-12)
    assert len(joints["c"]["bins"]) == 5
    edges = np.quantile(q[:, 3], np.linspace(0, 1, 6))
    bins = joints["d"]["bins"]
    assert [b["low"] for b in bins] == pytest.approx(edges[:-1].tolist()) and len(bins) == 5
    assert sum(b["count"] for b in bins) == 40


def test_a_torque_is_loaded_relative_to_the_largest_torque_whatever_its_scale(boundary_case):
    """The torque columns judged loaded where they vary by more than 1e-6 of the largest torque: the same
    verdicts (the second column constant: not loaded) for torques in N m and for the same torques times
    1e-300, and a torque of all zeros loads nothing. Seen failing on ``max(float(np.abs(tau).max()), 1e-300)``
    turned to ``1.0`` (a floor in N m)."""
    q, residual, tau, nominal = boundary_case
    robot = _robot("abcde")
    for scale in (1.0, 1e-300):
        where, _ = where_analysis(robot, q, nominal, residual, tau * scale, {}, rng=np.random.default_rng(0))
        loaded = [name for name, g in where["gravity_torque"].items() if g.get("loaded", True)]
        assert loaded == ["a", "c", "d", "e"]
        assert where["gravity_torque"]["b"] == {"loaded": False}
        assert len(where["gravity_torque"]["a"]["bins"]) == 5
    where, _ = where_analysis(robot, q, nominal, residual, np.zeros_like(tau), {}, rng=np.random.default_rng(0))
    assert all(g == {"loaded": False} for g in where["gravity_torque"].values())


def test_the_residual_varies_along_the_three_joints_of_largest_share_of_four():
    """Five joints, a residual following four of them (each predicting more than 5 % of it by its 10 nearest
    neighbours, by brute force here), the fifth noise: the three of largest share, largest first. Seen
    failing on ``[:3]`` turned to ``[:4]``."""
    rng = np.random.default_rng(22)
    n = 200
    q = rng.uniform(-2, 2, (n, 5))
    residual = np.column_stack([1.3 * np.sin(q[:, 0]), 1.15 * np.sin(q[:, 1]), np.sin(q[:, 2]) + 0.9 * np.sin(q[:, 3])])
    residual += rng.normal(0, 0.1, (n, 3))
    robot = _robot("abcde")
    where, _ = where_analysis(robot, q, rng.normal(size=(n, 3)), residual, rng.normal(size=(n, 5)), {},
                              rng=np.random.default_rng(0))
    centred = residual - residual.mean(axis=0)
    shares = {name: _knn_share(q[:, [j]], centred, 10) for j, name in enumerate("abcde")}
    above = sorted((s for s in shares if shares[s] > 0.05), key=lambda s: -shares[s])
    assert len(above) == 4 and "e" not in above
    assert where["varies_along"] == above[:3]
    for name in "abcde":
        assert where["along_joints"][name]["knn_explained_share"] == pytest.approx(shares[name], rel=1e-9)


def test_with_fewer_than_eleven_poses_every_other_pose_is_a_neighbour():
    """Eight poses: the neighbours are the seven others, whose mean of a centred residual is -r_i / 7, so each
    joint's and each pair's share is 1 - (8 / 7)^2 whatever the joints (closed form). Seen failing on
    ``min(10, q.shape[0] - 1)`` turned to ``q.shape[0] - 2``."""
    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, (8, 3))
    residual = rng.normal(size=(8, 3))
    where, _ = where_analysis(_robot("abc"), q, rng.normal(size=(8, 3)), residual, rng.normal(size=(8, 3)), {},
                              rng=np.random.default_rng(0))
    closed = 1.0 - (8 / 7) ** 2
    for name in "abc":
        assert where["along_joints"][name]["knn_explained_share"] == pytest.approx(closed, rel=1e-12)
    assert [p["knn_explained_share"] for p in where["along_joint_pairs"]] == pytest.approx([closed] * 3, rel=1e-12)
    assert where["varies_along"] == []


def test_copies_of_one_reading_name_the_first_two_rows_of_the_first_repeated_pose():
    """Two poses read three and two times (and one read once) whose readings agree to the last digit: the error
    counts the 5 readings of 2 repeated poses and names rows 3 and 5, the first two readings of the pose that
    sorts first (its joint values the least). Seen failing on ``np.flatnonzero(counts > 1)[0]`` turned to
    ``[1]`` and on ``[:2]`` turned to ``[:3]``."""
    q = np.array([[1.0, 1.0], [1.0, 1.0], [2.0, 0.0], [0.0, 0.0], [9.0, 9.0], [0.0, 0.0], [0.0, 0.0]])
    position = np.array([[1.0, 2.0, 3.0]] * 2 + [[5.0, 5.0, 5.0]] + [[0.5, 0.25, 0.125]] + [[7.0, 7.0, 7.0]]
                        + [[0.5, 0.25, 0.125]] * 2)
    with pytest.raises(InputError, match="the 5 readings of 2 repeated poses agree to the last digit") as raised:
        noise_from_repeats(q, position, min_dof=3)
    assert raised.value.parameter == "measurements" and raised.value.value == (3, 5)


def test_repeats_need_six_degrees_of_freedom_by_default():
    """Two poses read twice: 3 x (4 - 2) = 6 degrees of freedom, the default's least: an estimate, sqrt(sum of
    squared deviations / 6); one pose read twice (3) none. Seen failing on ``min_dof: int = 6`` turned to 7."""
    q = np.array([[0.0], [0.0], [1.0], [1.0], [2.0]])
    position = np.array([[0.0, 0.0, 0.0], [2e-5, 0.0, -2e-5], [1.0, 1.0, 1.0], [1.0, 1.0 + 4e-5, 1.0], [3.0, 3, 3]])
    estimate = noise_from_repeats(q, position)
    assert estimate.per_axis == pytest.approx(math.sqrt((2 * 1e-10 * 2 + 2 * 4e-10) / 6), rel=1e-9)
    assert noise_from_repeats(q[2:], position[2:]) is None


def _semivariogram_by_hand(q, residual, n_bins=20):
    """Joints standardised (a fixed joint stays 0), the residual as it is: half the squared differences over
    every pair, in ``n_bins`` equal-width bins of the pair distance, averaged over the three axes."""
    std = q.std(axis=0)
    x = (q - q.mean(axis=0)) / np.where(std > 0, std, 1.0)
    i, k = np.triu_indices(len(x), 1)
    distance = np.linalg.norm(x[i] - x[k], axis=1)
    half = 0.5 * (residual[i] - residual[k]) ** 2
    edges = np.linspace(distance.min(), distance.max(), n_bins + 1)
    which = np.minimum(np.searchsorted(edges, distance, side="right") - 1, n_bins - 1)
    used = [b for b in range(n_bins) if np.any(which == b)]
    lags = np.array([distance[which == b].mean() for b in used])
    gamma = np.array([half[which == b].mean() for b in used])  # over the pairs and the axes
    counts = np.array([np.sum(which == b) for b in used])
    return EmpiricalSemivariogram(lags, gamma[:, None], counts, None)


def test_a_structured_residuals_noise_is_the_nugget_of_its_twenty_bin_semivariogram():
    """With structure, the noise is the nugget of the Gaussian model fitted to the semivariogram of 20 bins,
    pooled over the axes (written out here on every pair of poses), capped by sqrt(RSS / (3N - p)); the words
    give the whole residual's figure in mm. Seen failing on ``n_bins=20`` turned to 21, on ``max(nugget,
    0.0)`` turned to ``1.0`` and on the words' ``sigma_rss * 1e3`` turned to ``* 1001.0``."""
    rng = np.random.default_rng(8)
    q = np.column_stack([rng.uniform(-2, 2, (120, 2)), np.zeros(120)])
    smooth = np.column_stack([np.sin(q[:, 0]), np.cos(q[:, 1]), np.sin(q[:, 0] + q[:, 1])]) * 2e-4
    residual = smooth + rng.normal(0, 2e-5, (120, 3))
    sigma_rss = math.sqrt(np.sum(residual**2) / (360 - 12))
    nugget = fit_gaussian_variogram(_semivariogram_by_hand(q, residual), 0).nugget
    estimate = noise_from_residual(q, residual, 12, structured=True)
    assert 0 < nugget < sigma_rss**2
    assert estimate.per_axis == pytest.approx(math.sqrt(nugget), rel=1e-6)
    assert f"the whole residual is {sigma_rss * 1e3:.4g} mm per axis" in estimate.detail
    # a residual all scatter, its nugget above its RSS figure: capped there
    flat = rng.normal(0, 2e-5, (120, 3))
    capped = noise_from_residual(q, flat, 300, structured=True)
    rss = math.sqrt(np.sum(flat**2) / 60)
    assert capped.per_axis <= rss * (1 + 1e-12)


def test_a_residual_that_does_not_vary_is_wholly_predicted_along_every_joint():
    """A constant residual (every pose off by the same vector): nothing left once centred, so the share every
    joint's and pair's neighbours predict is 1 (no division by its zero variance), every correlation 0. Seen
    failing on ``float(np.sum(centred**2)) or 1.0`` turned to ``or 0.0``."""
    rng = np.random.default_rng(4)
    q = rng.uniform(-2, 2, (30, 2))
    residual = np.tile([2.0**-13, -(2.0**-12), 2.0**-14], (30, 1))  # sums exact: the spread exactly 0
    where, _ = where_analysis(_robot("ab"), q, rng.normal(size=(30, 3)), residual, rng.normal(size=(30, 2)), {},
                              rng=np.random.default_rng(0))
    assert [where["along_joints"][n]["knn_explained_share"] for n in "ab"] == [1.0, 1.0]
    assert where["along_joint_pairs"] == [{"joints": ["a", "b"], "knn_explained_share": 1.0}]
    assert where["joints"]["a"]["correlation_xyz"] == [0.0, 0.0, 0.0]
