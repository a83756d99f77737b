"""Compensated commands for targets of a predictor fitted to measurements, with the figures before and after.

What ``tcr-accuracy compensate`` reports, as one typed result: the cyclic search of
:func:`~tcr_accuracy.prediction.compensation.compensate_joints` run on the robot whose TCP is the
measured point (the fitted TCP offset) with the predictor of what the robot adds beyond it; per
solved target the predicted real TCP at the uncompensated and at the compensated command and, for
targets measured at their uncompensated command, the prediction's held-out error there (about
what compensation really leaves). SI units (m, rad).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.kinematics import tcp_poses
from .compensation import CompensationResult, compensate_joints
from .error_prediction import finite_prediction
from .held_out import HeldOutError, held_out_error
from .nominal import nominal_error


@dataclass(frozen=True)
class TargetCompensation:
    """Compensation of N targets, with its figures for the S solved ones (base frame).

    Attributes
    ----------
    result : CompensationResult
        The cyclic search's verdict for every target (N rows).
    solved : ndarray of shape (S,)
        Indices of the solved targets (``result.converged``).
    q : ndarray of shape (S, n_joints)
        The solved targets' joint values: the uncompensated commands [rad, m].
    q_compensated : ndarray of shape (S, n_joints)
        Their compensated commands [rad, m].
    target : ndarray of shape (S, 3)
        Where the measured point should go: the model's (nominal FK with the fitted TCP offset) at q [m].
    predicted_before : ndarray of shape (S, 3)
        Predicted real position of the measured point at the uncompensated command [m].
    predicted_after : ndarray of shape (S, 3)
        Predicted real position at the compensated command [m].
    held_out : HeldOutError or None
        For targets measured at their uncompensated command: measured minus predicted error there.
    measured_before : ndarray of shape (S,) or None
        For measured targets: |measured point - target| at the uncompensated command [m].

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> model = tcr.MeasuredErrorModel(robot=robot, estimator=tcr.make_predictor("kriging", robot))
    >>> model = model.fit(measured.q[:150], measured.position[:150])
    >>> result = tcr.compensate_targets(model, measured.q[150:155])
    >>> isinstance(result, tcr.TargetCompensation), result.q_compensated.shape
    (True, (5, 6))
    """

    result: CompensationResult
    solved: np.ndarray
    q: np.ndarray
    q_compensated: np.ndarray
    target: np.ndarray
    predicted_before: np.ndarray
    predicted_after: np.ndarray
    held_out: HeldOutError | None = None
    measured_before: np.ndarray | None = None

    @property
    def error_before(self) -> np.ndarray:
        """(S,) predicted |real TCP - target| at the uncompensated command [m]."""
        return np.linalg.norm(self.predicted_before - self.target, axis=1)

    @property
    def miss_after(self) -> np.ndarray:
        """(S,) the model's own miss at the compensated command [m] (its prediction, not a measurement;
        what compensation really leaves is about :attr:`held_out`)."""
        return self.result.predicted_miss[self.solved]

    @property
    def correction(self) -> np.ndarray:
        """(S, n_joints) compensated minus uncompensated command [rad, m]."""
        return self.q_compensated - self.q

    @property
    def iterations(self) -> np.ndarray:
        """(S,) cycles each solved target took."""
        return self.result.iterations[self.solved]


def compensate_targets(model, q_targets, *, threshold: float = 1e-6, max_iter: int = 20, context=None,
                       measured=None, label: str = "the predictor") -> TargetCompensation:
    """Compensated commands for targets given as joint values, with a fitted
    :class:`~tcr_accuracy.prediction.composed.MeasuredErrorModel`.

    Parameters
    ----------
    model : MeasuredErrorModel
        Fitted to measured poses; the measured point (its fitted TCP offset) is what goes to the target.
    q_targets : array-like of shape (N, n_joints)
        Joint values whose measured point, on the model, is where the tool should go [rad, m].
    threshold : float, default=1e-6
        Stop a target when its predicted miss is below this [m].
    max_iter : int, default=20
        Most compensation cycles.
    context : MeasurementContext, optional
        The targets' payload, joints outside the chain, ..., for predictors that use them.
    measured : array-like of shape (N, 3), optional
        The targets' measured positions at their uncompensated commands, in the training data's
        tracker frame [m]: adds the held-out error.
    label : str, default="the predictor"
        What an error message calls the predictor.

    Returns
    -------
    TargetCompensation
        No target solved is no error here: ``solved`` is then empty and the figures have no rows.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> model = tcr.MeasuredErrorModel(robot=robot, estimator=tcr.make_predictor("kriging", robot))
    >>> model = model.fit(measured.q[:160], measured.position[:160])
    >>> done = tcr.compensate_targets(model, measured.q[160:165], threshold=1e-6)
    >>> done.q_compensated.shape
    (5, 6)
    """
    q_all = np.atleast_2d(np.asarray(q_targets, dtype=float))
    frame_robot = model.frame_robot_  # its TCP is the measured point
    result = compensate_joints(frame_robot, model.estimator_, q_all, threshold=threshold, max_iter=max_iter,
                               context=context)
    solved = np.flatnonzero(result.converged)
    q, q_comp, target = q_all[solved], result.q[solved], result.target[solved]
    context = None if context is None else context.subset(solved)

    def beyond(joints):  # what the robot adds beyond the measured point (base frame)
        return finite_prediction(model.predict_robot_error, joints, context, label)[0]

    if solved.size == 0:
        before = after = np.zeros((0, 3))
    else:
        before = target + beyond(q)
        after = tcp_poses(frame_robot, q_comp).position + beyond(q_comp)
    held = measured_before = None
    if measured is not None and solved.size:
        measured = np.asarray(measured, dtype=float)[solved]
        # the targets were measured at their uncompensated commands: how well the predicted
        # error there matches the measured one is what compensation can hope to remove
        held = held_out_error(model, q, measured, context=context)
        # measured against the target, the measured point of the nominal robot: the one nominal figure
        measured_before = nominal_error(model.registration_, model.robot, q, measured).error
    return TargetCompensation(result=result, solved=solved, q=q, q_compensated=q_comp, target=target,
                              predicted_before=before, predicted_after=after, held_out=held,
                              measured_before=measured_before)
