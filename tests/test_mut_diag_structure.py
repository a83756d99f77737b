"""The residual structure test's figures (``diagnosis/structure.py``) against computations written out
here: the k-NN shares and their permutation z by brute-force distances in numpy, the ridge's out-of-fold
predictions by scikit-learn's own pipeline, the power probe's ladder by a linear scan over a detector
whose verdict is a known threshold, the chi-square scatter test by scipy.stats, and the verdicts at their
thresholds. Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from knn_brute import knn_mean
from scipy import stats
from sklearn.linear_model import RidgeCV
from sklearn.model_selection import cross_val_predict
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tcr_accuracy.diagnosis.structure import (PROBE_AMPLITUDES, RIDGE_ALPHAS, RidgeFolds, StructureDetector,
                                              predictable_from_context, predictable_leftover, scatter_beyond_noise,
                                              scatter_test, smallest_detectable_structure, structure_verdict)
from tcr_accuracy.frames.noise import NoiseEstimate


def _features_by_hand(q, kinds):
    """sin, cos of q and 2q per revolute joint (z and z^2 for a prismatic one), then the products of
    every pair of joints' first harmonics (sin q, cos q; z)."""
    cols, first = [], []
    for j, kind in enumerate(kinds):
        v = q[:, j]
        if kind == "revolute":
            cols += [np.sin(v), np.cos(v), np.sin(2 * v), np.cos(2 * v)]
            first.append([np.sin(v), np.cos(v)])
        else:
            z = (v - v.mean()) / v.std()
            cols += [z, z * z]
            first.append([z])
    for a in range(len(kinds)):
        for b in range(a + 1, len(kinds)):
            cols += [u * w for u in first[a] for w in first[b]]
    return np.column_stack(cols)



def _case(seed=3, n=70):
    rng = np.random.default_rng(seed)
    q = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), rng.uniform(0.0, 0.5, n)])
    # a leftover along joint 1 (k-NN sees it along that joint) plus noise
    residual = np.column_stack([np.sin(2 * q[:, 1]), np.cos(q[:, 1]), q[:, 0] * 0.2]) * 1e-4
    residual += rng.normal(0, 4e-5, (n, 3))
    return q, residual


def test_smooth_features_are_the_harmonics_and_their_pairwise_products():
    """Revolute joints: sin q, cos q, sin 2q, cos 2q; a prismatic one: its z-score and square; then the
    first harmonics' pairwise products. Catches ``np.sin(2 * v)`` turned to ``np.sin(3 * v)`` and
    ``z**2`` turned to ``z**3``."""
    q, _ = _case()
    kinds = ["revolute", "revolute", "prismatic"]
    detector = StructureDetector(q, np.random.default_rng(0), kinds=kinds, n_permutations=5)
    np.testing.assert_allclose(detector.features, _features_by_hand(q, kinds), rtol=1e-12, atol=1e-12)


def test_structure_statistics_against_brute_force_neighbours_and_scikit_learn_ridge():
    """Every statistic of the test on a residual with a leftover along joint 1: for each subset of joints
    (all, each, each pair: 7 for three joints) the share of the centred residual's variance that the mean
    of its 10 nearest neighbours (brute-force distances in standardised joints, here) predicts, the same
    on the detector's shuffles, z = (share - mean of the shuffles) / their std, the best subset's p =
    min(1, 7 P(Z > z)); the ridge's share and paired z from scikit-learn's cross_val_predict on the
    features on the same folds; the critical z = Phi^-1(1 - alpha) by scipy. Seen failing on
    ``shares = 1.0 - error...`` turned to ``2.0 - ...`` and on the ridge's ``d.std(ddof=1)`` turned to
    ``ddof=2``."""
    q, residual = _case()
    kinds = ["revolute", "revolute", "prismatic"]
    detector = StructureDetector(q, np.random.default_rng(0), kinds=kinds, n_permutations=40)
    out = detector.test(residual)
    qs = (q - q.mean(axis=0)) / q.std(axis=0)
    centred = residual - residual.mean(axis=0)
    total = np.sum(centred**2)
    subsets = [(0, 1, 2), (0,), (1,), (2,), (0, 1), (0, 2), (1, 2)]
    best = None
    for subset in subsets:
        average = knn_mean(qs[:, subset], 10)

        def share(r):
            return 1.0 - np.sum((r - average @ r) ** 2) / total

        actual = share(centred)
        null = np.array([share(centred[perm]) for perm in detector.perms])
        z = (actual - null.mean()) / null.std(ddof=1)
        if best is None or z > best[0]:
            best = (z, list(subset), actual, null.mean(), null.std(ddof=1))
    z, joints, actual, null_mean, null_std = best
    assert out["n_subsets"] == 7 and out["n_poses_tested"] == 70 and out["k"] == 10
    assert out["along_joints"] == joints == [1]
    assert out["explained_share"] == pytest.approx(actual, rel=1e-9)
    assert out["null_mean"] == pytest.approx(null_mean, rel=1e-9, abs=1e-12)
    assert out["null_std"] == pytest.approx(null_std, rel=1e-9)
    assert out["gain_over_null"] == pytest.approx(actual - null_mean, rel=1e-9)
    assert out["z"] == pytest.approx(z, rel=1e-9)
    assert out["p_value"] == pytest.approx(min(1.0, 7 * stats.norm.sf(z)), rel=1e-9, abs=1e-300)
    predicted = cross_val_predict(make_pipeline(StandardScaler(), RidgeCV(alphas=np.logspace(-3, 3, 13))),
                                  _features_by_hand(q, kinds), centred, cv=detector.split)
    assert out["ridge_explained_share"] == pytest.approx(1.0 - np.sum((centred - predicted) ** 2) / total, rel=1e-6)
    d = np.sum(centred**2, axis=1) - np.sum((centred - predicted) ** 2, axis=1)
    assert out["ridge_z"] == pytest.approx(d.mean() / (d.std(ddof=1) / np.sqrt(70)), rel=1e-6)
    assert out["z_critical"] == pytest.approx(stats.norm.ppf(1 - 1e-3), rel=1e-12)
    assert out["local"] == (out["p_value"] < 1e-3 and out["gain_over_null"] > 0.05)
    assert out["global"] == (out["ridge_z"] > out["z_critical"] and out["ridge_explained_share"] > 0.05)
    assert out["remains"] and out["local"]
    # noise alone: nothing remains
    quiet = detector.test(np.random.default_rng(5).normal(0, 4e-5, (70, 3)))
    assert not quiet["remains"]


def test_ridge_folds_are_scikit_learns_ridge_cv_pipeline():
    """``RidgeFolds.predict`` against ``cross_val_predict(make_pipeline(StandardScaler(), RidgeCV(alphas)))``
    on the same folds, six random problems of 30 rows (a feature of small spread, a constant one). Seen failing
    on the hat diagonal's ``1.0 / len(train)`` turned to ``2.0 / len(train)`` and the scale guard
    ``10 * np.finfo(float).eps`` turned to a large one."""
    from sklearn.model_selection import KFold

    for seed in range(6):  # few rows per fold and a weak signal: the penalty chosen is a close call
        rng = np.random.default_rng(seed)
        n = 30
        # eight features, one of small spread (0.01 about 1: StandardScaler scales it up), one constant
        features = np.column_stack([rng.normal(size=(n, 8)), 1.0 + 0.01 * rng.normal(size=n), np.full(n, 2.0)])
        targets = np.column_stack([features[:, :8] @ rng.normal(size=8) * 0.3 + rng.normal(0, 1, n)
                                   + 50 * (features[:, 8] - 1), rng.normal(size=n)])
        split = KFold(n_splits=5, shuffle=True, random_state=seed)
        ours = RidgeFolds(features, split, RIDGE_ALPHAS).predict(targets)
        theirs = cross_val_predict(make_pipeline(StandardScaler(), RidgeCV(alphas=RIDGE_ALPHAS)), features,
                                   targets, cv=split)
        np.testing.assert_allclose(ours, theirs, rtol=1e-7, atol=1e-9)


class _ThresholdDetector:
    """Sees structure when the residual's RMS per axis is above ``threshold``: the ladder's answer is
    then known by a linear scan."""

    def __init__(self, n, threshold):
        self.q = np.zeros((n, 2))
        self.n_total = n
        self.threshold = threshold

    def restrict(self, values):
        return values

    def remains(self, residual):
        return float(np.sqrt(np.mean(residual**2))) > self.threshold

    def probe(self, noise, shape):  # the verdict along noise + a * shape, as StructureDetector.probe
        return lambda amplitude: self.remains(noise + amplitude * shape)


def test_power_probe_finds_the_smallest_flagged_amplitude_of_the_ladder():
    """Shapes scaled to a x noise RMS per axis (a = 0.5, 1, 2, ... 64) on top of the probe's own noise (drawn
    here again from the same seed): the smallest a a detector of known threshold flags, found here by a
    linear scan; the detectable size is a x noise x sqrt(3) [mm], the largest over the shapes; a shape
    not flagged even at 64 gives None. Seen failing on ``math.sqrt(3.0)`` turned to ``math.sqrt(4.0)``
    and the bisection's start ``lo, hi = -1, ...`` turned to ``0, ...`` (0.5 x never tried)."""
    n, noise = 200, 2e-5
    rng = np.random.default_rng(1)
    shapes = {"ramp": np.outer(np.linspace(-1, 1, n), [1.0, 0.5, 0.0]),
              "wave": np.column_stack([np.sin(np.arange(n)), np.cos(np.arange(n)), np.ones(n)]) * 7.0}
    assert PROBE_AMPLITUDES == (0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0)
    for threshold in (0.9 * noise, 1.5 * noise, 3.3 * noise, 20 * noise):
        detector = _ThresholdDetector(n, threshold)
        out = smallest_detectable_structure(detector, shapes, noise, np.random.default_rng(7))
        drawn = np.random.default_rng(7).standard_normal((n, 3)) * noise
        expected = {}
        for name, shape in shapes.items():
            rms = np.sqrt(np.mean(shape**2))
            flagged = [a for a in PROBE_AMPLITUDES
                       if np.sqrt(np.mean((drawn + shape * a * noise / rms) ** 2)) > threshold]
            expected[name] = flagged[0] * noise * np.sqrt(3) * 1e3
        assert out["per_shape_mm"] == pytest.approx(expected, rel=1e-12)
        assert out["smallest_detectable_mm"] == pytest.approx(max(expected.values()), rel=1e-12)
        assert out["largest_probed_mm"] == pytest.approx(64 * noise * np.sqrt(3) * 1e3, rel=1e-12)
        assert out["n_poses"] == out["of_poses"] == n
    blind = smallest_detectable_structure(_ThresholdDetector(n, 100 * noise), shapes, noise, rng)
    assert blind["smallest_detectable_mm"] is None and list(blind["per_shape_mm"].values()) == [None]


def test_structure_verdicts_at_their_thresholds():
    """No structure found: 'cannot tell' when the scatter test saw scatter beyond the noise whose excess
    sqrt(rms^2 - floor^2) (here 3-4-5: 0.4 mm over a 0.3 mm floor at 0.5 mm RMS) is below the smallest
    detectable leftover (0.41 mm), 'no' when it is above (0.39 mm); with the noise from this residual,
    'cannot tell' when the test only sees above the floor. Catches the excess's ``residual_rms**2 -
    noise_floor**2`` turned to ``+`` and ``* 1e3`` turned to ``* 1001.0``."""
    floor, rms = 0.3e-3, 0.5e-3
    quiet = {"remains": False}
    scatter = {"tested": True, "detected": True}
    assert structure_verdict({"remains": True}, {}, scatter, floor, rms)["verdict"] == "yes"
    hidden = structure_verdict(quiet, {"smallest_detectable_mm": 0.41, "n_poses": 50}, scatter, floor, rms)
    assert hidden["verdict"] == "cannot tell" and "0.4 mm RMS are left beyond the noise" in hidden["reason"]
    assert "from 0.41 mm" in hidden["reason"] and "with 50 poses" in hidden["reason"]
    assert structure_verdict(quiet, {"smallest_detectable_mm": 0.39999}, scatter, floor, rms)["verdict"] == "no"
    assert structure_verdict(quiet, {"smallest_detectable_mm": 0.4001}, scatter, floor, rms)["verdict"] == \
        "cannot tell"
    untested = {"tested": False}
    assert structure_verdict(quiet, {"smallest_detectable_mm": 0.31}, untested, floor, rms)["verdict"] == "cannot tell"
    assert structure_verdict(quiet, {"smallest_detectable_mm": 0.29}, untested, floor, rms)["verdict"] == "no"
    blind = {"smallest_detectable_mm": None, "largest_probed_mm": 2.2, "n_poses": 9}
    assert structure_verdict(quiet, blind, {"tested": True, "detected": False}, floor, rms)["verdict"] == "no"
    assert "2.2 mm" in structure_verdict(quiet, blind, scatter, floor, rms)["reason"]


def test_scatter_test_is_the_chi_square_written_with_scipy():
    """sigma^2 = RSS / (3N - p), chi^2 = RSS / noise^2 on 3N - p degrees of freedom (scipy's sf), the ratio
    sigma / noise and the extra sqrt(sigma^2 - noise^2); detected when p < alpha and the ratio > 1.1.
    Catches ``residual.size - n_parameters`` turned to ``+`` and ``min_ratio: float = 1.1`` turned to
    2.1."""
    rng = np.random.default_rng(2)
    residual = rng.normal(0, 1.25e-5, (60, 3))
    rss = np.sum(residual**2)
    out = scatter_test(residual, 12, 1e-5)
    sigma = np.sqrt(rss / 168)
    assert out["estimated_noise_per_axis_mm"] == pytest.approx(sigma * 1e3, rel=1e-12)
    assert out["tracker_noise_per_axis_mm"] == pytest.approx(1e-2, rel=1e-12)
    assert out["p_value"] == pytest.approx(stats.chi2.sf(rss / 1e-10, 168), rel=1e-9)
    assert out["ratio"] == pytest.approx(sigma / 1e-5, rel=1e-12)
    assert out["extra_per_axis_mm"] == pytest.approx(np.sqrt(sigma**2 - 1e-10) * 1e3, rel=1e-9)
    assert out["detected"] == (out["p_value"] < 1e-3 and out["ratio"] > 1.1) and out["detected"]
    # a ratio of 1.05 on many points: significant, yet under the 1.1 a noise figure is trusted to
    many = rng.normal(0, 1.05e-5, (4000, 3))
    weak = scatter_test(many, 0, 1e-5)
    assert weak["p_value"] < 1e-3 and 1.0 < weak["ratio"] < 1.1 and not weak["detected"]
    final = {"train_residual": residual.reshape(2, 30, 3), "n_parameters": 12}
    tested = scatter_beyond_noise(NoiseEstimate(1e-5, "given", True, ""), final, ["clearance"])
    assert tested["tested"] and tested["p_value"] == pytest.approx(out["p_value"], rel=1e-12)
    assert tested["stochastic_effects"] == ["clearance"]
    untested = scatter_beyond_noise(NoiseEstimate(2e-5, "residual", False, ""), final, [])
    assert not untested["tested"] and untested["estimated_noise_per_axis_mm"] == pytest.approx(0.02, rel=1e-12)


def test_predictable_leftover_is_the_best_of_neighbours_and_ridge_out_of_sample():
    """RMS per axis of what is left once the residual is predicted out of sample: the smallest of its own
    variance, each subset's 10-NN mean (brute force here) and a ridge (scikit-learn's RidgeCV, alphas
    1e-6 .. 1e3, on the detector's folds); from the rows' context, a standardised ridge. Catches
    ``np.logspace(-6, 3, 10)`` turned to ``np.logspace(-6, 3, 11)``... and ``min(best, ...)`` fed the
    mean of ``(centred + averaging @ centred)``."""
    q, along_one = _case(seed=9)
    detector = StructureDetector(q, np.random.default_rng(2), n_permutations=5)
    qs = (q - q.mean(axis=0)) / q.std(axis=0)
    smooth = np.column_stack([np.sin(q[:, 0]) * np.cos(q[:, 1]), np.cos(q[:, 0]) + np.sin(2 * q[:, 1]),
                              np.sin(q[:, 1]) * q[:, 2]]) * 1e-4 + np.random.default_rng(0).normal(0, 3e-5, (70, 3))
    winners = []
    for residual in (along_one, smooth):  # the neighbours along joint 1 win on the first, the ridge on the second
        centred = residual - residual.mean(axis=0)
        candidates = [np.mean(centred**2)]
        for subset in [(0, 1, 2), (0,), (1,), (2,), (0, 1), (0, 2), (1, 2)]:
            candidates.append(np.mean((centred - knn_mean(qs[:, subset], 10) @ centred) ** 2))
        ridge = cross_val_predict(RidgeCV(alphas=np.logspace(-6, 3, 10)), _features_by_hand(q, ["revolute"] * 3),
                                  centred, cv=detector.split)
        candidates.append(np.mean((centred - ridge) ** 2))
        assert predictable_leftover(detector, residual) == pytest.approx(math.sqrt(min(candidates)), rel=1e-6)
        winners.append(int(np.argmin(candidates)))
    assert 0 < winners[0] < 8 and winners[1] == 8
    residual = along_one
    centred = residual - residual.mean(axis=0)
    # from the context: a temperature the residual's x follows
    temperature = residual[:, 0] * 1e4 + np.random.default_rng(3).normal(0, 0.1, 70)
    model = make_pipeline(StandardScaler(), RidgeCV(alphas=np.logspace(-6, 3, 10)))
    predicted = cross_val_predict(model, temperature[:, None], centred, cv=detector.split)
    expected = math.sqrt(min(np.mean(centred**2), np.mean((centred - predicted) ** 2)))
    assert predictable_from_context(temperature[:, None], residual, detector.split) == pytest.approx(expected,
                                                                                                    rel=1e-9)
    assert expected < math.sqrt(np.mean(centred**2))
