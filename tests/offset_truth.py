"""A robot measured with its joints turned by hidden offsets, written out on Pinocchio for the tests
(the forward model is independent of the effect classes the diagnosis fits)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from tcr_accuracy.io.measurements import MeasurementSet


def measured_with_offsets(robot, offsets: np.ndarray, n_poses: int, seed: int, noise_m: float):
    """``n_poses`` uniform poses within the joint bounds, the tool frame's position at ``q + offsets``
    by Pinocchio's forward kinematics plus ``noise_m`` of noise per axis [m]. Returns (q, position,
    MeasurementSet)."""
    rng = np.random.default_rng(seed)
    low, high = robot.joint_bounds()
    q = rng.uniform(low, high, (n_poses, robot.n_joints))
    data = robot.model.createData()
    position = np.empty((n_poses, 3))
    for i, row in enumerate(q + offsets):
        pin.framesForwardKinematics(robot.model, data, robot.to_pinocchio_q(row))
        position[i] = data.oMf[robot.tool_frame_id].translation
    position += noise_m * rng.standard_normal(position.shape)
    return q, position, MeasurementSet(joint_names=robot.joint_names, q=q, position=position)
