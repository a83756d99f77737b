"""Task-workspace sampling and batched IK, checked by forward kinematics and by hand."""

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.kinematics import euler_zyx, rotation_from_euler_zyx, tcp_poses
from tcr_accuracy.analysis.sampling import TaskWorkspace, inverse_kinematics, sample_task_workspace, stratified_subset

UR5_REF = np.array([0.3, -1.2, 1.5, -1.9, -1.57, 0.4])
TC_REF = np.array([np.radians(15), np.radians(30), np.radians(-10), 0.2, np.radians(20), 0.0])


def test_euler_zyx_is_rz_ry_rx_by_hand():
    a, b, c = 0.3, -0.4, 1.1

    def rz(t):
        return np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])

    def ry(t):
        return np.array([[np.cos(t), 0, np.sin(t)], [0, 1, 0], [-np.sin(t), 0, np.cos(t)]])

    def rx(t):
        return np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])

    rot = rotation_from_euler_zyx(np.array([[a, b, c]]))[0]
    np.testing.assert_allclose(rot, rz(a) @ ry(b) @ rx(c), atol=1e-14)
    np.testing.assert_allclose(euler_zyx(rot[None])[0], [a, b, c], atol=1e-12)


def test_ik_reaches_full_poses_on_ur5_checked_by_forward_kinematics(ur5):
    rng = np.random.default_rng(0)
    q_true = UR5_REF + rng.uniform(-0.25, 0.25, (40, 6))
    pose = tcp_poses(ur5, q_true)
    ik = inverse_kinematics(ur5, pose.position, pose.rotation, UR5_REF)
    assert ik.n_failed == 0
    reached = tcp_poses(ur5, ik.q)
    assert np.abs(reached.position - pose.position).max() < 1e-6
    assert np.abs(reached.rotation - pose.rotation).max() < 1e-6
    assert np.all(ik.q >= ur5.lower_limits) and np.all(ik.q <= ur5.upper_limits)


def test_ik_reports_unreachable_targets_and_keeps_joints_in_limits(ur5):
    pose = tcp_poses(ur5, UR5_REF)
    far = pose.position + np.array([[0.0, 0.0, 0.0], [3.0, 0.0, 0.0]])  # 3 m beyond a 0.85 m reach
    ik = inverse_kinematics(ur5, far, np.repeat(pose.rotation, 2, axis=0), UR5_REF, max_iter=60)
    assert ik.success.tolist() == [True, False]
    assert ik.n_failed == 1
    assert ik.position_error[1] > 2.0
    assert np.all(np.isfinite(ik.q))
    assert np.all(ik.q >= ur5.lower_limits) and np.all(ik.q <= ur5.upper_limits)


def test_ik_clips_to_joint_limits(tool_changer):
    # a target that needs the telescopic joint j4 beyond its 600 mm stroke
    q = TC_REF.copy()
    q[3] = 0.6
    pose = tcp_poses(tool_changer, q)
    beyond = pose.position + 0.3 * (pose.position - tcp_poses(tool_changer, TC_REF * [1, 1, 1, 0, 1, 1]).position)
    ik = inverse_kinematics(tool_changer, beyond, None, TC_REF, max_iter=80)
    assert 0.0 <= ik.q[0, 3] <= 0.6 + 1e-15


def test_tool_changer_pose_has_five_independent_dof_and_best_effort_reaches_positions(tool_changer):
    model, data = tool_changer.model, tool_changer.model.createData()
    pin.computeJointJacobians(model, data, tool_changer.to_pinocchio_q(TC_REF))
    pin.updateFramePlacements(model, data)
    jac = pin.getFrameJacobian(model, data, tool_changer.tool_frame_id, pin.LOCAL)
    assert np.linalg.matrix_rank(jac, tol=1e-9) == 5  # j2, j3, j5 parallel, j4 slides in their plane
    ws = TaskWorkspace.around(tool_changer, TC_REF, 0.15, np.radians(10))
    positions, rotations = ws.sample(30, np.random.default_rng(1))
    ik = inverse_kinematics(tool_changer, positions, rotations, TC_REF, orientation="best_effort")
    ok = ik.success
    assert ok.sum() >= 25
    np.testing.assert_allclose(tcp_poses(tool_changer, ik.q[ok]).position, positions[ok], atol=1e-6)
    # the same targets demanded exactly: the random orientations are out of reach
    exact = inverse_kinematics(tool_changer, positions[:5], rotations[:5], TC_REF, orientation="exact",
                               max_iter=40)
    assert exact.n_failed >= 4


def test_stratified_subset_fills_every_joint_bin_unlike_a_random_pick():
    rng = np.random.default_rng(2)
    dense = rng.uniform(0, 1, (3000, 6)) ** 2  # crowded near 0 on every joint
    n = 40
    pick = stratified_subset(dense, n, rng)
    assert len(set(pick.tolist())) == n

    def empty_bins(q):
        lo, hi = dense.min(0), dense.max(0)
        b = np.clip(((q - lo) / (hi - lo) * n).astype(int), 0, n - 1)
        return [n - len(set(b[:, j])) for j in range(6)]

    random_pick = rng.choice(len(dense), n, replace=False)
    assert max(empty_bins(dense[pick])) <= 8
    assert min(empty_bins(dense[random_pick])) >= 12  # a random pick of a skewed set leaves many empty


def test_sample_task_workspace_on_ur5_stays_in_the_box(ur5):
    rng = np.random.default_rng(3)
    ws = TaskWorkspace.around(ur5, UR5_REF, [0.1, 0.1, 0.08], np.radians(10))
    sample = sample_task_workspace(ur5, ws, 30, rng, n_dense=300, q_init=UR5_REF)
    assert sample.q.shape == (30, 6)
    assert sample.n_failed == 300 - len(sample.dense_q)
    pose = tcp_poses(ur5, sample.q)
    assert np.all(pose.position >= ws.position_low - 1e-6) and np.all(pose.position <= ws.position_high + 1e-6)
    euler = euler_zyx(pose.rotation)
    above_low = np.mod(euler - ws.euler_low + 1e-6, 2 * np.pi)  # angles wrap at +-pi
    assert np.all(above_low <= ws.euler_high - ws.euler_low + 2e-6)


def test_unreachable_workspace_is_a_clear_input_error(ur5):
    ws = TaskWorkspace(np.array([3.0, 3.0, 3.0]), np.array([3.2, 3.2, 3.2]), np.zeros(3), np.zeros(3))
    with pytest.raises(InputError, match="reached only 0 of 20"):
        sample_task_workspace(ur5, ws, 5, np.random.default_rng(0), n_dense=20, q_init=UR5_REF, max_iter=30)
    with pytest.raises(InputError, match="upper bound"):
        TaskWorkspace(np.ones(3), np.zeros(3), np.zeros(3), np.zeros(3))
