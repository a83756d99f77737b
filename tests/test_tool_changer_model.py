"""The tool-changer URDF against the geometry written in the issue (seed Fig. 5, Eq. 24, 34)."""

import math

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy

from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.model.tool_changer import ToolChangerDimensions, tool_changer_urdf

from conftest import REPO

L1, L2, L3, L4, L5, L6 = 0.315, 0.210, 0.796, 0.560, 0.240, 0.165

# joint -> (kind, axis, origin in {S} at q = 0), typed in from the issue text
EXPECTED = {
    "j1": ("revolute", (0, 0, 1), (0, 0, L1)),
    "j2": ("revolute", (1, 0, 0), (0, 0, L1 + L2)),
    "j3": ("revolute", (1, 0, 0), (0, L3, L1 + L2)),
    "j4": ("prismatic", (0, 1, 0), None),
    "j5": ("revolute", (1, 0, 0), (0, L3 + L4 + L5, L1 + L2)),
    "j6": ("revolute", (0, 0, 1), (0, L3 + L4 + L5 + L6, L1 + L2)),
}


def test_committed_urdf_is_the_generator_output():
    committed = (REPO / "robots" / "tool_changer.urdf").read_text()
    assert committed == tool_changer_urdf(), "run scripts/make_tool_changer_urdf.py"


def test_joint_axes_and_origins_match_the_seed_geometry(tool_changer):
    model, data = tool_changer.model, tool_changer.model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    assert tool_changer.joint_names == list(EXPECTED)
    for j, (name, (kind, axis, origin)) in enumerate(EXPECTED.items(), start=1):
        assert tool_changer.joint_kinds[j - 1] == kind
        oMj = data.oMi[j]
        motion = tool_changer.motion_axes[j - 1]
        world_axis = oMj.rotation @ (motion[3:] if kind == "revolute" else motion[:3])
        np.testing.assert_allclose(world_axis, axis, atol=1e-15)
        if origin is not None:
            np.testing.assert_allclose(oMj.translation, origin, atol=1e-15)


def test_tool_frame_at_zero_is_seed_eq23(tool_changer):
    data = tool_changer.model.createData()
    pin.framesForwardKinematics(tool_changer.model, data, pin.neutral(tool_changer.model))
    oMt = data.oMf[tool_changer.tool_frame_id]
    np.testing.assert_allclose(oMt.translation, (0, L3 + L4 + L5 + L6, L1 + L2), atol=1e-15)
    np.testing.assert_allclose(oMt.rotation, np.eye(3), atol=1e-15)


def test_yourdfpy_loads_the_urdf_and_agrees_at_the_working_pose(tool_changer):
    urdf = yourdfpy.URDF.load(str(REPO / "robots" / "tool_changer.urdf"), load_meshes=False)
    assert sorted(urdf.actuated_joint_names) == sorted(EXPECTED)
    q = dict(zip(tool_changer.joint_names, tool_changer.working_pose))
    urdf.update_cfg(q)
    transform = urdf.get_transform(frame_to="tool", frame_from="base_link")
    # working pose by hand: j1 = 15 deg turns the planar arm (in the y-z plane) about z
    c2, s2 = math.cos(math.radians(30)), math.sin(math.radians(30))
    a23 = math.radians(30 - 10)
    a235 = math.radians(30 - 10 - 20)
    planar_y = L3 * c2 + L4 * math.cos(a23) + (L5 * math.cos(a23)) + L6 * math.cos(a235)
    planar_z = L1 + L2 + L3 * s2 + L4 * math.sin(a23) + L5 * math.sin(a23) + L6 * math.sin(a235)
    yaw = math.radians(15)
    expected = (-planar_y * math.sin(yaw), planar_y * math.cos(yaw), planar_z)
    np.testing.assert_allclose(transform[:3, 3], expected, atol=1e-12)


def test_other_dimensions_rebuild_the_robot():
    dims = ToolChangerDimensions(l3=1.0)
    from tcr_accuracy.model.robot import robot_from_urdf_text

    robot = robot_from_urdf_text(tool_changer_urdf(dims), "tool")
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, pin.neutral(robot.model))
    assert data.oMf[robot.tool_frame_id].translation[1] == pytest.approx(1.0 + L4 + L5 + L6, abs=1e-15)


def test_inertials_are_those_of_a_heavy_arm(tool_changer):
    moving_mass = sum(inertia.mass for inertia in tool_changer.model.inertias[1:])
    assert 300.0 < moving_mass < 1000.0
    assert np.all(np.isfinite(tool_changer.lower_limits)) and np.all(tool_changer.lower_limits < tool_changer.upper_limits)


def test_working_pose_is_the_seed_pose(tool_changer):
    np.testing.assert_allclose(
        tool_changer.working_pose * tool_changer.display_scale, [15, 30, -10, 0, -20, 0], atol=1e-12
    )
    assert load_robot(str(REPO / "robots" / "tool_changer.urdf")).working_pose[0] == pytest.approx(math.radians(15))
