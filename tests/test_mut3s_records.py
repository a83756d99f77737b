"""``diagnosis/records.py`` read whole (issue 36, third pass): the error statistics of residuals of one and of
two measured frames, and pooled over fold assignments, against numpy written out here. Each test names planted
changes it was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.records import ErrorStats


def test_statistics_of_two_measured_frames_pooled_over_two_fold_assignments():
    """Residuals of two measured frames on 5 rows (2, 5, 3), held out by two fold assignments: the pooled
    mean, RMS and max of the point errors' norms are over all 20 norms (numpy here), and the count is the
    measured points of one assignment, 10 (not the 20 pooled, not the 3 coordinates); one frame's (5, 3)
    residual alone gives its own five norms' figures and count 5. Seen failing on ``repeats[0].shape[0]``
    turned to ``shape[1]``, on ``np.linalg.norm(stacked(errors), axis=1)`` turned to ``axis=0`` and on
    ``np.mean(norm**2)`` turned to ``norm**3`` (planted by hand)."""
    rng = np.random.default_rng(5)
    repeats = [rng.normal(0, 1e-4, (2, 5, 3)) for _ in range(2)]
    norms = np.concatenate([np.sqrt(np.sum(r.reshape(-1, 3) ** 2, axis=1)) for r in repeats])
    pooled = ErrorStats.pooled(repeats)
    assert (pooled.mean, pooled.rms, pooled.max) == pytest.approx(
        (norms.mean(), np.sqrt(np.mean(norms**2)), norms.max()), rel=1e-12)
    assert pooled.count == 10
    one = ErrorStats.of(repeats[0][1])
    own = np.sqrt(np.sum(repeats[0][1] ** 2, axis=1))
    assert (one.mean, one.rms, one.max, one.count) == pytest.approx(
        (own.mean(), np.sqrt(np.mean(own**2)), own.max(), 5), rel=1e-12)
    assert ErrorStats.heldout({"heldout_stats": one}) is one
