"""Loading robots by file and by name, and the errors a user gets for bad input."""

import re
import warnings

import numpy as np
import pytest

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.robot import EXAMPLE_ROBOTS, JointLimitWarning, load_robot, robot_from_urdf_text

from conftest import REPO


@pytest.mark.parametrize("name", sorted(EXAMPLE_ROBOTS))
def test_example_robot_data_robots_load_by_name(name):
    robot = load_robot(name)
    assert robot.n_joints >= 6
    assert robot.model.existFrame(robot.tool_frame)


def test_panda_fingers_are_locked_out_of_the_chain():
    panda = load_robot("panda")
    assert panda.n_joints == 7 and not any("finger" in n for n in panda.joint_names)


def test_urdf_file_with_default_leaf_tool(tmp_path):
    text = (REPO / "robots" / "tool_changer.urdf").read_text()
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    robot = load_robot(str(path))
    # labelled by the URDF's own <robot name>, as named robots are, not by the file name
    assert robot.tool_frame == "tool" and robot.name == "tool_changer"


def test_two_link_closed_form():
    """A planar 2R arm from an inline URDF: x = a1 cos q1 + a2 cos(q1 + q2)."""
    text = """<robot name="planar">
      <link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
      <joint name="q1" type="revolute"><parent link="base"/><child link="l1"/>
        <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
      <joint name="q2" type="continuous"><parent link="l1"/><child link="l2"/>
        <origin xyz="0.7 0 0"/><axis xyz="0 0 1"/></joint>
      <joint name="t" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0.4 0 0"/></joint>
    </robot>"""
    from tcr_accuracy.model.kinematics import tcp_poses

    robot = robot_from_urdf_text(text, None)
    assert robot.tool_frame == "tip" and robot.joint_kinds == ["revolute", "revolute"]
    q = np.array([[0.3, -1.2], [2.0, 0.5]])
    got = tcp_poses(robot, q).position
    expected_x = 0.7 * np.cos(q[:, 0]) + 0.4 * np.cos(q[:, 0] + q[:, 1])
    expected_y = 0.7 * np.sin(q[:, 0]) + 0.4 * np.sin(q[:, 0] + q[:, 1])
    np.testing.assert_allclose(got[:, 0], expected_x, atol=1e-15)
    np.testing.assert_allclose(got[:, 1], expected_y, atol=1e-15)
    assert np.isnan(robot.upper_limits[1])  # continuous joint: unbounded


@pytest.mark.parametrize("text, message", [
    ("<robot><link name='a'", "does not parse"),
    ("<?xml version='1.0'?><!DOCTYPE r [<!ENTITY a 'aaaa'>]><robot name='r'/>", "entity"),
    ("<model name='x'/>", "needs <robot>"),
])
def test_bad_urdf_text_gives_one_clear_error(text, message):
    with pytest.raises(InputError, match=message):
        robot_from_urdf_text(text, "tool", source="bad.urdf")


def test_unknown_frame_lists_the_frames():
    with pytest.raises(InputError, match=r"no such frame.*tool_joint"):
        load_robot(None, "flange")


def test_unknown_robot_name():
    with pytest.raises(InputError, match="not a known robot name"):
        load_robot("kuka_kr300")


def test_joint_values_count_nonfinite_and_limits(tool_changer):
    with pytest.raises(InputError, match="expected 6 joint values"):
        tool_changer.check_joint_values(np.zeros(5))
    with pytest.raises(InputError, match="j2 has a non-finite"):
        tool_changer.check_joint_values(np.array([0, np.inf, 0, 0, 0, 0.0]))
    with pytest.warns(JointLimitWarning, match="j4 = 900 mm is outside"):
        tool_changer.check_joint_values(np.array([0, 0, 0, 0.9, 0, 0.0]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tool_changer.check_joint_values(tool_changer.working_pose)


_INERTIA = '<inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial>'


def _mimic_urdf(j1_mimic: str = "", j2_mimic: str = "", j3_mimic: str = "") -> str:
    """Three revolute joints in a row, each with the <mimic> element given."""
    links = "".join(f'<link name="l{k}">{_INERTIA}</link>' for k in (1, 2, 3))
    joints = "".join(
        f'<joint name="j{k}" type="revolute"><parent link="{"base" if k == 1 else f"l{k - 1}"}"/>'
        f'<child link="l{k}"/><origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>'
        f'<limit lower="-1" upper="1" effort="1" velocity="1"/>{m}</joint>'
        for k, m in ((1, j1_mimic), (2, j2_mimic), (3, j3_mimic)))
    return f'<robot name="m"><link name="base"/>{links}{joints}</robot>'


@pytest.mark.parametrize("mimics, said", [
    (dict(j2_mimic='<mimic joint="j2"/>'), "joint j2: <mimic> names the joint itself"),
    (dict(j1_mimic='<mimic joint="j2"/>', j2_mimic='<mimic joint="j1"/>'), "(a loop of <mimic> rules)"),
    (dict(j1_mimic='<mimic joint="j2"/>', j2_mimic='<mimic joint="j3"/>', j3_mimic='<mimic joint="j1"/>'),
     "(a loop of <mimic> rules)"),
    (dict(j2_mimic='<mimic joint="j3"/>', j3_mimic='<mimic joint="j1"/>'), "(a chain of <mimic> rules)"),
    (dict(j2_mimic='<mimic joint="nosuch"/>'), "names 'nosuch', no joint of this URDF"),
])
def test_29_10_a_mimic_rule_needs_another_joint_that_follows_none(mimics, said):
    with pytest.raises(InputError, match=re.escape(said)):
        robot_from_urdf_text(_mimic_urdf(**mimics), "l3")
    robot = robot_from_urdf_text(_mimic_urdf(j3_mimic='<mimic joint="j1" multiplier="2"/>'), "l3")
    assert robot.mimic["j3"].joint == "j1" and robot.mimic["j3"].multiplier == 2.0  # one rule: read
