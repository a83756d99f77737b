"""The ambiguity groups as reported (``diagnosis/ambiguity.py``: ``ambiguity_report``) against the groups
written out here, and the paired signed-rank z with ties (``diagnosis/paired.py``) against scipy (issue 36). Each test names a planted change it was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.ambiguity import ambiguity_report


def _row(effect: str, rms_mm: float) -> dict:
    return {"effect": effect, "effects": effect.split("+"), "heldout_rms_mm": rms_mm, "n_parameters": 3,
            "_squares": np.full(4, rms_mm**2)}


def test_only_groups_with_a_stand_in_are_reported_the_largest_first_without_their_private_arrays():
    """Three chosen effects: one with no stand-in (a group of one: not reported), one with one stand-in, one
    with two (first in the report, though found last). Each reported member is its row less the keys
    starting with "_". Seen failing on ``len(rows) > 1`` turned to ``len(rows) > 0`` and to
    ``len(rows) > 2``."""
    groups = {"drift": [_row("drift", 0.1)],
              "backlash": [_row("backlash", 0.2), _row("friction", 0.21)],
              "gear_errors": [_row("gear_errors", 0.3), _row("joint_offsets+cyclic", 0.31), _row("angle_table", 0.305)]}
    report = ambiguity_report(groups)
    assert [g["chosen"] for g in report] == ["gear_errors", "backlash"]
    assert report[0]["effects"] == ["gear_errors", "joint_offsets+cyclic", "angle_table"]
    assert report[1]["effects"] == ["backlash", "friction"]
    assert report[0]["members"][1] == {"effect": "joint_offsets+cyclic", "effects": ["joint_offsets", "cyclic"],
                                       "heldout_rms_mm": 0.31, "n_parameters": 3}
    assert all(not k.startswith("_") for g in report for m in g["members"] for k in m)


def test_signed_rank_z_with_ties_is_scipys_tie_corrected_normal_approximation():
    """Wilcoxon's one-sided z with tied |differences| (two groups of three, one pair) and zeros dropped is
    scipy's tie-corrected normal approximation, read back from its p-value; with every |difference| tied
    (n = 1, 2 and 5) it is still finite and scipy's. Seen failing on the ties' term ``(counts**3 - counts) /
    48.0`` turned to ``/ 49.0`` and to ``counts**2``."""
    from scipy import stats

    from tcr_accuracy.diagnosis.paired import signed_rank_z

    rng = np.random.default_rng(3501)
    d = np.concatenate([[0.5, -0.5, 0.5], [1.25, 1.25, -1.25], [2.0, -2.0], np.round(rng.uniform(0.1, 3.0, 9) * 64) / 64, [0.0, 0.0]])
    cases = [d, np.array([0.75]), np.array([0.75, -0.75]), np.array([0.75, 0.75, -0.75, 0.75, 0.75])]
    for diff in cases:
        before = np.abs(diff) + 1.0  # (N,) squares
        after = before - diff
        assert np.array_equal(before - after, diff)  # the ties exact (dyadic differences)
        p = stats.wilcoxon(diff, zero_method="wilcox", correction=False, alternative="greater",
                           method="approx").pvalue
        assert signed_rank_z(before, after) == pytest.approx(stats.norm.isf(p), rel=1e-9, abs=1e-12)
