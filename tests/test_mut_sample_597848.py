"""Three survivors of a measuring sample of issue 36's mutation run (seed 597848), each pinned by a fast direct
test against a computation written out here: the fold assignments of the candidate stage (scikit-learn's
RepeatedKFold seeded by the generator's first draw below 2^31 - 1), the implausibility of an effect with a
parameter whose physical range is the single value 0 (no bound to compare with: left out, not divided by), and
the ridge's standardisation of a feature that does not vary beyond rounding (divided by 1, as scikit-learn's
StandardScaler does for a constant feature). Each test names the planted change it was seen to catch."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from sklearn.model_selection import KFold

from tcr_accuracy.diagnosis.structure import RidgeFolds
from tcr_accuracy.diagnosis.uncertainty import implausibility


def test_a_parameter_whose_range_is_zero_is_left_out_of_the_implausibility():
    """Three parameters: 2 on [-4, 4], -1 on [-2, 1] (the bound on its own side: 2) and one held at 0 with the
    range [0, 0] (nothing to compare it with): sqrt(((2/4)^2 + (1/2)^2) / 2) = 0.5; an effect whose every range
    is [0, 0] is 0. Seen failing on ``finite = np.isfinite(bound) & (bound > 0)`` turned to ``bound > -1``
    (0 / 0 read as a figure: NaN)."""
    result = {"phi": np.array([2.0, -1.0, 0.0]), "scale": np.ones(3), "keep": {"geometry": np.arange(3)},
              "effects": ["geometry"]}
    bases = {"geometry": SimpleNamespace(lower=np.array([-4.0, -2.0, 0.0]), upper=np.array([4.0, 1.0, 0.0]))}
    assert implausibility(result, bases, "geometry") == pytest.approx(math.sqrt((0.5**2 + 0.5**2) / 2), rel=1e-12)
    pinned = {"geometry": SimpleNamespace(lower=np.zeros(3), upper=np.zeros(3))}
    assert implausibility({**result, "phi": np.zeros(3)}, pinned, "geometry") == 0.0


def test_a_feature_constant_but_for_rounding_is_standardised_by_one():
    """One feature 1 + k * 2^-52 (k = 0..3: a spread of a few 1e-16, below 10 eps of its size, so the
    standardisation divides it by 1, StandardScaler's rule for a constant feature), one penalty: each fold's
    out-of-fold prediction written out as the ridge with an intercept on z = x - mean(x_train):
    mean(y_train) + z_test * (z . (y - mean y)) / (z . z + alpha), alpha of the size of z . z. Seen failing on
    ``scale[...] = 1.0`` turned to ``2.0`` (z halved: every prediction's slope term 2.5 times smaller)."""
    k = np.array([0, 1, 2, 3, 1, 2, 3, 0, 2, 3, 0, 1], dtype=float)
    features = (1.0 + k * 2.0**-52)[:, None]
    y = np.sin(np.arange(12.0))[:, None]
    alpha = 1e-31
    split = KFold(n_splits=3)
    ours = RidgeFolds(features, split, np.array([alpha])).predict(y)
    expected = np.empty_like(y)
    for train, test in split.split(features):
        x = features[train]
        mean = x.mean(axis=0)
        assert x.std(axis=0)[0] < 10 * np.finfo(float).eps  # the case this test is about
        z = (x - mean)[:, 0]
        centred = y[train, 0] - y[train, 0].mean()
        slope = float(z @ centred) / (float(z @ z) + alpha)
        expected[test, 0] = y[train, 0].mean() + (features[test, 0] - mean[0]) * slope
    assert np.ptp(expected - y.mean()) > 0.1  # the slope term is of the size of y, not of the rounding
    np.testing.assert_allclose(ours, expected, rtol=1e-9, atol=1e-12)


def test_the_candidate_stage_draws_its_fold_seed_below_2_to_the_31_from_the_diagnosis_generator():
    """The fold assignments of stage 2 against scikit-learn's RepeatedKFold seeded, as the stage's docstring
    says, by the first draw of its generator: an integer below 2^31 - 1 (numpy's bounded draw written out here
    on a twin generator), on 30 poses of the UR5 measured exactly through Pinocchio. Seen failing on
    ``rng.integers(2**31 - 1)`` turned to ``2**31 + 1`` (another draw: other folds)."""
    import pinocchio as pin
    from sklearn.model_selection import RepeatedKFold

    from tcr_accuracy.diagnosis.stages.candidates import build_candidates
    from tcr_accuracy.diagnosis.stages.register import MeasuredFrame, register_measurements
    from tcr_accuracy.io.measurement_set import MeasurementSet
    from tcr_accuracy.model.robot import load_robot

    from hidden_robot import frame_id, random_poses

    robot = load_robot("ur5")
    rng = np.random.default_rng(31)
    q = random_poses(robot, 30, rng)
    data = robot.model.createData()
    tool = frame_id(robot.model, robot.tool_frame)
    positions = []
    for pose in q:
        pin.framesForwardKinematics(robot.model, data, pose)
        positions.append(data.oMf[tool].translation.copy())
    measured = MeasurementSet(joint_names=list(robot.joint_names), q=q, position=np.array(positions))
    registered = register_measurements([MeasuredFrame(robot, measured, robot.tool_frame)])
    engine = build_candidates(registered, ["frames"], folds=3, rank_tol=1e-6, tracker_noise=1e-5,
                              rng=np.random.default_rng(2024), fold_repeats=2).engine
    seed = int(np.random.default_rng(2024).integers(2**31 - 1))
    every = list(RepeatedKFold(n_splits=3, n_repeats=2, random_state=seed).split(np.arange(30)))
    assert len(engine.repeats) == 2
    for r, folds in enumerate(engine.repeats):
        for (train, test), (want_train, want_test) in zip(folds, every[3 * r:3 * (r + 1)], strict=True):
            np.testing.assert_array_equal(train, want_train)
            np.testing.assert_array_equal(test, want_test)
