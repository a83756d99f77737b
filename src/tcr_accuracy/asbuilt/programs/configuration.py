"""The arm configuration a 6-axis robot's controller names a Cartesian target's branch by.

* **KUKA** (Status and Turn, as KUKA's KRL and the controllers that follow it document them):
  Status bit 0 is set when the wrist root point (where axes 4, 5 and 6 cross) lies behind axis 1 (a
  negative x in the A1 frame: the robot's base frame turned with axis 1, the "overhead area"); bit 1
  when it lies in front of the straight line through axes 2 and 3; bit 2 when axis 5 is negative.
  Turn bit i is set when axis i+1 is negative.
* **ABB** (``confdata``): ``cf1``, ``cf4``, ``cf6`` are the quadrants of axes 1, 4 and 6
  (``floor(angle / 90 deg)``); ``cfx`` adds 4 when the wrist centre lies behind axis 1, 2 when it lies
  behind the lower arm (the line through axes 2 and 3) and 1 when axis 5 is negative.

The axes are the robot's six joints in chain order, their values as the controller's (the URDF's
joint values, which the ROS-Industrial descriptions of KUKA and ABB robots keep). "In front of" the
line through axes 2 and 3 is the side the robot's forward direction (x of the A1 frame) lies on when
that line is upright. Each is computed from the robot's own geometry at the joint values.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ...exceptions import InputError
from ...model.robot import RobotModel

#: A joint [rad] or a wrist position [m] this near a configuration boundary counts as on either side.
BOUNDARY = 1e-7


class ArmGeometry:
    """The configuration of a 6-axis arm at joint values, as KUKA and ABB name it (module docstring)."""

    def __init__(self, robot: RobotModel):
        if robot.n_joints != 6:
            raise InputError(f"{robot.name}: a program of a 6-axis controller, but the robot has {robot.n_joints} "
                             "joints")
        self.robot = robot
        self._data = robot.model.createData()
        self._axes = [robot.joint_axis(j) for j in range(6)]
        pin.forwardKinematics(robot.model, self._data, robot.to_pinocchio_q(np.zeros(6)))
        self._first_zero = self._data.oMi[1].copy()

    def _lines(self, q):
        pin.forwardKinematics(self.robot.model, self._data, self.robot.to_pinocchio_q(np.asarray(q, dtype=float)))
        points = [self._data.oMi[j + 1].translation.copy() for j in range(6)]
        directions = [self._data.oMi[j + 1].rotation @ a for j, a in enumerate(self._axes)]
        return points, directions, self._data.oMi[1].copy()

    def sides(self, q) -> tuple[bool, bool, bool]:
        """(wrist behind axis 1, wrist in front of the line through axes 2 and 3, axis 5 negative) at q (6,)."""
        behind, front, _ = self.signed_sides(q)
        return behind < 0.0, front > 0.0, bool(q[4] < 0.0)

    def matches(self, kind: str, q, given: tuple, tolerance: float = BOUNDARY) -> bool:
        """Whether the configuration at q (6,) is ``given`` (KUKA: Status bits 0-2 and Turn bits 0-5; ABB: cf1,
        cf4, cf6, cfx), a quantity within ``tolerance`` [rad, m] of its boundary counting as either side (a
        target on the x axis has axis 1 at zero: both Turn values name it)."""
        q = np.asarray(q, dtype=float)
        behind, front, _ = self.signed_sides(q)

        def either(value, boundary=0.0):
            return abs(value - boundary) <= tolerance

        if kind == "kuka":
            status, turn = given
            bits = [(status, 0, -behind), (status, 1, front), (status, 2, -q[4])]
            bits += [(turn, i, -q[i]) for i in range(6)]
            return all(either(value) or ((word >> bit) & 1) == int(value > 0) for word, bit, value in bits)
        cf1, cf4, cf6, cfx = given
        for quadrant, k in ((cf1, 0), (cf4, 3), (cf6, 5)):
            degrees = math.degrees(q[k])
            if int(math.floor(degrees / 90.0)) != quadrant and not either(math.radians(degrees - 90.0 * round(
                    degrees / 90.0))):
                return False
        bits = [(2, -behind), (1, -front), (0, -q[4])]
        return all(either(value) or ((cfx >> bit) & 1) == int(value > 0) for bit, value in bits)

    def signed_sides(self, q) -> tuple[float, float, float]:
        """(x of the wrist in the A1 frame [m], its distance in front of the line through axes 2 and 3 [m], axis 5
        [rad]) at q (6,): the signed quantities the configuration bits are the signs of."""
        points, directions, first = self._lines(q)
        wrist = _closest_point(points[4], directions[4], points[3], directions[3])
        a1 = first * self._first_zero.inverse()  # the base frame turned with axis 1
        local = a1.inverse().act(wrist)
        axis2 = directions[1] / np.linalg.norm(directions[1])
        up = a1.rotation[:, 2] - np.dot(a1.rotation[:, 2], axis2) * axis2
        forward = a1.rotation[:, 0] - np.dot(a1.rotation[:, 0], axis2) * axis2
        up, forward = up / np.linalg.norm(up), forward / np.linalg.norm(forward)
        line = points[2] - points[1]
        d = np.array([np.dot(line, forward), np.dot(line, up)])
        w = np.array([np.dot(wrist - points[1], forward), np.dot(wrist - points[1], up)])
        front = float(w @ np.array([d[1], -d[0]]) / max(np.linalg.norm(d), 1e-12))
        return float(local[0]), front, float(q[4])

    def kuka(self, q) -> tuple[int, int]:
        """(Status bits 0-2, Turn bits 0-5) at q (6,) [rad]."""
        behind, front, negative_a5 = self.sides(q)
        status = int(behind) | int(front) << 1 | int(negative_a5) << 2
        turn = sum(1 << i for i, v in enumerate(q) if v < 0.0)
        return status, turn

    def abb(self, q) -> tuple[int, int, int, int]:
        """(cf1, cf4, cf6, cfx) at q (6,) [rad]."""
        behind, front, negative_a5 = self.sides(q)
        quadrants = [int(math.floor(math.degrees(q[k]) / 90.0)) for k in (0, 3, 5)]
        return (*quadrants, 4 * int(behind) + 2 * int(not front) + int(negative_a5))


def _closest_point(p, u, r, v) -> np.ndarray:
    """The point of the line p + s u nearest the line r + t v (p itself where the lines are parallel)."""
    u, v = u / np.linalg.norm(u), v / np.linalg.norm(v)
    b = float(u @ v)
    if 1.0 - b * b < 1e-12:
        return np.asarray(p, dtype=float)
    w = p - r
    s = (b * (v @ w) - (u @ w)) / (1.0 - b * b)
    return p + s * u
