"""Predicting the remaining TCP error from measured poses, as scikit-learn estimators.

Every estimator here maps joint values Q (n, n_joints) [rad, m] to TCP position errors
E (n, 3) [m] (real minus nominal): ``fit(Q, E)`` returns self, ``predict(Q)`` gives (m, 3).

* :class:`JointKriging` -- the second seed's unbiased spatial interpolation in joint
  space with per-joint weights (its Eq. 14-20), one model per error axis, and its
  particle-filter search for the weights (its Fig. 11). Hand-written: no library ships
  a simple-kriging predictor whose anisotropy is searched by a particle filter (the
  Gaussian process below is the library's principled counterpart and is offered next
  to it).
* :class:`JointGaussianProcess` (``make_gaussian_process``) -- scikit-learn's
  GaussianProcessRegressor per error axis with an anisotropic RBF (one length scale per
  joint) plus a white-noise kernel, hyper-parameters by marginal likelihood from two
  starting points; ``predict(X, return_std=True)`` also gives the predictive standard
  deviation (kriging gives its kriging standard deviation the same way).
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
* :class:`DiagnosisCalibration` -- the parametric way with the whole effect library:
  :func:`tcr_accuracy.diagnosis.diagnose.diagnose` picks and fits the effects (geometry,
  compliance, gear errors, ...); predicts its fitted model minus the nominal one.
* :class:`MeasuredErrorModel` -- what the commands use: registers the tracker frame
  and the TCP offset on measured positions (:mod:`tcr_accuracy.prediction.registration`), then
  fits any estimator above to the error in the robot's base frame (what the TCP offset
  leaves of it, :class:`TcpOffset`).

:func:`make_predictor` builds an estimator by the names of :data:`METHODS`;
:func:`uncertainty_kind` says which of them give a standard deviation.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.linalg import cho_factor, cho_solve, qr, solve_triangular
from scipy.linalg.lapack import dpotrf, dtrtri
from scipy.optimize import least_squares
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin, TransformerMixin, clone
from sklearn.compose import TransformedTargetRegressor
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel
from sklearn.neural_network import MLPRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted, validate_data
from threadpoolctl import threadpool_limits

from ..model.errors import ErrorModel
from ..exceptions import InputError
from ..model.jacobians import error_jacobian
from ..model.kinematics import tcp_poses
from ..model.robot import JointLimitWarning
from ..analysis.semivariogram import empirical_semivariogram, fit_gaussian_variogram, standardize

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
        self.variograms_, ranges, weights, alphas, loo, history, chols = [], [], [], [], [], [], []
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
            chols.append(np.tril(factor[0]) if factor[1] else np.triu(factor[0]).T)
            kinv_diag = np.diag(cho_solve(factor, np.eye(n)))
            loo.append(np.sqrt(np.mean((alpha / kinv_diag) ** 2)) * (self.y_std_[k] or 1.0))
        self.range_ = np.array(ranges)
        self.weights_ = np.array(weights)
        self.alpha_ = np.array(alphas)  # (n_outputs, n)
        self.cholesky_ = np.array(chols)  # (n_outputs, n, n) lower factors of C + lambda I
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
    def predict(self, X, return_std=False):
        """Predicted errors at joint values X.

        Parameters
        ----------
        X : array-like of shape (m, n_joints)
        return_std : bool, default=False
            Also return the kriging standard deviation: ``y_std * sqrt(1 - c^T (C +
            lambda I)^-1 c)`` per output, the spread of the simple-kriging estimate under
            the unit-sill Gaussian covariance model (0 at a training point, the error's
            own spread far from all of them).

        Returns
        -------
        y_pred : ndarray of shape (m, n_outputs), or (m,) for a 1-D target
        y_std : ndarray of the same shape, only with return_std
        """
        check_is_fitted(self, "alpha_")
        X = validate_data(self, X, reset=False)
        Xs = (X - self.x_mean_) / np.where(self.x_std_ > 0, self.x_std_, 1.0)
        m, n = X.shape[0], self.X_train_std_.shape[0]
        out = np.empty((m, self.alpha_.shape[0]))
        var = np.empty((m, self.alpha_.shape[0])) if return_std else None
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
                if return_std:
                    v = solve_triangular(self.cholesky_[k], arg.T, lower=True, check_finite=False)
                    var[start:stop, k] = np.maximum(1.0 - np.einsum("ij,ij->j", v, v), 0.0)
        y_scale = np.where(self.y_std_ > 0, self.y_std_, 0.0)
        out = self.y_mean_ + out * y_scale
        if not return_std:
            return out[:, 0] if self._y_1d else out
        std = np.sqrt(var) * y_scale
        return (out[:, 0], std[:, 0]) if self._y_1d else (out, std)


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


#: Starting points of the GP's likelihood search: (signal variance, white-noise variance),
#: in units of the standardised target's variance; length scales start at 1.
GP_STARTS = {"smooth": (1.0, 1e-4), "noisy": (0.1, 0.1)}


class JointGaussianProcess(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """A Gaussian process per error axis on standardised joint values (scikit-learn's).

    Kernel: ``amplitude * k(q, q') + white noise`` with k an anisotropic RBF or Matern
    5/2 kernel (one length scale per joint), on joint values standardised to zero mean
    and unit std and targets standardised per axis. Hyper-parameters by marginal
    likelihood (scikit-learn's ``GaussianProcessRegressor``), from each of ``starts``;
    the start with the highest log marginal likelihood wins. Two starts because the
    likelihood of real data often has two optima: a smooth error field with little
    noise, and a short-range field over a large nugget; one start only finds the optimum
    of its own basin.

    Parameters
    ----------
    kernel : {"rbf", "matern52"}, default="rbf"
    length_scale_bounds : tuple of float, default=(0.05, 1000.0)
        In standardised joint units.
    noise_level_bounds : tuple of float, default=(1e-9, 1.0)
        White-noise variance bounds, in units of the target's variance.
    starts : tuple of str, default=("smooth", "noisy")
        Starting points: "smooth" (signal variance 1, noise 1e-4, length scales 1) and
        "noisy" (signal variance 0.1, noise 0.1, length scales 1).
    max_optimize_samples : int or None, default=600
        Optimise the hyper-parameters on at most this many training rows (drawn with
        random_state), then condition on all rows with them fixed; None: all rows.
        Each likelihood step costs O(n^3) and a gradient of size n^2 per length scale:
        on 1000 real UR5 poses, 600 rows took a quarter of the time of all 1000 and
        reached a log marginal likelihood (on all rows) within 0.1 %.
    n_restarts_optimizer : int, default=0
        Further random restarts per start (scikit-learn's option).
    random_state : int, RandomState or None, default=None

    Attributes
    ----------
    estimators_ : list of GaussianProcessRegressor, one per output
    kernels_ : list of the fitted kernels
    log_marginal_likelihood_ : ndarray of shape (n_outputs,)
    start_ : list of str, the winning start per output
    noise_std_ : ndarray of shape (n_outputs,)
        Fitted white-noise standard deviation [target units].
    x_mean_, x_scale_ : ndarray of shape (n_features,)
    y_mean_, y_scale_ : ndarray of shape (n_outputs,)

    Examples
    --------
    >>> import numpy as np
    >>> X = np.random.default_rng(0).uniform(-1, 1, (40, 2))
    >>> gp = JointGaussianProcess(random_state=0).fit(X, np.sin(X[:, 0]))
    >>> mean, std = gp.predict(X[:3], return_std=True)
    """

    def __init__(self, *, kernel="rbf", length_scale_bounds=(0.05, 1e3), noise_level_bounds=(1e-9, 1.0),
                 starts=("smooth", "noisy"), max_optimize_samples=600, n_restarts_optimizer=0,
                 random_state=None):
        self.kernel = kernel
        self.length_scale_bounds = length_scale_bounds
        self.noise_level_bounds = noise_level_bounds
        self.starts = starts
        self.max_optimize_samples = max_optimize_samples
        self.n_restarts_optimizer = n_restarts_optimizer
        self.random_state = random_state

    def _kernel(self, start: str, n_features: int):
        if start not in GP_STARTS:
            raise InputError(f"starts: unknown start {start!r}; choose from {', '.join(GP_STARTS)}")
        signal, noise = GP_STARTS[start]
        lower, upper = self.length_scale_bounds
        noise = float(np.clip(noise, *self.noise_level_bounds))
        if self.kernel == "rbf":
            shape = RBF(length_scale=np.ones(n_features), length_scale_bounds=(lower, upper))
        elif self.kernel == "matern52":
            shape = Matern(length_scale=np.ones(n_features), length_scale_bounds=(lower, upper), nu=2.5)
        else:
            raise InputError(f"kernel must be 'rbf' or 'matern52', got {self.kernel!r}")
        return ConstantKernel(signal, (1e-3, 1e3)) * shape + WhiteKernel(noise, self.noise_level_bounds)

    def fit(self, X, y):
        """Fit to joint values X (n, n_joints) and errors y (n,) or (n, n_outputs); returns self."""
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        if not self.starts:
            raise InputError("starts: give at least one starting point ('smooth', 'noisy')")
        self._y_1d = y.ndim == 1
        Y = y[:, None] if self._y_1d else y
        Xs, self.x_mean_, self.x_scale_ = standardize(X)
        Ys, self.y_mean_, std = standardize(Y)
        self.y_scale_ = np.where(std > 0, std, 1.0)
        n = X.shape[0]
        rng = check_random_state(self.random_state)
        rows = np.arange(n)
        if self.max_optimize_samples is not None and n > self.max_optimize_samples:
            rows = np.sort(rng.choice(n, int(self.max_optimize_samples), replace=False))
        self.estimators_, self.kernels_, self.start_, lml, noise = [], [], [], [], []
        for k in range(Ys.shape[1]):
            best = None
            for start in self.starts:
                gp = GaussianProcessRegressor(kernel=self._kernel(start, X.shape[1]), normalize_y=False,
                                              n_restarts_optimizer=self.n_restarts_optimizer,
                                              random_state=rng.randint(np.iinfo(np.int32).max))
                # one BLAS thread: on a shared 2-core machine the likelihood optimisation of
                # 600 rows took 6 s with one thread and 53 s with two (oversubscription).
                # A length scale at its upper bound is a joint the error does not depend on:
                # expected, so scikit-learn's warning about it is not passed on.
                with threadpool_limits(limits=1, user_api="blas"), warnings.catch_warnings():
                    warnings.filterwarnings("ignore", message="The optimal value found for dimension",
                                            category=ConvergenceWarning)
                    gp.fit(Xs[rows], Ys[rows, k])
                if best is None or gp.log_marginal_likelihood_value_ > best[0].log_marginal_likelihood_value_:
                    best = (gp, start)
            gp, start = best
            if rows.size < n:  # condition on every row with the hyper-parameters found
                gp = GaussianProcessRegressor(kernel=gp.kernel_, normalize_y=False, optimizer=None).fit(Xs, Ys[:, k])
            self.estimators_.append(gp)
            self.kernels_.append(gp.kernel_)
            self.start_.append(start)
            lml.append(gp.log_marginal_likelihood_value_)
            noise.append(np.sqrt(gp.kernel_.k2.noise_level) * self.y_scale_[k])
        self.log_marginal_likelihood_ = np.array(lml)
        self.noise_std_ = np.array(noise)
        return self

    def predict(self, X, return_std=False):
        """Predicted errors at X (m, n_joints), and optionally their standard deviation.

        Parameters
        ----------
        X : array-like of shape (m, n_joints)
        return_std : bool, default=False
            Also return the predictive standard deviation of a new measurement of the
            error: the Gaussian process' own spread plus its fitted white noise
            (``noise_std_``), which holds the tracker noise and whatever the robot does
            that does not vary smoothly with the joints (repeatability, drift).

        Returns
        -------
        y_pred : ndarray of shape (m, n_outputs), or (m,) for a 1-D target
        y_std : ndarray of the same shape, only with return_std
        """
        check_is_fitted(self, "estimators_")
        X = validate_data(self, X, reset=False)
        Xs = (X - self.x_mean_) / np.where(self.x_scale_ > 0, self.x_scale_, 1.0)
        mean = np.empty((X.shape[0], len(self.estimators_)))
        std = np.empty_like(mean)
        for k, gp in enumerate(self.estimators_):
            if return_std:
                mu, sd = gp.predict(Xs, return_std=True)
                std[:, k] = sd * self.y_scale_[k]
            else:
                mu = gp.predict(Xs)
            mean[:, k] = self.y_mean_[k] + mu * self.y_scale_[k]
        if not return_std:
            return mean[:, 0] if self._y_1d else mean
        return (mean[:, 0], std[:, 0]) if self._y_1d else (mean, std)


def make_gaussian_process(n_joints: int | None = None, *, random_state=None, **options) -> JointGaussianProcess:
    """The ``gp`` method: :class:`JointGaussianProcess` with its defaults (options override).

    ``n_joints`` is accepted for backward compatibility; the length scales follow the data.
    """
    return JointGaussianProcess(random_state=random_state, **options)


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
    :func:`~tcr_accuracy.model.jacobians.error_jacobian` at every training pose; a QR
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
    residual : estimator (e.g. :class:`JointGaussianProcess`)

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

    def predict(self, X):
        """(m, 3) error of the fitted offset at joint values X (m, n_joints) [m]."""
        check_is_fitted(self, "offset_")
        X = validate_data(self, X, reset=False)
        return tcp_poses(self.robot, X).rotation @ self.offset_


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
        from ..diagnosis.diagnose import diagnose
        from ..io.measurements import MeasurementSet

        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        if self.robot is None:
            raise InputError("DiagnosisCalibration needs a robot")
        if y.ndim != 2 or y.shape[1] != 3 or X.shape[1] != self.robot.n_joints:
            raise InputError(f"DiagnosisCalibration: needs joint values (n, {self.robot.n_joints}) and position "
                             f"errors (n, 3), got {X.shape} and {y.shape}")
        positions = tcp_poses(self.robot, X).position + y
        mset = MeasurementSet(joint_names=list(self.robot.joint_names), q=X, position=positions,
                              source="training errors", **_measured_context(context))
        seed = 0 if self.random_state is None else int(check_random_state(self.random_state).randint(2**31 - 1))
        effects = self.effects
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", JointLimitWarning)
            self.diagnosis_ = diagnose(self.robot, mset, effects=effects, folds=self.folds, seed=seed,
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
            # the diagnosis predicts in the frame of the positions it was given: here the base frame
            return self.diagnosis_.predict(self.robot, X, context) - tcp_poses(self.robot, X).position


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


def uncertainty_kind(estimator) -> str | None:
    """What ``predict(X, return_std=True)`` of a fitted estimator gives, or None.

    "kriging standard deviation", "Gaussian process predictive standard deviation",
    the residual model's (for :class:`ResidualCorrected`) or None.
    """
    if isinstance(estimator, JointKriging):
        return "kriging standard deviation"
    if isinstance(estimator, JointGaussianProcess):
        return "Gaussian process predictive standard deviation"
    if isinstance(estimator, ResidualCorrected):
        model = getattr(estimator, "residual_", estimator.residual)
        return uncertainty_kind(model)
    if isinstance(estimator, MeasuredErrorModel):
        return uncertainty_kind(getattr(estimator, "error_model_", estimator.estimator))
    return None


class MeasuredErrorModel(BaseEstimator):
    """An error predictor fitted to measured TCP positions in a tracker's own frame.

    ``fit(X, P)`` first registers the tracker frame and the TCP offset on the training
    data (:func:`tcr_accuracy.prediction.registration.register_tracker`), maps the measured
    positions into the robot's base frame, and fits ``estimator`` to what the TCP
    offset leaves of the error there; the base-frame error is then
    ``TCP offset term + estimator``. ``predict`` maps the predicted real TCP back to
    the tracker frame, so it predicts what the tracker will read.

    Parameters
    ----------
    robot : RobotModel
    estimator : estimator
        ``fit(Q (n, n_joints), E (n, 3))`` / ``predict(Q) -> (m, 3)`` on base-frame
        errors [m] (any of :data:`METHODS` by :func:`make_predictor`).
    fit_frame : bool, default=True
        Fit the tracker frame. False: the measured positions are in the base frame
        already (only the TCP offset is fitted).

    Attributes
    ----------
    registration_ : tcr_accuracy.prediction.registration.Registration
    errors_ : ndarray of shape (n, 3)
        Training errors, real minus nominal TCP position in the base frame [m].
    error_model_ : ResidualCorrected
        TCP offset plus the fitted estimator; ``error_model_.predict(Q)`` gives the
        base-frame error (m, 3) [m].
    """

    def __init__(self, *, robot=None, estimator=None, fit_frame=True):
        self.robot = robot
        self.estimator = estimator
        self.fit_frame = fit_frame

    def fit(self, X, y, context=None):
        """Joint values X (n, n_joints) [rad, m], measured positions y (n, 3) in the tracker frame [m];
        ``context``: the rows' MeasurementContext, for the estimators that take one."""
        from .registration import register_tracker

        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        if self.robot is None or self.estimator is None:
            raise InputError("MeasuredErrorModel needs a robot and an estimator")
        self.registration_ = register_tracker(self.robot, X, y, fit_base=self.fit_frame)
        self.errors_ = self.registration_.to_base(y) - tcp_poses(self.robot, X).position
        self.error_model_ = ResidualCorrected(base=TcpOffset(robot=self.robot), residual=self.estimator)
        self.error_model_.fit(X, self.errors_, context=context)
        return self

    def predict_error(self, X, return_std=False, context=None):
        """Base-frame error (real minus nominal TCP position) at X (m, n_joints) [m].

        With return_std, also its standard deviation (m, 3), or None when the
        estimator has none (see :func:`uncertainty_kind`).
        """
        check_is_fitted(self, "error_model_")
        return self.error_model_.predict(X, return_std=return_std, context=context)

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
        check_is_fitted(self, "error_model_")
        X = validate_data(self, X, reset=False)
        measured = self.registration_.to_base(np.asarray(y, dtype=float)) - tcp_poses(self.robot, X).position
        return measured - self.predict_error(X, context=context)


METHODS = ("kriging", "kriging-pf", "gp", "idw-joint", "idw-cartesian", "mlp-cartesian", "calibration",
           "calibration+gp", "diagnosis", "diagnosis+gp")

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
    if method == "diagnosis":
        return DiagnosisCalibration(robot=robot, random_state=random_state)
    if method == "diagnosis+gp":
        return ResidualCorrected(base=DiagnosisCalibration(robot=robot, random_state=random_state),
                                 residual=make_gaussian_process(robot.n_joints, random_state=random_state))
    raise InputError(f"unknown prediction method {method!r}; choose one of {', '.join(METHODS)}")
