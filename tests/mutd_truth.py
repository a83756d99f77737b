"""A hidden truth for the mutd tests (issue 36): poses of the tool-changer whose joints are off by a few
hundredths of a degree, measured through Pinocchio with 30 um of noise per axis."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from tcr_accuracy.io.measurements import MeasurementSet
from tcr_accuracy.model.robot import load_robot

#: the hidden joint offsets [rad; m for the prismatic fourth joint]
OFFSETS = np.array([np.radians(0.05), np.radians(-0.03), np.radians(0.04), 3e-4, np.radians(0.06),
                    np.radians(0.02)])


def offset_measurements(n: int, seed: int):
    """(robot, MeasurementSet) of n uniform poses within the joint bounds, the tool's position computed with
    the joints at q + OFFSETS by Pinocchio's forward kinematics, plus N(0, 30 um) per axis."""
    robot = load_robot()
    rng = np.random.default_rng(seed)
    low, high = robot.joint_bounds()
    q = rng.uniform(low, high, size=(n, robot.n_joints))
    model, data = robot.model, robot.model.createData()
    position = np.empty((n, 3))
    for i, row in enumerate(q + OFFSETS):
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(row))
        position[i] = data.oMf[robot.tool_frame_id].translation
    position += 3e-5 * rng.standard_normal(position.shape)
    return robot, MeasurementSet(joint_names=robot.joint_names, q=q, position=position)
