"""Corrected commands for a controller that takes no model ("program filtering").

A controller that cannot load a calibration still moves where its own model says: the nominal
robot with the measured point as its TCP (the tool the user configured). The filter takes the
targets a program would send it and returns the commands to send instead, so that the real
robot, as the full calibrated model predicts it, puts the measured point on the target:

* **joint targets** (N, n_joints): the target is where the controller's model puts the point at
  those joints; the corrected command is a joint vector;
* **Cartesian targets** (N, 3) positions in the base frame [m], optionally with orientations:
  the controller's own inverse kinematics of the target gives its joints (from a seed, or its
  working pose); the corrected command is a joint vector and the Cartesian pose to send for it
  (the controller's forward kinematics at the corrected joints).

The correction is :func:`~tcr_accuracy.prediction.compensation.compensate_joints` with the full
model's predicted error (every effect, at the targets' load, the robot as at the campaign's
end): minimum-norm joint steps on the position until the model's miss is below the threshold.
Each target keeps its own verdict; the predicted error before and after is given per target.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..analysis.sampling import inverse_kinematics
from ..exceptions import InputError
from ..model.context import MeasurementContext
from ..model.kinematics import tcp_poses
from ..prediction.compensation import compensate_joints
from .model import AsBuiltModel


@dataclass(frozen=True)
class FilteredTargets:
    """Targets and their corrected commands.

    target_q : (N, n_joints) the joints the controller would use for each target [rad, m]
    command_q : (N, n_joints) corrected joint commands [rad, m] (the target's where unsolved)
    target_position : (N, 3) where the measured point should be, base frame [m]
    command_position, command_rotation : (N, 3), (N, 3, 3) the Cartesian command for the corrected
        joints (the controller's forward kinematics)
    error_before : (N,) [m] |full model at target_q - target|: what the robot misses uncorrected
    error_after : (N,) [m] |full model at command_q - target|: what it misses corrected
    solved : (N,) bool
    status : (N,) "ok", or why not ("no inverse kinematics", "outside limits", "singular", ...)
    cartesian : whether the targets were Cartesian
    """

    target_q: np.ndarray
    command_q: np.ndarray
    target_position: np.ndarray
    command_position: np.ndarray
    command_rotation: np.ndarray
    error_before: np.ndarray
    error_after: np.ndarray
    solved: np.ndarray
    status: np.ndarray
    cartesian: bool


class _FullModelError:
    """The full model's TCP minus the controller's, at the targets' context (an estimator's predict)."""

    def __init__(self, model: AsBuiltModel, controller, context: MeasurementContext):
        self.model, self.controller, self.context = model, controller, context

    def predict(self, q, context=None):
        context = self.context if context is None else context
        return self.model.tcp_poses(q, context).position - tcp_poses(self.controller, q).position


def filter_joint_targets(model: AsBuiltModel, q, context: MeasurementContext | None = None, *,
                         threshold: float = 1e-7) -> FilteredTargets:
    """Corrected joint commands for joint targets.

    Parameters
    ----------
    model : AsBuiltModel
        The full calibrated model.
    q : (N, n_joints) target joints [rad, m]
    context : MeasurementContext, optional
        The targets' load and the joints outside the chain (default: none, no load).
    threshold : float, default=1e-7
        Stop correcting a target when the model's miss is below this [m].

    Returns
    -------
    FilteredTargets

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    >>> filtered = tcr.filter_joint_targets(tcr.AsBuiltModel.from_diagnosis(robot, d), measured.q[:5])
    >>> int(filtered.solved.sum())
    5
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    return _filtered(model, q, context, threshold, np.array(["ok"] * len(q), dtype=object), cartesian=False)


def filter_pose_targets(model: AsBuiltModel, positions, rotations=None, *, q_seed=None,
                        context: MeasurementContext | None = None, threshold: float = 1e-7) -> FilteredTargets:
    """Corrected commands for Cartesian targets of the measured point.

    Parameters
    ----------
    model : AsBuiltModel
    positions : (N, 3) targets in the robot's base frame [m]
    rotations : (N, 3, 3), optional
        Target orientations of the TCP frame (the controller's IK holds them where it can).
    q_seed : (n_joints,) or (N, n_joints), optional
        Where the controller's IK starts (the branch); default its working pose.
    context, threshold : as :func:`filter_joint_targets`

    Returns
    -------
    FilteredTargets

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets"], folds=3)
    >>> model = tcr.AsBuiltModel.from_diagnosis(robot, d)
    >>> targets = model.measured_point_robot()
    >>> filtered = tcr.filter_pose_targets(model, tcr.tcp_poses(targets, measured.q[:5]).position, q_seed=measured.q[:5])
    >>> int(filtered.solved.sum())
    5
    """
    positions = np.atleast_2d(np.asarray(positions, dtype=float))
    if positions.ndim != 2 or positions.shape[1] != 3 or not np.all(np.isfinite(positions)):
        raise InputError(f"compensation filter: targets must be finite positions (N, 3), got {positions.shape}")
    controller = model.measured_point_robot()
    orientation = "exact" if rotations is not None and controller.n_joints >= 6 else "best_effort"
    ik = inverse_kinematics(controller, positions, rotations, q_seed, orientation=orientation)
    status = np.where(ik.success, "ok", "no inverse kinematics").astype(object)
    return _filtered(model, ik.q, context, threshold, status, cartesian=True, requested=positions)


def _filtered(model, q_target, context, threshold, status, cartesian: bool, requested=None) -> FilteredTargets:
    """The commands for ``q_target``; the targets are ``requested`` (Cartesian targets, also where the
    IK did not reach them) or the controller's TCP at ``q_target`` (joint targets)."""
    controller = model.measured_point_robot()
    n = len(q_target)
    if q_target.ndim != 2 or q_target.shape[1] != controller.n_joints or not np.all(np.isfinite(q_target)):
        raise InputError(f"compensation filter: targets must be finite joint values (N, {controller.n_joints})")
    context = model.state_context(context, n)
    target = tcp_poses(controller, q_target).position if requested is None else requested.copy()
    command = q_target.copy()
    solved = status == "ok"
    rows = np.flatnonzero(solved)
    if rows.size:
        result = compensate_joints(controller, _FullModelError(model, controller, context.subset(rows)),
                                   q_target[rows], threshold=threshold, context=context.subset(rows))
        command[rows[result.converged]] = result.q[result.converged]
        solved[rows[~result.converged]] = False
        status[rows[~result.converged]] = [f"{r}: {d}" for r, d in zip(result.reason[~result.converged],
                                                                      result.detail[~result.converged])]
    before = np.linalg.norm(model.tcp_poses(q_target, context).position - target, axis=1)
    after = np.linalg.norm(model.tcp_poses(command, context).position - target, axis=1)
    pose = tcp_poses(controller, command)
    return FilteredTargets(target_q=q_target, command_q=command, target_position=target,
                           command_position=pose.position, command_rotation=pose.rotation, error_before=before,
                           error_after=after, solved=solved, status=status, cartesian=cartesian)
