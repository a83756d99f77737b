"""The frames' registration at its edge (second pass of issue 36's mutation line over ``frames/``):
a TCP offset fitted alone from one pose, where the residuals are exactly as many as the unknowns.
Each test names a planted change it was seen to catch.
"""

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy import load_robot
from tcr_accuracy.frames.registration import register_tracker


@pytest.mark.parametrize("n_poses", [1, 2])
def test_a_tcp_offset_alone_is_fitted_from_one_pose_exactly(n_poses):
    """Positions read in the base frame (no tracker frame fitted) at a point 10, -20, 30 mm from the UR5's
    TCP in its own frame, written out on Pinocchio: the offset fitted from one pose (three residuals,
    three unknowns: Levenberg-Marquardt still applies) or two is that point to 1e-9 m, and nothing else
    moves. Written when the least-squares method's choice ``"lm" if 3 N >= columns else "trf"`` was
    found dead (the identifiable columns never outnumber the 3 N residuals) and removed; seen failing
    on the fitted offset's sign turned (``p[cols] = -theta``)."""
    robot = load_robot("ur5")
    offset = np.array([0.010, -0.020, 0.030])
    q = np.random.default_rng(0).uniform(-1.0, 1.0, (n_poses, 6))
    data = robot.model.createData()
    measured = []
    for row in q:
        pin.framesForwardKinematics(robot.model, data, row)
        measured.append(data.oMf[robot.tool_frame_id].act(offset))
    fitted = register_tracker(robot, q, np.array(measured), fit_base=False)
    assert fitted.fitted == ("frames.tool.dx", "frames.tool.dy", "frames.tool.dz")
    tool = [fitted.parameter_names.index(f"frames.tool.{c}") for c in ("dx", "dy", "dz")]
    np.testing.assert_allclose(fitted.frames_parameters[tool], offset, atol=1e-9)
    np.testing.assert_allclose(np.delete(fitted.frames_parameters, tool), 0.0, atol=0.0)
    np.testing.assert_allclose(fitted.trackerMbase, np.eye(4), atol=0.0)
    assert fitted.residual_rms < 1e-9 and fitted.n_points == n_poses
