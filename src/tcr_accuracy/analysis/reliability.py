"""Reliability where plain Monte Carlo is weak: first-order covariance and rare tails.

Three independent ways to the probability that the TCP misses a tolerance ball,
P(|dP| > T), each with its own limits:

1. Monte Carlo counts with an exact (Clopper-Pearson) binomial interval
   (:func:`binomial_interval`, scipy's ``binomtest``). Sound for any model, but a
   probability of 1e-6 needs about 1e8 samples before the count says anything.
2. First order: dP ~ N(J mu_x, J Sigma_x J^T) with J the TCP's error Jacobian from
   Pinocchio (:func:`first_order`). Then |dP|^2 is a weighted sum of noncentral
   chi-square variables (scipy has none); :func:`gaussian_exceedance` integrates
   its tail in spherical coordinates with a closed-form radial part. Exact for a linear
   model with Gaussian errors, and fast at any probability; it ignores
   nonlinearity and non-Gaussian inputs.
3. Importance sampling on the exact nonlinear model (:func:`importance_exceedance`):
   the sources are written as functions of independent standard normals u (normal
   sources directly, others through ``ppf(Phi(u))``), the few directions of u that
   move the TCP (the row space of the linearised map, rank <= 3) are sampled with an
   inflated spread k, all other directions with the true one. The weights are exact
   density ratios ``k^r exp(-|y|^2 (1 - 1/k^2) / 2)`` over only those r directions, so
   they stay tame in any number of sources. k puts the proposal's typical radius at the
   nearest failure, counted from where the TCP sits at the sources' medians (a budget
   with a bias already outside the tolerance needs no inflation: k = 1, plain sampling).
   The estimate is self-normalised (sum of the failing weights over the sum of all), so it
   is a probability in [0, 1] whatever the draw; its standard error is the delta method's
   and the interval the normal one (reported with the effective sample size that backs
   it). It needs sources that are functions of independent scalars (an ErrorBudget); the
   joint clearance model (nonlinear in s and theta) gets the other two.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..model.errors import ErrorBudget
from ..exceptions import InputError
from ..model.jacobians import error_jacobian


from ..model.kinematics import tcp_chain_soa, tcp_poses


@dataclass(frozen=True)
class FirstOrder:
    """First-order (linearised) TCP error distribution.

    mean : (6,) expected TCP displacement (linear [m], rotation vector [rad]), J mu_x
    covariance : (6, 6) J Sigma_x J^T
    jacobian : (6, n_params) from :func:`~tcr_accuracy.model.jacobians.error_jacobian`
    euler_covariance : (3, 3) first-order covariance of the ZYX Euler angle errors [rad^2]
    """

    mean: np.ndarray
    covariance: np.ndarray
    jacobian: np.ndarray
    euler_covariance: np.ndarray

    @property
    def euler_std(self) -> np.ndarray:
        """(3,) standard deviations of the ZYX Euler angle errors (about z, y, x) [rad]."""
        return np.sqrt(np.maximum(np.diag(self.euler_covariance), 0.0))

    @property
    def position_std(self) -> np.ndarray:
        """(3,) standard deviations of dx, dy, dz [m]."""
        return np.sqrt(np.maximum(np.diag(self.covariance)[:3], 0.0))

    @property
    def rotation_std(self) -> np.ndarray:
        """(3,) standard deviations of the rotation vector's components [rad]."""
        return np.sqrt(np.maximum(np.diag(self.covariance)[3:], 0.0))


def euler_zyx_rate_matrix(rotation: np.ndarray) -> np.ndarray:
    """(3, 3) M with omega = M d(a, b, c) for R = Rz(a) Ry(b) Rx(c), omega in the base frame.

    Its inverse maps a small rotation vector (base frame) to the ZYX Euler angle errors.
    """
    a = np.arctan2(rotation[1, 0], rotation[0, 0])
    b = np.arctan2(-rotation[2, 0], np.hypot(rotation[2, 1], rotation[2, 2]))
    return np.array([[0.0, -np.sin(a), np.cos(a) * np.cos(b)],
                     [0.0, np.cos(a), np.sin(a) * np.cos(b)],
                     [1.0, 0.0, -np.sin(b)]])


def first_order(sampler, q: np.ndarray) -> FirstOrder:
    """J mu_x and J Sigma_x J^T at joint values q (n_joints,) for any sampler with
    ``parameter_mean()`` and ``parameter_covariance()`` (ErrorBudget, ClearanceModel)."""
    em = sampler.error_model
    jac = error_jacobian(em.robot, np.asarray(q, dtype=float), em)
    cov_x = sampler.parameter_covariance()
    cov = jac @ cov_x @ jac.T
    to_euler = np.linalg.inv(euler_zyx_rate_matrix(tcp_poses(em.robot, q).rotation[0]))
    return FirstOrder(mean=jac @ sampler.parameter_mean(), covariance=cov, jacobian=jac,
                      euler_covariance=to_euler @ cov[3:, 3:] @ to_euler.T)


# ---------------------------------------------------------------------------------------
# Intervals on Monte Carlo counts
# ---------------------------------------------------------------------------------------
def binomial_interval(count: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Exact Clopper-Pearson interval for a probability from ``count`` hits in ``n`` trials."""
    ci = stats.binomtest(int(count), int(n)).proportion_ci(confidence_level=confidence, method="exact")
    return float(ci.low), float(ci.high)


# ---------------------------------------------------------------------------------------
# Gaussian tail of |dP| (generalised chi-square)
# ---------------------------------------------------------------------------------------
def gaussian_exceedance(mean: np.ndarray, covariance: np.ndarray, threshold: float,
                        nodes: int = 160) -> float:
    """P(|d| > threshold) for d ~ N(mean, covariance) in R^k (k <= 3).

    Parameters
    ----------
    mean : (k,)
    covariance : (k, k) symmetric positive semi-definite
    threshold : float > 0
    nodes : int
        Gauss-Legendre nodes per angular coordinate.

    Notes
    -----
    Integrated in whitened coordinates z (d = mean + V Lambda^(1/2) z, z standard normal),
    where the density is the same in every direction: along each ray z = r omega the ball
    |d| <= threshold is an interval [r1, r2] of r (a quadratic's roots; none when the ray
    misses it), and the mass of the ray outside it is ``F(r1) + S(r2)``, F and S the chi
    distribution's CDF and tail with k degrees of freedom (scipy). What remains is an average
    over directions (Gauss-Legendre nodes on the circle or sphere) of a bounded positive
    function: no narrow peak to miss, whether the mean lies inside the ball (the deep tail:
    every term positive, relative accuracy kept at 1e-6 and below) or far outside it in units
    of the spread (P near 1: an integral over directions of the density itself, done in the
    tolerance's coordinates, misses a peak of width spread / |mean| and said 1e-96 there).
    Directions with (numerically) zero variance are removed first; their constant offset
    enlarges or shrinks the effective threshold.
    """
    mean = np.asarray(mean, dtype=float)
    lam, vec = np.linalg.eigh(np.asarray(covariance, dtype=float))
    proj = vec.T @ mean
    x = float(threshold) ** 2
    keep = lam > max(lam.max(), 0.0) * 1e-12
    x -= float(np.sum(proj[~keep] ** 2))
    lam, proj = lam[keep], proj[keep]
    if lam.size == 0:
        return float(x < 0.0)
    if x <= 0.0:
        return 1.0
    k = lam.size
    if k > 3:
        raise ValueError("gaussian_exceedance handles up to 3 dimensions")
    # directions omega (m, k) and quadrature weights (m,) summing to 1
    if k == 1:
        omega, weights = np.array([[1.0], [-1.0]]), np.full(2, 0.5)
    elif k == 2:
        t, w = np.polynomial.legendre.leggauss(2 * nodes)
        phi = np.pi * (t + 1.0)
        omega, weights = np.stack([np.cos(phi), np.sin(phi)], axis=1), w / 2.0
    else:
        t, wt = np.polynomial.legendre.leggauss(nodes)  # cos(polar angle)
        u, wu = np.polynomial.legendre.leggauss(2 * nodes)
        phi = np.pi * (u + 1.0)
        sin_t = np.sqrt(1.0 - t * t)
        omega = np.stack([np.outer(sin_t, np.cos(phi)).ravel(), np.outer(sin_t, np.sin(phi)).ravel(),
                          np.repeat(t, phi.size)], axis=1)
        weights = np.outer(wt, wu).ravel() / 4.0
    # |mean + Lambda^(1/2) r omega|^2 = a r^2 + 2 b r + c <= x along each ray
    root = np.sqrt(lam)
    a = (omega * omega) @ lam
    b = omega @ (root * proj)
    c = float(proj @ proj)
    disc = b * b - a * (c - x)
    hit = disc > 0.0
    sq = np.sqrt(np.where(hit, disc, 0.0))
    r1 = np.where(hit, np.maximum((-b - sq) / a, 0.0), 0.0)
    r2 = np.where(hit, np.maximum((-b + sq) / a, 0.0), 0.0)  # r1 = r2 = 0: the ray misses the ball
    chi = stats.chi(k)
    outside = np.where(hit & (r2 > r1), chi.cdf(r1) + chi.sf(r2), 1.0)
    return float(min(1.0, max(0.0, np.sum(weights * outside))))


# ---------------------------------------------------------------------------------------
# Importance sampling on the exact model
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TailEstimate:
    """P(|dP| > threshold) by importance sampling.

    probability : the estimate, in [0, 1] (self-normalised)
    ci95 : (low, high) normal interval on the estimate, clipped to [0, 1]
    standard_error : of the estimate
    effective_samples : (sum w 1)^2 / sum (w 1)^2 over the failing samples
    inflation : the spread factor k of the proposal
    rank : number of inflated directions
    n_samples : int
    """

    probability: float
    ci95: tuple[float, float]
    standard_error: float
    effective_samples: float
    inflation: float
    rank: int
    n_samples: int


def _standard_normal_map(budget: ErrorBudget, u: np.ndarray) -> np.ndarray:
    """Source values (s, N) from independent standard normals u (s, N)."""
    out = np.empty_like(u)
    for i, src in enumerate(budget.sources):
        if src.distribution == "normal":
            out[i] = src.mean + src.std * u[i]
        else:
            out[i] = src.ppf(stats.norm.cdf(u[i]))
    return out


def _source_slopes(budget: ErrorBudget) -> np.ndarray:
    """(s,) d value / d u at u = 0 (central difference of the ppf map for non-normal sources)."""
    h = 1e-4
    plus = _standard_normal_map(budget, np.full((len(budget.sources), 1), h))[:, 0]
    minus = _standard_normal_map(budget, np.full((len(budget.sources), 1), -h))[:, 0]
    return (plus - minus) / (2 * h)


def importance_exceedance(budget: ErrorBudget, q: np.ndarray, threshold: float, n_samples: int,
                          rng: np.random.Generator, inflation: float | None = None,
                          chunk: int = 20_000) -> TailEstimate:
    """P(|dP| > threshold) [threshold in m] by importance sampling (see module docstring).

    Parameters
    ----------
    budget : ErrorBudget
    q : (n_joints,) joint values [rad, m]
    threshold : float > 0 [m]
    n_samples : int
    rng : numpy Generator
    inflation : float, optional
        Spread factor k of the proposal in the influential directions; default
        ``max(1, (threshold - |d0|) / (s_max sqrt(r)))`` with d0 the TCP's displacement at the
        sources' medians (u = 0, on the exact model) and s_max the largest singular value of the
        linearised map u -> dP, which puts the proposal's typical radius at the nearest failure
        point (k = 1 where d0 already fails: the tail is then no rare event).

    Returns
    -------
    TailEstimate
    """
    if threshold <= 0:
        raise InputError(f"tail threshold must be > 0, got {threshold}")
    em = budget.error_model
    robot = em.robot
    q = np.asarray(q, dtype=float)
    matrix = budget.matrix  # (p, s)
    jac = error_jacobian(robot, q, em)[:3]  # (3, p)
    g = jac @ matrix * _source_slopes(budget)[None, :]  # (3, s): dP per unit u
    _, sing, vt = np.linalg.svd(g, full_matrices=False)
    rank = int(np.sum(sing > sing.max() * 1e-9)) if sing.size and sing.max() > 0 else 0
    basis = vt[:rank].T  # (s, r)
    nominal = tcp_poses(robot, q).position[0]
    if inflation is None:
        at_median = matrix @ _standard_normal_map(budget, np.zeros((len(budget.sources), 1)))
        offset = float(np.linalg.norm(tcp_chain_soa(robot, q, at_median, em)[1][:, 0] - nominal))
        # at most 1e4: a failure 1e4 spreads away has a probability below 1e-300 (no draw reaches it)
        inflation = min(max(1.0, (threshold - offset) / (sing[0] * np.sqrt(rank))), 1e4) if rank else 1.0
    k = float(inflation)
    sum_w = sum_w_sq = 0.0  # every sample's weight
    sum_w1 = sum_w1_sq = 0.0  # the failing samples'
    done = 0
    while done < n_samples:
        n = min(chunk, n_samples - done)
        u = rng.standard_normal((len(budget.sources), n))
        if rank:
            y = basis.T @ u  # (r, n) true-spread coordinates in the influential subspace
            u = u + (k - 1.0) * basis @ y  # inflate them: y -> k y
            y_sq = np.sum(y * y, axis=0) * k * k
            log_w = rank * np.log(k) - 0.5 * y_sq * (1.0 - 1.0 / (k * k))
        else:
            log_w = np.zeros(n)
        values = _standard_normal_map(budget, u)
        x_t = matrix @ values
        _, pos = tcp_chain_soa(robot, q, x_t, em)
        fail = np.linalg.norm(pos - nominal[:, None], axis=0) > threshold
        w = np.exp(log_w)
        sum_w += w.sum()
        sum_w_sq += (w * w).sum()
        sum_w1 += w[fail].sum()
        sum_w1_sq += (w[fail] ** 2).sum()
        done += n
    # self-normalised: sum w 1 / sum w (E[w] = 1 under the proposal), a probability whatever the draw;
    # delta-method variance sum w^2 (1 - p)^2 over the failing plus p^2 over the others, / (sum w)^2
    p = sum_w1 / sum_w if sum_w > 0 else 0.0
    var = (sum_w1_sq * (1.0 - p) ** 2 + (sum_w_sq - sum_w1_sq) * p * p) / sum_w**2 if sum_w > 0 else 0.0
    se = float(np.sqrt(max(var, 0.0)))
    ess = sum_w1**2 / sum_w1_sq if sum_w1_sq > 0 else 0.0
    p = float(min(1.0, max(0.0, p)))
    return TailEstimate(probability=p, ci95=(max(0.0, p - 1.96 * se), min(1.0, p + 1.96 * se)),
                        standard_error=se, effective_samples=float(ess), inflation=k, rank=rank,
                        n_samples=int(n_samples))
