"""The one home of the TCP's Jacobians: in the joints (:func:`tcp_jacobian`, what IK and
compensation step with) and in the error parameters (the error Jacobian).

The error Jacobian comes from Pinocchio's frame kinematic regressor (the placements; a joint's own
column is its placement's block along its motion axis), chained with the derivative of ``exp6`` at
the current error vector;
batched over poses (:func:`error_jacobians`), one pose at x = 0 (:func:`error_jacobian`).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .errors import ErrorModel
from .robot import RobotModel


def chain_columns(model: pin.Model) -> list[int]:
    """Pinocchio's velocity index of each joint of a chain model (one DoF each), in joint order."""
    return [model.joints[j].idx_v for j in range(1, model.njoints)]


def tcp_jacobian(robot: RobotModel, q: np.ndarray, data: pin.Data | None = None,
                 frame_id: int | None = None) -> tuple[pin.SE3, np.ndarray]:
    """The TCP's pose and its Jacobian in the joints at one configuration.

    Parameters
    ----------
    robot : RobotModel
    q : ndarray of shape (n_joints,)
        Joint values [rad, m].
    data : pinocchio.Data, optional
        Work data of ``robot.model`` to reuse across calls (made when not given).
    frame_id : int, optional
        Another frame of ``robot.model`` (default the TCP).

    Returns
    -------
    oMf : pinocchio.SE3
        The frame's pose in the base frame.
    jacobian : ndarray of shape (6, n_joints)
        Its spatial velocity per joint velocity, linear rows first, axes of the base frame
        (``LOCAL_WORLD_ALIGNED``) [m/rad, rad/rad; m/m for prismatic joints].
    """
    model = robot.model
    data = model.createData() if data is None else data
    frame = robot.tool_frame_id if frame_id is None else frame_id
    pin.computeJointJacobians(model, data, robot.to_pinocchio_q(np.asarray(q, dtype=float)))
    pose = pin.updateFramePlacement(model, data, frame)
    return pose, pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)[:, chain_columns(model)]


# ---------------------------------------------------------------------------------------
# First-order sensitivity of the TCP to the error parameters
# ---------------------------------------------------------------------------------------
def error_jacobian(robot: RobotModel, q: np.ndarray, error_model: ErrorModel | None = None) -> np.ndarray:
    """d(TCP pose)/dx at x = 0 for one pose q (n_joints,), shape (6, n_params).

    Rows are the TCP's linear displacement (base-frame axes, at the TCP point) then its
    rotation vector (base frame), as in Pinocchio's LOCAL_WORLD_ALIGNED: one row of
    :func:`error_jacobians`.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    q : array-like of shape (n_joints,)
        Joint values [rad, m].
    error_model : ErrorModel, optional
        Layout of the error parameters; built from the robot when omitted.

    Returns
    -------
    ndarray of shape (6, n_params)
        d(TCP displacement [m], rotation vector [rad]) / dx.

    Examples
    --------
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> tcr.error_jacobian(robot, robot.working_pose).shape  # (6, n_params): twist per error parameter
    (6, 54)
    """
    q = robot.check_joint_values(np.asarray(q, dtype=float), source="q")
    return error_jacobians(robot, q[None], None, error_model)[1][0]


#: skew(p)_ij = -eps_ijk p_k
_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[0, 1, 2] = _LEVI_CIVITA[1, 2, 0] = _LEVI_CIVITA[2, 0, 1] = 1.0
_LEVI_CIVITA[0, 2, 1] = _LEVI_CIVITA[2, 1, 0] = _LEVI_CIVITA[1, 0, 2] = -1.0


def error_jacobians(robot: RobotModel, q, x=None, error_model: ErrorModel | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """TCP Jacobians with respect to joint offsets and error parameters, per row (batched).

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    q : (N, n_joints) actual joint values [SI] (commanded plus joint-side offsets)
    x : (n_error_params,) or (N, n_error_params), optional
        Error vector(s) the Jacobians are taken at: one for every row, or one per row
        (effects that depend on the pose, such as lateral compliance, give each row its own).
    error_model : ErrorModel, optional
        Layout of x; built from the robot when omitted.

    Returns
    -------
    jq : (N, 6, n_joints) d(TCP)/d(q), jx : (N, 6, n_error_params) d(TCP)/d(x).
    Rows: TCP displacement in base-frame axes, then rotation vector, as Pinocchio's
    LOCAL_WORLD_ALIGNED. From Pinocchio's frame kinematic regressor of the perturbed model
    (each joint's column is its placement's block along the joint's motion axis), chained with
    the derivative of ``exp6`` (``pin.Jexp6``) at x.

    Examples
    --------
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> poses, jacobians = tcr.error_jacobians(robot, np.zeros((4, 6)))
    >>> jacobians.shape
    (4, 6, 54)
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    em = error_model or ErrorModel(robot)
    n, nj, p = q.shape[0], robot.n_joints, em.size
    xs = None if x is None else np.atleast_2d(np.asarray(x, dtype=float))
    per_row = xs is not None and xs.shape[0] > 1 and bool(np.any(xs != xs[0]))
    if not per_row:
        x_mean = np.zeros(em.size) if xs is None else xs.mean(axis=0)
        work = em.perturbed_robot(x_mean) if x_mean.any() else robot
        rows = [(range(n), work.model, _exp6_chains(robot, em, x_mean))]
    else:
        # one model copy, its placements rewritten per row
        model = pin.Model(robot.model)
        rows = [([i], model, _exp6_chains(robot, em, xs[i]), xs[i]) for i in range(n)]
    jx = np.empty((n, 6, p))
    frame_id = robot.tool_frame_id
    plain_q = robot.model.nq == nj
    regressors = np.empty((n, 6, nj, 6))  # per pose and joint placement: base-frame axes, at the TCP
    rotations = np.empty((n, 3, 3))
    positions = np.empty((n, 3))
    chains = np.empty((n, nj, 6, 6)) if per_row else None
    base_chains = np.empty((n, 6, 6)) if per_row else None
    tool_chains = np.empty((n, 6, 6)) if per_row else None
    data = None
    for block in rows:
        indices, model, (chain, base_chain, tool_chain) = block[:3]
        if per_row:
            placements, tool = em.perturbed_placements(block[3])
            for j, placement in enumerate(placements):
                model.jointPlacements[j + 1] = placement
            frame = model.frames[frame_id]
            frame.placement = tool
            model.frames[frame_id] = frame
        if data is None or not per_row:
            data = model.createData()
        flat = regressors.reshape(n, 6, 6 * nj)
        for i in indices:  # the per-pose Pinocchio calls, nothing else: a third of the time went to the rest
            pin.forwardKinematics(model, data, q[i] if plain_q else robot.to_pinocchio_q(q[i]))
            pose = pin.updateFramePlacement(model, data, frame_id)
            rotations[i] = pose.rotation
            positions[i] = pose.translation
            flat[i] = pin.computeFrameKinematicRegressor(model, data, frame_id, pin.LOCAL_WORLD_ALIGNED)
        if per_row:
            chains[indices], base_chains[indices], tool_chains[indices] = chain, base_chain, tool_chain
    # the joint's own velocity moves the TCP as a twist along its motion axis at its placement (the joint's
    # motion commutes with that axis): the frame Jacobian's column, without asking for it pose by pose
    jq = np.einsum("nrjk,jk->nrj", regressors, robot.motion_axes)
    # then chain each placement block with its exp6 derivative
    placement = jx[:, :, em.placement_slice].reshape(n, 6, nj, 6)
    if per_row:
        placement[:] = np.einsum("nijk,njkl->nijl", regressors, chains)
    else:
        for j in range(nj):
            placement[:, :, j] = regressors[:, :, j] @ chain[j]
    jx[:, :, em.drive_slice] = jq
    base = np.zeros((n, 6, 6))
    base[:, :3, :3] = np.eye(3)
    base[:, :3, 3:] = -np.einsum("nk,ikj->nij", positions, _LEVI_CIVITA)  # -skew(p)
    base[:, 3:, 3:] = np.eye(3)
    jx[:, :, em.base_slice] = base @ (base_chains if per_row else base_chain)
    tool = np.zeros((n, 6, 6))
    tool[:, :3, :3] = rotations
    tool[:, 3:, 3:] = rotations
    jx[:, :, em.tool_slice] = tool @ (tool_chains if per_row else tool_chain)
    return jq, jx


def _exp6_chains(robot: RobotModel, em: ErrorModel, x: np.ndarray):
    """Right Jacobians of exp6 at the twists of x (exp6(xi + d) = exp6(xi) exp6(Jr d)):
    per joint (nj, 6, 6) with the drive offset folded in, the base's left Jacobian and the tool's."""
    parts = em.split(x)
    axes = robot.motion_axes
    chain = np.empty((robot.n_joints, 6, 6))
    for j in range(robot.n_joints):
        jr = pin.Jexp6(pin.Motion(parts.placement[j]))
        drive = pin.exp6(axes[j] * parts.drive[j]).inverse().action
        chain[j] = drive @ jr
    base_xi = pin.Motion(parts.base)
    base_chain = pin.exp6(base_xi).action @ pin.Jexp6(base_xi)  # left Jacobian = Ad(exp) Jr
    return chain, base_chain, pin.Jexp6(pin.Motion(parts.tool))
