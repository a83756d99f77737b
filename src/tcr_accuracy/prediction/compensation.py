"""Joint compensation by cyclic search (the second seed's Section 3.3), target by target.

The commanded joints q_target put the model's TCP on the target ``p* = FK(q_target)``
(for measured data: the robot whose TCP is the measured point, see
:meth:`tcr_accuracy.frames.registration.Registration.measured_frame_robot`). The real
robot lands near ``FK(q) + e(q)`` instead, with e predicted by a fitted estimator (see
:mod:`tcr_accuracy.prediction.methods`). The cyclic search repeats

1. predicted real position ``p = FK(q) + e_hat(q)``;
2. miss ``d = p* - p``; stop when ``|d| < threshold``;
3. one minimum-norm Gauss-Newton step from the current q on the position rows of
   Pinocchio's frame Jacobian: the TCP moves by d with the least joint motion. (The
   predictors model the position error only; holding the nominal orientation exactly would
   ask wrist motions of several times the error that the model cannot justify. The
   orientation changes by about the correction itself, the size of the robot's own
   orientation errors. ``orientation="best_effort"`` holds it anyway: exactly where the
   frame Jacobian has rank 6, else in the position task's null space.)

Minimum-norm steps from the target joints keep the correction at what the predicted error
asks, ``J^+ e`` to first order: an IK that wanders along its null space or to another
branch is not a correction. Each target ends with its own verdict, so a few targets near
a limit or a singularity never sink the others:

* ``outside limits``: the correction would take a joint beyond its URDF limit;
* ``singular``: a 1 mm miss would ask more than ``max_gain`` of joint motion (near a
  singularity the correction is not determined by the model but by the noise);
* ``no convergence``: the predicted miss is still above the threshold after
  ``max_iter`` cycles, or the correction grew beyond ``drift_factor`` x the first-order one.

All targets are iterated together (one batched predict per cycle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..model.jacobians import tcp_jacobian
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel
from .composed import predict_with_context

#: Reasons a target is left unsolved (:attr:`CompensationResult.reason`).
REASONS = ("outside limits", "singular", "no convergence")


@dataclass(frozen=True)
class CompensationResult:
    """Compensated commands for N targets.

    q : (N, n_joints) compensated joint values to command [rad, m] (for an unsolved
        target: the last iterate, inside the limits)
    target : (N, 3) target TCP positions [m]
    predicted_miss : (N,) |target - (FK(q) + predicted error)| at the end [m]
    converged : (N,) predicted miss below the threshold with joints inside the limits
    iterations : (N,) cycles used
    reason : (N,) "" for a solved target, else one of :data:`REASONS`
    detail : (N,) a sentence on why (empty for a solved target), units in it
    first_order : (N, n_joints) the first-order correction ``J^+ e`` at the target joints [rad, m]
    """

    q: np.ndarray
    target: np.ndarray
    predicted_miss: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    reason: np.ndarray | None = None
    detail: np.ndarray | None = None
    first_order: np.ndarray | None = None


def compensate_joints(robot: RobotModel, predictor, q_target: np.ndarray, *, threshold: float = 1e-6,
                      max_iter: int = 20, orientation: str = "position", context=None,
                      max_gain: float = float(np.radians(2.0) / 1e-3), drift_factor: float = 3.0) -> CompensationResult:
    """Compensated joint commands for targets given as joint values, each target on its own.

    Parameters
    ----------
    robot : RobotModel
        The robot whose TCP is the point that should reach the target (nominal, or with the
        measured point's fitted offset).
    predictor : fitted estimator with ``predict(Q (N, n_joints)) -> (N, 3)`` errors [m]
    q_target : (N, n_joints) joint values whose TCP positions (of ``robot``) are the targets
    threshold : stop a target when the predicted miss is below this [m]
    max_iter : most cycles
    orientation : "position" (default): position-only minimum-norm steps; "best_effort" also
        holds the target orientation as the robot allows (exactly where the TCP's frame
        Jacobian has rank 6, else in the position task's null space).
    context : MeasurementContext of the targets, optional
        Their payload and the joints outside the TCP chain, for predictors that use them.
    max_gain : largest joint motion a unit TCP miss may ask at the target [rad/m] (default 2 deg
        per mm); above it the target is ``singular``
    drift_factor : a correction larger than this times the first-order one (plus the
        threshold's worth) is not justified by the model: ``no convergence``

    Returns
    -------
    CompensationResult
        The compensated joint commands ``q`` (N, n_joints) [rad, m], ``converged`` (N,),
        ``predicted_miss`` (N,) [m] and each target's status.

    Examples
    --------
    A predictor of a constant 0.1 mm error along x (a fitted ``MeasuredErrorModel``'s
    ``estimator_`` in practice, with its ``frame_robot_``):

    >>> import numpy as np, tcr_accuracy as tcr
    >>> from sklearn.dummy import DummyRegressor
    >>> robot = tcr.load_robot("ur5")
    >>> q = np.radians([[0, -90, 90, 0, 90, 0]])
    >>> predictor = DummyRegressor(strategy="constant", constant=[1e-4, 0.0, 0.0]).fit(q, np.zeros((1, 3)))
    >>> result = tcr.compensate_joints(robot, predictor, q)
    >>> bool(result.converged[0]), bool(result.predicted_miss[0] < 1e-6)
    (True, True)
    """
    q_target = np.atleast_2d(np.asarray(q_target, dtype=float))
    if q_target.ndim != 2 or q_target.shape[1] != robot.n_joints or not np.all(np.isfinite(q_target)):
        raise InputError(f"compensation: targets must be finite joint values (N, {robot.n_joints}), "
                         f"got shape {q_target.shape}")
    if orientation == "exact":
        orientation = "best_effort"  # the rank decides; kept for callers of the earlier signature
    if orientation not in ("best_effort", "position"):
        raise InputError(f"compensation: orientation must be 'best_effort' or 'position', got {orientation!r}")
    pose = tcp_poses(robot, q_target)
    target, rotation = pose.position, pose.rotation
    n = q_target.shape[0]
    lo, hi = robot.joint_bounds(np.inf)
    q = q_target.copy()
    reason = np.array([""] * n, dtype=object)
    detail = np.array([""] * n, dtype=object)
    iterations = np.zeros(n, dtype=int)
    first_order = np.zeros_like(q)
    active = np.ones(n, dtype=bool)
    miss = np.full(n, np.inf)
    for it in range(max_iter + 1):
        nominal = tcp_poses(robot, q)
        d = target - (nominal.position + np.asarray(predict_with_context(predictor, q, context),
                                                    dtype=float).reshape(n, 3))
        if not np.all(np.isfinite(d)):
            raise InputError("compensation: the predictor returned non-finite errors")
        miss = np.linalg.norm(d, axis=1)
        active &= miss >= threshold
        idx = np.flatnonzero(active)
        if idx.size == 0 or it == max_iter:
            break
        for i in idx:
            jac = tcp_jacobian(robot, q[i])[1]
            turn = pin.log3(rotation[i] @ nominal.rotation[i].T) if orientation == "best_effort" else np.zeros(3)
            step, gain = _step(jac, d[i], turn, orientation == "best_effort")
            if it == 0:
                first_order[i] = step
                if gain > max_gain:
                    reason[i], active[i] = "singular", False
                    detail[i] = (f"a 1 mm miss here asks {np.degrees(gain) * 1e-3:.3g} deg of joint motion "
                                 f"(limit {np.degrees(max_gain) * 1e-3:.3g})")
                    continue
            new = q[i] + step
            outside = np.flatnonzero((new < lo) | (new > hi))
            if outside.size:
                j = int(outside[0])
                side, limit = ("upper", hi[j]) if new[j] > hi[j] else ("lower", lo[j])
                reason[i], active[i] = "outside limits", False
                detail[i] = (f"{robot.joint_names[j]} would go {_display(robot, j, abs(new[j] - limit))} beyond its "
                             f"{side} limit")
                continue
            q[i] = new
            iterations[i] += 1
            allowed = drift_factor * np.abs(first_order[i]) + 10.0 * threshold * max_gain
            if np.any(np.abs(q[i] - q_target[i]) > allowed):
                reason[i], active[i] = "no convergence", False
                detail[i] = "the correction grew beyond what the predicted error asks (drift)"
    unsolved = (miss >= threshold) & (reason == "")
    reason[unsolved] = "no convergence"
    for i in np.flatnonzero(unsolved):
        detail[i] = f"predicted miss {miss[i] * 1e3:.4g} mm after {iterations[i]} cycles"
    converged = reason == ""
    return CompensationResult(q=q, target=target, predicted_miss=miss, converged=converged,
                              iterations=iterations, reason=reason, detail=detail, first_order=first_order)


def _step(jac: np.ndarray, d: np.ndarray, turn: np.ndarray, hold: bool, rcond: float = 1e-8):
    """Minimum-norm step (n,) moving the TCP by d (3,) [m] and turning it by ``turn`` (3,) [rad],
    and the gain [rad/m]: the largest joint motion a unit position miss asks.

    With ``hold`` and a rank-6 Jacobian, the full pose task; otherwise position first and the
    turn in its null space (task priority)."""
    jp, jr = jac[:3], jac[3:]
    sv = np.linalg.svd(jac, compute_uv=False)
    if hold and sv.size >= 6 and sv[5] > 1e-6 * sv[0]:
        pinv = np.linalg.pinv(jac, rcond=rcond)
        return pinv @ np.concatenate([d, turn]), float(np.linalg.norm(pinv[:, :3], 2))
    pinv_p = np.linalg.pinv(jp, rcond=rcond)
    step = pinv_p @ d
    if hold:
        null = np.eye(jac.shape[1]) - pinv_p @ jp
        step = step + null @ np.linalg.pinv(jr @ null, rcond=1e-6) @ (turn - jr @ step)
    return step, float(np.linalg.norm(pinv_p, 2))


def _display(robot: RobotModel, j: int, value: float) -> str:
    """A joint amount in the command line's unit (deg or mm), labelled."""
    return f"{value * robot.display_scale[j]:.4g} {robot.display_units[j]}"
