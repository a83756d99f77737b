"""Tolerance allocation: how far the error spreads may grow for a reliability target.

The largest factor by which all spreads (or those of some groups) can be multiplied
while ``P(|dP| < T) >= p`` still holds, found by root finding on a Monte Carlo with
common random numbers (the same uniform draws for every factor), so the answer is a
deterministic function of the seed. The spreads are those of the independent random
inputs of an error budget or a clearance model
(:func:`~tcr_accuracy.analysis.random_inputs.random_inputs`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from ..exceptions import AnalysisError, InputError
from ..model.kinematics import pose_error, tcp_poses
from .random_inputs import RandomInputs, random_inputs


@dataclass(frozen=True)
class ScaledSpread:
    """One input's standard deviation before and after allocation [its unit]."""

    name: str
    group: str
    unit: str
    nominal_std: float
    allowed_std: float


@dataclass(frozen=True)
class ToleranceAllocation:
    """The largest spread factor that keeps ``P(|dP| < tolerance) >= probability``.

    Attributes
    ----------
    factor : float
        Multiplier of the spreads of the scaled inputs (> 1: the budget may loosen).
    scaled_groups : tuple of str or None
        Groups whose spreads were scaled (None: all).
    tolerance : float
        T [m].
    probability : float
        Target p.
    nominal_probability : float
        P(|dP| < T) of the unscaled sampler, same draws.
    achieved_probability : float
        P(|dP| <= T) at ``factor``, same draws.
    spreads : list of ScaledSpread
        Every scaled input, nominal and allowed standard deviation.
    sampler : ErrorBudget or ClearanceModel with the allowed spreads
    n_samples : int
    """

    factor: float
    scaled_groups: tuple[str, ...] | None
    tolerance: float
    probability: float
    nominal_probability: float
    achieved_probability: float
    spreads: list[ScaledSpread]
    sampler: object
    n_samples: int


class _CommonRandomNumbers:
    """|dP| with the scaled inputs multiplied by s, always from the same draws."""

    def __init__(self, inputs: RandomInputs, q: np.ndarray, n_samples: int, rng: np.random.Generator,
                 scaled: np.ndarray):
        self.inputs, self.q = inputs, q
        self.robot, self.em = inputs.error_model.robot, inputs.error_model
        self.nominal = tcp_poses(self.robot, q)
        self.values = inputs.values_from_unit(rng.uniform(size=(n_samples, len(inputs.sources))))
        self.scaled = scaled
        if inputs.matrix is not None:  # linear: x(s) = s x_scaled + x_fixed
            a = inputs.matrix
            self.x_scaled = self.values[:, scaled] @ a[:, scaled].T
            self.x_fixed = self.values[:, ~scaled] @ a[:, ~scaled].T

    def norms(self, s: float) -> np.ndarray:
        if self.inputs.matrix is not None:
            x = s * self.x_scaled + self.x_fixed
        else:
            values = self.values.copy()
            values[:, self.scaled] *= s
            x = self.inputs.to_parameters(values)
        return pose_error(self.nominal, tcp_poses(self.robot, self.q, x, self.em)).position_norm


def allocate_tolerance(sampler, q: np.ndarray, tolerance: float, probability: float,
                       groups: Sequence[str] | None = None, n_samples: int = 50_000,
                       rng: np.random.Generator | None = None,
                       progress: Callable[[int], None] | None = None) -> ToleranceAllocation:
    """Largest factor on the spreads such that ``P(|dP| < tolerance) >= probability``.

    The probability is estimated on ``n_samples`` fixed draws (common random numbers):
    the factor s multiplies the values of the scaled inputs (scaling a spread and
    mean multiplies the value drawn at the same probability), so the Monte Carlo is a
    deterministic function of s. With k = ceil(p n), P >= p holds while the k-th
    smallest |dP| stays below T. That order statistic is continuous in s and, where
    the TCP error grows with the errors (every practical case; exactly so in the
    linear regime), increasing, so scipy's brentq finds where it equals T.

    Parameters
    ----------
    sampler : ErrorBudget or ClearanceModel
    q : ndarray of shape (n_joints,) [rad, m]
    tolerance : float
        T [m], > 0.
    probability : float
        Target p in (0, 1).
    groups : sequence of str, optional
        Scale only the inputs of these groups (e.g. ``["drive"]``); the others keep
        their spreads. Default: every input.
    n_samples : int
    rng : numpy Generator
    progress : callable, optional
        Called with 1 after each Monte Carlo evaluation (about 15 to 30 in all).
    """
    from scipy.optimize import brentq

    if not (tolerance > 0 and math.isfinite(tolerance)):
        raise InputError(f"tolerance {tolerance}: must be a finite number > 0")
    if not (0.0 < probability < 1.0):
        raise InputError(f"target probability {probability}: must lie strictly between 0 and 1")
    if n_samples < 10:
        raise InputError(f"tolerance allocation needs at least 10 samples, got {n_samples}")
    inputs = random_inputs(sampler)
    known = sorted({g for g, ok in zip(inputs.groups, inputs.scalable) if ok})
    group_set = None
    if groups is not None:
        group_set = set(groups)
        unknown = sorted(group_set - set(known))
        if unknown:
            raise InputError(f"unknown group(s) {', '.join(unknown)} (groups of this budget: {', '.join(known)})")
    scaled = inputs.scalable & np.array([group_set is None or g in group_set for g in inputs.groups])
    rng = rng if rng is not None else np.random.default_rng(0)
    crn = _CommonRandomNumbers(inputs, q, n_samples, rng, scaled)
    k = math.ceil(probability * n_samples)

    def excess(s: float) -> float:
        value = float(np.partition(crn.norms(s), k - 1)[k - 1]) - tolerance
        if progress is not None:
            progress(1)
        return value

    nominal_probability = float(np.mean(crn.norms(1.0) < tolerance))
    at_zero = excess(0.0)
    what = ", ".join(sorted(group_set)) if group_set else "every group"
    if at_zero >= 0:
        raise AnalysisError(
            f"P(|dP| < {tolerance * 1e3:g} mm) >= {probability:g} cannot be met by scaling {what}: even with "
            f"those spreads at zero the {probability:g} quantile of |dP| is {(at_zero + tolerance) * 1e3:.4g} mm")
    hi = 1.0
    while excess(hi) < 0:
        hi *= 4.0
        if hi > 1e9:
            raise AnalysisError(f"scaling {what} does not move the TCP: any spread meets the target")
    lo = hi / 4.0 if hi > 1.0 else 0.0
    while lo > 0.0 and excess(lo) >= 0:
        lo = lo / 4.0 if lo > 1e-12 else 0.0
    factor = float(brentq(excess, lo, hi, xtol=1e-14, rtol=1e-10))
    for _ in range(60):  # brentq may land a hair above the crossing: step to the side that meets the target
        if excess(factor) <= 0:
            break
        factor *= 1.0 - 1e-9
    spreads = [ScaledSpread(s.name, s.group, s.unit, math.sqrt(s.variance),
                            math.sqrt(s.variance) * (factor if ok else 1.0))
               for s, ok in zip(inputs.sources, scaled) if ok]
    return ToleranceAllocation(
        factor=factor, scaled_groups=tuple(sorted(group_set)) if group_set else None,
        tolerance=float(tolerance), probability=float(probability),
        nominal_probability=nominal_probability,
        achieved_probability=float(np.mean(crn.norms(factor) <= tolerance)),
        spreads=spreads, sampler=inputs.scaled_sampler(factor, group_set), n_samples=n_samples,
    )
