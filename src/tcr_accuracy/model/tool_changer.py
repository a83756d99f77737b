"""The shield-machine tool-changing robot: its dimensions and its URDF.

The robot (5 revolute + 1 prismatic joints) follows the structure of Qian et al.,
Sci. Rep. 12:20484 (2022), Fig. 5, Eq. (24) and (34), Table 2. With all joints at
zero the arm points along +y of the base frame {S} (z up):

====  ==========  ======  =========================================
joint kind        axis    joint origin in {S} at q = 0
====  ==========  ======  =========================================
j1    revolute    z       (0, 0, l1)
j2    revolute    x       (0, 0, l1 + l2)
j3    revolute    x       (0, l3, l1 + l2)
j4    prismatic   y       (0, l3 + l4, l1 + l2)   telescopic arm
j5    revolute    x       (0, l3 + l4 + l5, l1 + l2)
j6    revolute    z       (0, l3 + l4 + l5 + l6, l1 + l2)
tool  (frame)             (0, l3 + l4 + l5 + l6, l1 + l2), identity
====  ==========  ======  =========================================

Every dimension lives in :class:`ToolChangerDimensions`; ``tool_changer_urdf``
turns one into URDF text. ``robots/tool_changer.urdf`` is that text for the
default dimensions (``scripts/make_tool_changer_urdf.py`` rewrites it, or writes
a variant with other dimensions).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

#: The seed paper's working pose: (15 deg, 30 deg, -10 deg, 0 mm, -20 deg, 0 deg), SI units.
WORKING_POSE = np.array(
    [math.radians(15.0), math.radians(30.0), math.radians(-10.0), 0.0, math.radians(-20.0), 0.0]
)

#: Mass of a 17-inch disc cutter with its holder, the payload the robot swaps [kg].
DISC_CUTTER_MASS = 150.0


@dataclass(frozen=True)
class LinkBody:
    """Mass and box size of one moving link, for inertials and visuals (SI)."""

    mass: float  # [kg]
    width: float  # [m] section side of the box (or cylinder diameter)


@dataclass(frozen=True)
class ToolChangerDimensions:
    """Named dimensions of the tool-changer [m, kg, rad].

    ``l1`` .. ``l6`` are the seed's link lengths (Table 2: 315, 210, 796, 560,
    240, 165 mm). Masses describe a heavy hydraulic arm; they are plausible
    design values, not data from the seed paper (which gives none).
    """

    l1: float = 0.315
    l2: float = 0.210
    l3: float = 0.796
    l4: float = 0.560
    l5: float = 0.240
    l6: float = 0.165
    telescope_stroke: float = 0.600  # [m] travel of j4
    base_mass: float = 400.0  # [kg] pedestal, fixed to the cutterhead
    bodies: dict[str, LinkBody] = field(
        default_factory=lambda: {
            "turret": LinkBody(mass=110.0, width=0.30),  # moved by j1
            "base_arm": LinkBody(mass=140.0, width=0.22),  # moved by j2
            "extended_arm": LinkBody(mass=95.0, width=0.18),  # moved by j3
            "telescopic_arm": LinkBody(mass=70.0, width=0.14),  # moved by j4
            "wrist": LinkBody(mass=45.0, width=0.16),  # moved by j5
            "end_effector": LinkBody(mass=60.0, width=0.26),  # moved by j6, carries the connector
        }
    )

    def link_lengths(self) -> np.ndarray:
        """(6,) array of l1 .. l6 [m]."""
        return np.array([self.l1, self.l2, self.l3, self.l4, self.l5, self.l6])

    def as_dict(self) -> dict:
        return asdict(self)


# Per joint: (name, kind, axis, parent link, child link, origin relative to the parent
# joint frame as a function of the dimensions, lower, upper, effort, velocity).
def _joint_table(d: ToolChangerDimensions) -> list[dict]:
    deg = math.radians
    return [
        dict(name="j1", type="revolute", axis="0 0 1", parent="base_link", child="turret",
             xyz=(0.0, 0.0, d.l1), lower=deg(-180), upper=deg(180), effort=60000.0, velocity=0.5),
        dict(name="j2", type="revolute", axis="1 0 0", parent="turret", child="base_arm",
             xyz=(0.0, 0.0, d.l2), lower=deg(-60), upper=deg(75), effort=90000.0, velocity=0.4),
        dict(name="j3", type="revolute", axis="1 0 0", parent="base_arm", child="extended_arm",
             xyz=(0.0, d.l3, 0.0), lower=deg(-90), upper=deg(90), effort=50000.0, velocity=0.4),
        dict(name="j4", type="prismatic", axis="0 1 0", parent="extended_arm", child="telescopic_arm",
             xyz=(0.0, d.l4, 0.0), lower=0.0, upper=d.telescope_stroke, effort=40000.0, velocity=0.1),
        dict(name="j5", type="revolute", axis="1 0 0", parent="telescopic_arm", child="wrist",
             xyz=(0.0, d.l5, 0.0), lower=deg(-120), upper=deg(120), effort=15000.0, velocity=0.6),
        dict(name="j6", type="revolute", axis="0 0 1", parent="wrist", child="end_effector",
             xyz=(0.0, d.l6, 0.0), lower=deg(-180), upper=deg(180), effort=8000.0, velocity=0.8),
    ]


# Where each moving link's box sits in its joint frame: (centre, size) for a link that
# extends along +y by `length` (arms) or stands along +z (turret).
def _link_geometry(d: ToolChangerDimensions) -> dict[str, tuple[tuple, tuple]]:
    b = d.bodies
    return {
        "turret": ((0.0, 0.0, d.l2 / 2), (b["turret"].width, b["turret"].width, d.l2)),
        "base_arm": ((0.0, d.l3 / 2, 0.0), (b["base_arm"].width, d.l3, b["base_arm"].width)),
        "extended_arm": ((0.0, d.l4 / 2, 0.0), (b["extended_arm"].width, d.l4, b["extended_arm"].width)),
        # the telescopic arm slides inside the extended arm: its box reaches back into it
        "telescopic_arm": ((0.0, d.l5 / 2 - 0.15, 0.0),
                           (b["telescopic_arm"].width, d.l5 + 0.3, b["telescopic_arm"].width)),
        "wrist": ((0.0, d.l6 / 2, 0.0), (b["wrist"].width, d.l6, b["wrist"].width)),
        "end_effector": ((0.0, 0.05, 0.0), (b["end_effector"].width, 0.10, b["end_effector"].width)),
    }


def _fmt(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def _box_inertia(mass: float, size: tuple) -> tuple[float, float, float]:
    sx, sy, sz = size
    return (mass * (sy**2 + sz**2) / 12.0, mass * (sx**2 + sz**2) / 12.0, mass * (sx**2 + sy**2) / 12.0)


_COLOURS = {
    "turret": "0.85 0.55 0.10 1",
    "base_arm": "0.90 0.70 0.15 1",
    "extended_arm": "0.90 0.70 0.15 1",
    "telescopic_arm": "0.75 0.75 0.78 1",
    "wrist": "0.30 0.30 0.35 1",
    "end_effector": "0.20 0.45 0.75 1",
}


def tool_changer_urdf(dimensions: ToolChangerDimensions | None = None) -> str:
    """URDF text of the tool-changer for the given dimensions (default: the seed's)."""
    d = dimensions or ToolChangerDimensions()
    geometry = _link_geometry(d)
    out = [
        '<?xml version="1.0"?>',
        "<!-- Shield-machine tool-changing robot (5R + 1P). Generated by",
        "     scripts/make_tool_changer_urdf.py from tcr_accuracy.model.tool_changer; edit the",
        f"     dimensions there, not here. l1..l6 [m] = {_fmt(d.link_lengths())} -->",
        '<robot name="tool_changer">',
        '  <material name="pedestal"><color rgba="0.35 0.35 0.38 1"/></material>',
    ]
    for name, rgba in _COLOURS.items():
        out.append(f'  <material name="{name}_paint"><color rgba="{rgba}"/></material>')
    base_size = (0.6, 0.6, d.l1)
    ixx, iyy, izz = _box_inertia(d.base_mass, base_size)
    out += [
        '  <link name="base_link">',
        "    <inertial>",
        f'      <origin xyz="0 0 {d.l1 / 2!r}" rpy="0 0 0"/>',
        f'      <mass value="{d.base_mass!r}"/>',
        f'      <inertia ixx="{ixx!r}" ixy="0" ixz="0" iyy="{iyy!r}" iyz="0" izz="{izz!r}"/>',
        "    </inertial>",
        "    <visual>",
        f'      <origin xyz="0 0 {d.l1 / 2!r}" rpy="0 0 0"/>',
        f'      <geometry><box size="{_fmt(base_size)}"/></geometry>',
        '      <material name="pedestal"/>',
        "    </visual>",
        "  </link>",
    ]
    for joint in _joint_table(d):
        child = joint["child"]
        centre, size = geometry[child]
        body = d.bodies[child]
        ixx, iyy, izz = _box_inertia(body.mass, size)
        out += [
            f'  <joint name="{joint["name"]}" type="{joint["type"]}">',
            f'    <parent link="{joint["parent"]}"/>',
            f'    <child link="{child}"/>',
            f'    <origin xyz="{_fmt(joint["xyz"])}" rpy="0 0 0"/>',
            f'    <axis xyz="{joint["axis"]}"/>',
            f'    <limit lower="{joint["lower"]!r}" upper="{joint["upper"]!r}" '
            f'effort="{joint["effort"]!r}" velocity="{joint["velocity"]!r}"/>',
            "  </joint>",
            f'  <link name="{child}">',
            "    <inertial>",
            f'      <origin xyz="{_fmt(centre)}" rpy="0 0 0"/>',
            f'      <mass value="{body.mass!r}"/>',
            f'      <inertia ixx="{ixx!r}" ixy="0" ixz="0" iyy="{iyy!r}" iyz="0" izz="{izz!r}"/>',
            "    </inertial>",
            "    <visual>",
            f'      <origin xyz="{_fmt(centre)}" rpy="0 0 0"/>',
            f'      <geometry><box size="{_fmt(size)}"/></geometry>',
            f'      <material name="{child}_paint"/>',
            "    </visual>",
            "  </link>",
        ]
    # The TCP: centre of the quick-change connector, at the j6 origin (seed Eq. 23).
    out += [
        '  <joint name="tool_joint" type="fixed">',
        '    <parent link="end_effector"/>',
        '    <child link="tool"/>',
        '    <origin xyz="0 0 0" rpy="0 0 0"/>',
        "  </joint>",
        '  <link name="tool"/>',
        "</robot>",
        "",
    ]
    return "\n".join(out)
