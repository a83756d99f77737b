"""A Gaussian process per error axis in joint space: scikit-learn's, with two likelihood starts.

:class:`JointGaussianProcess` (the ``gp`` method, :func:`make_gaussian_process`) is
scikit-learn's GaussianProcessRegressor per error axis with an anisotropic RBF or Matern
kernel (one length scale per joint) plus white noise; ``predict(X, return_std=True)`` also
gives the predictive standard deviation. Joint values in [rad, m], errors in the targets'
units (metres in use).
"""

from __future__ import annotations

import warnings

import numpy as np
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted, validate_data
from threadpoolctl import threadpool_limits

from ..analysis.semivariogram import standardize
from ..exceptions import InputError

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

    def standardise(self, X) -> np.ndarray:
        """Joint values in the standardised units the fitted kernels' length scales are in."""
        return (X - self.x_mean_) / np.where(self.x_scale_ > 0, self.x_scale_, 1.0)

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
        Xs = self.standardise(X)
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
