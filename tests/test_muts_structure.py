"""The structure test's set-up, defaults and words (``diagnosis/structure.py``) where the earlier tests passed
their own values or did not look (issue 36), each against a computation written out here: the detector's
shuffles and folds re-drawn from the same seed with the default counts, the subset of poses above its
largest number, the neighbours of few poses, the semivariogram's nugget ratios in the report, the generic
smooth shape of the power probe (a fixed joint's features included), the spread floor of a null that does
not vary, the scatter test without an instrument noise or degrees of freedom, and every note that names (or
declines to name) scatter, with its millimetres. Each test names a planted change it was seen to catch."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from knn_brute import knn_mean
from sklearn.model_selection import KFold
from test_structure_probe import _harmonics  # the ridge features written out by hand

from tcr_accuracy.analysis.semivariogram import empirical_semivariogram, fit_gaussian_variogram
from tcr_accuracy.diagnosis import structure
from tcr_accuracy.diagnosis.structure import StructureDetector, scatter_test, smallest_detectable_structure, \
    smooth_shape


@pytest.fixture(scope="module")
def case():
    rng = np.random.default_rng(31)
    n = 60
    q = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), np.full(n, 0.4)])  # the third fixed
    residual = np.column_stack([np.sin(2 * q[:, 0]), np.cos(q[:, 1]), q[:, 0] * 0.3]) * 1e-4
    residual += rng.normal(0, 3e-5, (n, 3))
    return q, residual


def test_the_detectors_shuffles_and_folds_are_drawn_from_its_generator_with_the_default_counts(case):
    """By default 100 shuffles of the poses, then five shuffled folds seeded by the next integer below 2^31 - 1
    (scikit-learn's KFold), all drawn here again from the same seed; the report's k = 10, alpha 1e-3 and the
    5 % it must explain. Seen failing on ``n_permutations: int = 100`` turned to 101, ``folds: int = 5`` to 6,
    ``rng.integers(2**31 - 1)`` to ``2**32 - 1`` and ``min_explained: float = 0.05`` to ``1.05``."""
    q, residual = case
    detector = StructureDetector(q, np.random.default_rng(12))
    rng = np.random.default_rng(12)
    perms = [rng.permutation(60) for _ in range(100)]
    split = KFold(n_splits=5, shuffle=True, random_state=int(rng.integers(2**31 - 1)))
    assert len(detector.perms) == 100
    for got, expected in zip(detector.perms, perms):
        np.testing.assert_array_equal(got, expected)
    for (train, test), (train_expected, test_expected) in zip(detector.split.split(q), split.split(q)):
        np.testing.assert_array_equal(test, test_expected)
    assert detector.split.get_n_splits() == 5
    out = detector.test(residual)
    assert (out["k"], out["alpha"], out["min_explained"]) == (10, 1e-3, 0.05)
    assert out["local"] == (out["p_value"] < 1e-3 and out["gain_over_null"] > 0.05)


def test_above_its_largest_number_of_poses_the_test_runs_on_a_sorted_random_subset():
    """20,001 poses: the test runs on 20,000 drawn without replacement (sorted), the first draw of its
    generator; 20,000 poses: on all. Rows of all the poses are cut to the subset, others left as they are.
    Seen failing on ``MAX_POSES = 20_000`` turned to 20_001 and 19_999."""
    q = np.random.default_rng(0).uniform(-1, 1, (20_001, 2))
    detector = StructureDetector(q, np.random.default_rng(5), n_permutations=1)
    rows = np.sort(np.random.default_rng(5).choice(20_001, 20_000, replace=False))
    np.testing.assert_array_equal(detector.rows, rows)
    assert detector.n_total == 20_001 and detector.q.shape == (20_000, 2)
    np.testing.assert_array_equal(detector.restrict(np.arange(20_001)), rows)
    np.testing.assert_array_equal(detector.restrict(np.arange(7)), np.arange(7))
    assert StructureDetector(q[:20_000], np.random.default_rng(5), n_permutations=1).rows is None
    small = StructureDetector(q[:50], np.random.default_rng(5), n_permutations=1, max_poses=49)
    assert small.rows.size == 49


def test_few_poses_take_every_other_pose_as_neighbours(case):
    """Eight poses (fewer than k + 1): each pose's neighbours are the seven others along every subset of the two
    moving joints, so every share is 1 - (8 / 7)^2 (closed form: the others' mean of a centred residual is
    -r_i / 7); the fixed joint is in no subset. Seen failing on ``min(self.k, len(self.q) - 1)`` turned to
    ``len(self.q) - 2``."""
    q, residual = case
    detector = StructureDetector(q[:8], np.random.default_rng(1), n_permutations=3)
    shares = detector.shares(residual[:8])
    assert set(shares) == {(0, 1), (0,), (1,)}
    assert list(shares.values()) == pytest.approx([1 - (8 / 7) ** 2] * 3, rel=1e-12)


def test_the_report_carries_the_nugget_ratio_of_each_axis_from_twelve_bins(case):
    """With a generator the test also reports, per axis, the nugget ratio of the Gaussian model fitted to the
    residual's semivariogram over all joints in 12 bins. Seen failing on ``n_bins=12`` turned to 13 and on
    ``range(3)`` turned to ``range(4)``."""
    q, residual = case
    detector = StructureDetector(q, np.random.default_rng(2), n_permutations=10)
    out = detector.test(residual, np.random.default_rng(0))
    semi = empirical_semivariogram(q, residual, n_bins=12)
    assert out["semivariogram_nugget_ratio_xyz"] == pytest.approx(
        [fit_gaussian_variogram(semi, c).nugget_ratio for c in range(3)], rel=1e-9)


def test_the_generic_smooth_shape_is_the_standardised_features_times_normal_weights(case):
    """The power probe's shape when no effect suggests one: the smooth joint features (the fixed joint's
    constant, left 0 once centred), each centred and scaled to unit spread, times a (F, 3) standard normal
    draw of the same generator. Seen failing on the fixed feature's divisor ``1.0`` turned to ``0.0`` (NaN)
    and on ``features.std(axis=0) > 0`` turned to ``> 1``."""
    q, _ = case
    detector = StructureDetector(q, np.random.default_rng(3), n_permutations=2)
    features = _harmonics(q)
    centred = features - features.mean(axis=0)
    spread = centred.std(axis=0)
    standardised = np.where(spread > 1e-12, centred / np.where(spread > 1e-12, spread, 1.0), 0.0)
    expected = standardised @ np.random.default_rng(8).standard_normal((features.shape[1], 3))
    got = smooth_shape(detector, np.random.default_rng(8))
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9)


def test_a_null_that_does_not_vary_is_read_against_a_spread_floor_of_1e_12(case):
    """Every shuffle the same: the null's spread is 0 and the z is the gain over the floor 1e-12. Seen failing on
    ``max(float(null.std(ddof=1)), 1e-12)`` turned to ``1.000000000001``."""
    q, residual = case
    detector = StructureDetector(q, np.random.default_rng(4), n_permutations=4)
    shuffle = np.roll(np.arange(60), 7)
    detector.perms = [shuffle] * 4
    qs = (q[:, :2] - q[:, :2].mean(axis=0)) / q[:, :2].std(axis=0)
    centred = residual - residual.mean(axis=0)
    total = np.sum(centred**2)
    best = -np.inf
    for subset in [(0, 1), (0,), (1,)]:
        average = knn_mean(qs[:, subset], 10)
        gain = (np.sum((centred[shuffle] - average @ centred[shuffle]) ** 2)
                - np.sum((centred - average @ centred) ** 2)) / total
        best = max(best, gain / 1e-12)
    out = detector.test(residual)
    assert out["null_std"] < 1e-12
    assert out["z"] == pytest.approx(best, rel=1e-6)


def test_the_scatter_test_without_an_instrument_noise_or_degrees_of_freedom():
    """A noise of 0: chi-square and ratio infinite, p 0, scatter detected; more parameters than numbers: one
    degree of freedom (sigma^2 = RSS). Seen failing on ``if tracker_noise > 0`` turned to ``> -1`` (a division
    by 0) and on ``max(residual.size - n_parameters, 1)`` turned to ``2``."""
    residual = np.array([[1e-5, -2e-5, 3e-5], [0.0, 1e-5, -1e-5]])
    rss = float(np.sum(residual**2))
    out = scatter_test(residual, 10, 0.0)
    assert out["p_value"] == 0.0 and out["ratio"] == math.inf and out["detected"]
    assert out["estimated_noise_per_axis_mm"] == pytest.approx(math.sqrt(rss) * 1e3, rel=1e-12)
    assert out["extra_per_axis_mm"] == pytest.approx(math.sqrt(rss) * 1e3, rel=1e-12)


def test_the_power_probe_says_its_noise_and_skips_a_shape_of_zeros():
    """The probe's method in words with the noise in mm (3 significant digits); a shape of zeros is not
    probed; the poses counted. Seen failing on the words' ``noise_per_axis * 1e3`` turned to ``* 1001.0``."""
    detector = SimpleNamespace(q=np.zeros((40, 2)), n_total=40, restrict=lambda values: values,
                               probe=lambda noise, shape: (lambda amplitude: amplitude >= 2.0))
    out = smallest_detectable_structure(detector, {"none": np.zeros((40, 3)), "ramp": np.ones((40, 3))},
                                        2.3449e-5, np.random.default_rng(0))
    assert out["method"].startswith("each shape added to Gaussian noise of 0.0234 mm per axis at RMS 0.5, 1, 2, ")
    assert list(out["per_shape_mm"]) == ["ramp"]
    assert out["smallest_detectable_mm"] == pytest.approx(2.0 * 2.3449e-5 * math.sqrt(3) * 1e3, rel=1e-12)
    assert (out["n_poses"], out["of_poses"]) == (40, 40)


MM = 1e-3


def _name(monkeypatch, verdict, from_joints, from_context, stochastic=(), detected=True):
    monkeypatch.setattr(structure, "predictable_leftover", lambda detector, residual: from_joints)
    monkeypatch.setattr(structure, "predictable_from_context", lambda features, residual, split: from_context)
    detector = SimpleNamespace(restrict=lambda values: values, split=None)
    scatter = {"detected": detected, "estimated_noise_per_axis_mm": 0.6}
    notes = []
    structure.name_scatter(scatter, {"verdict": verdict, "reason": "a reason"}, list(stochastic),
                           SimpleNamespace(per_axis=0.12344 * MM), notes, detector=detector,
                           residual=np.zeros((10, 3)), context={"temperature_c": np.arange(10.0)})
    return scatter, notes


def test_every_note_on_scatter_beyond_the_noise_says_its_millimetres(monkeypatch):
    """0.6 mm per axis left against 0.12344 mm of noise: predicted from the joints to 0.2 mm (structure), from
    the temperature to 0.2 mm (structure), by neither (scatter: named clearance where clearance is a stochastic
    effect of the model, random scatter else; or "cannot tell" with the verdict's reason), each note with its
    figures to 4 decimals; nothing said when no scatter was detected. Seen failing on the notes'
    ``sigma * 1e3`` turned to ``* 1001.0``, ``after * 1e3`` to ``/ 1e3`` and ``noise.per_axis * 1e3`` to
    ``* 1001.0``."""
    scatter, notes = _name(monkeypatch, "no", 0.2 * MM, 0.6 * MM)
    assert scatter["named"] is None and scatter["predicted_from_joints_left_per_axis_mm"] == pytest.approx(0.2)
    assert notes == ["0.6000 mm per axis is left against 0.1234 mm of noise, but predicted from the joint values out "
                     "of sample it leaves 0.2000 mm: structure the vocabulary does not express, not random scatter"]
    scatter, notes = _name(monkeypatch, "no", 0.6 * MM, 0.2 * MM)
    assert scatter["named"] is None and scatter["predicted_from_context_left_per_axis_mm"] == pytest.approx(0.2)
    assert notes == ["0.6000 mm per axis is left against 0.1234 mm of noise, but predicted out of sample from the "
                     "rows' temperature_c it leaves 0.2000 mm: structure along them that the vocabulary does not "
                     "express, not random scatter"]
    scatter, notes = _name(monkeypatch, "no", 0.6 * MM, 0.6 * MM, stochastic=["clearance"])
    assert scatter["named"] == "clearance"
    assert notes == ["random scatter beyond the tracker noise: 0.6000 mm per axis vs 0.1234 mm, without spatial "
                     "structure: joint play (clearance) or a noisier instrument"]
    scatter, notes = _name(monkeypatch, "no", 0.6 * MM, 0.6 * MM)
    assert scatter["named"] == "random scatter"
    scatter, notes = _name(monkeypatch, "cannot tell", 0.6 * MM, 0.6 * MM)
    assert "named" not in scatter
    assert notes == ["0.6000 mm per axis left against 0.1234 mm of noise: whether it is structure or scatter cannot "
                     "be told (a reason); measure more poses"]
    scatter, notes = _name(monkeypatch, "no", 0.2 * MM, 0.2 * MM, detected=False)
    assert notes == [] and "named" not in scatter


def test_a_constant_residual_is_wholly_predicted_and_a_fixed_prismatic_joint_gives_zero_features():
    """A residual that does not vary: every subset's share 1 (nothing left, no division by its zero variance);
    a prismatic joint that does not move: its z-score and square are 0 (its spread read as 1). Seen failing on
    ``float(np.sum(centred**2)) or 1.0`` in ``shares`` turned to ``or 0.0`` and on ``(v.std() or 1.0)``
    turned to ``or 0.0`` (NaN features)."""
    rng = np.random.default_rng(6)
    q = np.column_stack([rng.uniform(-2, 2, 30), np.full(30, 0.25)])
    detector = StructureDetector(q, np.random.default_rng(0), kinds=["revolute", "prismatic"], n_permutations=2)
    assert detector.shares(np.tile([2.0**-13, 0.0, -(2.0**-14)], (30, 1))) == {(0,): 1.0}
    features = detector.features
    v = q[:, 0]
    np.testing.assert_allclose(features, np.column_stack([np.sin(v), np.cos(v), np.sin(2 * v), np.cos(2 * v),
                                                          np.zeros(30), np.zeros(30), np.zeros(30), np.zeros(30)]),
                               rtol=1e-15, atol=0)


def test_ridge_folds_with_a_feature_of_zeros_are_scikit_learns_pipeline():
    """A feature that is 0 on every row (the sine of a joint held at 0): StandardScaler leaves it (its spread is
    read as 1 below 10 machine epsilons of max(|mean|, 1)), so the out-of-fold predictions equal scikit-learn's
    ``cross_val_predict(make_pipeline(StandardScaler(), RidgeCV(alphas)))``. Seen failing on
    ``np.maximum(np.abs(mean), 1.0)`` turned to ``0.0`` (0 / 0)."""
    from sklearn.linear_model import RidgeCV
    from sklearn.model_selection import cross_val_predict
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    from tcr_accuracy.diagnosis.structure import RIDGE_ALPHAS, RidgeFolds

    rng = np.random.default_rng(3)
    features = np.column_stack([rng.normal(size=(30, 4)), np.zeros(30)])
    targets = features[:, :4] @ rng.normal(size=(4, 2)) + rng.normal(0, 0.5, (30, 2))
    split = KFold(n_splits=5, shuffle=True, random_state=1)
    theirs = cross_val_predict(make_pipeline(StandardScaler(), RidgeCV(alphas=RIDGE_ALPHAS)), features, targets,
                               cv=split)
    np.testing.assert_allclose(RidgeFolds(features, split, RIDGE_ALPHAS).predict(targets), theirs, rtol=1e-7,
                               atol=1e-9)
