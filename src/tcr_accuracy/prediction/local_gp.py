"""Gaussian processes of local neighbourhoods in joint space, for training sets of 10^4-10^6 poses.

A Gaussian process conditioned on n poses holds an n x n covariance: 80 GB at 10^5 poses.
:class:`LocalGaussianProcess` (the ``local-gp`` method) keeps the part of it that matters
for a prediction: the kernel's hyper-parameters are learnt once, by marginal likelihood
on a random subset (:class:`~tcr_accuracy.prediction.gaussian_process.JointGaussianProcess`),
the training poses are covered by overlapping neighbourhoods (the ``expert_size`` poses
nearest to each of k-means' centres in standardised joint space, about two neighbourhoods
per pose), and a query is answered by the Gaussian process of the neighbourhood whose
centre is nearest, conditioned on its poses only (a "local experts" approximation: the
kernel's length scales are shorter than the neighbourhoods, so the poses left out
carry almost no weight). The neighbourhood models are built when a query needs them and
dropped after, so memory stays at a few expert_size^2 matrices whatever n is.

scikit-learn has no sparse or local Gaussian process; this composes its
``GaussianProcessRegressor``, ``MiniBatchKMeans`` and ``NearestNeighbors``.
Joint values in [rad, m], errors in the targets' units (metres in use).
"""

from __future__ import annotations

import math

import numpy as np
from sklearn.base import BaseEstimator, MultiOutputMixin, RegressorMixin
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted, validate_data
from threadpoolctl import threadpool_limits

from .gaussian_process import JointGaussianProcess


class LocalGaussianProcess(MultiOutputMixin, RegressorMixin, BaseEstimator):
    """A Gaussian process per error axis, conditioned on the neighbourhood of each query.

    Parameters
    ----------
    expert_size : int, default=600
        Training poses per neighbourhood. With at most this many poses in all, one
        Gaussian process on all of them (the ``gp`` method with the same kernel).
    coverage : float, default=2.0
        Neighbourhoods per training pose on average: ``coverage * n / expert_size`` centres.
    max_optimize_samples : int, default=600
        Rows the kernel's hyper-parameters are learnt on (see JointGaussianProcess).
    kernel : {"rbf", "matern52"}, default="rbf"
    random_state : int, RandomState or None, default=None

    Attributes
    ----------
    hyper_ : JointGaussianProcess, fitted on a random subset: the kernels and the
        standardisation of joints and errors
    centres_ : ndarray (n_experts, n_features), standardised joint values
    members_ : ndarray (n_experts, expert_size) of training row indices
    noise_std_ : ndarray (n_outputs,), the fitted white noise [target units]
    """

    def __init__(self, *, expert_size=600, coverage=2.0, max_optimize_samples=600, kernel="rbf",
                 random_state=None):
        self.expert_size = expert_size
        self.coverage = coverage
        self.max_optimize_samples = max_optimize_samples
        self.kernel = kernel
        self.random_state = random_state

    def fit(self, X, y):
        """Fit to joint values X (n, n_joints) and errors y (n,) or (n, n_outputs); returns self."""
        from sklearn.cluster import MiniBatchKMeans
        from sklearn.neighbors import NearestNeighbors

        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True)
        self._y_1d = y.ndim == 1
        Y = y[:, None] if self._y_1d else y
        n = X.shape[0]
        rng = check_random_state(self.random_state)
        subset = np.sort(rng.choice(n, min(n, self.expert_size), replace=False))
        self.hyper_ = JointGaussianProcess(kernel=self.kernel, max_optimize_samples=self.max_optimize_samples,
                                           random_state=rng.randint(np.iinfo(np.int32).max)).fit(X[subset], Y[subset])
        self.noise_std_ = self.hyper_.noise_std_
        self._X, self._Y = self.hyper_.standardise(X), (Y - self.hyper_.y_mean_) / self.hyper_.y_scale_
        size = min(n, int(self.expert_size))
        if n <= size:
            self.centres_ = self._X.mean(axis=0, keepdims=True)
            self.members_ = np.arange(n)[None]
            return self
        n_experts = max(2, math.ceil(self.coverage * n / size))
        kmeans = MiniBatchKMeans(n_clusters=n_experts, n_init=1, batch_size=4096,
                                 random_state=rng.randint(np.iinfo(np.int32).max)).fit(self._X)
        self.centres_ = kmeans.cluster_centers_
        self.members_ = NearestNeighbors(n_neighbors=size).fit(self._X).kneighbors(
            self.centres_, return_distance=False)
        return self

    def predict(self, X, return_std=False):
        """Predicted errors at X (m, n_joints), and optionally their standard deviation
        (the neighbourhood model's predictive spread of a new measurement, fitted white
        noise included, as JointGaussianProcess gives it)."""
        from sklearn.neighbors import NearestNeighbors

        check_is_fitted(self, "members_")
        X = validate_data(self, X, reset=False)
        Xs = self.hyper_.standardise(X)
        expert = NearestNeighbors(n_neighbors=1).fit(self.centres_).kneighbors(Xs, return_distance=False)[:, 0]
        n_out = self._Y.shape[1]
        mean, std = np.empty((X.shape[0], n_out)), np.empty((X.shape[0], n_out))
        for e in np.unique(expert):
            queries, rows = expert == e, self.members_[e]
            for k, kernel in enumerate(self.hyper_.kernels_):
                # the learnt kernel, conditioned on this neighbourhood only (no optimisation)
                gp = GaussianProcessRegressor(kernel=kernel, normalize_y=False, optimizer=None)
                with threadpool_limits(limits=1, user_api="blas"):
                    gp.fit(self._X[rows], self._Y[rows, k])
                    mu, sd = gp.predict(Xs[queries], return_std=True)
                mean[queries, k] = self.hyper_.y_mean_[k] + mu * self.hyper_.y_scale_[k]
                std[queries, k] = sd * self.hyper_.y_scale_[k]
        if self._y_1d:
            mean, std = mean[:, 0], std[:, 0]
        return (mean, std) if return_std else mean
