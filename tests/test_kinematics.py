"""Batched engine against the plain per-sample Pinocchio loop, Jacobians against finite
differences, and pose-error metrics against closed forms."""

import math

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.model.errors import ErrorModel
from tcr_accuracy.model.jacobians import error_jacobian
from tcr_accuracy.model.chain import SMALL_ANGLE, _small_cos_sin
from tcr_accuracy.model.kinematics import (
    euler_zyx,
    exp6_batch,
    pose_error,
    tcp_poses,
    tcp_poses_pinocchio,
    TcpPoses,
)
from tcr_accuracy.model.robot import load_robot

from conftest import random_joint_values


@pytest.mark.parametrize("name", ["tool_changer", "ur5", "panda"])
@pytest.mark.parametrize("scale", [1e-4, 3e-2])
def test_engine_matches_the_pinocchio_loop(name, scale):
    robot = load_robot(name)
    em = ErrorModel(robot)
    rng = np.random.default_rng(1)
    q = random_joint_values(robot, 30, rng)
    x = rng.normal(0, scale, (30, em.size))
    engine = tcp_poses(robot, q, x, em)
    loop = tcp_poses_pinocchio(robot, q, x, em)
    np.testing.assert_allclose(engine.position, loop.position, atol=1e-12)
    np.testing.assert_allclose(engine.rotation, loop.rotation, atol=1e-12)


def test_sparse_fast_paths_match_the_general_path(tool_changer):
    """Pure translations and single-axis rotations take shortcuts; compare to the loop."""
    em = ErrorModel(tool_changer)
    rng = np.random.default_rng(4)
    x = np.zeros((25, em.size))
    x[:, em.index("j3.dy")] = rng.normal(0, 1e-3, 25)
    x[:, em.index("j5.ry")] = rng.normal(0, 1e-2, 25)
    x[:, em.index("tool.rz")] = rng.normal(0, 1e-2, 25)
    x[:, em.drive_slice] = rng.normal(0, 1e-2, (25, 6))
    q = tool_changer.working_pose
    np.testing.assert_allclose(tcp_poses(tool_changer, q, x, em).position,
                               tcp_poses_pinocchio(tool_changer, q, x, em).position, atol=1e-12)


def test_broadcasting_one_pose_many_errors_and_many_poses_one_error(tool_changer):
    em = ErrorModel(tool_changer)
    rng = np.random.default_rng(0)
    q = random_joint_values(tool_changer, 7, rng)
    x = rng.normal(0, 1e-3, em.size)
    many_q = tcp_poses(tool_changer, q, x, em)
    assert many_q.position.shape == (7, 3) and many_q.rotation.shape == (7, 3, 3)
    one_by_one = np.array([tcp_poses(tool_changer, qi, x, em).position[0] for qi in q])
    np.testing.assert_allclose(many_q.position, one_by_one, atol=1e-15)


def test_exp6_batch_equals_pinocchio_exp6():
    rng = np.random.default_rng(3)
    twists = np.concatenate([rng.normal(0, 1, (20, 6)), rng.normal(0, 1e-7, (20, 6)), np.zeros((1, 6))])
    rot, trans = exp6_batch(twists)
    for i, twist in enumerate(twists):
        expected = pin.exp6(twist)
        np.testing.assert_allclose(rot[:, :, i], expected.rotation, atol=1e-14)
        np.testing.assert_allclose(trans[:, i], expected.translation, atol=1e-14)


@pytest.mark.parametrize("name", ["tool_changer", "ur5"])
def test_error_jacobian_matches_seeded_finite_differences(name):
    robot = load_robot(name)
    em = ErrorModel(robot)
    rng = np.random.default_rng(9)
    q = random_joint_values(robot, 1, rng)[0]
    jac = error_jacobian(robot, q, em)
    nominal = tcp_poses(robot, q)
    step = 1e-6
    numeric = np.zeros_like(jac)
    for k in range(em.size):
        plus, minus = em.zeros(), em.zeros()
        plus[k], minus[k] = step, -step
        ep = pose_error(nominal, tcp_poses(robot, q, plus, em))
        emn = pose_error(nominal, tcp_poses(robot, q, minus, em))
        numeric[:3, k] = (ep.position[0] - emn.position[0]) / (2 * step)
        numeric[3:, k] = (ep.rotation_vector[0] - emn.rotation_vector[0]) / (2 * step)
    np.testing.assert_allclose(jac, numeric, atol=1e-8)


def _rot(axis, angle):
    return pin.exp3(np.asarray(axis, float) * angle)


def test_euler_zyx_of_a_known_composition():
    a, b, c = 0.3, -0.4, 1.1
    r = _rot([0, 0, 1], a) @ _rot([0, 1, 0], b) @ _rot([1, 0, 0], c)
    np.testing.assert_allclose(euler_zyx(r[None])[0], [a, b, c], atol=1e-14)


def test_pose_error_metrics_closed_form():
    nominal = TcpPoses(position=np.array([[1.0, 2.0, 3.0]]), rotation=np.eye(3)[None])
    angle = 1e-3
    actual = TcpPoses(position=np.array([[1.0 + 3e-4, 2.0 - 4e-4, 3.0]]),
                      rotation=_rot([0, 0, 1], angle)[None])
    err = pose_error(nominal, actual)
    assert err.position_norm[0] == pytest.approx(5e-4, abs=1e-15)
    np.testing.assert_allclose(err.euler_zyx[0], [angle, 0, 0], atol=1e-15)
    np.testing.assert_allclose(err.rotation_vector[0], [0, 0, angle], atol=1e-15)
    assert err.rotation_angle[0] == pytest.approx(angle, rel=1e-12)


def test_euler_difference_wraps_across_pi():
    nominal = TcpPoses(position=np.zeros((1, 3)), rotation=_rot([0, 0, 1], math.pi - 1e-3)[None])
    actual = TcpPoses(position=np.zeros((1, 3)), rotation=_rot([0, 0, 1], -math.pi + 1e-3)[None])
    assert pose_error(nominal, actual).euler_zyx[0, 0] == pytest.approx(2e-3, abs=1e-12)


def test_small_angle_series_agree_with_libm_to_the_last_bits():
    """The Horner series that replace numpy's cos and sin up to SMALL_ANGLE, against libm."""
    x = np.concatenate([np.linspace(-SMALL_ANGLE, SMALL_ANGLE, 400_001), [1e-300, -1e-12, 3e-8]])
    cos, sin = _small_cos_sin(x)
    assert np.all(np.abs(cos - np.cos(x)) <= 2 * np.spacing(np.cos(x)))
    assert np.all(np.abs(sin - np.sin(x)) <= 2 * np.spacing(np.abs(np.sin(x))))
