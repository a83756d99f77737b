"""Joint compensation by cyclic search (the second seed's Section 3.3).

The commanded joints q_target put the nominal TCP on the target ``p* = FK(q_target)``.
The real robot lands near ``FK(q) + e(q)`` instead, with e predicted by a fitted
estimator (see :mod:`tcr_accuracy.prediction.methods`). The cyclic search repeats

1. predicted real position ``p = FK(q) + e_hat(q)``;
2. miss ``d = p* - p``; stop when ``|d| < threshold``;
3. move the nominal target by the miss and solve the inverse kinematics for
   ``FK(q) + d`` (Pinocchio Jacobians, :func:`~tcr_accuracy.analysis.sampling.inverse_kinematics`)
   from the current q, keeping the target orientation as well as the robot can.

All targets are iterated together (one batched predict and one batched IK per cycle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError
from ..model.kinematics import tcp_poses
from .composed import predict_with_context
from ..model.robot import RobotModel
from ..analysis.sampling import inverse_kinematics


@dataclass(frozen=True)
class CompensationResult:
    """Compensated commands for N targets.

    q : (N, n_joints) compensated joint values to command [rad, m]
    target : (N, 3) target TCP positions [m]
    predicted_miss : (N,) |target - (FK(q) + predicted error)| at the end [m]
    converged : (N,) predicted miss below the threshold with joints inside the limits
    iterations : (N,) cycles used
    """

    q: np.ndarray
    target: np.ndarray
    predicted_miss: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray


def compensate_joints(robot: RobotModel, predictor, q_target: np.ndarray, *, threshold: float = 1e-6,
                      max_iter: int = 20, orientation: str = "best_effort", context=None) -> CompensationResult:
    """Compensated joint commands for targets given as nominal joint values.

    Parameters
    ----------
    robot : RobotModel, the nominal robot
    predictor : fitted estimator with ``predict(Q (N, n_joints)) -> (N, 3)`` errors [m]
    q_target : (N, n_joints) joint values whose nominal TCP positions are the targets
    threshold : stop a target when the predicted miss is below this [m]
    max_iter : most cycles
    orientation : passed to the IK ("best_effort": position first; "exact" also holds
        the orientation, only for robots with a full-rank 6-DoF Jacobian)
    context : MeasurementContext of the targets, optional
        Their payload and the joints outside the TCP chain, for predictors that use them.
    """
    q_target = np.atleast_2d(np.asarray(q_target, dtype=float))
    if q_target.shape[1] != robot.n_joints or not np.all(np.isfinite(q_target)):
        raise InputError(f"compensation: targets must be finite joint values (N, {robot.n_joints}), "
                         f"got shape {q_target.shape}")
    pose = tcp_poses(robot, q_target)
    target, rotation = pose.position, pose.rotation
    q = q_target.copy()
    n = q.shape[0]
    active = np.ones(n, dtype=bool)
    iterations = np.zeros(n, dtype=int)
    ik_ok = np.ones(n, dtype=bool)
    miss = np.full(n, np.inf)
    for it in range(max_iter + 1):
        nominal = tcp_poses(robot, q).position
        d = target - (nominal + np.asarray(predict_with_context(predictor, q, context), dtype=float).reshape(n, 3))
        if not np.all(np.isfinite(d)):
            raise InputError("compensation: the predictor returned non-finite errors")
        miss = np.linalg.norm(d, axis=1)
        active &= miss >= threshold
        idx = np.flatnonzero(active)
        if idx.size == 0 or it == max_iter:
            break
        ik = inverse_kinematics(robot, nominal[idx] + d[idx], rotation[idx], q[idx],
                                tol_position=0.05 * threshold, orientation=orientation, max_iter=50)
        q[idx] = ik.q
        ik_ok[idx] = ik.success
        active[idx[~ik.success]] = False  # out of reach: stop, report
        iterations[idx] += 1
    converged = (miss < threshold) & ik_ok
    return CompensationResult(q=q, target=target, predicted_miss=miss, converged=converged,
                              iterations=iterations)
