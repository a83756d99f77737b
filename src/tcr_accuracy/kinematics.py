"""Batched forward kinematics of nominal and perturbed robots, and TCP pose errors.

The engine works on whole batches in numpy, not one Pinocchio call per sample:
rotations are kept as (3, 3, N) and translations as (3, N) arrays ("structure of
arrays") so that every operation runs over contiguous length-N vectors. Pinocchio
computes one pose at a time; Monte Carlo needs millions, which is why this part is
written by hand. ``tcp_poses_pinocchio`` is the plain per-sample Pinocchio path,
kept as the reference the engine is tested and benchmarked against.

Shapes: N samples on axis 0 of every input and output. Joint values q are
(N, n_joints) or (n_joints,) [rad, m]; error vectors x are (N, n_params) or
(n_params,) (see :mod:`tcr_accuracy.errors`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from .errors import ErrorModel
from .exceptions import InputError
from .robot import REVOLUTE, RobotModel


@dataclass(frozen=True)
class TcpPoses:
    """TCP poses in the base frame.

    position : ndarray of shape (N, 3) [m]
    rotation : ndarray of shape (N, 3, 3)
    """

    position: np.ndarray
    rotation: np.ndarray

    def __len__(self) -> int:
        return self.position.shape[0]


@dataclass(frozen=True)
class PoseError:
    """Actual minus nominal TCP pose.

    position : (N, 3) position error in the base frame [m]
    position_norm : (N,) |dP| [m]
    euler_zyx : (N, 3) differences of the ZYX Euler angles (about z, then y, then x)
        of the actual and nominal orientations [rad], wrapped to (-pi, pi]
    rotation_vector : (N, 3) rotation vector of ``R_actual R_nominal^T`` (base frame) [rad]
    rotation_angle : (N,) its norm [rad]
    """

    position: np.ndarray
    position_norm: np.ndarray
    euler_zyx: np.ndarray
    rotation_vector: np.ndarray
    rotation_angle: np.ndarray


# ---------------------------------------------------------------------------------------
# Batched SE3 pieces in (3, 3, N) / (3, N) layout
# ---------------------------------------------------------------------------------------
def _skew_sq_terms(w: np.ndarray):
    """theta (N,), and the Rodrigues coefficients for w of shape (3, N)."""
    theta_sq = np.einsum("in,in->n", w, w)
    theta = np.sqrt(theta_sq)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    safe_sq = safe * safe
    # Taylor series below 1e-4 rad keep full double precision
    a = np.where(small, 1.0 - theta_sq / 6.0, np.sin(safe) / safe)  # sin t / t
    b = np.where(small, 0.5 - theta_sq / 24.0, (1.0 - np.cos(safe)) / safe_sq)  # (1 - cos t) / t^2
    c = np.where(small, 1.0 / 6.0 - theta_sq / 120.0, (safe - np.sin(safe)) / (safe_sq * safe))
    return a, b, c


def _hat_products(w: np.ndarray):
    """[w] and [w]^2 as (3, 3, N) for w (3, N)."""
    wx, wy, wz = w
    zero = np.zeros_like(wx)
    hat = np.array([[zero, -wz, wy], [wz, zero, -wx], [-wy, wx, zero]])
    hat_sq = np.einsum("ijn,jkn->ikn", hat, hat)
    return hat, hat_sq


def exp6_batch(twist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched ``pin.exp6``: twists (N, 6) as (v, w) to R (3, 3, N) and p (3, N)."""
    v = np.ascontiguousarray(twist[:, :3].T)
    w = np.ascontiguousarray(twist[:, 3:].T)
    a, b, c = _skew_sq_terms(w)
    hat, hat_sq = _hat_products(w)
    eye = np.eye(3)[:, :, None]
    rot = eye + a * hat + b * hat_sq
    left_jacobian = eye + b * hat + c * hat_sq
    p = np.einsum("ijn,jn->in", left_jacobian, v)
    return rot, p


def _compose(ra, pa, rb, pb):
    """(ra, pa) * (rb, pb) for batched or constant (3, 3)/(3,) right factors."""
    if rb.ndim == 2:
        r = np.einsum("ijn,jk->ikn", ra, rb)
        p = pa + np.einsum("ijn,j->in", ra, pb)
    else:
        r = np.einsum("ijn,jkn->ikn", ra, rb)
        p = pa + np.einsum("ijn,jn->in", ra, pb)
    return r, p


def _rotate_about_axis(r: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """r * Rot(axis, angle) for a constant unit axis (3,) and angles (N,)."""
    k = int(np.argmax(np.abs(axis)))
    if abs(abs(axis[k]) - 1.0) < 1e-15:  # a coordinate axis: only two columns change
        i, j = (k + 1) % 3, (k + 2) % 3
        sign = np.sign(axis[k])
        c, s = np.cos(angle), sign * np.sin(angle)
        out = np.empty_like(r)
        out[:, k] = r[:, k]
        out[:, i] = c * r[:, i] + s * r[:, j]
        out[:, j] = c * r[:, j] - s * r[:, i]
        return out
    twist = np.zeros((angle.shape[0], 6))
    twist[:, 3:] = np.outer(angle, axis)
    rot, _ = exp6_batch(twist)
    return np.einsum("ijn,jkn->ikn", r, rot)


def _apply_twist(r, p, twist: np.ndarray):
    """(r, p) * exp6(twist) for twists (N, 6), skipping parts that are zero everywhere."""
    rot_part = twist[:, 3:]
    if not rot_part.any():  # a pure translation: exp6 = (I, v)
        return r, p + np.einsum("ijn,nj->in", r, twist[:, :3])
    nonzero = np.flatnonzero(np.any(twist != 0.0, axis=0))
    if len(nonzero) == 1:  # a rotation about one coordinate axis of the frame
        axis = np.zeros(3)
        axis[nonzero[0] - 3] = 1.0
        return _rotate_about_axis(r, axis, rot_part[:, nonzero[0] - 3]), p
    rot, trans = exp6_batch(twist)
    return _compose(r, p, rot, trans)


def _broadcast(q: np.ndarray, x: np.ndarray | None, n_joints: int, n_params: int | None):
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[1] != n_joints:
        raise InputError(f"joint values have {q.shape[1]} columns, the robot has {n_joints} joints")
    if x is None:
        return q, None, q.shape[0]
    x = np.atleast_2d(np.asarray(x, dtype=float))
    if x.shape[1] != n_params:
        raise InputError(f"error vectors have {x.shape[1]} columns, the error model has {n_params}")
    n = max(q.shape[0], x.shape[0])
    for name, arr in (("joint values", q), ("error vectors", x)):
        if arr.shape[0] not in (1, n):
            raise InputError(f"{name}: {arr.shape[0]} rows do not broadcast against {n}")
    return q, x, n


def tcp_poses(robot: RobotModel, q: np.ndarray, x: np.ndarray | None = None,
              error_model: ErrorModel | None = None) -> TcpPoses:
    """TCP poses of the nominal robot (x None) or of as-built robots, batched.

    Parameters
    ----------
    robot : RobotModel
    q : array-like of shape (N, n_joints) or (n_joints,)
        Joint values [rad, m].
    x : array-like of shape (N, n_params) or (n_params,), optional
        Error parameter vectors (see :class:`~tcr_accuracy.errors.ErrorModel`).
        q and x broadcast against each other along axis 0.
    error_model : ErrorModel, optional
        Layout of x; built from the robot when omitted.

    Returns
    -------
    TcpPoses with position (N, 3) and rotation (N, 3, 3).
    """
    if x is not None and error_model is None:
        error_model = ErrorModel(robot)
    q, x, n = _broadcast(q, x, robot.n_joints, error_model.size if error_model else None)
    parts = error_model.split(x) if x is not None else None
    axes = robot.motion_axes
    kinds = robot.joint_kinds
    r = np.repeat(np.eye(3)[:, :, None], n, axis=2)
    p = np.zeros((3, n))
    for j, placement in enumerate(robot.joint_placements):
        r, p = _compose(r, p, placement.rotation, placement.translation)
        value = np.broadcast_to(q[:, j], (n,))
        if parts is not None:
            twist = np.broadcast_to(parts.placement[:, j, :], (n, 6))
            if twist.any():
                r, p = _apply_twist(r, p, np.ascontiguousarray(twist))
            value = value + np.broadcast_to(parts.drive[:, j], (n,))
        if kinds[j] == REVOLUTE:
            r = _rotate_about_axis(r, axes[j][3:], value)
        else:
            p = p + np.einsum("ijn,j->in", r, axes[j][:3]) * value
    tool = robot.tool_placement
    r, p = _compose(r, p, tool.rotation, tool.translation)
    if parts is not None:
        tool_twist = np.broadcast_to(parts.tool, (n, 6))
        if tool_twist.any():
            r, p = _apply_twist(r, p, np.ascontiguousarray(tool_twist))
        base_twist = np.broadcast_to(parts.base, (n, 6))
        if base_twist.any():
            rb, pb = exp6_batch(np.ascontiguousarray(base_twist))
            r, p = np.einsum("ijn,jkn->ikn", rb, r), pb + np.einsum("ijn,jn->in", rb, p)
    return TcpPoses(position=np.ascontiguousarray(p.T), rotation=np.ascontiguousarray(r.transpose(2, 0, 1)))


def tcp_poses_pinocchio(robot: RobotModel, q: np.ndarray, x: np.ndarray | None = None,
                        error_model: ErrorModel | None = None) -> TcpPoses:
    """The plain way: one perturbed Pinocchio model and one forward kinematics per sample.

    Same inputs and outputs as :func:`tcp_poses`. Slow; the reference for tests and
    benchmarks.
    """
    if x is not None and error_model is None:
        error_model = ErrorModel(robot)
    q, x, n = _broadcast(q, x, robot.n_joints, error_model.size if error_model else None)
    position = np.empty((n, 3))
    rotation = np.empty((n, 3, 3))
    frame_id = robot.tool_frame_id
    nominal_data = robot.model.createData()
    for i in range(n):
        qi = q[i if q.shape[0] > 1 else 0]
        if x is None:
            model, data = robot.model, nominal_data
        else:
            model = error_model.perturbed_robot(x[i if x.shape[0] > 1 else 0]).model
            data = model.createData()
        pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(qi))
        position[i] = data.oMf[frame_id].translation
        rotation[i] = data.oMf[frame_id].rotation
    return TcpPoses(position=position, rotation=rotation)


# ---------------------------------------------------------------------------------------
# Pose error metrics
# ---------------------------------------------------------------------------------------
def euler_zyx(rotation: np.ndarray) -> np.ndarray:
    """ZYX Euler angles (about z, then y, then x): R = Rz(a) Ry(b) Rx(c).

    rotation : (N, 3, 3) -> (N, 3) columns (a, b, c) [rad].
    """
    rotation = np.asarray(rotation)
    a = np.arctan2(rotation[:, 1, 0], rotation[:, 0, 0])
    b = np.arctan2(-rotation[:, 2, 0], np.hypot(rotation[:, 2, 1], rotation[:, 2, 2]))
    c = np.arctan2(rotation[:, 2, 1], rotation[:, 2, 2])
    return np.stack([a, b, c], axis=1)


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def pose_error(nominal: TcpPoses, actual: TcpPoses) -> PoseError:
    """Actual minus nominal; the two broadcast along axis 0."""
    dp = actual.position - nominal.position
    relative = np.einsum("nij,nkj->nik", actual.rotation, np.broadcast_to(nominal.rotation, actual.rotation.shape))
    rotvec = Rotation.from_matrix(relative).as_rotvec()
    return PoseError(
        position=dp,
        position_norm=np.linalg.norm(dp, axis=1),
        euler_zyx=_wrap(euler_zyx(actual.rotation) - euler_zyx(nominal.rotation)),
        rotation_vector=rotvec,
        rotation_angle=np.linalg.norm(rotvec, axis=1),
    )


# ---------------------------------------------------------------------------------------
# First-order sensitivity of the TCP to the error parameters
# ---------------------------------------------------------------------------------------
def error_jacobian(robot: RobotModel, q: np.ndarray, error_model: ErrorModel | None = None) -> np.ndarray:
    """d(TCP pose)/dx at x = 0, shape (6, n_params).

    Rows are the TCP's linear displacement (base-frame axes, at the TCP point) then its
    rotation vector (base frame), as in Pinocchio's LOCAL_WORLD_ALIGNED. Placement
    columns come from Pinocchio's frame kinematic regressor, drive columns from the
    frame Jacobian; base and tool columns are adjoint maps.
    """
    error_model = error_model or ErrorModel(robot)
    q = robot.check_joint_values(np.asarray(q, dtype=float), source="q")
    model, data = robot.model, robot.model.createData()
    frame_id = robot.tool_frame_id
    qp = robot.to_pinocchio_q(q)
    pin.computeJointJacobians(model, data, qp)
    pin.updateFramePlacements(model, data)
    oMtool = data.oMf[frame_id]
    jac = np.zeros((6, error_model.size))
    # regressor of the TCP w.r.t. placement twists, in the LOCAL TCP frame
    regressor_local = pin.computeFrameKinematicRegressor(model, data, frame_id, pin.LOCAL)
    to_aligned = np.zeros((6, 6))
    to_aligned[:3, :3] = oMtool.rotation
    to_aligned[3:, 3:] = oMtool.rotation
    jac[:, error_model.placement_slice] = to_aligned @ regressor_local
    frame_jac = pin.getFrameJacobian(model, data, frame_id, pin.LOCAL_WORLD_ALIGNED)
    for j in range(1, model.njoints):
        jac[:, error_model.drive_slice.start + j - 1] = frame_jac[:, model.joints[j].idx_v]
    # base twist (left, base frame): TCP point moves by v + w x p, rotates by w
    p = oMtool.translation
    base = np.zeros((6, 6))
    base[:3, :3] = np.eye(3)
    base[:3, 3:] = -pin.skew(p)
    base[3:, 3:] = np.eye(3)
    jac[:, error_model.base_slice] = base
    # tool twist (right, TCP frame): linear and angular parts rotate into base axes
    jac[:, error_model.tool_slice] = to_aligned
    return jac
