"""Batched forward kinematics of nominal and perturbed robots, and TCP pose errors.

The engine works on whole batches in numpy, not one Pinocchio call per sample:
the running rotation and translation are kept entry by entry ("structure of
arrays"), each entry a Python float when it is the same for every sample or a
contiguous length-N vector when it is not. At a fixed pose the nominal transforms
fold into constants and only the error factors cost vector operations, and exact
zeros and ones in a factor are skipped (see ``_chain``). Pinocchio computes one pose
at a time; Monte Carlo needs millions, which is why this part is written by hand. ``tcp_poses_pinocchio`` is the plain per-sample Pinocchio path,
kept as the reference the engine is tested and benchmarked against.

Shapes: N samples on axis 0 of every input and output. Joint values q are
(N, n_joints) or (n_joints,) [rad, m]; error vectors x are (N, n_params) or
(n_params,) (see :mod:`tcr_accuracy.model.errors`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from .errors import ErrorModel
from ..exceptions import InputError
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


# ---------------------------------------------------------------------------------------
# The chain engine: 3x3 rotation and 3-vector as lists of scalars or (N,) arrays
# ---------------------------------------------------------------------------------------
# Every entry of the running rotation R (9, row-major) and translation p (3) is either a
# Python float (the same for every sample) or a contiguous (N,) array. A factor whose
# entries are exactly 0 or 1 costs nothing (skipped or passed through), constants are
# multiplied once, and only entries that really vary per sample cost vector
# operations. So at a fixed pose the nominal joint transforms fold into constants, a
# pure translation error costs 3 multiply-adds per nonzero component, a drive error
# about a coordinate axis only touches two columns, and no (3, 3, N) einsum is needed.
# The result is the exact product of exponentials (no linearisation).
def _mul(a, b):
    if isinstance(a, float):
        if a == 0.0:
            return 0.0
        if a == 1.0:
            return b
        if a == -1.0:
            return -b
    if isinstance(b, float):
        if b == 0.0:
            return 0.0
        if b == 1.0:
            return a
        if b == -1.0:
            return -a
    return a * b


def _add(a, b):
    if isinstance(a, float) and a == 0.0:
        return b
    if isinstance(b, float) and b == 0.0:
        return a
    return a + b


def _dot3_owned(r0, r1, r2, c0, c1, c2):
    """(r0 c0 + r1 c1 + r2 c2, owned): zero/one factors skipped, arrays summed in place
    when the sum is a fresh array (owned) rather than one of the inputs."""
    acc, owned = 0.0, False
    for a, b in ((r0, c0), (r1, c1), (r2, c2)):
        term = _mul(a, b)
        if isinstance(term, float) and term == 0.0:
            continue
        if isinstance(acc, float):
            if isinstance(term, float):
                acc = acc + term
            elif acc == 0.0:
                acc, owned = term, (term is not a and term is not b)
            else:
                acc, owned = term + acc, True
        elif owned:
            acc += term
        else:
            acc, owned = acc + term, True
    return acc, owned


def _dot3(r0, r1, r2, c0, c1, c2):
    return _dot3_owned(r0, r1, r2, c0, c1, c2)[0]


def _add_to(base, addend_owned):
    """base + addend, in place in the addend when it is a fresh array."""
    addend, owned = addend_owned
    if owned and not isinstance(base, float):
        addend += base
        return addend
    return _add(base, addend)


def _chain_compose(r, p, c, t):
    """(r, p) * (c, t): r, c lists of 9 entries (row-major), p, t lists of 3."""
    new_p = p
    if not all(isinstance(v, float) and v == 0.0 for v in t):
        new_p = [_add_to(p[i], _dot3_owned(r[3 * i], r[3 * i + 1], r[3 * i + 2], t[0], t[1], t[2]))
                 for i in range(3)]
    if all(isinstance(v, float) for v in c) and c == [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]:
        return r, new_p
    new_r = [_dot3(r[3 * i], r[3 * i + 1], r[3 * i + 2], c[k], c[3 + k], c[6 + k])
             for i in range(3) for k in range(3)]
    return new_r, new_p


def _cos_sin(angle):
    if isinstance(angle, float):
        return float(np.cos(angle)), float(np.sin(angle))
    return np.cos(angle), np.sin(angle)


def _axis_rotation(axis: np.ndarray, angle):
    """Rot(axis, angle) as 9 entries; exact zeros/ones kept for a coordinate axis."""
    c, s = _cos_sin(angle)
    k = int(np.argmax(np.abs(axis)))
    if abs(abs(axis[k]) - 1.0) < 1e-15:
        if axis[k] < 0:
            s = -s
        m = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        i, j = (k + 1) % 3, (k + 2) % 3
        m[3 * i + i], m[3 * j + j] = c, c
        m[3 * i + j], m[3 * j + i] = -s if isinstance(s, float) else np.negative(s), s
        return m
    # Rodrigues for a general unit axis: I + sin [a] + (1 - cos) [a]^2
    hat = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    hat_sq = hat @ hat
    one_minus_c = 1.0 - c
    return [_add(float(np.eye(3)[i, k]), _add(_mul(float(hat[i, k]), s), _mul(float(hat_sq[i, k]), one_minus_c)))
            for i in range(3) for k in range(3)]


def _se3_entries(m: pin.SE3):
    return [float(v) for v in m.rotation.reshape(-1)], [float(v) for v in m.translation]


def _twist_factor(twist: list):
    """exp6 of a twist given as 6 entries (floats or (N,) arrays) -> (9 entries, 3 entries)."""
    if all(isinstance(v, float) for v in twist):
        return _se3_entries(pin.exp6(np.array(twist)))
    if all(isinstance(v, float) and v == 0.0 for v in twist[3:]):  # pure translation
        return [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], list(twist[:3])
    rot_nonzero = [k for k in range(3) if not (isinstance(twist[3 + k], float) and twist[3 + k] == 0.0)]
    lin_zero = all(isinstance(v, float) and v == 0.0 for v in twist[:3])
    if lin_zero and len(rot_nonzero) == 1:  # rotation about one coordinate axis
        axis = np.zeros(3)
        axis[rot_nonzero[0]] = 1.0
        return _axis_rotation(axis, twist[3 + rot_nonzero[0]]), [0.0, 0.0, 0.0]
    return _exp6_entries(twist)


def _exp6_entries(twist: list):
    """Rodrigues on entries (floats or (N,) arrays), as ``pin.exp6``; zero entries cost nothing.

    R = I + a [w] + b [w]^2 and V = I + b [w] + c [w]^2 (translation V v), written out
    with [w]^2 = w w^T - |w|^2 I, and the Taylor series of a, b, c below 1e-4 rad.
    """
    v, w = twist[:3], twist[3:]
    theta_sq = _add(_add(_mul(w[0], w[0]), _mul(w[1], w[1])), _mul(w[2], w[2]))
    theta_sq = np.asarray(theta_sq, dtype=float)
    theta = np.sqrt(theta_sq)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    sin_t, cos_t = np.sin(safe), np.cos(safe)
    a = np.where(small, 1.0 - theta_sq / 6.0, sin_t / safe)
    b = np.where(small, 0.5 - theta_sq / 24.0, (1.0 - cos_t) / (safe * safe))
    c = np.where(small, 1.0 / 6.0 - theta_sq / 120.0, (safe - sin_t) / (safe * safe * safe))

    def matrix(f1, f2):
        # I + f1 [w] + f2 (w w^T - theta^2 I)
        out = []
        for i in range(3):
            for k in range(3):
                entry = _mul(f2, _mul(w[i], w[k]))
                if i == k:
                    entry = _add(entry, 1.0 - f2 * theta_sq)
                else:
                    # [w]_ik = -eps_ikl w_l
                    l_ = 3 - i - k
                    sign = 1.0 if (i, k) in ((2, 1), (0, 2), (1, 0)) else -1.0
                    entry = _add(entry, _mul(f1, _mul(sign, w[l_])))
                out.append(entry)
        return out

    rot = matrix(a, b)
    if all(isinstance(e, float) and e == 0.0 for e in v):
        return rot, [0.0, 0.0, 0.0]
    left = matrix(b, c)
    trans = [_dot3(left[3 * i], left[3 * i + 1], left[3 * i + 2], v[0], v[1], v[2]) for i in range(3)]
    return rot, trans


def _column(values, i: int):
    """Row i of a (p, M) array as a float (M == 1), 0.0 when it is all zero, else a contiguous array.

    ``values`` may also be a list of rows, each a float or an (M,) array.
    """
    row = values[i]
    if isinstance(row, float):
        return row
    if row.shape[0] == 1:
        return float(row[0])
    if not row.any():
        return 0.0
    return row


def _chain(robot: RobotModel, q_cols: np.ndarray, x_cols: np.ndarray | None, error_model: ErrorModel | None):
    """TCP (R entries, p entries) from joint values (n, Nq) and error vectors (p, Nx), axis 1 samples."""
    axes = robot.motion_axes
    kinds = robot.joint_kinds
    identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    r, p = identity, [0.0, 0.0, 0.0]
    em = error_model
    if x_cols is not None:
        base = [_column(x_cols, i) for i in range(em.base_slice.start, em.base_slice.stop)]
        if not all(isinstance(v, float) and v == 0.0 for v in base):
            r, p = _twist_factor(base)
    for j, placement in enumerate(robot.joint_placements):
        r, p = _chain_compose(r, p, *_se3_entries(placement))
        value = _column(q_cols, j)
        if x_cols is not None:
            start = em.placement_slice.start + 6 * j
            twist = [_column(x_cols, i) for i in range(start, start + 6)]
            if not all(isinstance(v, float) and v == 0.0 for v in twist):
                r, p = _chain_compose(r, p, *_twist_factor(twist))
            drive = _column(x_cols, em.drive_slice.start + j)
            if isinstance(value, float) and not isinstance(drive, float):
                # Rot(a, q + dq) = Rot(a, dq) Rot(a, q): the constant part stays a constant
                r, p = _joint_motion(r, p, kinds[j], axes[j], drive)
            else:
                value = _add(value, drive)
        r, p = _joint_motion(r, p, kinds[j], axes[j], value)
    r, p = _chain_compose(r, p, *_se3_entries(robot.tool_placement))
    if x_cols is not None:
        tool = [_column(x_cols, i) for i in range(em.tool_slice.start, em.tool_slice.stop)]
        if not all(isinstance(v, float) and v == 0.0 for v in tool):
            r, p = _chain_compose(r, p, *_twist_factor(tool))
    return r, p


def _joint_motion(r, p, kind, axis6, value):
    if isinstance(value, float) and value == 0.0:
        return r, p
    if kind == REVOLUTE:
        return _chain_compose(r, p, _axis_rotation(axis6[3:], value), [0.0, 0.0, 0.0])
    identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    return _chain_compose(r, p, identity, [_mul(float(a), value) for a in axis6[:3]])


def tcp_chain_soa(robot: RobotModel, q: np.ndarray, x_t: np.ndarray | None = None,
                  error_model: ErrorModel | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The engine in structure-of-arrays form, for callers that loop over chunks.

    Parameters
    ----------
    q : array-like of shape (n_joints,) or (n_joints, N)
        Joint values [rad, m], samples on axis 1.
    x_t : array-like of shape (n_params, N) or (n_params, 1), optional
        Error vectors, transposed (samples on axis 1; contiguous rows are fastest).
        May also be a list of n_params rows, each a float (same for every sample,
        0.0 for an unused parameter) or an (N,) array.

    Returns
    -------
    rotation : (9, N) row-major entries of the TCP rotations
    position : (3, N) TCP positions [m]
    """
    q_cols = np.asarray(q, dtype=float)
    if q_cols.ndim == 1:
        q_cols = q_cols[:, None]
    n = q_cols.shape[1]
    if x_t is not None:
        if not isinstance(x_t, list):
            x_t = np.asarray(x_t, dtype=float)
            n = max(n, x_t.shape[1])
        else:
            n = max([n] + [np.size(v) for v in x_t])
        error_model = error_model or ErrorModel(robot)
    r, p = _chain(robot, q_cols, x_t, error_model)
    rot = np.empty((9, n))
    pos = np.empty((3, n))
    for i, v in enumerate(r):
        rot[i] = v
    for i, v in enumerate(p):
        pos[i] = v
    return rot, pos


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
    np.arctan2(r10, r00, out=out[0])
    np.arctan2(-r20, np.hypot(r21, r22), out=out[1])
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
