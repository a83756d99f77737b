"""The figures every stage of the diagnosis reports: error statistics of a set of residuals and
the rows of the shrink table. SI units inside; ``to_dict`` gives the JSON form (mm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .paired import stacked


@dataclass(frozen=True)
class ErrorStats:
    """Mean, RMS and max of position error norms [m], over ``count`` measured points."""

    mean: float
    rms: float
    max: float
    count: int

    @staticmethod
    def of(errors: np.ndarray) -> "ErrorStats":
        norm = np.linalg.norm(stacked(errors), axis=1)
        return ErrorStats(float(norm.mean()), float(np.sqrt(np.mean(norm**2))), float(norm.max()), int(norm.size))

    @staticmethod
    def heldout(result: dict) -> "ErrorStats":
        """A fit's held-out errors (:meth:`~tcr_accuracy.diagnosis.fitting.FitEngine.evaluate`),
        pooled over its fold assignments (:meth:`pooled`, taken when it was fitted)."""
        return result["heldout_stats"]

    @staticmethod
    def pooled(repeats: list) -> "ErrorStats":
        """Held-out errors of several fold assignments ((N, 3) or (n_parts, N, 3) each) pooled;
        ``count`` is the number of measured points."""
        repeats = [stacked(h) for h in repeats]
        stats = ErrorStats.of(np.concatenate(repeats))
        return ErrorStats(stats.mean, stats.rms, stats.max, repeats[0].shape[0])

    def to_dict(self) -> dict:
        return {"mean_mm": self.mean * 1e3, "rms_mm": self.rms * 1e3, "max_mm": self.max * 1e3, "count": self.count}


@dataclass(frozen=True)
class Step:
    """One row of the shrink table: the model after adding ``effect``."""

    effect: str
    effects: tuple
    n_parameters: int
    train_rms: float
    heldout: ErrorStats
    z_statistic: float | None  # paired test against the previous step (None for frames)
    #: (gain, low, high) [m]: how much this step lowers the held-out RMS, with its 95 % interval
    gain: tuple | None = None

    def to_dict(self) -> dict:
        out = {"effect": self.effect, "effects": list(self.effects), "n_parameters": self.n_parameters,
               "train_rms_mm": self.train_rms * 1e3, "heldout_rms_mm": self.heldout.rms * 1e3,
               "heldout_mean_mm": self.heldout.mean * 1e3, "heldout_max_mm": self.heldout.max * 1e3,
               "heldout_count": self.heldout.count, "z_vs_previous": self.z_statistic}
        if self.gain is not None:
            out["gain_heldout_rms_mm"] = self.gain[0] * 1e3
            out["gain_interval_mm"] = [self.gain[1] * 1e3, self.gain[2] * 1e3]
        return out
