"""Lateral compliance names its two tilts after coordinate axes only where the joint axis is one.

A two-joint arm written as URDF (:mod:`small_arms`): the first joint turns about z (its tilts are x and y), the
second about (0, 0.6, 0.8), whose perpendiculars (0, -0.8, 0.6) and (1, 0, 0) are not both
coordinate axes, so its tilts are u and v. Seen failing on the coordinate test's ``1 - 1e-12``
turned to ``1 * 1e-12`` (every axis then counts as a coordinate one and the tilted joint's tilts
are named y and x).

And the layout of no effect at all: no column, no scale, no bound (the union layout's empty case,
seen failing on ``np.zeros(0)`` turned to ``np.zeros(-1)``).
"""

import numpy as np

from tcr_accuracy.diagnosis.gram import ColumnLayout
from tcr_accuracy.effects import make_effect

from small_arms import two_joint_arm



def test_the_tilts_of_a_joint_about_no_coordinate_axis_are_u_and_v():
    robot = two_joint_arm(second_axis="0 0.6 0.8")
    effect = make_effect("lateral_compliance", robot)
    assert effect.parameter_names() == ["lateral_compliance.turn.x", "lateral_compliance.turn.y",
                                        "lateral_compliance.second.u", "lateral_compliance.second.v"]
    u, v = robot.axis_perpendiculars(1)
    axis = np.array([0.0, 0.6, 0.8])
    np.testing.assert_allclose([u @ axis, v @ axis, u @ v, np.linalg.norm(u), np.linalg.norm(v)],
                               [0.0, 0.0, 0.0, 1.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(np.cross(u, v), axis, atol=1e-12)


def test_a_layout_of_no_effect_has_no_column():
    layout = ColumnLayout({})
    assert layout.n_columns == 0 and layout.names == []
    for field in (layout.scale, layout.lower, layout.upper, layout.penalty):
        assert field.shape == (0,)
    assert layout.indices([], {}).shape == (0,) and layout.columns_of([]).shape == (0,)
