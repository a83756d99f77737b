"""Spatial similarity of TCP errors: do nearby poses have similar errors?

For every pair of measured poses (i, k): the joint distance ``Dq = |q_i - q_k|``, the
Cartesian distance ``Dp = |p_i - p_k|`` of the nominal TCP positions and the error
distance ``De = |e_i - e_k|``. The Pearson correlation of De with Dq, and of De with
Dp, says in which space errors are the more predictable from neighbours (the second
seed's Tables 1 and 2). Distances come from scipy.spatial, the correlation and its
p-value from scipy.stats (the p-value treats the n(n-1)/2 pairs as independent,
which they are not, so it is optimistic; the seed reports the same quantity).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import pdist
from scipy.stats import pearsonr

from ..exceptions import InputError
from .semivariogram import standardize


@dataclass(frozen=True)
class PairDistances:
    """All pairwise distances, (n(n-1)/2,) each, in scipy's condensed order.

    joint : Dq [rad, m mixed, or standardised units]
    cartesian : Dp [m]
    error : De [m]
    """

    joint: np.ndarray
    cartesian: np.ndarray
    error: np.ndarray


@dataclass(frozen=True)
class SimilarityResult:
    """PCC of De with Dq (joint) and with Dp (cartesian), their p-values, and sizes."""

    pcc_joint: float
    p_value_joint: float
    pcc_cartesian: float
    p_value_cartesian: float
    n_points: int
    n_pairs: int


def pair_distances(q: np.ndarray, positions: np.ndarray, errors: np.ndarray,
                   standardise_joints: bool = False) -> PairDistances:
    """Pairwise distances of joint values q (n, n_joints), positions (n, 3) and errors (n, 3).

    standardise_joints : scale each joint column to unit std first (use it when
        revolute and prismatic joints mix, so radians and metres do not)
    """
    q = np.asarray(q, dtype=float)
    positions = np.asarray(positions, dtype=float)
    errors = np.asarray(errors, dtype=float)
    if q.ndim != 2 or positions.shape != (q.shape[0], 3) or errors.shape != (q.shape[0], 3):
        raise InputError(f"similarity: need q (n, n_joints), positions (n, 3), errors (n, 3); got "
                         f"{q.shape}, {positions.shape}, {errors.shape}")
    if q.shape[0] < 3:
        raise InputError(f"similarity: needs at least 3 poses, got {q.shape[0]}")
    if standardise_joints:
        q = standardize(q)[0]
    return PairDistances(joint=pdist(q), cartesian=pdist(positions), error=pdist(errors))


def spatial_similarity(q: np.ndarray, positions: np.ndarray, errors: np.ndarray,
                       standardise_joints: bool = False) -> SimilarityResult:
    """Pearson correlation of the error distance with the joint and the Cartesian distance."""
    d = pair_distances(q, positions, errors, standardise_joints)
    for name, values in (("joint", d.joint), ("Cartesian", d.cartesian), ("error", d.error)):
        if np.ptp(values) == 0:
            raise InputError(f"similarity: all {name} distances are equal; the poses do not vary")
    joint = pearsonr(d.error, d.joint)
    cart = pearsonr(d.error, d.cartesian)
    return SimilarityResult(float(joint.statistic), float(joint.pvalue), float(cart.statistic),
                            float(cart.pvalue), int(np.shape(q)[0]), d.error.size)
