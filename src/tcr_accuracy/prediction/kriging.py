"""Joint-weighted simple kriging: the second seed's predictor of the TCP error in joint space.

:class:`JointKriging` is the seed's unbiased spatial interpolation with per-joint weights
(its Eq. 14-20), one model per error axis, and its particle-filter search for the weights
(its Fig. 11). Hand-written: no library ships a simple-kriging predictor whose anisotropy is
searched by a particle filter (:mod:`.gaussian_process` is the library's principled
counterpart). Joint values in [rad, m], errors in the targets' units (metres in use).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.linalg.lapack import dpotrf, dtrtri
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin
from sklearn.utils.validation import check_is_fitted, validate_data
from threadpoolctl import threadpool_limits

from ..analysis.semivariogram import empirical_semivariogram, fit_gaussian_variogram, standardize
from ..exceptions import InputError
from .checks import check_enough_points

_CHUNK = 1024  # query rows per block in JointKriging.predict (keeps the block in cache)


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
        check_enough_points(n, d, type(self).__name__)
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
