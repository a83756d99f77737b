"""Lateral compliance names its two tilts after coordinate axes only where the joint axis is one.

A two-joint arm written here as URDF: the first joint turns about z (its tilts are x and y), the
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
from tcr_accuracy.model.robot import load_robot

URDF = """<?xml version="1.0"?>
<robot name="tilted_arm">
  <link name="base"><inertial><mass value="5"/><origin xyz="0 0 0.05"/>
    <inertia ixx="0.05" iyy="0.05" izz="0.05" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><inertial><mass value="3"/><origin xyz="0.2 0 0"/>
    <inertia ixx="0.02" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="fore"><inertial><mass value="2"/><origin xyz="0.15 0 0"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tool"/>
  <joint name="turn" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="100" velocity="1"/></joint>
  <joint name="tilted" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="0.4 0 0"/><axis xyz="0 0.6 0.8"/><limit lower="-3" upper="3" effort="100" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="fore"/><child link="tool"/><origin xyz="0.3 0 0"/></joint>
</robot>
"""


def test_the_tilts_of_a_joint_about_no_coordinate_axis_are_u_and_v(tmp_path):
    path = tmp_path / "tilted_arm.urdf"
    path.write_text(URDF)
    robot = load_robot(path, tool="tool")
    effect = make_effect("lateral_compliance", robot)
    assert effect.parameter_names() == ["lateral_compliance.turn.x", "lateral_compliance.turn.y",
                                        "lateral_compliance.tilted.u", "lateral_compliance.tilted.v"]
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
