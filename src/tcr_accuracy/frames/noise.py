"""The instrument's own noise, as the measurement frames reveal it.

:class:`NoiseEstimate` is a per-axis noise figure with where it came from. Two sources do not
depend on the robot's errors at all: several measured frames on one rigid body keep their
distances whatever the robot does (:func:`noise_from_rigid_frames`), and base references scatter
about the tracker's drift (:func:`tcr_accuracy.frames.drift.tracker_drift`). Lengths in m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class NoiseEstimate:
    """Per-axis standard deviation of the measurement scatter [m], and where it came from.

    source : ``given`` (the instrument's figure), ``repeated poses`` (pooled scatter of
        readings of the same pose), ``residual`` (the final residual, which the structure
        test found without structure: all of it is scatter) or ``residual nugget`` (the
        part of a structured residual that does not vary with the joints: its
        semivariogram extrapolated to zero joint distance)
    independent : True when it does not come from the residual it judges (given or
        repeated poses): only then can scatter beyond the instrument be tested
    detail : one line for the report
    """

    per_axis: float
    source: str
    independent: bool
    detail: str

    def to_dict(self) -> dict:
        return {"per_axis_mm": self.per_axis * 1e3, "source": self.source, "independent": self.independent,
                "detail": self.detail}


def noise_from_rigid_frames(nominal: list[np.ndarray], measured: list[np.ndarray], labels: list[str],
                            tolerance: float = 1e-9, min_rows: int = 6) -> NoiseEstimate | None:
    """The instrument's scatter from several measured frames on one rigid body, or None.

    nominal, measured : per frame (N, 3) positions [m], in the robot's and the tracker's
    frame. Two frames whose nominal distance does not change with the pose (reflectors on
    the same link) keep their measured distance too, whatever the robot's errors; with
    independent isotropic noise sigma per axis on each point, the distance varies by
    sigma * sqrt(2) (the noise of both points projected on the line between them). The
    pairs' variances are pooled. Needs at least ``min_rows`` rows.
    """
    if len(nominal) < 2 or nominal[0].shape[0] < min_rows:
        return None
    variances, pairs = [], []
    for a in range(len(nominal)):
        for b in range(a + 1, len(nominal)):
            model = np.linalg.norm(nominal[a] - nominal[b], axis=1)
            if model.mean() <= 1e-6 or np.ptp(model) > tolerance + 1e-9 * model.mean():
                continue  # not on one rigid body, or the same point
            distance = np.linalg.norm(measured[a] - measured[b], axis=1)
            variances.append(float(np.var(distance, ddof=1)) / 2.0)
            pairs.append(f"{labels[a]}-{labels[b]}")
    if not variances:
        return None
    sigma = math.sqrt(float(np.mean(variances)))
    n = nominal[0].shape[0]
    return NoiseEstimate(sigma, "rigid frames", True,
                         f"scatter of the distances between measured frames on one rigid body ({', '.join(pairs)}; "
                         f"{n} rows): the instrument's own noise, whatever the robot does")
