"""A joint held still through a campaign (``diagnosis/structure.py``, ``diagnosis/residuals.py``), issue 36:
numpy's spread of 60 equal values of 0.4 is 1.7e-16, the rounding of their mean, not 0, and such a joint was
taken as moving -- the structure test counted it in its subsets (three more for Bonferroni, neighbours along a
constant), standardised a still prismatic joint's rounding to +-1 features, and the where-analysis listed it
among the joints the gap varies along. A bug found by the third pass's mutation sample (a survivor on the
still joint's spread); fixed by asking whether the values differ (``np.ptp``). Each test names a planted change
it was seen to catch."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.residuals import where_analysis
from tcr_accuracy.diagnosis.structure import StructureDetector

N = 60


@pytest.fixture(scope="module")
def poses():
    rng = np.random.default_rng(21)
    still = np.full(N, 0.4)
    assert still.std() > 0  # the rounding this file is about
    stroke = rng.uniform(0.1, 0.4, N)  # a prismatic joint moving 0.3 m: spread and range below one
    return np.column_stack([rng.uniform(-2, 2, N), still, stroke, still])


def test_a_joint_held_still_is_in_no_subset_and_a_still_prismatic_joint_gives_zero_features(poses):
    """Joints: a revolute one moving, a revolute one held at 0.4 rad, a prismatic one moving 0.3 m, a prismatic
    one held at 0.4 m. The subsets are the two moving joints together, each, and their pair (the first and last
    the same: four); the moving prismatic joint's features are its z-score (numpy's spread written out) and its
    square, the still one's zeros, and so are its products with the revolute joints' harmonics. Seen failing on
    ``np.ptp(self.q[:, j]) > 0`` turned to ``> -1`` (the still joints in seven more subsets), on ``np.ptp(v) >
    0`` turned to ``> -1`` (the still joint's +-1 features) and to ``> 1``, and on ``spread > 0`` turned to
    ``> 1`` (the 0.3 m stroke read as still)."""
    detector = StructureDetector(poses, np.random.default_rng(0), kinds=["revolute", "revolute", "prismatic",
                                                                           "prismatic"], n_permutations=3)
    assert detector.subsets == [(0, 2), (0,), (2,), (0, 2)]
    v, held, stroke = poses[:, 0], poses[:, 1], poses[:, 2]
    z = (stroke - stroke.mean()) / np.sqrt(np.mean((stroke - stroke.mean()) ** 2))
    zero = np.zeros(N)
    first = [[np.sin(v), np.cos(v)], [np.sin(held), np.cos(held)], [z], [zero]]
    columns = [np.sin(v), np.cos(v), np.sin(2 * v), np.cos(2 * v), np.sin(held), np.cos(held), np.sin(2 * held),
               np.cos(2 * held), z, z**2, zero, zero]
    columns += [u * w for i in range(4) for k in range(i + 1, 4) for u in first[i] for w in first[k]]
    np.testing.assert_allclose(detector.features, np.column_stack(columns), rtol=1e-12, atol=1e-15)
    assert detector.test(np.random.default_rng(1).normal(0, 1e-4, (N, 3)))["n_subsets"] == 4


def test_a_stroke_whose_spread_squares_to_nothing_gives_zero_features_not_nan():
    """A prismatic joint whose values differ by 1e-170 m: their range is above 0, their spread (the root of
    squares that underflow) is 0, and its features are zeros, not 0 / 0. Seen failing on ``spread > 0`` turned
    to ``> -1``."""
    rng = np.random.default_rng(22)
    q = np.column_stack([rng.uniform(-2, 2, N), np.repeat([0.0, 1e-170], N // 2)])
    assert np.ptp(q[:, 1]) > 0 and q[:, 1].std() == 0
    with np.errstate(divide="raise", invalid="raise"):
        features = StructureDetector(q, np.random.default_rng(0), kinds=["revolute", "prismatic"],
                                     n_permutations=2).features
    np.testing.assert_array_equal(features[:, 4:], 0.0)


def test_the_gap_does_not_vary_along_a_joint_held_still(poses):
    """The where-analysis on the four joints, the gap a function of the moving revolute joint: the joints held
    still are not in ``along_joints`` nor in any pair (the two moving joints, one pair). Seen failing on
    ``np.ptp(q[:, j]) == 0`` turned to ``== 1`` and ``== -1`` (the still joints listed, with neighbours along
    a constant)."""
    rng = np.random.default_rng(23)
    robot = SimpleNamespace(joint_names=["a", "b", "c", "d"],
                            joint_kinds=["revolute", "revolute", "prismatic", "prismatic"])
    residual = np.column_stack([np.sin(poses[:, 0]), np.cos(poses[:, 0]), poses[:, 2]]) * 1e-4
    where, _ = where_analysis(robot, poses, rng.normal(size=(N, 3)), residual, rng.normal(size=(N, 4)), {},
                              rng=np.random.default_rng(0))
    assert list(where["along_joints"]) == ["a", "c"]
    assert [p["joints"] for p in where["along_joint_pairs"]] == [["a", "c"]]
