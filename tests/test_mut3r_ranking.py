"""The largest of several shares (``diagnosis/attribution.py``'s ``rank_largest``), third pass of issue 36: where
the model with every effect leaves no held-out error at all (a simulation without noise, every effect in the
model), each share is the held-out RMS without it, and the largest must still be found by its share, not by the
order the names came in. Each test names a planted change it was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.attribution import rank_largest
from tcr_accuracy.diagnosis.uncertainty import PoseBootstrap

N = 20


def test_the_largest_share_is_found_where_the_full_model_leaves_no_held_out_error():
    """The full model's held-out squared errors all 0; without gravity, geometry or backlash they are planted at
    RMS 0.1, 0.3 and 0.2 mm (names given smallest first): the largest is geometry, compared with backlash then
    gravity, each difference the two RMS apart (sqrt of the mean of the planted squares, written out here).
    Seen failing on the sort key ``-(table.point[n] - table.point[final])`` turned to ``-(table.point[n] **
    table.point[final])`` (every key 1 when the full model's RMS is 0: the names' own order)."""
    rng = np.random.default_rng(51)
    squares = {"final": np.zeros(N)}
    for name, rms in (("gravity", 0.1e-3), ("geometry", 0.3e-3), ("backlash", 0.2e-3)):
        raw = rng.gamma(2.0, 1.0, N)
        squares[name] = raw * (rms**2 / raw.mean())
    table = PoseBootstrap.draw(N, n_replicates=200, random_state=1).read(squares)
    assert table.point["final"] == 0.0
    ranking = rank_largest(table, squares, ["gravity", "geometry", "backlash"], "final", 3.0)
    assert [(c.larger, c.smaller) for c in ranking] == [("geometry", "backlash"), ("geometry", "gravity")]
    assert [c.difference for c in ranking] == pytest.approx([0.1e-3, 0.2e-3], rel=1e-12)
