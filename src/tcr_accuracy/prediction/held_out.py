"""The held-out error of a fitted predictor: measured minus predicted error at poses it was not fitted to.

The one figure that says how good a prediction (and so a compensation) is: the measured TCP
positions of poses the predictor never saw, mapped into the robot's base frame with the training
data's tracker frame, against the error it predicts there. SI units (m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.kinematics import tcp_poses


@dataclass(frozen=True)
class HeldOutError:
    """Measured minus predicted error at held-out poses, robot base frame.

    Attributes
    ----------
    residual : ndarray of shape (N, 3)
        Measured error minus predicted error [m]: the prediction's miss per pose.
    measured_error : ndarray of shape (N, 3)
        The measured point mapped into the base frame (the training data's tracker frame) minus
        the nominal TCP [m]; the TCP offset of the measured point included.
    std : ndarray of shape (N, 3) or None
        The predictor's standard deviation at these poses [m], where it gives one.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> model = tcr.MeasuredErrorModel(robot=robot, estimator=tcr.make_predictor("kriging", robot))
    >>> model = model.fit(measured.q[:150], measured.position[:150])
    >>> score = tcr.held_out_error(model, measured.q[150:], measured.position[150:])
    >>> isinstance(score, tcr.HeldOutError), score.residual.shape
    (True, (50, 3))
    """

    residual: np.ndarray
    measured_error: np.ndarray
    std: np.ndarray | None = None

    @property
    def miss(self) -> np.ndarray:
        """(N,) |measured - predicted error| per pose [m]."""
        return np.linalg.norm(self.residual, axis=1)

    @property
    def count(self) -> int:
        """Number of held-out poses."""
        return int(self.residual.shape[0])

    @property
    def mean(self) -> float:
        """Mean of :attr:`miss` [m]."""
        return float(self.miss.mean())

    @property
    def rms(self) -> float:
        """RMS of :attr:`miss` [m]."""
        return float(np.sqrt(np.mean(self.miss ** 2)))

    @property
    def max(self) -> float:
        """Largest :attr:`miss` [m]."""
        return float(self.miss.max())

    @property
    def within_2std(self) -> float | None:
        """Share of the axis misses (3N values) within 2 predicted standard deviations, or None
        without a standard deviation (near 0.95 when the predictor's std is honest)."""
        return None if self.std is None else float(np.mean(np.abs(self._z) <= 2.0))

    @property
    def z_rms(self) -> float | None:
        """RMS of the axis misses over their predicted standard deviations (near 1 when honest), or None."""
        return None if self.std is None else float(np.sqrt(np.mean(self._z ** 2)))

    @property
    def _z(self) -> np.ndarray:
        return self.residual / np.maximum(self.std, 1e-300)


def held_out_error(model, q, measured, *, context=None, predicted=None, std=None) -> HeldOutError:
    """The held-out error of a fitted :class:`~tcr_accuracy.prediction.composed.MeasuredErrorModel`.

    Parameters
    ----------
    model : MeasuredErrorModel
        Fitted; its tracker frame maps ``measured`` into the base frame.
    q : array-like of shape (N, n_joints)
        Joint values of the held-out poses [rad, m].
    measured : array-like of shape (N, 3)
        Their measured positions in the training data's tracker frame [m].
    context : MeasurementContext, optional
        The poses' payload, joints outside the chain, ..., for predictors that use them.
    predicted : array-like of shape (N, 3), optional
        ``model.predict_error(q)`` when already computed (a local model predicts slowly).
    std : array-like of shape (N, 3), optional
        The predicted standard deviation at q [m], for :attr:`HeldOutError.within_2std`.

    Returns
    -------
    HeldOutError
        ``residual = R^T (measured - t) - FK(q) - predicted error`` [m], base frame.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> model = tcr.MeasuredErrorModel(robot=robot, estimator=tcr.make_predictor("kriging", robot))
    >>> model = model.fit(measured.q[:150], measured.position[:150])
    >>> score = tcr.held_out_error(model, measured.q[150:], measured.position[150:])
    >>> isinstance(score, tcr.HeldOutError), score.residual.shape
    (True, (50, 3))
    """
    q = np.asarray(q, dtype=float)
    measured_error = model.registration_.to_base(np.asarray(measured, dtype=float)) - tcp_poses(model.robot, q).position
    residual = measured_error - (model.predict_error(q, context=context) if predicted is None else predicted)
    return HeldOutError(residual=residual, measured_error=measured_error,
                        std=None if std is None else np.asarray(std, dtype=float))
