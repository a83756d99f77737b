"""The structure test's fast paths (``diagnosis/structure.py``, issue 39) against computations written
out here on explicit matrices: the power probe's line of residuals (:class:`ProbeLine`, the k-NN sums of
squares expanded in the amplitude) against the k-NN shares of dense brute-force averaging matrices and
scikit-learn's ridge pipeline at each amplitude, and the k-NN shares the where-analysis reads
(:meth:`StructureDetector.shares`) against the same dense matrices. Each test names a planted change it
was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest
from knn_brute import knn_mean
from scipy import stats
from sklearn.linear_model import RidgeCV
from sklearn.model_selection import cross_val_predict
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tcr_accuracy.diagnosis.residuals import where_analysis
from tcr_accuracy.diagnosis.structure import StructureDetector
from tcr_accuracy.model.robot import load_robot

SUBSETS = [(0, 1, 2), (0,), (1,), (2,), (0, 1), (0, 2), (1, 2)]



def _harmonics(q: np.ndarray) -> np.ndarray:
    """The ridge's features for revolute joints: sin, cos of q and 2q, the first harmonics' pairwise products."""
    cols, first = [], []
    for v in q.T:
        cols += [np.sin(v), np.cos(v), np.sin(2 * v), np.cos(2 * v)]
        first.append([np.sin(v), np.cos(v)])
    for a in range(len(first)):
        for b in range(a + 1, len(first)):
            cols += [u * w for u in first[a] for w in first[b]]
    return np.column_stack(cols)


def _verdict_by_hand(q, residual, perms, split, alpha=1e-3, min_explained=0.05):
    """(best subset's z, its joints, its share, remains) of the structure test on ``residual`` written out on
    dense averaging matrices and scikit-learn's RidgeCV pipeline."""
    qs = (q - q.mean(axis=0)) / q.std(axis=0)
    centred = residual - residual.mean(axis=0)
    total = np.sum(centred**2)
    best = None
    for subset in SUBSETS:
        average = knn_mean(qs[:, subset], 10)
        shares = np.array([1.0 - np.sum((r - average @ r) ** 2) / total
                           for r in [centred] + [centred[p] for p in perms]])
        null = shares[1:]
        z = (shares[0] - null.mean()) / null.std(ddof=1)
        if best is None or z > best[0]:
            best = (z, list(subset), shares[0], shares[0] - null.mean())
    z, joints, share, gain = best
    local = min(1.0, len(SUBSETS) * stats.norm.sf(z)) < alpha and gain > min_explained
    predicted = cross_val_predict(make_pipeline(StandardScaler(), RidgeCV(alphas=np.logspace(-3, 3, 13))),
                                  _harmonics(q), centred, cv=split)
    d = np.sum(centred**2, axis=1) - np.sum((centred - predicted) ** 2, axis=1)
    ridge_share = 1.0 - np.sum((centred - predicted) ** 2) / total
    global_ = d.mean() / (d.std(ddof=1) / np.sqrt(d.size)) > stats.norm.isf(alpha) and ridge_share > min_explained
    return z, joints, share, bool(local or global_)


def test_probe_line_is_the_structure_test_at_each_amplitude():
    """noise + a * shape for a on the probe's ladder: the line's best subset, its z and share, and the verdict
    against the k-NN test on dense brute-force averaging matrices with the probe's 30 shuffles and
    scikit-learn's ridge on the same folds, each amplitude computed afresh. The shape varies along joint 1
    (the k-NN test sees it from some amplitude on) plus a smooth function of joint 0 (the ridge sees it),
    so the ladder crosses from 'none' to 'remains'. Seen failing with the cross term ``2 * a * uv`` turned
    to ``a * uv`` and with the line's total left at the noise's alone (``nn``)."""
    rng = np.random.default_rng(11)
    n = 90
    q = rng.uniform(-2.5, 2.5, (n, 3))
    detector = StructureDetector(q, np.random.default_rng(4))
    noise = rng.normal(0.0, 2e-5, (n, 3))
    shape = np.column_stack([np.sign(np.sin(3 * q[:, 1])), np.cos(2 * q[:, 1]), 0.6 * np.sin(q[:, 0])]) * 2e-5
    line = detector.probe(noise, shape)
    verdicts = []
    for a in (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 16.0):
        z, joints, share, remains = _verdict_by_hand(q, noise + a * shape, detector.perms[:30], detector.split)
        best = line.local(a)
        assert best["joints"] == joints
        assert best["z"] == pytest.approx(z, rel=1e-9)
        assert best["explained_share"] == pytest.approx(share, rel=1e-9, abs=1e-12)
        assert line(a) == remains
        verdicts.append(remains)
    assert verdicts[0] is False and verdicts[-1] is True  # the ladder crosses


def test_knn_shares_and_the_where_analysis_are_brute_force_neighbour_shares():
    """The share of a residual's variance each subset's 10 nearest neighbours predict (a pose not its own
    neighbour), from :meth:`StructureDetector.shares` and as the where-analysis reports it along each joint
    and pair when given them, against dense brute-force averaging matrices on the standardised joints.
    Seen failing with the residual left uncentred in ``shares`` (``centred.mean`` not subtracted)."""
    robot = load_robot("ur5")
    rng = np.random.default_rng(3)
    n = 80
    q = np.zeros((n, robot.n_joints))
    q[:, :3] = rng.uniform(-2.0, 2.0, (n, 3))  # three moving joints: the subsets above
    residual = np.column_stack([np.sin(2 * q[:, 1]), q[:, 0] * q[:, 2], np.ones(n)]) * 1e-4
    residual += rng.normal(0.0, 3e-5, (n, 3))
    detector = StructureDetector(q, np.random.default_rng(1), n_permutations=5)
    moving = q[:, :3]
    qs = (moving - moving.mean(axis=0)) / moving.std(axis=0)
    centred = residual - residual.mean(axis=0)
    expected = {s: 1.0 - np.sum((centred - knn_mean(qs[:, s], 10) @ centred) ** 2) / np.sum(centred**2)
                for s in SUBSETS}
    shares = detector.shares(residual)
    assert set(shares) == set(expected)
    for subset, share in expected.items():
        assert shares[subset] == pytest.approx(share, rel=1e-9, abs=1e-12)
    nominal = rng.normal(size=(n, 3))
    tau = rng.normal(size=(n, robot.n_joints))
    where, _ = where_analysis(robot, q, nominal, residual, tau, {}, rng=np.random.default_rng(0),
                              knn_shares=detector.shares)
    names = robot.joint_names
    assert list(where["along_joints"]) == names[:3]
    for j in range(3):
        assert where["along_joints"][names[j]]["knn_explained_share"] == pytest.approx(expected[(j,)], rel=1e-9)
    pairs = {tuple(p["joints"]): p["knn_explained_share"] for p in where["along_joint_pairs"]}
    for a, b in [(0, 1), (0, 2), (1, 2)]:
        assert pairs[(names[a], names[b])] == pytest.approx(expected[(a, b)], rel=1e-9)
