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
   the estimate is unbiased for the true model and its weights stay tame in any
   number of sources. The interval is the normal one on the weighted mean
   (reported with the effective sample size that backs it). It needs sources that
   are functions of independent scalars (an ErrorBudget); the joint clearance model
   (nonlinear in s and theta) gets the other two.
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
    Integrated in polar/spherical coordinates: along each ray omega the Gaussian
    density is exp(-(alpha r^2 - 2 beta r + gamma) / 2), whose integral
    int_T^inf r^(k-1) ... dr has a closed form in erfc; the remaining 1-D (circle) or
    2-D (sphere) integral over directions uses Gauss-Legendre nodes. Every term is
    positive, so the relative accuracy holds deep in the tail (1e-6 and below),
    where formulas of the type 1/2 + (oscillating integral) lose all digits.
    Directions with (numerically) zero variance are removed first; their constant
    offset enlarges or shrinks the effective threshold.
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
    radius = np.sqrt(x)
    k = lam.size
    if k > 3:
        raise ValueError("gaussian_exceedance handles up to 3 dimensions")
    # directions omega (m, k) and quadrature weights (m,)
    if k == 1:
        omega, weights = np.array([[1.0], [-1.0]]), np.ones(2)
    elif k == 2:
        t, w = np.polynomial.legendre.leggauss(2 * nodes)
        phi = np.pi * (t + 1.0)
        omega, weights = np.stack([np.cos(phi), np.sin(phi)], axis=1), np.pi * w
    else:
        t, wt = np.polynomial.legendre.leggauss(nodes)  # cos(polar angle)
        u, wu = np.polynomial.legendre.leggauss(2 * nodes)
        phi = np.pi * (u + 1.0)
        sin_t = np.sqrt(1.0 - t * t)
        omega = np.stack([np.outer(sin_t, np.cos(phi)).ravel(), np.outer(sin_t, np.sin(phi)).ravel(),
                          np.repeat(t, phi.size)], axis=1)
        weights = np.outer(wt, np.pi * wu).ravel()
    inv = 1.0 / lam
    alpha = (omega * omega) @ inv  # omega^T Sigma^-1 omega
    beta = omega @ (inv * proj)  # omega^T Sigma^-1 mu
    gamma = float(np.sum(inv * proj * proj))
    m = beta / alpha
    t0 = radius - m
    sqrt_a = np.sqrt(alpha)
    i0 = np.sqrt(2.0 * np.pi) / sqrt_a * stats.norm.sf(t0 * sqrt_a)  # int e^{-a t^2/2}
    e0 = np.exp(-0.5 * alpha * t0 * t0)
    i1 = e0 / alpha  # int t e^{-a t^2/2}
    if k == 1:
        radial = i0
    elif k == 2:
        radial = i1 + m * i0
    else:
        i2 = t0 * e0 / alpha + i0 / alpha  # int t^2 e^{-a t^2/2}
        radial = i2 + 2.0 * m * i1 + m * m * i0
    log_const = -0.5 * (gamma - beta * beta / alpha) - 0.5 * k * np.log(2.0 * np.pi) - 0.5 * np.sum(np.log(lam))
    return float(min(1.0, np.sum(weights * radial * np.exp(log_const))))


# ---------------------------------------------------------------------------------------
# Importance sampling on the exact model
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TailEstimate:
    """P(|dP| > threshold) by importance sampling.

    probability : the estimate
    ci95 : (low, high) normal interval on the weighted mean, clipped to [0, 1]
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
        ``max(1, threshold / (s_max sqrt(r)))`` with s_max the largest singular value of
        the linearised map u -> dP, which puts the proposal's typical radius at the
        nearest failure point.

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
    if inflation is None:
        inflation = max(1.0, threshold / (sing[0] * np.sqrt(max(rank, 1)))) if rank else 1.0
    k = float(inflation)
    nominal = tcp_poses(robot, q).position[0]
    total = total_sq = 0.0
    sum_w1 = sum_w1_sq = 0.0
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
        w = np.where(fail, np.exp(log_w), 0.0)
        total += w.sum()
        total_sq += (w * w).sum()
        sum_w1 += w.sum()
        sum_w1_sq += (w * w).sum()
        done += n
    p = total / n_samples
    var = max(total_sq / n_samples - p * p, 0.0) / max(n_samples - 1, 1)
    se = float(np.sqrt(var))
    ess = sum_w1**2 / sum_w1_sq if sum_w1_sq > 0 else 0.0
    return TailEstimate(probability=float(p), ci95=(max(0.0, p - 1.96 * se), min(1.0, p + 1.96 * se)),
                        standard_error=se, effective_samples=float(ess), inflation=k, rank=rank,
                        n_samples=int(n_samples))
