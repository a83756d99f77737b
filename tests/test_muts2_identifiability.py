"""Which parameters the measurements tell apart (``diagnosis/identifiability.py``), second pass (issue 36), on
the columns of known independent motions that tests/test_mutfit_identifiability.py builds (orthonormal
directions: each column's own motion a closed form). Each test names a planted change it was seen to catch."""

from __future__ import annotations

import math

import pytest
from test_mutfit_identifiability import N_POSES, _bases

from tcr_accuracy.diagnosis.identifiability import identifiability


@pytest.mark.parametrize("report", [True, False])
def test_an_effect_missing_from_a_threshold_dict_is_held_to_no_threshold(report):
    """Thresholds per effect with b left out: a at 5 um keeps its three columns, b is judged at 0 m (only the
    rank tolerance), so it keeps b2 (0.63 um RMS of its own: under a's threshold, over none) and b4, with the
    report and without; the report's threshold is the largest given, 5 um. Seen failing on
    ``threshold = thresholds.get(name, 0.0)`` turned to ``1.0`` (b judged at 1 m RMS keeps nothing), in the
    report's loop and in the quick one."""
    bases, _, _ = _bases()
    own = 2e-6 / math.sqrt(N_POSES)
    assert own < 5e-6
    keep, out = identifiability(bases, ["a", "b"], 1e-6, {"a": 5e-6}, report=report)
    assert keep["a"].tolist() == [0, 1, 2] and keep["b"].tolist() == [1, 3]
    if report:
        assert out["min_motion_mm"] == pytest.approx(5e-3, rel=1e-12)
        assert out["effects"]["b"]["n_identifiable"] == 2
    # the same b held to 5 um by name: b2 goes
    assert identifiability(bases, ["a", "b"], 1e-6, {"a": 5e-6, "b": 5e-6}, report=report)[0]["b"].tolist() == [3]
