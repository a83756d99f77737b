"""Measurement uncertainty budgets, as the GUM (JCGM 100:2008) combines them.

A figure a report states (a TCP position error's mean, RMS or max on stated poses, an ISO 9283 AP
or RP, a fitted parameter) gets an :class:`UncertaintyBudget`: its contributions, each a standard
uncertainty with how it was obtained (GUM type A: from the data's own scatter; type B: from a
specification or a stated range), combined as the root sum of squares (GUM 5.1.2, the
contributions taken as uncorrelated), and expanded with the coverage factor k = 2 (GUM 6.2.1,
about 95 % for a normal distribution). A contribution that cannot be evaluated from what is
recorded is kept in the budget, marked not evaluated, with why: the budget then says what it leaves
out instead of looking smaller.

The pieces here are the computations; :mod:`tcr_accuracy.results.budgets` assembles them for the
figures of a set of results, and :mod:`tcr_accuracy.view.calibration_report` words them.

* :func:`mpe_uncertainty`: an instrument's maximum permissible error ``a + b L`` at the distance L
  of each point from the instrument, read as the half-width of a rectangular distribution
  (GUM 4.3.7: ``u = MPE / sqrt(3)``).
* :func:`registration_uncertainty`: a rigid frame fitted (Kabsch) to n points with per-axis
  scatter sigma moves a point at ``r`` from the fitted points' centroid by a translation of
  covariance ``sigma^2 / n I`` and a rotation of covariance ``sigma^2 A^-1``, ``A = sum(|r_i|^2 I -
  r_i r_i^T)`` (the points' inertia tensor): first order, ``Cov = sigma^2 (I / n + [r]x A^-1 [r]x^T)``.
* :func:`fit_uncertainty`: a least-squares fit of p parameters to m coordinates predicts, averaged
  over the fitted points, with variance ``sigma^2 p / m`` per coordinate (the hat matrix's trace is p).
* :func:`temperature_uncertainty`: the robot's size over a stated temperature range, a rectangular
  distribution of the expansion ``alpha dT R`` over it.

Point sets are summarised by their first and second moments and their bounding box
(:class:`PointSet`), enough for all of the above and small enough to keep in a result file. Lengths
in m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: The coverage factor of every expanded uncertainty (GUM 6.2.1: about 95 % for a normal distribution).
COVERAGE_FACTOR = 2.0
#: Linear expansion coefficient taken for the robot's links [1/K]: aluminium's, the largest of the
#: structural metals arms are built of (steel 11.7e-6): the conservative choice where the
#: material is not stated.
EXPANSION_PER_K = 23e-6
#: The GUM type of an evaluation: from the data's scatter, or from other information.
TYPE_A, TYPE_B = "A", "B"


@dataclass(frozen=True)
class Contribution:
    """One line of a budget.

    Attributes
    ----------
    source : str
        What it is ("instrument MPE", "measurement noise", "frame registration", "temperature", "fit").
    standard_uncertainty : float or None
        Its standard uncertainty in the figure's unit [m for lengths]; None: not evaluated.
    how : str
        How it was obtained, or why it was not (one sentence).
    evaluation : str
        GUM type: "A" (statistical, from the data) or "B" (from a specification or stated range).
    """

    source: str
    standard_uncertainty: float | None
    how: str
    evaluation: str = TYPE_B

    def to_dict(self, scale: float = 1e3) -> dict:
        """JSON-ready; lengths in mm (``scale``: SI to the dict's unit)."""
        u = self.standard_uncertainty
        return {"source": self.source, "standard_uncertainty": None if u is None else u * scale, "how": self.how,
                "evaluation": self.evaluation}

    @classmethod
    def from_dict(cls, doc: dict, scale: float = 1e3) -> "Contribution":
        u = doc.get("standard_uncertainty")
        return cls(doc["source"], None if u is None else u / scale, doc["how"], doc.get("evaluation", TYPE_B))


@dataclass(frozen=True)
class UncertaintyBudget:
    """A figure with its contributions, combined (root sum of squares) and expanded (k = 2).

    Attributes
    ----------
    figure : str
        What the figure is ("full model, mean on the 20 held-out poses").
    value : float
        The figure [m for lengths].
    unit : str
        Its SI unit ("m", "rad", ...).
    contributions : tuple of Contribution
    coverage_factor : float, default 2
    """

    figure: str
    value: float
    unit: str
    contributions: tuple = field(default=())
    coverage_factor: float = COVERAGE_FACTOR

    @property
    def combined(self) -> float:
        """Combined standard uncertainty: root sum of squares of the evaluated contributions (GUM 5.1.2)."""
        return math.sqrt(sum(c.standard_uncertainty ** 2 for c in self.contributions
                             if c.standard_uncertainty is not None))

    @property
    def expanded(self) -> float:
        """Expanded uncertainty U = k u_c (GUM 6.2.1)."""
        return self.coverage_factor * self.combined

    @property
    def not_evaluated(self) -> list[str]:
        """The contributions left out of the combination (not evaluated)."""
        return [c.source for c in self.contributions if c.standard_uncertainty is None]

    def to_dict(self) -> dict:
        """JSON-ready, lengths in mm."""
        scale = 1e3 if self.unit == "m" else 1.0
        return {"figure": self.figure, "value": self.value * scale, "unit": "mm" if self.unit == "m" else self.unit,
                "combined_standard_uncertainty": self.combined * scale, "coverage_factor": self.coverage_factor,
                "expanded_uncertainty": self.expanded * scale,
                "contributions": [c.to_dict(scale) for c in self.contributions]}


@dataclass(frozen=True)
class PointSet:
    """Measured points summarised: count, mean, covariance and bounding box, in the frame they were
    measured in (the tracker's) [m].

    Attributes
    ----------
    n : int
    mean : ndarray of shape (3,)
    covariance : ndarray of shape (3, 3)
        About the mean, divided by n (the points' own spread, not an estimate of a population's).
    lower, upper : ndarray of shape (3,)
        The bounding box.
    """

    n: int
    mean: np.ndarray
    covariance: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of(cls, points) -> "PointSet":
        """From points (N, 3) [m]."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        centred = points - points.mean(axis=0)
        return cls(len(points), points.mean(axis=0), centred.T @ centred / len(points), points.min(axis=0),
                   points.max(axis=0))

    def second_moment(self, about) -> np.ndarray:
        """(3, 3) mean of ``(p - about)(p - about)^T`` over the points [m^2]."""
        d = self.mean - np.asarray(about, dtype=float)
        return self.covariance + np.outer(d, d)

    def corners(self) -> np.ndarray:
        """(8, 3) the bounding box's corners [m]."""
        return np.array([[(self.lower, self.upper)[(k >> i) & 1][i] for i in range(3)] for k in range(8)])

    def distance(self, origin=(0.0, 0.0, 0.0)) -> tuple[float, float, float]:
        """(RMS, least bound, largest bound) of the points' distance from ``origin`` [m]: the RMS exactly
        (from the moments), the largest no more than the farthest corner of the box, the least no less
        than the nearest point of the box."""
        origin = np.asarray(origin, dtype=float)
        rms = math.sqrt(float(np.trace(self.second_moment(origin))))
        largest = float(np.max(np.linalg.norm(self.corners() - origin, axis=1)))
        least = float(np.linalg.norm(np.clip(origin, self.lower, self.upper) - origin))
        return rms, least, largest

    def to_dict(self) -> dict:
        """JSON-ready, in mm."""
        return {"n": self.n, "mean_mm": (self.mean * 1e3).tolist(),
                "covariance_mm2": (self.covariance * 1e6).tolist(), "lower_mm": (self.lower * 1e3).tolist(),
                "upper_mm": (self.upper * 1e3).tolist()}

    @classmethod
    def from_dict(cls, doc: dict) -> "PointSet":
        return cls(int(doc["n"]), np.asarray(doc["mean_mm"], dtype=float) * 1e-3,
                   np.asarray(doc["covariance_mm2"], dtype=float) * 1e-6, np.asarray(doc["lower_mm"]) * 1e-3,
                   np.asarray(doc["upper_mm"], dtype=float) * 1e-3)


def mpe_uncertainty(mpe, distance) -> np.ndarray:
    """Standard uncertainty [m] of a point measured at ``distance`` [m] from an instrument of
    maximum permissible error ``a + b L`` (``mpe`` = (a [m], b [m/m])): the MPE as the half-width of a
    rectangular distribution, ``u = (a + b L) / sqrt(3)`` (GUM 4.3.7)."""
    a, b = mpe
    return (a + b * np.asarray(distance, dtype=float)) / math.sqrt(3.0)


def axis_sigma(residual_rms: float, n_points: int, n_parameters: int) -> float:
    """Per-axis standard deviation [m] from the RMS of 3-D residual norms over ``n_points`` points of
    a fit of ``n_parameters``: ``rms sqrt(3n / (3n - p)) / sqrt(3)`` (the residual's degrees of freedom)."""
    dof = max(3 * n_points - n_parameters, 1)
    return residual_rms * math.sqrt(3 * n_points / dof) / math.sqrt(3.0)


def registration_covariance(fitted: PointSet, sigma: float, at) -> np.ndarray:
    """(N, 3, 3) first-order covariance [m^2] of a point at ``at`` (N, 3) [m] mapped by a rigid frame
    fitted (Kabsch) to the points of ``fitted`` with independent per-axis scatter ``sigma`` [m]:
    ``sigma^2 (I / n + [r]x A^-1 [r]x^T)``, ``r = at - centroid``, ``A = n (tr(C) I - C)`` (C: their
    covariance)."""
    at = np.atleast_2d(np.asarray(at, dtype=float))
    inertia_inverse = np.linalg.inv(fitted.n * (np.trace(fitted.covariance) * np.eye(3) - fitted.covariance))
    r = at - fitted.mean
    skew = np.zeros((len(r), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -r[:, 2], r[:, 1], -r[:, 0]
    skew = skew - skew.transpose(0, 2, 1)
    return sigma ** 2 * (np.eye(3) / fitted.n + skew @ inertia_inverse @ skew.transpose(0, 2, 1))


def registration_uncertainty(fitted: PointSet, sigma: float, evaluated: PointSet) -> tuple[float, float]:
    """(RMS over the evaluated points, largest at the evaluated box's corners) of the per-axis
    standard uncertainty [m] a fitted rigid frame (:func:`registration_covariance`) adds to a point.

    The RMS is exact from the evaluated points' moments (the covariance's trace is quadratic in r);
    the largest is bounded by the corners of their box (it is convex in r)."""
    inertia_inverse = np.linalg.inv(fitted.n * (np.trace(fitted.covariance) * np.eye(3) - fitted.covariance))
    moment = evaluated.second_moment(fitted.mean)
    # E tr([r]x M [r]x^T) = tr(M (tr(T) I - T)), T = E[r r^T]
    mean_trace = 3.0 / fitted.n + float(np.trace(inertia_inverse @ (np.trace(moment) * np.eye(3) - moment)))
    corners = np.trace(registration_covariance(fitted, 1.0, evaluated.corners()), axis1=1, axis2=2)
    return sigma * math.sqrt(mean_trace / 3.0), sigma * math.sqrt(float(corners.max()) / 3.0)


def fit_uncertainty(sigma: float, n_parameters: int, n_coordinates: int) -> float:
    """Per-coordinate standard uncertainty [m] a least-squares fit of ``n_parameters`` to
    ``n_coordinates`` measured coordinates of scatter ``sigma`` [m] leaves in its predictions,
    averaged over the fitted points: ``sigma sqrt(p / m)`` (the hat matrix's trace is p)."""
    return sigma * math.sqrt(min(n_parameters / max(n_coordinates, 1), 1.0))


def temperature_uncertainty(range_c, reach_m: float, expansion_per_k: float = EXPANSION_PER_K) -> float:
    """Standard uncertainty [m] of a position at ``reach_m`` from the robot's base over the
    temperature range ``range_c`` (low, high) [degC]: the expansion ``alpha (high - low) R`` as the
    full width of a rectangular distribution (GUM 4.3.7: half-width / sqrt(3))."""
    low, high = range_c
    return expansion_per_k * (high - low) * reach_m / 2.0 / math.sqrt(3.0)


def statistic_noise(sigma: float, n: int, statistic: str) -> float:
    """Standard uncertainty [m] that independent per-axis noise ``sigma`` [m] of each measured point
    gives a statistic of n error norms: the noise along each error's direction is sigma; the mean
    and the RMS average it over the n poses (``sigma / sqrt(n)``), the max is one pose's (``sigma``)."""
    return sigma if statistic == "max" else sigma / math.sqrt(max(n, 1))


__all__ = ["COVERAGE_FACTOR", "Contribution", "EXPANSION_PER_K", "PointSet", "TYPE_A", "TYPE_B",
           "UncertaintyBudget", "axis_sigma", "fit_uncertainty", "mpe_uncertainty", "registration_covariance",
           "registration_uncertainty", "statistic_noise", "temperature_uncertainty"]
