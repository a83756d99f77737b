"""Parametric calibrations as error predictors: fit a model of the robot, predict with it.

* :class:`GeometricCalibration` -- least squares of the identifiable geometric error
  parameters (``jacobians.error_jacobians`` gives the identification Jacobian, the
  diagnosis' identifiability test picks the identifiable columns, scipy solves).
* :class:`DiagnosisCalibration` -- the whole effect library:
  :func:`tcr_accuracy.diagnosis.diagnose.diagnose` picks and fits the effects (geometry,
  compliance, gear errors, ...); predicts its fitted model minus the nominal one.

Both map joint values (n, n_joints) [rad, m] to base-frame TCP position errors (n, 3) [m].
"""

from __future__ import annotations

import warnings
from numbers import Integral, Real

import numpy as np
from scipy.optimize import least_squares
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted, validate_data

from ..diagnosis.identifiability import SensitivityColumns, identifiability
from ..exceptions import InputError
from ..hyperparameters import validate_hyperparameters
from ..model.errors import ErrorModel
from ..model.jacobians import error_jacobians
from ..model.kinematics import tcp_poses
from ..model.robot import JointLimitWarning
from .checks import check_joints_and_position_errors


class GeometricCalibration(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """Least squares of the identifiable geometric error parameters from position errors.

    The identification Jacobian is the position rows of
    :func:`~tcr_accuracy.model.jacobians.error_jacobians` at the training poses; the
    diagnosis' identifiability test
    (:func:`~tcr_accuracy.diagnosis.identifiability.identifiability`, a QR decomposition with
    column pivoting) keeps the identifiable parameters of its column-normalised form (each
    column at unit norm, so a pivot |R_ii| is the share of a column no earlier one
    explains, kept above rank_tol); scipy's least_squares then fits them on the exact
    (nonlinear) forward kinematics. Predicts ``FK_x(q) - FK(q)``.

    Parameters
    ----------
    robot : RobotModel
    rank_tol : float, pivot threshold of the identifiability test, relative to the
        column's own norm

    Attributes
    ----------
    x_ : (n_params,) fitted error vector (zeros for unidentifiable parameters)
    identifiable_ : (r,) indices of the fitted parameters
    parameter_names_ : names of the fitted parameters
    """

    _parameter_constraints = {"rank_tol": [Interval(Real, 0, 1, closed="neither")]}

    def __init__(self, *, robot=None, rank_tol=1e-6):
        self.robot = robot
        self.rank_tol = rank_tol

    def fit(self, X, y):
        validate_hyperparameters(self)
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        check_joints_and_position_errors(self.robot, X, y, type(self).__name__)
        em = ErrorModel(self.robot)
        sensitivity = error_jacobians(self.robot, X, None, em)[1][:, :3]  # (n, 3, p) [m per unit] at x = 0
        jac = sensitivity.reshape(-1, em.size)  # (3n, p)
        norms = np.linalg.norm(jac, axis=0)
        # only the parameters that move the TCP at all enter the test: zero columns would change
        # the QR's rounding, and with it which member of a group of dependent columns is kept
        moves = np.flatnonzero(norms > 1e-12)
        unit = sensitivity[:, :, moves] / norms[moves]  # each column at unit norm
        columns = SensitivityColumns([em.names[i] for i in moves], unit, np.ones(moves.size))
        keep, _ = identifiability({"geometry": columns}, ["geometry"], self.rank_tol)
        ident = moves[keep["geometry"]]
        if 3 * X.shape[0] < 2 * ident.size:  # an (almost) exact fit: nothing left to check it, std 0
            raise InputError(f"GeometricCalibration: {X.shape[0]} poses give {3 * X.shape[0]} equations for "
                             f"{ident.size} identifiable parameters, too few to check the fit (it would pass "
                             f"through every pose); measure at least {-(-2 * ident.size // 3)} poses (twice "
                             "as many equations as parameters)")
        nominal = tcp_poses(self.robot, X).position
        target = y.ravel()
        j_id = jac[:, ident]

        def residual(theta):
            x = np.zeros(em.size)
            x[ident] = theta
            return (tcp_poses(self.robot, X, x, em).position - nominal).ravel() - target

        # the Jacobian at x = 0 stays a good (chord) Jacobian for millimetre-sized errors
        sol = least_squares(residual, np.zeros(ident.size), jac=lambda theta: j_id, x_scale="jac")
        x = np.zeros(em.size)
        x[ident] = sol.x
        self.x_ = x
        self.identifiable_ = ident
        self.parameter_names_ = [em.names[i] for i in ident]
        self.error_model_ = em
        return self

    def predict(self, X):
        check_is_fitted(self, "x_")
        X = validate_data(self, X, reset=False)
        return tcp_poses(self.robot, X, self.x_, self.error_model_).position - tcp_poses(self.robot, X).position


class DiagnosisCalibration(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """A parametric calibration with the effect library: the diagnosis' fitted model.

    ``fit`` runs :func:`tcr_accuracy.diagnosis.diagnose.diagnose` on the positions ``FK(X) + y``
    (base frame): it picks the effects (geometry, joint offsets, compliance, gear
    errors, ...) by k-fold held-out error and fits their parameters; ``predict`` is that
    fitted model's TCP position minus the nominal one. The context (payload,
    temperature, approach directions) is the default one: the predictors see joint
    values only.

    Parameters
    ----------
    robot : RobotModel
    effects : list of str or None, default=None
        Effects the diagnosis may choose from (None: the whole vocabulary).
    folds : int, default=5
        k of the diagnosis' cross-validation.
    tracker_noise : float, default=2e-5
        Per-axis measurement noise [m] the diagnosis assumes.
    random_state : int or None, default=None
        Seed of the fold split (None: 0).

    Attributes
    ----------
    diagnosis_ : tcr_accuracy.diagnosis.diagnose.Diagnosis
    selected_effects_ : list of str
    """

    #: :class:`~tcr_accuracy.prediction.composed.MeasuredErrorModel` gives it the robot whose TCP is the
    #: measured point: the effects act with their lever arms to it, as in ``diagnose``
    models_measured_point = True

    _parameter_constraints = {"folds": [Interval(Integral, 2, 1000, closed="both")],
                              "tracker_noise": [None, Interval(Real, 1e-9, 1.0, closed="both")]}

    def __init__(self, *, robot=None, effects=None, folds=5, tracker_noise=2e-5, random_state=None):
        self.robot = robot
        self.effects = effects
        self.folds = folds
        self.tracker_noise = tracker_noise
        self.random_state = random_state

    def fit(self, X, y, context=None):
        """Joint values X (n, n_joints) [rad, m], base-frame errors y (n, 3) [m]; returns self.

        ``context`` (MeasurementContext of the rows, optional): payload, temperature,
        approach directions and the joints outside the TCP chain, which the gravity
        effects need (a second arm loads the torso)."""
        validate_hyperparameters(self)
        from ..diagnosis.diagnose import diagnose
        from ..io.measurements import MeasurementSet

        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        check_joints_and_position_errors(self.robot, X, y, type(self).__name__)
        positions = tcp_poses(self.robot, X).position + y
        mset = MeasurementSet(joint_names=list(self.robot.joint_names), q=X, position=positions,
                              source="training errors", **_measured_context(context))
        seed = 0 if self.random_state is None else int(check_random_state(self.random_state).randint(2**31 - 1))
        effects = self.effects
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", JointLimitWarning)
            self.diagnosis_ = diagnose(self.robot, mset, effects=effects, folds=self.folds, random_state=seed,
                                       tracker_noise=self.tracker_noise)
        self.selected_effects_ = list(self.diagnosis_.selected_effects)
        return self

    def predict(self, X, context=None):
        """(m, 3) errors of the fitted model at joint values X (m, n_joints) [m] (and the
        rows' context, as in :meth:`fit`)."""
        check_is_fitted(self, "diagnosis_")
        X = validate_data(self, X, reset=False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", JointLimitWarning)
            # the "tracker" frame of the diagnosis is the frame of the positions it was given: here the
            # base frame, so a constant offset of the errors (which the diagnosis puts in its frame) is kept
            return self.diagnosis_.tracker_positions(self.robot, X, context) - tcp_poses(self.robot, X).position


def _measured_context(context) -> dict:
    """MeasurementSet fields from a MeasurementContext: the columns that carry information."""
    if context is None:
        return {}
    from ..model.context import REFERENCE_TEMPERATURE_C

    payload = np.asarray(context.payload_kg, dtype=float)
    temperature = np.asarray(context.temperature_c, dtype=float)
    direction = np.asarray(context.direction, dtype=float)
    return {"payload_kg": payload if np.any(payload != 0) else None,
            "temperature_c": temperature if np.any(temperature != REFERENCE_TEMPERATURE_C) else None,
            "direction": direction if np.any(direction != 0) else None,
            "outside_q": context.outside_q}

