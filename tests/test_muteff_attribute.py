"""The attribution's reported figures (``diagnosis/stages/attribute.py``) by hand (issue 36): a family's share,
its interval and the held-out RMS without it in mm; two fitted motions compared with the standard error
of their difference (the delta method written out here on a covariance and gradients chosen by hand), the
ones larger beyond a threshold, and the note that says so with its millimetres. Each test names a planted
change it was seen to catch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tcr_accuracy.diagnosis.attribution import ShareComparison
from tcr_accuracy.diagnosis.records import ErrorStats
from tcr_accuracy.diagnosis.stages.attribute import FamilyShare, MotionSizes, _motion_note, larger_motion
from tcr_accuracy.effects.mechanisms import FAMILIES

MM = 1e-3


def test_a_family_share_in_mm_with_its_interval_and_the_held_out_rms_without_it():
    """The gravity family's share 0.412 mm [0.25, 0.6] with held-out errors of norms 0.3, 0.4 and 1.2 mm
    without it (RMS sqrt((0.09 + 0.16 + 1.44) / 3) mm), compared with the largest family (0.2 mm more,
    [0.05, 0.35], z 4.1 against 3): the JSON in mm, the family's words, its members and stand-ins.
    Seen failing on ``self.interval[1] * 1e3`` turned to ``* 1001.0`` and ``heldout_without.rms * 1e3`` to
    ``/ 1e3``."""
    errors = np.array([[0.3, 0.0, 0.0], [0.0, 0.4, 0.0], [0.0, 0.0, 1.2]]) * MM
    below = ShareComparison("geometric", "gravity", 0.2 * MM, (0.05 * MM, 0.35 * MM), 4.1, 3.0)
    share = FamilyShare("gravity", ("compliance", "lateral_compliance"), 0.412 * MM, (0.25 * MM, 0.6 * MM),
                        ErrorStats.of(errors), ("backlash",), below)
    doc = share.to_dict()
    assert doc["share_mm"] == pytest.approx(0.412, rel=1e-12)
    assert doc["interval_mm"] == pytest.approx([0.25, 0.6], rel=1e-12)
    assert doc["heldout_rms_without_mm"] == pytest.approx(math.sqrt((0.09 + 0.16 + 1.44) / 3), rel=1e-12)
    assert doc["what"] == FAMILIES["gravity"] and doc["effects"] == ["compliance", "lateral_compliance"]
    assert doc["stand_ins"] == ["backlash"]
    compared = doc["below_largest"]
    assert compared.pop("interval_mm") == pytest.approx([0.05, 0.35], rel=1e-12)
    assert (compared.pop("larger"), compared.pop("smaller"), compared.pop("ranked")) == ("geometric", "gravity", True)
    assert compared == pytest.approx({"difference_mm": 0.2, "z": 4.1, "z_threshold": 3.0}, rel=1e-12)
    assert "below_largest" not in FamilyShare("geometric", ("geometry",), 0.6 * MM, (0.4 * MM, 0.8 * MM),
                                              ErrorStats.of(errors)).to_dict()


def _sizes():
    """Three motions (0.5, 0.8 and 0.52 mm) over two parameters with their covariance (chosen by hand)."""
    covariance = np.array([[4.0, 1.0], [1.0, 2.0]]) * 1e-9
    return MotionSizes(size={"compliance": 0.5 * MM, "family gravity": 0.5 * MM, "geometry": 0.8 * MM,
                             "backlash": 0.52 * MM},
                       gradient={"compliance": np.array([1.0, 0.0]), "family gravity": np.array([1.0, 0.0]),
                                 "geometry": np.array([0.0, 1.0]), "backlash": np.array([0.5, 0.5])},
                       covariance=covariance), covariance


def test_two_motions_differ_by_their_sizes_with_the_delta_methods_standard_error():
    """geometry less compliance: 0.3 mm, its standard error sqrt(g^T C g) with g = (-1, 1): sqrt(4 + 2 - 2 x 1)
    x 1e-9 = 4e-9 m^2; a motion is larger than another's beyond a threshold in standard errors only where
    the difference exceeds that many (geometry by 4.74 of them, backlash by 0.63). Seen failing on
    ``self.size[larger] - self.size[smaller]`` turned to ``+`` and ``g @ self.covariance @ g`` with
    ``g = self.gradient[larger] - ...`` turned to ``+``, and ``difference > threshold * se`` to ``threshold / se``."""
    sizes, covariance = _sizes()
    difference, se = sizes.difference("geometry", "compliance")
    g = np.array([-1.0, 1.0])
    assert difference == pytest.approx(0.3 * MM, rel=1e-12)
    assert se == pytest.approx(math.sqrt(g @ covariance @ g), rel=1e-12) == pytest.approx(2 * math.sqrt(1e-9))
    assert larger_motion(sizes, "compliance", ["compliance", "geometry", "backlash"], 5.0) == []
    assert larger_motion(sizes, "compliance", ["compliance", "geometry", "backlash"], 3.0) == ["geometry"]
    # backlash: 0.02 mm larger, g = (-0.5, 0.5), its standard error sqrt(1 + 0.5 - 0.5) x sqrt(1e-9) m
    assert sizes.difference("backlash", "compliance")[1] == pytest.approx(math.sqrt(1e-9), rel=1e-12)
    assert larger_motion(sizes, "compliance", ["compliance", "geometry", "backlash"], 0.5) == ["geometry", "backlash"]
    threshold = 0.3 * MM / se
    assert larger_motion(sizes, "compliance", ["geometry"], threshold * 0.999) == ["geometry"]
    assert larger_motion(sizes, "compliance", ["geometry"], threshold * 1.001) == []


def test_the_note_of_a_larger_motion_gives_both_sizes_and_the_difference_in_mm():
    """The family with the largest held-out share (gravity) moves the TCP by 0.5 mm RMS, geometry's by 0.8 mm:
    the note gives 0.5 and 0.8 mm (4 significant digits), the difference 0.3 mm and its standard error
    0.063 mm (2 x sqrt(1e-9) m), the family's name without its key prefix, and the level it speaks of.
    Seen failing on ``sizes.size[name] * 1e3`` turned to ``* 1001.0`` and the difference's ``[1] * 1e3``
    turned to ``[1] / 1e3``."""
    sizes, _ = _sizes()
    note = _motion_note(sizes, "family gravity", ["geometry"], "family")
    se_mm = 2 * math.sqrt(1e-9) / MM
    assert note == (f"the family with the largest held-out share, gravity, moves the TCP by 0.5 mm RMS beyond the "
                    f"frames, less than geometry 0.8 mm (larger by 0.3 +- {se_mm:.2g} mm): the share and the motion "
                    f"rank them apart in opposite orders, so the family is not named apart from geometry")
    assert f"{se_mm:.2g}" == "0.063"


def test_what_stands_in_for_a_chosen_effect_is_every_alternative_after_it_once():
    """The selection's groups list the chosen effect first, then the swaps the held-out rows do not rank
    below it: its stand-ins are their effects in order, each once, never itself; its group adds them to it.
    Seen failing on ``rows[1:]`` turned to ``rows[2:]``."""
    from tcr_accuracy.diagnosis.stages.attribute import group_members, stand_ins_of

    groups = {"compliance": [{"effects": ["compliance"]}, {"effects": ["lateral_compliance", "joint_offsets"]},
                             {"effects": ["backlash", "compliance"]}, {"effects": ["backlash"]}],
              "geometry": [{"effects": ["geometry"]}]}
    assert stand_ins_of(groups) == {"compliance": ("lateral_compliance", "joint_offsets", "backlash"),
                                    "geometry": ()}
    assert group_members(groups, "compliance") == ["compliance", "lateral_compliance", "joint_offsets", "backlash"]
    assert group_members(groups, None) == [] and group_members(groups, "drift") == ["drift"]
