"""Gravity on the robot: the one home of gravity torques and joint wrenches.

Model layer (imports :mod:`robot` and :mod:`context`). Gravity is computed on the
robot's *whole* kinematic tree (``RobotModel.full_model``), so the joints that do not
move the TCP still load the ones that do: a second arm, a head or a gripper hanging off
the torso changes the torque on the torso joints with its pose. Their values come from
``outside_q`` (the measurement's columns for those joints) or sit at neutral.

Signs: everything here is what gravity *exerts*, the opposite of what the drives must
apply to hold the arm (``pin.computeGeneralizedGravity``), so a positive compliance lets
a joint sag the way gravity pulls.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from .robot import RobotModel
from .urdf import find_frame


def gravity_model(robot: RobotModel, link_mass_factors=None, payload_kg: float = 0.0) -> pin.Model:
    """A copy of the robot's whole-tree Pinocchio model with scaled link masses and a point payload.

    Parameters
    ----------
    link_mass_factors : array-like of shape (n_joints,), optional
        Factor on the mass (and rotational inertia) of the body moved by each chain joint.
    payload_kg : float
        Point mass added at the TCP frame's origin [kg].
    """
    full = robot.full_model
    model = pin.Model(full)
    if link_mass_factors is not None:
        factors = np.asarray(link_mass_factors, dtype=float)
        if factors.shape != (robot.n_joints,) or np.any(factors < 0):
            raise InputError(f"link mass factors: need {robot.n_joints} values >= 0")
        for k, j in enumerate(robot.chain_joint_ids):
            inertia = model.inertias[j]
            model.inertias[j] = pin.Inertia(inertia.mass * factors[k], inertia.lever, inertia.inertia * factors[k])
    if payload_kg:
        frame = model.frames[_full_tool_frame_id(robot)]
        point = pin.Inertia(float(payload_kg), np.zeros(3), np.zeros((3, 3)))
        model.inertias[frame.parentJoint] = model.inertias[frame.parentJoint] + frame.placement.act(point)
    return model


def _full_tool_frame_id(robot: RobotModel) -> int:
    if robot.full_model is robot.model:
        return robot.tool_frame_id
    return find_frame(robot.full_model, robot.tool_frame)


def gravity_torque(robot: RobotModel, q: np.ndarray, payload_kg=0.0, link_mass_factors=None,
                   outside_q: np.ndarray | None = None) -> np.ndarray:
    """Torque (force) that gravity exerts on each chain joint, shape (N, n_joints) [Nm, N].

    Parameters
    ----------
    robot : RobotModel
        The robot (its full model's link masses and inertias).
    q : array-like of shape (N, n_joints)
        Chain joint values [rad, m].
    payload_kg : float or array-like of shape (N,)
        Point mass at the TCP frame, per row [kg].
    link_mass_factors : array-like of shape (n_joints,), optional
        See :func:`gravity_model`.
    outside_q : array-like of shape (N, n_outside), optional
        Values of the joints that do not move the TCP (``robot.outside_joint_names``).

    Returns
    -------
    ndarray of shape (N, n_joints)
        Torque [Nm] on revolute joints, force [N] on prismatic ones.

    Notes
    -----
    Gravity torque is linear in the payload mass, so two Pinocchio models (arm, arm +
    1 kg) serve every row.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> tau = tcr.gravity_torque(robot, robot.working_pose[None], payload_kg=2.0)  # [Nm]
    >>> tau.shape
    (1, 6)
    """
    return -_gravity(robot, q, payload_kg, link_mass_factors, outside_q, wrench=False)


def gravity_wrench(robot: RobotModel, q: np.ndarray, payload_kg=0.0, link_mass_factors=None,
                   outside_q: np.ndarray | None = None) -> np.ndarray:
    """Wrench gravity exerts on the part of the robot each chain joint carries, (N, n_joints, 6).

    Row layout ``(force [N], moment about the joint's origin [Nm])``, in the joint's own
    (moving) frame: minus Pinocchio's RNEA joint force ``data.f[j]`` at zero velocity and
    acceleration. Its projection on the joint's motion axis is :func:`gravity_torque`; the
    moment across the axis is what bends the joint's bearing (lateral compliance).
    Arguments as :func:`gravity_torque`.
    """
    return -_gravity(robot, q, payload_kg, link_mass_factors, outside_q, wrench=True)


#: The last few gravity batches: compliance and backlash, perturb and Jacobian, all ask
#: for the same rows during a fit. Keyed by the model's identity and the inputs' bytes.
_CACHE: dict = {}


def _digest(a) -> bytes | None:
    if a is None:
        return None
    a = np.ascontiguousarray(a, dtype=float)
    return hashlib.blake2b(a.tobytes() + str(a.shape).encode(), digest_size=16).digest()


def _gravity(robot, q, payload_kg, link_mass_factors, outside_q, *, wrench: bool) -> np.ndarray:
    q = np.atleast_2d(np.asarray(q, dtype=float))
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (q.shape[0],))
    factors = None if link_mass_factors is None else np.asarray(link_mass_factors, dtype=float)
    if outside_q is not None:
        outside_q = np.atleast_2d(np.asarray(outside_q, dtype=float))
        if outside_q.shape != (q.shape[0], len(robot.outside_joint_names)):
            raise InputError(f"outside joint values: shape {outside_q.shape}, expected "
                             f"({q.shape[0]}, {len(robot.outside_joint_names)})")
    key = (id(robot.model), wrench, _digest(q), _digest(payload), _digest(factors), _digest(outside_q))
    cached = _CACHE.get(key)
    if cached is not None and cached[0] is robot.model:
        return cached[1].copy()
    arm = gravity_model(robot, factors)
    with_unit = gravity_model(robot, factors, payload_kg=1.0)
    d_arm, d_unit = arm.createData(), with_unit.createData()
    chain = robot.chain_joint_ids
    idx_v = np.array([arm.joints[j].idx_v for j in chain])
    any_payload = bool(np.any(payload != 0))
    configurations = robot.full_configurations(q, outside_q)
    zero = np.zeros(arm.nv)
    out = np.empty((q.shape[0], len(chain), 6) if wrench else q.shape)
    for i, qi in enumerate(configurations):
        if wrench:
            pin.rnea(arm, d_arm, qi, zero, zero)
            value = np.array([d_arm.f[j].vector for j in chain])
            if any_payload:
                pin.rnea(with_unit, d_unit, qi, zero, zero)
                value = value + payload[i] * (np.array([d_unit.f[j].vector for j in chain]) - value)
        else:
            g_arm = pin.computeGeneralizedGravity(arm, d_arm, qi)
            value = g_arm
            if any_payload:
                value = g_arm + payload[i] * (pin.computeGeneralizedGravity(with_unit, d_unit, qi) - g_arm)
            value = value[idx_v]
        out[i] = value
    if len(_CACHE) >= 8:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = (robot.model, out.copy())
    return out
