"""Estimators built of estimators, and the measured-position front end the commands use.

* :class:`ResidualCorrected` -- a base model plus a second model of its residual
  (calibration + GP, diagnosis + GP, TCP offset + any method).
* :class:`TcpOffset` -- the error of a constant TCP offset (the ``frames`` effect's).
* :class:`MeasuredErrorModel` -- registers the tracker frame and the TCP offset on
  measured positions (:mod:`tcr_accuracy.frames.registration`), then fits any
  estimator to the base-frame error that the TCP offset leaves.
* :func:`uncertainty_kind` -- which fitted estimators give a standard deviation.
* :func:`predict_with_context` -- pass the rows' MeasurementContext to the estimators
  that take one.

Joint values in [rad, m], errors and positions in [m].
"""

from __future__ import annotations

import numpy as np
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin, clone
from sklearn.utils.validation import check_is_fitted, validate_data

from ..exceptions import InputError
from ..model.kinematics import tcp_poses
from .bayesian import BayesianCalibration
from .gaussian_process import JointGaussianProcess
from .kriging import JointKriging
from .local_gp import LocalGaussianProcess


class ResidualCorrected(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """A base model plus a second model fitted to its residual: ``base(X) + residual(X)``.

    Parameters
    ----------
    base : estimator (e.g. GeometricCalibration)
    residual : estimator (e.g. :class:`~tcr_accuracy.prediction.gaussian_process.JointGaussianProcess`)

    Attributes
    ----------
    base_, residual_ : the fitted estimators
    """

    def __init__(self, *, base=None, residual=None):
        self.base = base
        self.residual = residual

    def fit(self, X, y, context=None):
        """Fit the base model to y, then the residual model to ``y - base(X)``; returns self.

        ``context`` (a MeasurementContext of the rows) goes to the members that take one."""
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        self.base_ = _fit_with_context(clone(self.base), X, y, context)
        self.residual_ = _fit_with_context(clone(self.residual), X, y - predict_with_context(self.base_, X, context),
                                           context)
        return self

    def predict(self, X, return_std=False, context=None):
        """``base(X) + residual(X)``; with return_std, the residual model's standard
        deviation (None when it has none). The base model's parameters count as exact:
        its own estimation spread is not added.

        Parameters
        ----------
        X : array-like of shape (m, n_features)
        return_std : bool, default=False

        Returns
        -------
        y_pred : ndarray of shape (m, n_outputs)
        y_std : ndarray of shape (m, n_outputs) or None, only with return_std
        """
        check_is_fitted(self, "base_")
        X = validate_data(self, X, reset=False)
        base = predict_with_context(self.base_, X, context)
        if not return_std:
            return base + predict_with_context(self.residual_, X, context)
        if uncertainty_kind(self.residual_) is None:
            return base + predict_with_context(self.residual_, X, context), None
        mean, std = predict_with_context(self.residual_, X, context, return_std=True)
        return base + mean, std


    @classmethod
    def from_fitted(cls, base, residual, n_features: int) -> "ResidualCorrected":
        """The sum of two estimators fitted elsewhere (e.g. the residual on another robot model)."""
        out = cls(base=base, residual=residual)
        out.base_, out.residual_, out.n_features_in_ = base, residual, int(n_features)
        return out


def _takes_context(method) -> bool:
    import inspect

    return "context" in inspect.signature(method).parameters


def _fit_with_context(estimator, X, y, context):
    """``estimator.fit(X, y)``, with the rows' context when the estimator takes one (as
    scikit-learn passes ``sample_weight`` only to estimators whose ``fit`` has it)."""
    if context is not None and _takes_context(estimator.fit):
        return estimator.fit(X, y, context=context)
    return estimator.fit(X, y)


def predict_with_context(estimator, X, context, **options):
    """``estimator.predict(X)``, with the rows' context when the estimator takes one."""
    if context is not None and _takes_context(estimator.predict):
        return estimator.predict(X, context=context, **options)
    return estimator.predict(X, **options)


class TcpOffset(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """The TCP position error of a constant offset d of the TCP in its own frame.

    ``e(q) = R(q) d`` with R(q) the nominal TCP orientation: exactly the ``frames``
    effect's TCP offset. Least squares in closed form: R is orthogonal, so
    ``d = mean_i R_i^T e_i``.

    Parameters
    ----------
    robot : RobotModel

    Attributes
    ----------
    offset_ : ndarray of shape (3,)
        TCP offset in the TCP frame [m].
    """

    def __init__(self, *, robot=None):
        self.robot = robot

    def fit(self, X, y):
        """Joint values X (n, n_joints), base-frame errors y (n, 3) [m]; returns self."""
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        if self.robot is None:
            raise InputError("TcpOffset needs a robot")
        if y.ndim != 2 or y.shape[1] != 3:
            raise InputError(f"TcpOffset: needs position errors (n, 3), got {y.shape}")
        rotation = tcp_poses(self.robot, X).rotation
        self.offset_ = np.einsum("nji,nj->i", rotation, y) / X.shape[0]
        return self

    @classmethod
    def from_offset(cls, robot, offset) -> "TcpOffset":
        """The error of a known offset (3,) [m] in the TCP frame (e.g. a registration's)."""
        out = cls(robot=robot)
        out.offset_, out.n_features_in_ = np.asarray(offset, dtype=float).reshape(3), robot.n_joints
        return out

    def predict(self, X):
        """(m, 3) error of the fitted offset at joint values X (m, n_joints) [m]."""
        check_is_fitted(self, "offset_")
        X = validate_data(self, X, reset=False)
        return tcp_poses(self.robot, X).rotation @ self.offset_


def _measured_point_robots(estimator) -> list[str]:
    """The ``robot`` parameters (set_params keys) of the estimators in ``estimator`` that model the
    robot's effects at the measured point (class attribute ``models_measured_point``): their lever
    arms depend on where that point is, so they are given the robot whose TCP it is. The others
    (a geometric calibration's linearised parameters, joint-space regressors) fit the error beyond
    the measured point on the nominal chain, as their identifiability test was tuned on."""
    params = estimator.get_params(deep=True)
    keys = []
    for key in params:
        if key != "robot" and not key.endswith("__robot"):
            continue
        owner = estimator if key == "robot" else params[key[:-len("__robot")]]
        if getattr(owner, "models_measured_point", False):
            keys.append(key)
    return keys


def uncertainty_kind(estimator) -> str | None:
    """What ``predict(X, return_std=True)`` of a fitted estimator gives, or None.

    "kriging standard deviation", "Gaussian process predictive standard deviation",
    "Bayesian posterior predictive standard deviation", the residual model's (for
    :class:`ResidualCorrected`) or None.
    """
    if isinstance(estimator, JointKriging):
        return "kriging standard deviation"
    if isinstance(estimator, (JointGaussianProcess, LocalGaussianProcess)):
        return "Gaussian process predictive standard deviation"
    if isinstance(estimator, BayesianCalibration):
        return "Bayesian posterior predictive standard deviation"
    if isinstance(estimator, ResidualCorrected):
        model = getattr(estimator, "residual_", estimator.residual)
        return uncertainty_kind(model)
    if isinstance(estimator, MeasuredErrorModel):
        return uncertainty_kind(getattr(estimator, "error_model_", estimator.estimator))
    return None


class MeasuredErrorModel(BaseEstimator):
    """An error predictor fitted to measured TCP positions in a tracker's own frame.

    ``fit(X, P)`` first registers the tracker frame and the TCP offset on the training
    data (:func:`tcr_accuracy.frames.registration.register_tracker`) and maps the
    measured positions into the robot's base frame. The TCP offset belongs to the
    measured point (a reflector 150 mm off the flange, a tool tip): the estimator is
    fitted to what the robot adds beyond that point, and the effect models in it (the
    diagnosis) on the robot whose TCP *is* that point (``frame_robot_``), so that rotation
    errors of the wrist act with the right lever arm.
    The base-frame error is then ``TCP offset term + estimator``. ``predict`` maps the
    predicted real TCP back to the tracker frame, so it predicts what the tracker will read.

    Parameters
    ----------
    robot : RobotModel
    estimator : estimator
        ``fit(Q (n, n_joints), E (n, 3))`` / ``predict(Q) -> (m, 3)`` on base-frame
        errors [m] (any of :data:`~tcr_accuracy.prediction.methods.METHODS` by
        :func:`~tcr_accuracy.prediction.methods.make_predictor`); the ``robot`` of every
        estimator in it with ``models_measured_point = True`` is set to ``frame_robot_``.
    fit_frame : bool, default=True
        Fit the tracker frame. False: the measured positions are in the base frame
        already (only the TCP offset is fitted).

    Attributes
    ----------
    registration_ : tcr_accuracy.frames.registration.Registration
    frame_robot_ : RobotModel
        The robot with the fitted TCP offset: its TCP is the measured point.
    errors_ : ndarray of shape (n, 3)
        Training errors, real minus nominal TCP position in the base frame [m].
    estimator_ : estimator
        The estimator fitted to the error beyond the measured point (base frame) [m].
    error_model_ : ResidualCorrected
        TCP offset term plus ``estimator_``; ``error_model_.predict(Q)`` gives the
        base-frame error (m, 3) [m] of the nominal robot.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> train, test = measured.subset(slice(0, 160)), measured.subset(slice(160, 200))
    >>> model = tcr.MeasuredErrorModel(robot=robot, estimator=tcr.make_predictor("kriging", robot))
    >>> model = model.fit(train.q, train.position, context=train.context)
    >>> model.predict(test.q, context=test.context).shape
    (40, 3)
    """

    def __init__(self, *, robot=None, estimator=None, fit_frame=True):
        self.robot = robot
        self.estimator = estimator
        self.fit_frame = fit_frame

    def __repr__(self, N_CHAR_MAX=700) -> str:
        """scikit-learn's repr of the parameters, on one line."""
        return " ".join(super().__repr__(N_CHAR_MAX).split())

    def fit(self, X, y, context=None):
        """Joint values X (n, n_joints) [rad, m], measured positions y (n, 3) in the tracker frame [m];
        ``context``: the rows' MeasurementContext, for the estimators that take one."""
        from .nominal import nominal_registration

        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        if self.robot is None or self.estimator is None:
            raise InputError("MeasuredErrorModel needs a robot and an estimator")
        self.registration_ = nominal_registration(self.robot, X, y, fit_frame=self.fit_frame)  # the one 'nominal'
        measured = self.registration_.to_base(y)
        self.frame_robot_ = self.registration_.measured_frame_robot(self.robot)
        self.errors_ = measured - tcp_poses(self.robot, X).position
        estimator = clone(self.estimator)
        estimator.set_params(**{k: self.frame_robot_ for k in _measured_point_robots(estimator)})
        self.estimator_ = _fit_with_context(estimator, X, measured - tcp_poses(self.frame_robot_, X).position,
                                            context)
        self.error_model_ = ResidualCorrected.from_fitted(
            TcpOffset.from_offset(self.robot, self.registration_.tool_offset), self.estimator_, X.shape[1])
        return self

    def predict_error(self, X, return_std=False, context=None):
        """Base-frame error (real minus nominal TCP position) at X (m, n_joints) [m].

        With return_std, also its standard deviation (m, 3), or None when the
        estimator has none (see :func:`uncertainty_kind`).
        """
        check_is_fitted(self, "error_model_")
        return self.error_model_.predict(X, return_std=return_std, context=context)

    def predict_robot_error(self, X, return_std=False, context=None):
        """What the robot adds beyond the measured point (the TCP offset term left out): base-frame
        error of ``frame_robot_`` at X (m, n_joints) [m], with its std (m, 3) or None on request."""
        check_is_fitted(self, "estimator_")
        if not return_std:
            return predict_with_context(self.estimator_, X, context)
        if uncertainty_kind(self.estimator_) is None:
            return predict_with_context(self.estimator_, X, context), None
        return predict_with_context(self.estimator_, X, context, return_std=True)

    def predict(self, X, context=None):
        """(m, 3) predicted tracker readings at joint values X (m, n_joints) [m]."""
        check_is_fitted(self, "error_model_")
        X = validate_data(self, X, reset=False)
        return self.registration_.to_tracker(tcp_poses(self.robot, X).position + self.predict_error(X, context=context))

    def heldout_residual(self, X, y, context=None) -> np.ndarray:
        """Measured minus predicted error at poses the model was not fitted to.

        Parameters
        ----------
        X : array-like of shape (m, n_joints)
        y : array-like of shape (m, 3)
            Measured positions in the tracker frame of the training data [m].

        Returns
        -------
        ndarray of shape (m, 3)
            In the base frame [m]: ``to_base(y) - FK(X) - predict_error(X)``.
        """
        from .held_out import held_out_error

        check_is_fitted(self, "error_model_")
        return held_out_error(self, validate_data(self, X, reset=False), y, context=context).residual
