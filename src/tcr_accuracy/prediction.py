"""Predicting the remaining TCP error from measured poses, as scikit-learn estimators.

Every estimator here maps joint values Q (n, n_joints) [rad, m] to TCP position errors
E (n, 3) [m] (real minus nominal): ``fit(Q, E)`` returns self, ``predict(Q)`` gives (m, 3).

* :class:`JointKriging` -- the second seed's unbiased spatial interpolation in joint
  space with per-joint weights (its Eq. 14-20), one model per error axis, and its
  particle-filter search for the weights (its Fig. 11). Hand-written: no library ships
  a simple-kriging predictor whose anisotropy is searched by a particle filter (the
  Gaussian process below is the library's principled counterpart and is offered next
  to it).
* :func:`make_gaussian_process` -- scikit-learn's GaussianProcessRegressor with an
  anisotropic RBF (one length scale per joint, per error axis) plus a white-noise
  kernel, hyper-parameters by marginal likelihood.
* :class:`InverseDistanceWeighting` -- Shepard interpolation, hand-written because
  scikit-learn's nearest-neighbour regressor with ``weights="distance"`` fixes the
  power at 1 and IDW with a power is a few lines.
* :func:`make_cartesian_mlp`, :func:`make_cartesian_idw` -- what Cartesian-space methods
  see: the nominal TCP position (and orientation) from :class:`TcpFeatures`, then
  scikit-learn's MLPRegressor or the IDW above.
* :class:`GeometricCalibration` -- the parametric way: least squares of the
  identifiable geometric error parameters (``jacobians.error_jacobian`` gives the
  identification Jacobian, a pivoted QR picks the identifiable columns, scipy solves),
  optionally with a Gaussian process on its residual (:class:`ResidualCorrected`).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve, qr
from scipy.linalg.lapack import dpotrf, dtrtri
from scipy.optimize import least_squares
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin, TransformerMixin, clone
from sklearn.compose import TransformedTargetRegressor
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
from sklearn.multioutput import MultiOutputRegressor
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.validation import check_is_fitted, validate_data
from threadpoolctl import threadpool_limits

from .errors import ErrorModel
from .exceptions import InputError
from .jacobians import error_jacobian
from .kinematics import tcp_poses
from .semivariogram import empirical_semivariogram, fit_gaussian_variogram, standardize

_CHUNK = 1024  # query rows per block in JointKriging.predict (keeps the block in cache)


def _check_enough_points(n_samples: int, n_features: int, who: str) -> None:
    if n_samples <= n_features:
        raise InputError(
            f"{who}: needs more training points than joints, got n_samples = {n_samples} for "
            f"{n_features} joints; measure at least {n_features + 1} (the seed used 160 for 6)")


def _sq_diffs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(d, n_a, n_b) squared coordinate differences."""
    return (a.T[:, :, None] - b.T[:, None, :]) ** 2


class JointKriging(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """Joint-weighted simple kriging of each error axis in standardised joint space.

    For error axis k with joint weights w (n_joints,) and Gaussian-variogram range r
    (fitted to the empirical semivariogram of the standardised data), the covariance
    of two poses is ``exp(-3 |w * (qs_i - qs_j)|^2 / r^2)`` (qs standardised joints);
    the prediction at q is ``c(q)^T (C + lambda I)^-1 es_k`` on the standardised
    errors, mapped back to metres.

    Parameters
    ----------
    weights : None, array of shape (n_joints,) or (n_outputs, n_joints)
        Joint weights (the start of the search when it runs); None: all ones.
    regularization : float
        lambda added to the covariance diagonal (standardised error variance units);
        0 interpolates the training points exactly.
    n_bins : int
        Bins of the empirical semivariogram the range is fitted to.
    weight_search : None or "particle_filter"
        Search the weights per error axis with the seed's particle filter; a particle's
        importance is the Gaussian likelihood of its leave-one-out prediction error on
        the training data (closed form, so no held-out data and never the test set).
    n_particles, max_iter, sigma_init : particle filter size, iterations and the
        initial std of the particles around the starting weights.
    random_fraction : share of each generation replaced by fresh random particles.
    tol : stop when the mean leave-one-out RMS error of the swarm (standardised units)
        falls below this.
    patience : also stop when the best particle has not improved for this many
        iterations (None: run to max_iter).
    random_state : int, Generator or None
        Seed of the particle filter.

    Attributes
    ----------
    weights_ : (n_outputs, n_joints) the joint weights used
    range_ : (n_outputs,) fitted variogram ranges (standardised joint units)
    variograms_ : list of fitted GaussianVariogram, one per output
    loo_rmse_ : (n_outputs,) leave-one-out RMS error of the final model [target units]
    search_history_ : list (per output) of best LOO error per iteration, or None
    n_iter_ : (n_outputs,) particle-filter iterations run (1: the single direct solve)
    """

    def __init__(self, *, weights=None, regularization=1e-4, n_bins=20, weight_search=None,
                 n_particles=60, max_iter=40, sigma_init=0.3, random_fraction=0.2, tol=0.0,
                 patience=10, random_state=None):
        self.weights = weights
        self.regularization = regularization
        self.n_bins = n_bins
        self.weight_search = weight_search
        self.n_particles = n_particles
        self.max_iter = max_iter
        self.sigma_init = sigma_init
        self.random_fraction = random_fraction
        self.tol = tol
        self.patience = patience
        self.random_state = random_state

    # -- fit -------------------------------------------------------------------------
    def fit(self, X, y):
        """Fit to joint values X (n, n_joints) and errors y (n,) or (n, n_outputs)."""
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        n, d = X.shape
        _check_enough_points(n, d, type(self).__name__)
        if self.weight_search not in (None, "particle_filter"):
            raise InputError(f"weight_search must be None or 'particle_filter', got {self.weight_search!r}")
        if self.regularization < 0:
            raise InputError(f"regularization must be >= 0, got {self.regularization}")
        self._y_1d = y.ndim == 1
        Y = y[:, None] if self._y_1d else y
        n_out = Y.shape[1]
        Xs, self.x_mean_, self.x_std_ = standardize(X)
        Ys, self.y_mean_, self.y_std_ = standardize(Y)
        self.X_train_std_ = Xs
        start = self._initial_weights(n_out, d)
        sq = _sq_diffs(Xs, Xs)
        rng = np.random.default_rng(self.random_state)
        self.variograms_, ranges, weights, alphas, loo, history = [], [], [], [], [], []
        for k in range(n_out):
            emp = empirical_semivariogram(Xs * start[k], Ys[:, k], n_bins=self.n_bins, standardise=False)
            vg = fit_gaussian_variogram(emp, 0)
            self.variograms_.append(vg)
            ranges.append(vg.range_)
            w = start[k]
            hist = None
            if self.weight_search == "particle_filter":
                # thousands of small (n x n) factorisations: BLAS threads only add overhead
                # (as scikit-learn's KMeans does, limit them for the loop)
                with threadpool_limits(limits=1, user_api="blas"):
                    w, hist = self._particle_filter(sq, Ys[:, k], w, vg.range_, rng)
            weights.append(w)
            history.append(hist)
            kmat = self._cov(sq, w, vg.range_) + self.regularization * np.eye(n)
            try:
                factor = cho_factor(kmat)
            except np.linalg.LinAlgError:
                raise InputError(self._singular_message(X)) from None
            alpha = cho_solve(factor, Ys[:, k])
            if not np.all(np.isfinite(alpha)):
                raise InputError(self._singular_message(X))
            alphas.append(alpha)
            kinv_diag = np.diag(cho_solve(factor, np.eye(n)))
            loo.append(np.sqrt(np.mean((alpha / kinv_diag) ** 2)) * (self.y_std_[k] or 1.0))
        self.range_ = np.array(ranges)
        self.weights_ = np.array(weights)
        self.alpha_ = np.array(alphas)  # (n_outputs, n)
        self.loo_rmse_ = np.array(loo)
        self.search_history_ = history if self.weight_search else None
        self.n_iter_ = np.array([len(h) if h else 1 for h in history])
        return self

    def _initial_weights(self, n_out: int, d: int) -> np.ndarray:
        if self.weights is None:
            return np.ones((n_out, d))
        w = np.asarray(self.weights, dtype=float)
        if w.ndim == 1 and w.size == d:
            w = np.broadcast_to(w, (n_out, d))
        if w.shape != (n_out, d) or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise InputError(f"weights: expected non-negative values of shape ({d},) or ({n_out}, {d}), "
                             f"got {np.shape(self.weights)}")
        return np.array(w)

    @staticmethod
    def _cov(sq: np.ndarray, w: np.ndarray, range_: float) -> np.ndarray:
        return np.exp(-3.0 * np.tensordot(w**2, sq, axes=1) / range_**2)

    def _singular_message(self, X) -> str:
        _, first, counts = np.unique(X, axis=0, return_index=True, return_counts=True)
        dup = first[counts > 1]
        where = f" (e.g. training row {int(dup[0])} appears {int(counts[counts > 1][0])} times)" if dup.size else ""
        return ("kriging covariance is singular: duplicate or nearly identical joint vectors"
                f"{where}; remove duplicates or set regularization > 0")

    def _loo_rmse(self, sq, e, w, range_) -> float:
        n = e.size
        kmat = self._cov(sq, w, range_) + max(self.regularization, 1e-10) * np.eye(n)
        chol, info = dpotrf(kmat, lower=True, overwrite_a=True)  # K = L L^T (LAPACK)
        if info != 0:
            return np.inf
        linv, info = dtrtri(chol, lower=True)
        if info != 0:
            return np.inf
        # K^-1 = L^-T L^-1: its diagonal is the column sums of squares of L^-1
        kinv_diag = np.einsum("ij,ij->j", linv, linv)
        alpha = linv.T @ (linv @ e)
        # leave-one-out residuals of a linear smoother in closed form: (K^-1 e)_i / (K^-1)_ii
        value = float(np.sqrt(np.mean((alpha / kinv_diag) ** 2)))
        return value if np.isfinite(value) else np.inf

    def _particle_filter(self, sq, e, w_init, range_, rng):
        """The seed's Fig. 11: importance from the LOO error, resampling plus random particles."""
        d = w_init.size
        n_p = max(int(self.n_particles), 4)
        n_random = int(round(self.random_fraction * n_p))
        particles = np.abs(rng.normal(w_init, self.sigma_init, (n_p, d)))
        particles[0] = w_init
        best_w, best_err = w_init.copy(), self._loo_rmse(sq, e, w_init, range_)
        history = []
        for it in range(int(self.max_iter)):
            errs = np.array([self._loo_rmse(sq, e, p, range_) for p in particles])
            i = int(np.argmin(errs))
            if errs[i] < best_err:
                best_err, best_w = float(errs[i]), particles[i].copy()
            history.append(best_err)
            finite = np.isfinite(errs)
            if finite.any() and errs[finite].mean() < self.tol:
                break
            if (self.patience is not None and len(history) > self.patience
                    and history[-1 - self.patience] <= history[-1] * (1 + 1e-6)):
                break
            spread = errs[finite].std() if finite.sum() > 1 else 1.0
            like = np.where(finite, np.exp(-0.5 * ((errs - errs[finite].min()) / max(spread, 1e-12)) ** 2), 0.0)
            if like.sum() <= 0:
                like = np.ones(n_p)
            prob = like / like.sum()
            # systematic resampling, then a shrinking multiplicative jitter
            positions = (rng.random() + np.arange(n_p - n_random)) / (n_p - n_random)
            idx = np.minimum(np.searchsorted(np.cumsum(prob), positions), n_p - 1)
            jitter = self.sigma_init * 0.5 * 0.9**it
            kept = particles[idx] * np.exp(rng.normal(0.0, jitter, (idx.size, d)))
            fresh = np.abs(rng.normal(best_w, 2 * self.sigma_init, (n_random, d)))
            particles = np.vstack([kept, fresh])
            particles[0] = best_w
        return best_w, history

    # -- predict -----------------------------------------------------------------------
    def predict(self, X):
        """Predicted errors at joint values X (m, n_joints) -> (m, n_outputs) (or (m,))."""
        check_is_fitted(self, "alpha_")
        X = validate_data(self, X, reset=False)
        Xs = (X - self.x_mean_) / np.where(self.x_std_ > 0, self.x_std_, 1.0)
        m, n = X.shape[0], self.X_train_std_.shape[0]
        out = np.empty((m, self.alpha_.shape[0]))
        buffer = np.empty((min(m, _CHUNK), n))
        for k in range(self.alpha_.shape[0]):
            # scale so that exp(arg) is the covariance: arg = -3 |w (x - x')|^2 / r^2, written as
            # 2 a.b - |a|^2 - |b|^2 so that the (m, n) work is one BLAS product and in-place
            # passes over cache-sized chunks
            scale = self.weights_[k] * np.sqrt(3.0) / self.range_[k]
            a, b = Xs * scale, self.X_train_std_ * scale
            a_sq, b_sq, b2 = (a**2).sum(1), (b**2).sum(1), 2.0 * b.T
            for start in range(0, m, _CHUNK):
                stop = min(start + _CHUNK, m)
                arg = buffer[: stop - start]
                np.matmul(a[start:stop], b2, out=arg)
                arg -= a_sq[start:stop, None]
                arg -= b_sq
                np.minimum(arg, 0.0, out=arg)
                np.exp(arg, out=arg)
                out[start:stop, k] = arg @ self.alpha_[k]
        out = self.y_mean_ + out * np.where(self.y_std_ > 0, self.y_std_, 0.0)
        return out[:, 0] if self._y_1d else out


class InverseDistanceWeighting(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """Shepard's inverse distance weighting on standardised features.

    ``y(x) = sum_i d_i^-p y_i / sum_i d_i^-p`` over all training points; a query that
    coincides with a training point returns its value.

    Parameters
    ----------
    power : float, the exponent p
    """

    def __init__(self, *, power=2.0):
        self.power = power

    def fit(self, X, y):
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        _check_enough_points(X.shape[0], X.shape[1], type(self).__name__)
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


def make_gaussian_process(n_joints: int, *, random_state=None, n_restarts_optimizer=0):
    """scikit-learn GP per error axis: ConstantKernel * anisotropic RBF (one length scale
    per joint) + WhiteKernel on standardised joint values, targets normalised, hyper-
    parameters by marginal likelihood. In: (n, n_joints); out: (n, n_outputs)."""
    kernel = (ConstantKernel(1.0, (1e-3, 1e3))
              * RBF(length_scale=np.ones(n_joints), length_scale_bounds=(1e-2, 1e3))
              + WhiteKernel(1e-4, (1e-9, 1e0)))
    gp = GaussianProcessRegressor(kernel=kernel, normalize_y=True, n_restarts_optimizer=n_restarts_optimizer,
                                  random_state=random_state)
    return make_pipeline(StandardScaler(), MultiOutputRegressor(gp))


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


class GeometricCalibration(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """Least squares of the identifiable geometric error parameters from position errors.

    The identification Jacobian stacks the position rows of
    :func:`~tcr_accuracy.jacobians.error_jacobian` at every training pose; a QR
    decomposition with column pivoting of its column-normalised form keeps the
    identifiable parameters (|R_ii| > rank_tol |R_00|); scipy's least_squares then fits
    them on the exact (nonlinear) forward kinematics. Predicts ``FK_x(q) - FK(q)``.

    Parameters
    ----------
    robot : RobotModel
    rank_tol : float, relative pivot threshold of the identifiability test

    Attributes
    ----------
    x_ : (n_params,) fitted error vector (zeros for unidentifiable parameters)
    identifiable_ : (r,) indices of the fitted parameters
    parameter_names_ : names of the fitted parameters
    """

    def __init__(self, *, robot=None, rank_tol=1e-6):
        self.robot = robot
        self.rank_tol = rank_tol

    def fit(self, X, y):
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        if self.robot is None:
            raise InputError("GeometricCalibration needs a robot")
        if y.ndim != 2 or y.shape[1] != 3 or X.shape[1] != self.robot.n_joints:
            raise InputError(f"GeometricCalibration: needs joint values (n, {self.robot.n_joints}) and "
                             f"position errors (n, 3), got {X.shape} and {y.shape}")
        em = ErrorModel(self.robot)
        jac = np.vstack([error_jacobian(self.robot, q, em)[:3] for q in X])  # (3n, p)
        norms = np.linalg.norm(jac, axis=0)
        usable = np.flatnonzero(norms > 1e-12)
        _, r, piv = qr(jac[:, usable] / norms[usable], mode="economic", pivoting=True)
        diag = np.abs(np.diag(r))
        rank = int((diag > self.rank_tol * diag[0]).sum())
        ident = np.sort(usable[piv[:rank]])
        if 3 * X.shape[0] < rank:
            raise InputError(f"GeometricCalibration: {X.shape[0]} poses give {3 * X.shape[0]} equations for "
                             f"{rank} identifiable parameters; measure more poses")
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


class ResidualCorrected(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """A base model plus a second model fitted to its residual: ``base(X) + residual(X)``.

    Parameters
    ----------
    base : estimator (e.g. GeometricCalibration)
    residual : estimator (e.g. the Gaussian process of make_gaussian_process)
    """

    def __init__(self, *, base=None, residual=None):
        self.base = base
        self.residual = residual

    def fit(self, X, y):
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        self.base_ = clone(self.base).fit(X, y)
        self.residual_ = clone(self.residual).fit(X, y - self.base_.predict(X))
        return self

    def predict(self, X):
        check_is_fitted(self, "base_")
        X = validate_data(self, X, reset=False)
        return self.base_.predict(X) + self.residual_.predict(X)


METHODS = ("kriging", "kriging-pf", "gp", "idw-joint", "idw-cartesian", "mlp-cartesian", "calibration",
           "calibration+gp")


def make_predictor(method: str, robot, *, random_state=None):
    """A fresh estimator by name (see METHODS)."""
    if method == "kriging":
        return JointKriging()
    if method == "kriging-pf":
        return JointKriging(weight_search="particle_filter", random_state=random_state)
    if method == "gp":
        return make_gaussian_process(robot.n_joints, random_state=random_state)
    if method == "idw-joint":
        return InverseDistanceWeighting()
    if method == "idw-cartesian":
        return make_cartesian_idw(robot)
    if method == "mlp-cartesian":
        return make_cartesian_mlp(robot, random_state=random_state)
    if method == "calibration":
        return GeometricCalibration(robot=robot)
    if method == "calibration+gp":
        return ResidualCorrected(base=GeometricCalibration(robot=robot),
                                 residual=make_gaussian_process(robot.n_joints, random_state=random_state))
    raise InputError(f"unknown prediction method {method!r}; choose one of {', '.join(METHODS)}")
