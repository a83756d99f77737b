"""The seed's comparison methods: inverse distance weighting, and Cartesian-space features.

* :class:`InverseDistanceWeighting` -- Shepard interpolation, hand-written because
  scikit-learn's nearest-neighbour regressor with ``weights="distance"`` fixes the power
  at 1 and IDW with a power is a few lines.
* :func:`make_cartesian_mlp`, :func:`make_cartesian_idw` -- what Cartesian-space methods
  see: the nominal TCP position [m] (and orientation) from :class:`TcpFeatures`, then
  scikit-learn's MLPRegressor or the IDW above.
"""

from __future__ import annotations

from numbers import Real

import numpy as np
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin, TransformerMixin
from sklearn.compose import TransformedTargetRegressor
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import check_is_fitted, validate_data

from ..exceptions import InputError
from ..hyperparameters import validate_hyperparameters
from ..model.kinematics import tcp_poses
from .checks import check_enough_points



class InverseDistanceWeighting(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """Shepard's inverse distance weighting on standardised features.

    ``y(x) = sum_i d_i^-p y_i / sum_i d_i^-p`` over all training points; a query that
    coincides with a training point returns its value.

    Parameters
    ----------
    power : float, the exponent p
    """

    _parameter_constraints = {"power": [Interval(Real, 0, 100, closed="right")]}

    def __init__(self, *, power=2.0):
        self.power = power

    def fit(self, X, y):
        validate_hyperparameters(self)
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        check_enough_points(X.shape[0], X.shape[1], type(self).__name__)
        self.scaler_ = StandardScaler().fit(X)
        self.X_train_ = self.scaler_.transform(X)
        self.y_train_ = y
        return self

    def predict(self, X):
        check_is_fitted(self, "X_train_")
        X = self.scaler_.transform(validate_data(self, X, reset=False))
        a, b = X, self.X_train_
        dist = np.sqrt(np.maximum((a**2).sum(1)[:, None] + (b**2).sum(1)[None, :] - 2.0 * a @ b.T, 0.0))
        hit = dist < 1e-12
        with np.errstate(divide="ignore"):
            w = np.where(hit, 0.0, dist ** -float(self.power))
        exact = hit.any(axis=1)
        w[exact] = hit[exact]  # exact hits: the training value itself
        w /= w.sum(axis=1, keepdims=True)
        return w @ self.y_train_


class TcpFeatures(TransformerMixin, BaseEstimator):
    """Joint values (n, n_joints) -> nominal TCP features: position (3) [m], optionally the
    first two columns of the rotation matrix (6), a continuous orientation code.

    Parameters
    ----------
    robot : RobotModel
    orientation : bool
    """

    def __init__(self, *, robot=None, orientation=True):
        self.robot = robot
        self.orientation = orientation

    def fit(self, X, y=None):
        validate_data(self, X)
        if self.robot is None:
            raise InputError("TcpFeatures needs a robot")
        return self

    def transform(self, X):
        X = validate_data(self, X, reset=False)
        pose = tcp_poses(self.robot, X)
        if not self.orientation:
            return pose.position
        return np.hstack([pose.position, pose.rotation[:, :, :2].reshape(len(X), 6)])



def make_cartesian_mlp(robot, *, random_state=None, hidden_layer_sizes=(64, 64)):
    """The seed's Cartesian MLP baseline: nominal TCP position + orientation, scaled, into
    scikit-learn's MLPRegressor (scaled targets)."""
    mlp = MLPRegressor(hidden_layer_sizes=hidden_layer_sizes, alpha=1e-4, learning_rate_init=1e-3,
                       max_iter=5000, tol=1e-7, n_iter_no_change=50, random_state=random_state)
    return make_pipeline(TcpFeatures(robot=robot, orientation=True), StandardScaler(),
                         TransformedTargetRegressor(regressor=mlp, transformer=StandardScaler()))


def make_cartesian_idw(robot, *, power=2.0):
    """The seed's Cartesian IDW baseline: IDW on the nominal TCP position."""
    return make_pipeline(TcpFeatures(robot=robot, orientation=False), InverseDistanceWeighting(power=power))

