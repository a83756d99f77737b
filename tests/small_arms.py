"""A two-joint arm written as URDF for tests that need a joint layout no bundled robot has (a joint
about no coordinate axis, a joint of more than a turn each way): the first joint turns about z, the
second about ``second_axis``; both within +-``travel`` rad; light point masses on each link. And an arm
of one joint, revolute or prismatic (effects of one parameter, or none)."""

from __future__ import annotations

from tcr_accuracy.model.robot import robot_from_urdf_text


def two_joint_arm(second_axis: str = "0 1 0", travel: float = 3.0):
    """The arm as a RobotModel, its TCP the frame ``tool`` 0.3 m past the second joint's link."""
    limit = f'<limit lower="{-travel}" upper="{travel}" effort="100" velocity="1"/>'
    inertial = ('<inertial><mass value="{m}"/><origin xyz="{x} 0 0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" '
                'ixy="0" ixz="0" iyz="0"/></inertial>')
    text = f"""<?xml version="1.0"?>
<robot name="two_joint_arm">
  <link name="base">{inertial.format(m=5, x=0)}</link>
  <link name="upper">{inertial.format(m=3, x=0.2)}</link>
  <link name="fore">{inertial.format(m=2, x=0.15)}</link>
  <link name="tool"/>
  <joint name="turn" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>{limit}</joint>
  <joint name="second" type="revolute"><parent link="upper"/><child link="fore"/>
    <origin xyz="0.4 0 0"/><axis xyz="{second_axis}"/>{limit}</joint>
  <joint name="flange" type="fixed"><parent link="fore"/><child link="tool"/><origin xyz="0.3 0 0"/></joint>
</robot>
"""
    return robot_from_urdf_text(text, "tool", name="two_joint_arm")


def one_joint_arm(kind: str = "revolute"):
    """One joint (``kind``: revolute about z, or prismatic along z, within +-1), its TCP the frame ``tool``
    0.4 m along x from it."""
    text = f"""<?xml version="1.0"?>
<robot name="one_joint_{kind}">
  <link name="base"/>
  <link name="arm"><inertial><mass value="2"/><origin xyz="0.2 0 0"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
    ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="tool"/>
  <joint name="only" type="{kind}"><parent link="base"/><child link="arm"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="100" velocity="1"/></joint>
  <joint name="flange" type="fixed"><parent link="arm"/><child link="tool"/><origin xyz="0.4 0 0"/></joint>
</robot>
"""
    return robot_from_urdf_text(text, "tool", name=f"one_joint_{kind}")
