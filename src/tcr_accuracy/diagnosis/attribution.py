"""What the fitted model attributes to each effect, and where its first-order effect models end.

* :func:`contributions` -- the TCP motion each chosen effect's fitted parameters cause,
  beyond what a rigid frame change could absorb.
* :func:`rank_largest` -- the largest of several shares (own shares, family shares) against
  each other one: the difference of the two and its 95 % interval, paired on the same bootstrap
  replicates, and the selection's paired test on the same rows; the data rank them apart only where
  both do, and the primary effect or family is otherwise one of those tied, not the largest by a hair.
* :func:`fixed_point_check` -- the effects are first order in their own joint deflections
  (compliance takes gravity at the commanded pose): how far one fixed-point step would move
  the TCP, against the noise floor.

Lengths in m inside; the returned dicts carry mm in ``_mm`` keys.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..effects.compose import fixed_point_motion
from .paired import entry_z
from ..model.errors import ErrorModel
from ..model.kinematics import tcp_poses


def contributions(part, bases, chosen, full_parameters, nominal) -> dict:
    """How much of the gap each chosen effect accounts for: the TCP motion its fitted
    parameters cause, after taking out what a rigid frame change could absorb."""
    frames_g = bases["frames"].per_part[0].g[:, :3]
    frames_cols = frames_g.reshape(-1, frames_g.shape[2])
    em = ErrorModel(part.robot)
    contribution = {}
    for e in chosen:
        x_e = bases[e].per_part[0].basis.errors(full_parameters[e])
        motion = (tcp_poses(part.robot, part.q, x_e, em).position - nominal).ravel()
        rigid = frames_cols @ np.linalg.lstsq(frames_cols, motion, rcond=None)[0]
        contribution[e] = float(np.sqrt(np.mean((motion - rigid) ** 2) * 3))
    return contribution


def fixed_point_check(part, bases, full_parameters, noise_floor) -> tuple[float, float, str | None]:
    """The fitted model is first order in its joint deflections (gravity at the commanded
    pose): how much one fixed-point step (gravity at the deflected pose) would move the TCP
    [m], RMS and max, and a note when the RMS is more than a quarter of the noise floor [m]."""
    effects = [bases[e].per_part[0].effect for e in full_parameters]  # with the options they were fitted with
    motion = fixed_point_motion(part.robot, effects, list(full_parameters.values()), part.q, part.context)
    rms = float(np.sqrt(np.mean(np.sum(motion**2, axis=1))))
    largest = float(np.max(np.linalg.norm(motion, axis=1)))
    note = None
    if not rms <= 0.25 * noise_floor:
        note = (f"the fitted joint deflections are large enough that first order is not enough: evaluated at "
                f"the deflected joints (gravity where the arm sags to, gear errors where the joint really is) "
                f"they move the TCP by {rms * 1e3:.4g} mm RMS more, {rms / noise_floor:.2g} x the noise floor; "
                "what is left, and any effect chosen late for it, may partly be that")
    return rms, largest, note


@dataclass(frozen=True)
class ShareComparison:
    """Two shares of the held-out error compared on the same rows (SI units).

    Attributes
    ----------
    larger, smaller : str
        What the shares are of (an effect, a family): the larger point estimate first.
    difference : float
        The larger share minus the smaller [m] (the held-out RMS without ``larger`` minus that without
        ``smaller``).
    interval : (float, float)
        Its 95 % interval [m], from the same bootstrap replicates as both shares (paired).
    z : float
        The selection's paired test on the same rows (:func:`~.paired.entry_z`): how clearly the
        per-row squared errors without ``larger`` exceed those without ``smaller``.
    threshold : float
        The z it must exceed (the selection's).
    """

    larger: str
    smaller: str
    difference: float
    interval: tuple
    z: float
    threshold: float

    @property
    def ranked(self) -> bool:
        """The held-out rows rank ``larger`` above ``smaller``: the test that lets an effect into the
        model passes (z above ``threshold``) and the difference's 95 % interval lies above zero, so that
        no answer names the larger of two by less than the diagnosis asks of an effect, nor against its
        own printed interval."""
        return bool(self.z > self.threshold and self.interval[0] > 0.0)

    def to_dict(self) -> dict:
        return {"larger": self.larger, "smaller": self.smaller, "difference_mm": self.difference * 1e3,
                "interval_mm": [self.interval[0] * 1e3, self.interval[1] * 1e3], "z": self.z,
                "z_threshold": self.threshold, "ranked": self.ranked}


def rank_largest(table, squares: dict, names: list, final, threshold: float) -> list[ShareComparison]:
    """The largest share of ``names`` against each other one, largest first.

    ``squares``: name -> per-row squared held-out errors of the model without it, and of the model
    with all (``final``); ``table``: their :class:`~.uncertainty.BootstrapTable`. A share is the rise
    of the held-out RMS without it. The difference of two shares and its interval are read on the same
    replicates, the paired test (:func:`~.paired.entry_z`) on the same rows. Returns [] for fewer than
    two names."""
    if len(names) < 2:
        return []
    ranked = sorted(names, key=lambda n: -(table.point[n] - table.point[final]))
    top = ranked[0]
    out = []
    for other in ranked[1:]:
        d = table.difference(top, other)
        out.append(ShareComparison(top, other, d.value, (d.low, d.high), entry_z(squares[top], squares[other]),
                                   float(threshold)))
    return out
