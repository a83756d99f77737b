"""The ambiguity groups as reported (``diagnosis/ambiguity.py``: ``ambiguity_report``) against the groups
written out here (issue 36). Each test names a planted change it was seen to catch."""

from __future__ import annotations

import numpy as np

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
