"""The error a fitted predictor expects at given poses, and its held-out error where they were measured.

What ``tcr-accuracy predict`` reports, as one typed result: the predicted error (real minus
nominal TCP, base frame), the part the robot adds beyond the measured point's TCP offset (a
reflector 150 mm off the flange is where the measured point sits, no error), the predictor's
standard deviation and, for measured poses, :class:`~tcr_accuracy.prediction.held_out.HeldOutError`.
SI units (m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import AnalysisError
from ..model.kinematics import tcp_poses
from .composed import uncertainty_kind
from .held_out import HeldOutError, held_out_error


@dataclass(frozen=True)
class ErrorPrediction:
    """The predicted TCP position error at N poses, robot base frame.

    Attributes
    ----------
    predicted_error : ndarray of shape (N, 3)
        Real minus nominal TCP position [m], the measured point's TCP offset included.
    tcp_offset_error : ndarray of shape (N, 3)
        The fitted TCP offset's share of it [m] (where the measured point sits, not an error).
    std : ndarray of shape (N, 3) or None
        The predictor's standard deviation per axis [m], where it gives one.
    uncertainty : str or None
        What ``std`` is (:func:`~tcr_accuracy.prediction.composed.uncertainty_kind`), None without one.
    held_out : HeldOutError or None
        Measured minus predicted error, for poses with measured positions.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> model = tcr.MeasuredErrorModel(robot=robot, estimator=tcr.make_predictor("kriging", robot))
    >>> model = model.fit(measured.q[:150], measured.position[:150])
    >>> prediction = tcr.predict_errors(model, measured.q[150:])
    >>> isinstance(prediction, tcr.ErrorPrediction), prediction.predicted_error.shape
    (True, (50, 3))
    """

    predicted_error: np.ndarray
    tcp_offset_error: np.ndarray
    std: np.ndarray | None = None
    uncertainty: str | None = None
    held_out: HeldOutError | None = None

    @property
    def robot_error(self) -> np.ndarray:
        """(N, 3) what the robot adds beyond the nominal robot carrying the fitted TCP offset [m]."""
        return self.predicted_error - self.tcp_offset_error

    def robot_error_statistics(self) -> dict[str, tuple[float, float, float, float]]:
        """``{"mean" | "RMS" | "max": (|e|, |ex|, |ey|, |ez|)}`` of :attr:`robot_error` over the poses [m]."""
        error = self.robot_error
        norm = np.linalg.norm(error, axis=1)
        return {"mean": (norm.mean(), *np.abs(error).mean(axis=0)),
                "RMS": (np.sqrt(np.mean(norm ** 2)), *np.sqrt(np.mean(error ** 2, axis=0))),
                "max": (norm.max(), *np.abs(error).max(axis=0))}


def predict_errors(model, q, *, context=None, measured=None, label: str = "the predictor") -> ErrorPrediction:
    """The error a fitted :class:`~tcr_accuracy.prediction.composed.MeasuredErrorModel` predicts at q.

    Parameters
    ----------
    model : MeasuredErrorModel
        Fitted to measured poses.
    q : array-like of shape (N, n_joints)
        Joint values to predict at [rad, m].
    context : MeasurementContext, optional
        The poses' payload, joints outside the chain, ..., for predictors that use them.
    measured : array-like of shape (N, 3), optional
        Measured positions at q in the training data's tracker frame [m]: adds the held-out error.
    label : str, default="the predictor"
        What an error message calls the predictor.

    Returns
    -------
    ErrorPrediction

    Raises
    ------
    AnalysisError
        The predictor returned a non-finite error or standard deviation.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> train, test = measured.subset(slice(0, 160)), measured.subset(slice(160, 200))
    >>> model = tcr.MeasuredErrorModel(robot=robot, estimator=tcr.make_predictor("kriging", robot))
    >>> model = model.fit(train.q, train.position, context=train.context)
    >>> result = tcr.predict_errors(model, test.q, context=test.context, measured=test.position)
    >>> result.predicted_error.shape, result.held_out.residual.shape  # [m]
    ((40, 3), (40, 3))
    """
    q = np.asarray(q, dtype=float)
    predicted, std = finite_prediction(model.predict_error, q, context, label)
    # the error is where the measured point goes beyond where the nominal robot with the fitted
    # TCP offset puts it; the offset itself (a reflector 150 mm off the flange) is no error
    offset = model.registration_.tcp_positions(model.robot, q) - tcp_poses(model.robot, q).position
    held = None if measured is None else held_out_error(model, q, measured, context=context, predicted=predicted,
                                                        std=std)
    return ErrorPrediction(predicted_error=predicted, tcp_offset_error=offset, std=std,
                           uncertainty=uncertainty_kind(model) if std is not None else None, held_out=held)


def finite_prediction(predict, q, context, label: str):
    """``predict(q, return_std=True, context=...)`` as (N, 3) arrays [m] (std None when there is none),
    checked finite."""
    predicted, std = predict(q, return_std=True, context=context)
    predicted = np.asarray(predicted, dtype=float).reshape(-1, 3)
    if not np.all(np.isfinite(predicted)) or (std is not None and not np.all(np.isfinite(std))):
        raise AnalysisError(f"{label} predicted non-finite errors")
    return predicted, (None if std is None else np.asarray(std, dtype=float).reshape(-1, 3))
