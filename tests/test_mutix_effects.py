"""Effects' figures no test held exactly (second pass of issue 36's mutation line over ``effects/``):
how many times an angle table's mode oscillates per turn when it only grazes zero, and the place
each built-in effect holds in ``random_scenario``'s draw order where a plugged-in effect joins it.
Each test names a planted change it was seen to catch.
"""

import math

import numpy as np
import pytest
from scipy.interpolate import BSpline

from tcr_accuracy import load_robot
from tcr_accuracy.analysis.simulate import dominant_candidates
from tcr_accuracy.effects import make_effect, plugged_in
from tcr_accuracy.effects.angle_table import DEGREE, JointTable

from test_effect_registry import ElbowDroop, ElbowDroopDraws


def _table_of(functions, lower, upper, intervals=8):
    """A JointTable over [lower, upper] [rad] whose modes are the given functions of the angle (each
    a cubic at most: the cubic B-splines hold it exactly), their coefficients by least squares."""
    knots = np.concatenate([np.full(DEGREE, lower), np.linspace(lower, upper, intervals + 1),
                            np.full(DEGREE, upper)])
    x = np.linspace(lower, upper, 200)
    design = BSpline.design_matrix(x, knots, DEGREE).toarray()
    modes = np.linalg.lstsq(design, np.column_stack([f(x) for f in functions]), rcond=None)[0]
    return JointTable(knots, modes, np.ones(len(functions)))


def test_a_mode_that_only_grazes_zero_does_not_oscillate():
    """Each joint's table spans 0 to 2 rad (a third of a turn), read on 4001 points. Its modes, by
    hand: -(q - 1)^2 touches zero from below at q = 1 (a grid point) and never crosses it: 0 cycles
    per turn; (q - 1)^2 - 0.25 crosses zero twice: one cycle over 2 / (2 pi) turns, pi per turn;
    (q - 1)^3 crosses once: half a cycle, pi / 2 per turn. Seen failing on the values within 1e-6 of
    the largest read as ``1.0`` instead of ``0.0`` (the graze counted as two sign changes, pi per turn)."""
    robot = load_robot("ur5")
    effect = make_effect("angle_table", robot)
    table = _table_of([lambda q: -(q - 1.0) ** 2, lambda q: (q - 1.0) ** 2 - 0.25, lambda q: (q - 1.0) ** 3],
                      0.0, 2.0)
    effect.__dict__["_tables"] = {j: table for j in effect.revolute}
    per_turn = 2.0 / (2.0 * math.pi)
    expected = np.tile([0.0, 1.0 / per_turn, 0.5 / per_turn], len(effect.revolute))
    np.testing.assert_allclose(effect.mode_cycles_per_turn(), expected, rtol=1e-12, atol=0.0)


@pytest.mark.parametrize("place", [1, 2, 3, 4, 5, 6])
def test_a_plugged_in_effect_is_drawn_at_its_place_among_the_built_in_ones(place):
    """``random_scenario`` draws its dominant effects in the order of their places, the name deciding
    between equal places; the built-in places are compliance 1, backlash 2, thermal 3, transmission 4,
    encoder_scale 5. An effect plugged in at a place, named to sort first ("aa_droop") or last
    ("zz_droop"), comes just before or just after the built-in one there. Seen failing on
    thermal's ``dominant_place=3`` turned to 4 or 2, and on each other built-in's place moved by one."""
    built_in = ["compliance", "backlash", "thermal", "transmission", "encoder_scale"]
    for name, after in (("aa_droop", False), ("zz_droop", True)):
        plugged = type(name.title(), (ElbowDroop,), {"name": name, "simulation": ElbowDroopDraws(dominant_place=place)})
        expected = list(built_in)
        expected.insert(min(place - 1 + after, len(built_in)), name)
        with plugged_in(plugged):
            assert list(dominant_candidates()) == expected
