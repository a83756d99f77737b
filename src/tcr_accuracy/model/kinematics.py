"""Batched forward kinematics of nominal and perturbed robots, and TCP pose errors.

The engine works on whole batches in numpy, not one Pinocchio call per sample
(:mod:`tcr_accuracy.model.chain`, re-exported here as :func:`tcp_chain_soa`).
``tcp_poses_pinocchio`` is the plain per-sample Pinocchio path, kept as the reference the
engine is tested and benchmarked against.

Shapes: N samples on axis 0 of every input and output. Joint values q are
(N, n_joints) or (n_joints,) [rad, m]; error vectors x are (N, n_params) or
(n_params,) (see :mod:`tcr_accuracy.model.errors`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from .chain import tcp_chain_soa
from .errors import ErrorModel
from ..exceptions import InputError
from .robot import RobotModel


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


def _check_finite(values: np.ndarray, what: str) -> None:
    """InputError naming the first row and column of ``values`` (N, k) that is NaN or infinite
    (a pose of NaN joints has no TCP: it would come back as NaN, unsaid)."""
    bad = ~np.isfinite(values)
    if bad.any():
        row, column = np.argwhere(bad)[0]
        raise InputError(f"{what}: row {row}, column {column} is {values[row, column]}, not a finite number")


def _broadcast(q: np.ndarray, x: np.ndarray | None, n_joints: int, n_params: int | None):
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.shape[1] != n_joints:
        raise InputError(f"joint values have {q.shape[1]} columns, the robot has {n_joints} joints")
    _check_finite(q, "joint values")
    if x is None:
        return q, None, q.shape[0]
    x = np.atleast_2d(np.asarray(x, dtype=float))
    if x.shape[1] != n_params:
        raise InputError(f"error vectors have {x.shape[1]} columns, the error model has {n_params}")
    _check_finite(x, "error vectors")
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
        Error parameter vectors (see :class:`~tcr_accuracy.model.errors.ErrorModel`).
        q and x broadcast against each other along axis 0.
    error_model : ErrorModel, optional
        Layout of x; built from the robot when omitted.

    Returns
    -------
    TcpPoses with position (N, 3) and rotation (N, 3, 3).

    Examples
    --------
    >>> import numpy as np, tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> pose = tcr.tcp_poses(robot, np.radians([0, -90, 90, 0, 90, 0]))
    >>> pose.position.shape
    (1, 3)
    """
    if x is not None and error_model is None:
        error_model = ErrorModel(robot)
    q, x, n = _broadcast(q, x, robot.n_joints, error_model.size if error_model else None)
    x_t = np.ascontiguousarray(x.T) if x is not None else None
    rot, pos = tcp_chain_soa(robot, np.ascontiguousarray(q.T), x_t, error_model)
    return TcpPoses(position=np.ascontiguousarray(pos.T), rotation=np.ascontiguousarray(rot.T).reshape(n, 3, 3))


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

    rotation : (N, 3, 3) -> (N, 3) columns (a, b, c) [rad]. The one home of the package's
    Euler convention (:func:`euler_zyx_entries` is the same on structure-of-arrays rows,
    :func:`rotation_from_euler_zyx` its inverse).
    """
    rotation = np.asarray(rotation)
    return euler_zyx_entries(rotation[:, 0, 0], rotation[:, 1, 0], rotation[:, 2, 0], rotation[:, 2, 1],
                             rotation[:, 2, 2]).T


def euler_zyx_entries(r00, r10, r20, r21, r22, out: np.ndarray | None = None) -> np.ndarray:
    """(3, N) ZYX Euler angles from five entries of the rotations (each (N,)), into ``out`` if given."""
    out = np.empty((3, np.shape(r00)[0])) if out is None else out
    # cos(beta) = sqrt(r21^2 + r22^2), squared in out[1] with out[2] as scratch: the entries of a
    # rotation are at most 1, so np.hypot's guard against overflow is not needed (it costs 4x)
    np.multiply(r21, r21, out=out[1])
    np.multiply(r22, r22, out=out[2])
    out[1] += out[2]
    np.sqrt(out[1], out=out[1])
    np.arctan2(r20, out[1], out=out[1])
    np.negative(out[1], out=out[1])  # atan2(-y, x) = -atan2(y, x)
    np.arctan2(r10, r00, out=out[0])
    np.arctan2(r21, r22, out=out[2])
    return out


def rotation_from_euler_zyx(euler: np.ndarray) -> np.ndarray:
    """ZYX Euler angles (N, 3) (a, b, c) [rad] -> rotations (N, 3, 3), R = Rz(a) Ry(b) Rx(c)."""
    return Rotation.from_euler("ZYX", np.atleast_2d(euler)).as_matrix()


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def pose_error(nominal: TcpPoses, actual: TcpPoses) -> PoseError:
    """Actual minus nominal; the two broadcast along axis 0.

    Parameters
    ----------
    nominal : TcpPoses
        Positions (N, 3) [m] and rotations (N, 3, 3), or one of each.
    actual : TcpPoses
        The same shapes.

    Returns
    -------
    PoseError
        Position error (N, 3) [m] and rotation error (N, 3) [rad] in the base frame.

    Examples
    --------
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> q = np.zeros((1, 6))
    >>> x = tcr.ErrorModel(robot).zeros()
    >>> x[0] = 1e-4  # shoulder_pan_joint.dx: 0.1 mm
    >>> error = tcr.pose_error(tcr.tcp_poses(robot, q), tcr.tcp_poses(robot, q, x))
    >>> round(float(error.position_norm[0]) * 1e3, 3)  # [mm]
    0.1
    """
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
