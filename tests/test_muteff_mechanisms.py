"""What a fitted effect's values say of its cause (``effects/mechanisms.py``), read by hand (issue 36): which
parameters the data resolve (beyond two standard errors), which mechanism each one's interval reaches,
their shares of the TCP motion in percent, and whether the effect is physical and textbook. Each test
names a planted change it was seen to catch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tcr_accuracy.effects import make_effect
from tcr_accuracy.effects.mechanisms import read_mechanism

DEG = math.pi / 180.0


def test_backlash_values_read_by_the_mechanism_each_interval_reaches_with_their_shares_of_the_motion(tool_changer):
    """The tool changer's backlash (a dead band 0 .. 0.5 deg / 0.5 mm; a compensation set too high, -2 x that
    .. 0): j1 0.2 deg (a dead band), j2 -0.3 deg (the compensation), j3 0.6 deg +- 0.01 (beyond both: no
    mechanism), j4 0.52 mm +- 0.015 mm (its interval value +- 2 std reaches 0.5 mm: a dead band), j5 0.025
    deg +- 0.01 (2.5 standard errors: resolved), j6 -2 deg held on its bound (no mechanism). Weighed by
    |value| x motion per unit, the shares by hand: the dead band's (j1, j4, j5), the unexplained (j3, j6),
    the compensation's (j2), in percent; not physical (the unexplained share is over half), not textbook;
    each resolved parameter with its mechanism key. Seen failing on ``significance: float = 2.0`` turned
    to ``3.0`` (j5 unresolved) or ``1.0`` (j4 unexplained) and ``unexplained_share: float = 0.5`` to ``1.5``."""
    effect = make_effect("backlash", tool_changer)
    values = np.array([0.2 * DEG, -0.3 * DEG, 0.6 * DEG, 0.52e-3, 0.025 * DEG, -2.0 * DEG])
    std = np.array([0.01 * DEG, 0.01 * DEG, 0.01 * DEG, 0.015e-3, 0.01 * DEG, 0.01 * DEG])
    motion = np.array([0.1, 0.8, 0.5, 1.0, 0.3, 0.05])  # m of TCP per unit [rad or m]
    pinned = np.array([False] * 5 + [True])
    reading = read_mechanism(effect, values, std, motion=motion, pinned=pinned)
    weight = np.abs(values) * motion
    share = {"dead_band": weight[[0, 3, 4]].sum(), "unexplained": weight[[2, 5]].sum(),
             "lost_motion_compensation": weight[1]}
    total = sum(share.values())
    order = sorted(share, key=lambda k: -share[k])
    assert reading.keys == tuple(order)
    assert [p["mechanism"] for p in reading.parameters] == ["dead_band", "lost_motion_compensation", None,
                                                            "dead_band", "dead_band", None]
    assert [p["textbook"] for p in reading.parameters] == [True, False, False, True, True, False]
    assert [p["unit"] for p in reading.parameters] == ["rad", "rad", "rad", "m", "rad", "rad"]
    assert reading.physical == (share["unexplained"] < 0.5 * total) and not reading.physical
    assert not reading.textbook
    band, compensation = effect.mechanisms()
    words = {"dead_band": f"{band.words} (j1, j4, j5, {share['dead_band'] / total:.0%} of its TCP motion)",
             "lost_motion_compensation": f"{compensation.words} (j2, {share['lost_motion_compensation'] / total:.0%} "
                                         "of its TCP motion)",
             "unexplained": f"values the data push beyond every mechanism backlash can stand for (j3, j6, "
                            f"{share['unexplained'] / total:.0%} of its TCP motion): another cause with the same "
                            "signature, or a model that does not describe this robot"}
    assert reading.mechanism == "; ".join(words[k] for k in order)
    checks = {"dead_band": band.check, "lost_motion_compensation": compensation.check}
    assert reading.check == "; ".join(checks[k] for k in order if k in checks)
    doc = reading.to_dict()
    assert doc["parameters"][3]["value"] == pytest.approx(0.52e-3) and doc["mechanism_keys"] == list(order)

    # the same values with j3 and j6 barely moving the TCP: physical (the unexplained share under half)
    light = read_mechanism(effect, values, std, motion=np.array([0.1, 0.8, 0.001, 1.0, 0.3, 0.001]), pinned=pinned)
    assert light.physical and not light.textbook and light.keys[-1] == "unexplained"


def test_a_reading_within_the_effects_own_physics_is_textbook_and_names_no_joints_when_all_are_read(tool_changer):
    """Encoder scales of 200 ppm on every joint (+- 20 ppm): one mechanism (ratio_error) for all, so the words
    are its own without joints or a share, textbook and physical; with j2 at 3 % (the wrong ratio's, not
    the physics' 1 %) the two are each given with their joints and their shares of the motion (the motion
    per unit, by default, the inverse of the typical 300 ppm, the same for every joint); nothing resolved,
    the nonzero values read, with their joint. Seen failing on ``len(order) > 1`` turned to ``> 2`` and
    ``len(members) < len(names)`` to ``len(members) < len(names) - 1``."""
    effect = make_effect("encoder_scale", tool_changer)
    std = np.full(6, 2e-5)
    reading = read_mechanism(effect, np.full(6, 2e-4), std)
    ratio, wrong = effect.mechanisms()
    assert reading.mechanism == ratio.words and reading.keys == ("ratio_error",)
    assert reading.physical and reading.textbook and reading.check == ratio.check
    values = np.full(6, 2e-4)
    values[1] = 0.03
    mixed = read_mechanism(effect, values, std)
    share = 0.03 / (0.03 + 5 * 2e-4)
    assert mixed.keys == ("wrong_ratio", "ratio_error")
    assert mixed.mechanism == (f"{wrong.words} (j2, {share:.0%} of its TCP motion); {ratio.words} (j1, j3, j4, j5, j6, "
                               f"{1 - share:.0%} of its TCP motion)")
    assert mixed.physical and not mixed.textbook
    # nothing resolved: every nonzero value is read (what the values would mean)
    faint = read_mechanism(effect, np.r_[1e-5, np.zeros(5)], np.full(6, 1e-4))
    assert faint.keys == ("ratio_error",) and [p["parameter"] for p in faint.parameters] == ["encoder_scale.j1"]
    assert faint.mechanism == f"{ratio.words} (j1)"
    five = read_mechanism(effect, np.r_[np.full(5, 2e-4), 0.0], std)
    assert five.mechanism == f"{ratio.words} (j1, j2, j3, j4, j5)"
