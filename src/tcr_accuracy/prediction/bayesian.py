"""The linearised effect vocabulary with a fitted prior as an error predictor (``predict --method bayes``).

:class:`BayesianCalibration` fits the model ``plan-poses`` designs for
(:mod:`tcr_accuracy.diagnosis.bayes_design`): the TCP error is, to first order, ``G(q) theta`` with one
column per parameter of every effect the joint values drive (geometry, compliance, encoder scale,
transmission, gear and cyclic errors, angle tables; 513 columns on a UR5); the geometric parameters
are free, every other effect's are normal with a standard deviation ``tau_e`` typical sizes, and
``tau_e`` and the noise are the ones that make the training errors most probable (type-II maximum
likelihood, :func:`~tcr_accuracy.diagnosis.bayes_design.fit_prior`). It predicts the posterior mean,
and with ``return_std`` the posterior predictive standard deviation (the parameters' spread plus the
fitted noise). Unlike ``diagnosis`` it selects nothing: an effect the data do not support is shrunk to
what they show, not left out, which is what predicts best from few poses (UR5, 60 poses: see
``docs/pose-design.md``). Joint values (n, n_joints) [rad, m] in, base-frame TCP position errors
(n, 3) [m] out.
"""

from __future__ import annotations

import warnings
from numbers import Real

import numpy as np
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted, validate_data

from ..diagnosis.bayes_design import BayesianErrorModel, design_columns, design_vocabulary, fit_prior
from ..effects import effect_class
from ..exceptions import InputError
from ..hyperparameters import validate_hyperparameters
from ..model.robot import JointLimitWarning
from .checks import check_joints_and_position_errors


class BayesianCalibration(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """The posterior mean of the linearised effect vocabulary under a prior fitted to the training errors.

    Parameters
    ----------
    robot : RobotModel
    effects : list of str or None, default=None
        Effects to model (None: every effect the joint values and the payload drive,
        :func:`~tcr_accuracy.diagnosis.bayes_design.design_vocabulary`; ``frames`` always in).
    tracker_noise : float or None, default=None
        Per-axis measurement noise [m] to hold; None: fitted with the prior (it then holds the
        instrument's noise plus what the vocabulary cannot express).

    Attributes
    ----------
    prior_ : tcr_accuracy.diagnosis.bayes_design.EffectPrior
        The fitted prior scales per effect [typical sizes] and the noise [m].
    model_ : tcr_accuracy.diagnosis.bayes_design.BayesianErrorModel
        The posterior: mean ``theta_`` [typical sizes] and covariance.
    effects_ : list of str
        The effects modelled, vocabulary order.
    n_parameters_ : int
        Columns of the linearised model.
    noise_std_ : ndarray of shape (3,)
        The noise per axis [m] (``prior_.noise_m``, the same on each axis).
    loo_rmse_ : ndarray of shape (3,)
        Leave-one-pose-out RMS error per axis on the training poses [m] (closed form, the prior held at its
        fit to all of them): the predictor's own statement of its accuracy.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> from tcr_accuracy.prediction.bayesian import BayesianCalibration
    >>> robot = tcr.load_robot("ur5")
    >>> model = BayesianCalibration(robot=robot).fit(train_q, train_errors)  # doctest: +SKIP
    >>> mean, std = model.predict(query_q, return_std=True)  # doctest: +SKIP
    """

    #: :class:`~tcr_accuracy.prediction.composed.MeasuredErrorModel` gives it the robot whose TCP is the
    #: measured point, so that rotations act with their lever arms to it (as for ``diagnosis``)
    models_measured_point = True

    _parameter_constraints = {"effects": [None, list, tuple],
                              "tracker_noise": [None, Interval(Real, 1e-9, 1.0, closed="both")]}

    def __init__(self, *, robot=None, effects=None, tracker_noise=None):
        self.robot = robot
        self.effects = effects
        self.tracker_noise = tracker_noise

    def _columns(self, X, context, effects):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", JointLimitWarning)
            return design_columns(self.robot, X, effects, context=context)

    def _vocabulary(self) -> list[str]:
        """The effects to model: ``effects`` checked (each a vocabulary effect the pose drives), or all of them."""
        if self.effects is None:
            return design_vocabulary()
        for name in self.effects:
            effect_class(name, vocabulary_only=True, source=f"{type(self).__name__}: effects")
        chosen = design_vocabulary(self.effects)
        outside = [name for name in self.effects if name not in chosen]
        if outside:
            raise InputError(f"{type(self).__name__}: effects: {', '.join(outside)}: not a function of the joint "
                             f"values and the payload (drift, temperature, approach direction, clearance); "
                             f"it models {', '.join(design_vocabulary())}")
        return chosen

    def fit(self, X, y, context=None):
        """Joint values X (n, n_joints) [rad, m], base-frame errors y (n, 3) [m]; returns self.

        ``context`` (MeasurementContext of the rows, optional): the payload, which the compliance
        effects' columns depend on."""
        validate_hyperparameters(self)
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        check_joints_and_position_errors(self.robot, X, y, type(self).__name__)
        columns = self._columns(X, context, self._vocabulary())
        self.prior_ = fit_prior(columns, y, noise_m=self.tracker_noise)
        self.model_ = BayesianErrorModel(self.prior_).fit(columns, y)
        self.effects_ = list(columns.effects)
        self.n_parameters_ = columns.n_parameters
        self.noise_std_ = np.full(3, self.prior_.noise_m)
        self.loo_rmse_ = np.sqrt(np.mean(self.model_.leave_one_out(columns, y) ** 2, axis=0))
        return self

    def predict(self, X, return_std=False, context=None):
        """The posterior mean error at joint values X (m, n_joints) [rad, m] (and the rows' context).

        Returns
        -------
        y_pred : ndarray of shape (m, 3)
            Base-frame TCP position error [m].
        y_std : ndarray of shape (m, 3), only with return_std
            Posterior predictive standard deviation of a measurement there, per axis [m]: the
            parameters' posterior spread plus the fitted noise.
        """
        check_is_fitted(self, "model_")
        X = validate_data(self, X, reset=False)
        return self.model_.predict(self._columns(X, context, self.effects_), return_std=return_std)
