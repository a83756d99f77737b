"""The batched error Jacobians (``model/jacobians.py``: Pinocchio's frame kinematic regressor in base-frame
axes, the joints' columns from their motion axes; issue 39) against central finite differences of the
TCP pose from Pinocchio's plain per-pose forward kinematics of the perturbed model, away from x = 0: each
pose at its own error vector (a prismatic joint among them), and a continuous joint (two configuration
entries for one joint value)."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.model.jacobians import error_jacobians
from tcr_accuracy.model.kinematics import pose_error, tcp_poses_pinocchio
from tcr_accuracy.model.robot import load_robot, robot_from_urdf_text

PLANAR = """<robot name="planar">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tip"/>
  <joint name="q1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="q2" type="continuous"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.7 0 0.1" rpy="0.2 0 0"/><axis xyz="0 1 0"/></joint>
  <joint name="q3" type="prismatic"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.5" effort="1" velocity="1"/></joint>
  <joint name="t" type="fixed"><parent link="l3"/><child link="tip"/><origin xyz="0.4 0.05 0"/></joint>
</robot>"""


def _numeric(robot, em, q, x, step=1e-6):
    """(6, n_joints), (6, p): central differences of the TCP's displacement and rotation vector (base axes)
    from the pose at (q, x), in q and in x, by Pinocchio's per-pose kinematics of the perturbed model."""
    at = tcp_poses_pinocchio(robot, q, x, em)

    def moved(dq, dx):
        e = pose_error(at, tcp_poses_pinocchio(robot, q + dq, x + dx, em))
        return np.concatenate([e.position[0], e.rotation_vector[0]])

    jq = np.column_stack([(moved(d, 0.0) - moved(-d, 0.0)) / (2 * step) for d in np.eye(q.size) * step])
    jx = np.column_stack([(moved(0.0, d) - moved(0.0, -d)) / (2 * step) for d in np.eye(em.size) * step])
    return jq, jx


@pytest.mark.parametrize("case", ["tool_changer, an error vector per pose", "continuous joint, one error vector"])
def test_error_jacobians_are_the_finite_differences_of_the_perturbed_kinematics(case):
    """Seen failing with the regressor asked for in the TCP's own axes (``pin.LOCAL``) and with the joints'
    columns taken from the wrong motion axes (``robot.motion_axes[::-1]``)."""
    rng = np.random.default_rng(21)
    if case.startswith("tool_changer"):
        robot = load_robot("tool_changer")
        lower, upper = robot.joint_bounds()
        q = lower + rng.random((3, robot.n_joints)) * (upper - lower)
        em = ErrorModel(robot)
        x = rng.normal(0.0, 2e-3, (3, em.size))
    else:
        robot = robot_from_urdf_text(PLANAR, None)
        assert robot.model.nq == 4 and robot.n_joints == 3  # the continuous joint as its cos and sin
        q = np.array([[0.3, -2.9, 0.1], [2.0, 3.1, 0.4]])
        em = ErrorModel(robot)
        x = rng.normal(0.0, 2e-3, em.size)
    jq, jx = error_jacobians(robot, q, x, em)
    for i in range(q.shape[0]):
        expected_q, expected_x = _numeric(robot, em, q[i], x[i] if x.ndim == 2 else x)
        np.testing.assert_allclose(jq[i], expected_q, atol=2e-8)
        np.testing.assert_allclose(jx[i], expected_x, atol=2e-8)
