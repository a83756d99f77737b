"""Semivariograms of TCP errors in configuration (joint) space.

How similar are the errors of two poses whose joint values are a distance h apart?
The empirical semivariance of error component e over the pairs (i, k) with h_ik in a
bin is ``gamma(h) = sum (e_i - e_k)^2 / (2 N_bin)``. Joint values and errors are
standardised first (zero mean, unit std per column), so that joints of different
ranges and errors of different axes compare; then a spatially uncorrelated error
has gamma ~ 1 at every lag, and an error that varies smoothly with the joints has
gamma -> 0 as h -> 0.

Along one joint (``joint=j``) the distance is ``|q_ij - q_kj|`` of standardised values:
along which joints does the error vary?

The Gaussian model ``gamma(h) = nugget + sill * (1 - exp(-3 h^2 / range^2))`` is
fitted by weighted least squares (scipy). Used by ``diagnose`` (is structure left in
the residual?) and ``prediction`` (kriging in joint space). No library ships
variograms over arbitrary joint distances with per-dimension variants, hence the
small hand-written core; distances come from scipy.spatial.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist

from ..exceptions import InputError


def nearest_neighbours(points: np.ndarray, k: int) -> np.ndarray:
    """(n, k) indices of each point's k nearest other points among points (n, d), nearest first.

    The k + 1 nearest of each point (itself at distance 0 first) from scipy's k-d tree, without
    the first: what ``NearestNeighbors(n_neighbors=k + 1).fit(points).kneighbors(points)[:, 1:]``
    gives (the same indices where no two distances tie), in a tenth of its time for the few
    dimensions the diagnosis asks about (one joint, two, all six), and without scikit-learn's
    thread pool around each query. A point with a duplicate may keep itself and drop the duplicate
    (either sits at distance 0), as scikit-learn's did.
    """
    points = np.asarray(points, dtype=float)
    _, index = cKDTree(points).query(points, k=k + 1)
    return np.asarray(index, dtype=np.intp).reshape(points.shape[0], k + 1)[:, 1:]


def standardize(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Columns of values (n, k) to zero mean and unit std; constant columns stay 0.

    Returns (standardised (n, k), mean (k,), std (k,)).
    """
    values = np.asarray(values, dtype=float)
    mean = values.mean(axis=0)
    std = values.std(axis=0)
    safe = np.where(std > 0, std, 1.0)
    return (values - mean) / safe, mean, std


@dataclass(frozen=True)
class EmpiricalSemivariogram:
    """Binned semivariance.

    lags : (n_bins,) mean pair distance in each bin (standardised joint units)
    semivariance : (n_bins, k) gamma per error column
    counts : (n_bins,) number of pairs per bin (empty bins are dropped)
    joint : index of the joint the distance runs along, or None for all joints
    """

    lags: np.ndarray
    semivariance: np.ndarray
    counts: np.ndarray
    joint: int | None


def empirical_semivariogram(q: np.ndarray, errors: np.ndarray, n_bins: int = 20, joint: int | None = None,
                            standardise: bool = True, max_pairs: int = 2_000_000,
                            rng: np.random.Generator | None = None) -> EmpiricalSemivariogram:
    """Empirical semivariogram of errors (n, k) over joint values q (n, n_joints).

    Parameters
    ----------
    q : array-like of shape (n, n_joints), joint values [rad, m]
    errors : array-like of shape (n, k), e.g. TCP position errors (n, 3)
    n_bins : equal-width distance bins between the smallest and largest distance
    joint : distance along this joint only, or over all joints (None)
    standardise : standardise q and errors column-wise first
    max_pairs : above this many pairs, this many pairs drawn at random are used: i uniform over the
        points, then k uniform over the others (rng, in that order)
    """
    q = np.asarray(q, dtype=float)
    errors = np.asarray(errors, dtype=float)
    if errors.ndim == 1:
        errors = errors[:, None]
    if q.ndim != 2 or errors.shape[0] != q.shape[0]:
        raise InputError(f"semivariogram: q {q.shape} and errors {errors.shape} must have the same rows")
    if q.shape[0] < 3:
        raise InputError(f"semivariogram: needs at least 3 points, got {q.shape[0]}")
    if n_bins < 1:
        raise InputError(f"semivariogram: n_bins must be >= 1, got {n_bins}")
    if standardise:
        q, _, _ = standardize(q)
        errors, _, _ = standardize(errors)
    if joint is not None:
        q = q[:, [joint]]
    n = q.shape[0]
    if n * (n - 1) // 2 > max_pairs:
        # draw the pairs, not all n^2/2 distances (10^5 poses would need 40 GB for them)
        rng = rng or np.random.default_rng(0)
        i = rng.integers(0, n, max_pairs)
        k = rng.integers(0, n - 1, max_pairs)
        k += k >= i  # a pose other than i, uniformly
        # one coordinate at a time, as 1-D takes (numpy's fast gather; the rows of a (n, d) array were
        # gathered five times slower), the squares summed in the order np.sum(axis=1) adds a row's: the same
        # floats as the (pairs, d) differences summed per row
        distance = None
        for column in q.T:
            difference = column.take(i)
            difference -= column.take(k)
            np.square(difference, out=difference)
            if distance is None:
                distance = difference
            else:
                distance += difference
        np.sqrt(distance, out=distance)
        halves = []
        for column in errors.T:
            half = column.take(i)
            half -= column.take(k)
            np.square(half, out=half)
            half *= 0.5
            halves.append(half)
    else:
        distance = pdist(q)
        i, k = np.triu_indices(n, 1)
        squared = errors[i]
        squared -= errors[k]
        np.square(squared, out=squared)
        squared *= 0.5
        halves = [squared[:, c] for c in range(errors.shape[1])]
    edges = np.linspace(distance.min(), distance.max(), n_bins + 1)
    which = np.searchsorted(edges, distance, side="right")  # >= 1: the first edge is the smallest distance
    which -= 1
    np.minimum(which, n_bins - 1, out=which)
    counts = np.bincount(which, minlength=n_bins)
    lag_sum = np.bincount(which, weights=distance, minlength=n_bins)
    gamma = np.stack([np.bincount(which, weights=half, minlength=n_bins) for half in halves], axis=1)
    used = counts > 0
    return EmpiricalSemivariogram(
        lags=lag_sum[used] / counts[used],
        semivariance=gamma[used] / counts[used][:, None],
        counts=counts[used],
        joint=joint,
    )


def per_joint_semivariograms(q: np.ndarray, errors: np.ndarray, n_bins: int = 20,
                             **kwargs) -> list[EmpiricalSemivariogram]:
    """One semivariogram along each joint (the seed's Fig. 10b-d), shapes as above."""
    return [empirical_semivariogram(q, errors, n_bins, joint=j, **kwargs) for j in range(np.shape(q)[1])]


@dataclass(frozen=True)
class GaussianVariogram:
    """gamma(h) = nugget + sill * (1 - exp(-3 h^2 / range^2)), h in standardised joint units."""

    nugget: float
    sill: float
    range_: float

    def __call__(self, h: np.ndarray) -> np.ndarray:
        h = np.asarray(h, dtype=float)
        return self.nugget + self.sill * (1.0 - np.exp(-3.0 * h**2 / self.range_**2))

    @property
    def nugget_ratio(self) -> float:
        """nugget / (nugget + sill): 1 = no spatial structure, 0 = smooth in joint space."""
        total = self.nugget + self.sill
        return self.nugget / total if total > 0 else 1.0


def fit_gaussian_variogram(empirical: EmpiricalSemivariogram, column: int = 0) -> GaussianVariogram:
    """Least-squares fit of the Gaussian model to one column, weighted by pair counts."""
    h = empirical.lags
    gamma = empirical.semivariance[:, column]
    weights = np.sqrt(empirical.counts / empirical.counts.sum())
    top = max(float(gamma.max()), 1e-12)
    h_max = max(float(h.max()), 1e-12)

    def residual(theta):
        model = GaussianVariogram(*theta)
        return weights * (model(h) - gamma)

    start = np.array([max(float(gamma[0]), 0.0) * 0.5, top, 0.5 * h_max])
    lower = np.array([0.0, 0.0, 1e-3 * h_max])
    upper = np.array([top * 2, top * 4, 10.0 * h_max])
    fit = least_squares(residual, np.clip(start, lower, upper), bounds=(lower, upper))
    return GaussianVariogram(*fit.x)
