"""Progress of the discriminating design (``diagnosis/design.py``): one call with 1 per pose chosen, as a
progress bar's update reads it (that line ran in no test). Seen failing on ``progress(1)`` -> ``progress(2)`` /
``progress(0)`` (issue 36)."""

from __future__ import annotations

import numpy as np
from test_mutfit_design import _poses
from test_mutp_design import NOISE_M, _rivals

from tcr_accuracy.diagnosis.design import plan_discriminating_poses
from tcr_accuracy.model.robot import load_robot


def test_the_discriminating_design_reports_one_per_pose_chosen():
    """Three poses chosen of 12 candidates: three calls with 1, and the poses the same as without a progress."""
    robot = load_robot()
    measured, candidates = _poses(robot, 5, 1), _poses(robot, 12, 2)
    calls = []
    planned = plan_discriminating_poses(robot, measured, [_rivals(robot)], 3, candidates=candidates, noise_m=NOISE_M,
                                        progress=calls.append)
    assert calls == [1, 1, 1]
    np.testing.assert_array_equal(planned, plan_discriminating_poses(robot, measured, [_rivals(robot)], 3,
                                                                     candidates=candidates, noise_m=NOISE_M))
