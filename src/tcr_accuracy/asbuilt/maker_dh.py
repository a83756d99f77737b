"""The makers' published Denavit-Hartenberg tables, and the as-built robot in their convention.

A user of a named robot compares a calibration with what the maker publishes and what the
controller stores, in the maker's own frames and signs. For the robots of example-robot-data
whose makers publish a table:

* **Universal Robots UR3, UR5, UR10** (CB3): standard DH, a, d, alpha as published by Universal
  Robots ("DH parameters for calculations of kinematics and dynamics"), frame 0 the controller's
  ``base`` (example-robot-data's ``base_link`` turned 180 deg about z), frame 6 the flange
  ``tool0``. UR's controller stores its own calibration in this form, plain DH without Hayati's
  beta (a tilted parallel pair puts d hundreds of metres away, as in ur_calibration's
  documentation), so the as-built table here is plain DH too.
* **Franka Emika Panda**: modified DH (Craig) as Franka publishes it, frame 0 ``panda_link0``,
  then the flange (d = 0.107 m) and the hand's TCP (turned -45 deg about z, 0.1034 m out) in the
  tool transform.

The as-built table uses the published one as its reference (:mod:`tcr_accuracy.asbuilt.dh`):
each frame is the as-built one closest to the published frame, so the columns nominal, as built
and correction read in the maker's signs. Lengths in m, angles in rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.robot import RobotModel
from .dh import DhTable, dh_table, mdh_table, rot_z, trans

HALF_PI = math.pi / 2.0


@dataclass(frozen=True)
class PublishedTable:
    """A maker's table: rows of (a [m], alpha [rad], d [m], theta [rad]) with its convention.

    maker : who publishes it, and where
    convention : "DH" or "MDH"
    rows : (n, 4) a, alpha, d, theta
    base : (4, 4) the robot's base frame (example-robot-data's) to the table's frame 0
    tool : (4, 4) the table's last frame to the robot's TCP frame
    hayati : whether the maker's calibrated tables use Hayati's beta
    """

    maker: str
    convention: str
    rows: tuple
    base: np.ndarray
    tool: np.ndarray
    hayati: bool

    def table(self, robot: RobotModel) -> DhTable:
        """The published table as a :class:`~tcr_accuracy.asbuilt.dh.DhTable` for ``robot``'s joints."""
        params = [(a, alpha, d, theta, 0.0) for a, alpha, d, theta in self.rows]
        return DhTable.from_rows(self.convention, robot.joint_names, ["theta"] * len(params), params, self.base,
                                 self.tool)


def _ur(d1: float, a2: float, a3: float, d4: float, d5: float, d6: float) -> PublishedTable:
    alpha = (HALF_PI, 0.0, 0.0, HALF_PI, -HALF_PI, 0.0)
    a = (0.0, a2, a3, 0.0, 0.0, 0.0)
    d = (d1, 0.0, 0.0, d4, d5, d6)
    return PublishedTable("Universal Robots (published DH parameters, CB3)", "DH",
                          tuple(zip(a, alpha, d, (0.0,) * 6)), rot_z(math.pi), np.eye(4), hayati=False)


#: example-robot-data name -> the maker's published table.
PUBLISHED = {
    "ur3": _ur(0.1519, -0.24365, -0.21325, 0.11235, 0.08535, 0.0819),
    "ur5": _ur(0.089159, -0.425, -0.39225, 0.10915, 0.09465, 0.0823),
    "ur10": _ur(0.1273, -0.612, -0.5723, 0.163941, 0.1157, 0.0922),
    "panda": PublishedTable(
        "Franka Emika (published modified DH parameters, Craig's convention)", "MDH",
        ((0.0, 0.0, 0.333, 0.0), (0.0, -HALF_PI, 0.0, 0.0), (0.0, HALF_PI, 0.316, 0.0),
         (0.0825, HALF_PI, 0.0, 0.0), (-0.0825, -HALF_PI, 0.384, 0.0), (0.0, HALF_PI, 0.0, 0.0),
         (0.088, HALF_PI, 0.0, 0.0)),
        np.eye(4), trans(z=0.107) @ rot_z(-math.pi / 4.0) @ trans(z=0.1034), hayati=True),
}


def published_table(source: str, robot: RobotModel) -> tuple[PublishedTable, DhTable] | None:
    """The maker's table of the robot loaded as ``source`` (an example-robot-data name), or None
    when the maker publishes none here or ``robot`` is not measured at the maker's TCP frame."""
    published = PUBLISHED.get(str(source).lower())
    if published is None or len(published.rows) != robot.n_joints:
        return None
    expected = {"panda": "panda_hand_tcp"}.get(str(source).lower(), "tool0")
    if robot.tool_frame != expected:
        return None
    return published, published.table(robot)


def maker_table(as_built: RobotModel, nominal: RobotModel, published: PublishedTable) -> DhTable:
    """The as-built robot in the maker's convention, frames nearest the published ones.

    Parameters
    ----------
    as_built : RobotModel
        The calibrated chain (the URDF's geometry).
    nominal : RobotModel
        The nominal robot: which axes are parallel by design.
    published : PublishedTable

    Returns
    -------
    DhTable
        Checked against the as-built robot's forward kinematics (1e-9 m);
        :class:`~tcr_accuracy.asbuilt.dh.NoDhForm` when the maker's form cannot carry it.
    """
    build = dh_table if published.convention == "DH" else mdh_table
    return build(as_built, nominal, reference=published.table(nominal), hayati=published.hayati)
