"""Denavit-Hartenberg tables of a robot's chain, read off its joint axes (for controllers).

The joint axes at q = 0 are lines in the base frame (Pinocchio's joint placements and motion
axes); the last "axis" is the TCP frame's z line. Two conventions, each with a fixed base
transform ``base_M_0`` in front and a fixed tool transform at the end:

* **DH** (standard, Denavit-Hartenberg 1955): frame i on axis i+1, row i
  ``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, joint i adds to theta_i (revolute) or d_i
  (prismatic). Two axes that are parallel in the nominal robot but tilted by a calibration put
  their common normal metres away: a DH table cannot carry that geometry, and :func:`dh_table`
  raises :class:`NoDhForm` naming the joints.
* **MDH** (modified, Craig 1986, with Hayati's beta for parallel axes): frame i on axis i, row i
  ``Rx(alpha) Tx(a) Ry(beta) Rz(theta_i) Tz(d_i)`` from frame i-1; beta is 0 except after a
  pair of axes parallel in the nominal robot, where the x axis runs in the plane normal to the
  first axis (Hayati 1983). Any chain of revolute and prismatic joints has one.

Lengths in m, angles in rad (tables for people: :mod:`tcr_accuracy.cli.export`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from .robot import RobotModel

#: Axes closer than this angle [rad] in the nominal robot count as parallel.
PARALLEL_RAD = 1e-6


class NoDhForm(InputError):
    """The robot's axes admit no (useful) standard DH table; the message says which and why."""


@dataclass(frozen=True)
class DhTable:
    """A chain as DH or MDH rows.

    convention : "DH" or "MDH"
    joints : joint names, one row each
    variable : "theta" or "d" per row (what the joint value adds to)
    params : (n, 5) rows of (a [m], alpha [rad], d [m], theta [rad], beta [rad]); beta is 0 in DH
    base : (4, 4) base_M_0; tool : (4, 4) n_M_tcp
    """

    convention: str
    joints: tuple
    variable: tuple
    params: np.ndarray
    base: np.ndarray
    tool: np.ndarray

    def row_transform(self, i: int, value: float) -> np.ndarray:
        """(4, 4) transform of row i at joint value ``value`` [rad or m]."""
        a, alpha, d, theta, beta = self.params[i]
        if self.variable[i] == "theta":
            theta = theta + value
        else:
            d = d + value
        if self.convention == "DH":
            return _rz(theta) @ _tz(d) @ _tx(a) @ _rx(alpha)
        return _rx(alpha) @ _tx(a) @ _ry(beta) @ _rz(theta) @ _tz(d)

    def tcp(self, q) -> np.ndarray:
        """(4, 4) base_M_tcp at joint values q (n,) [SI]: the product of the rows."""
        out = self.base.copy()
        for i, value in enumerate(np.asarray(q, dtype=float)):
            out = out @ self.row_transform(i, value)
        return out @ self.tool


def axis_lines(robot: RobotModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The joint axes at q = 0: points (n, 3) and unit directions (n, 3) in the base frame [m],
    and base_M_tcp (4, 4)."""
    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, robot.to_pinocchio_q(np.zeros(robot.n_joints)))
    pin.updateFramePlacements(model, data)
    points, directions = [], []
    for j, axis in enumerate(robot.motion_axes):
        placement = data.oMi[j + 1]
        local = axis[3:] if np.linalg.norm(axis[3:]) > 0 else axis[:3]  # revolute: w; prismatic: v
        points.append(placement.translation.copy())
        directions.append(placement.rotation @ (local / np.linalg.norm(local)))
    return np.array(points), np.array(directions), data.oMf[robot.tool_frame_id].homogeneous.copy()


def dh_table(robot: RobotModel, nominal: RobotModel | None = None) -> DhTable:
    """The standard DH table of ``robot``; ``nominal`` (default: robot) says which axes are parallel
    by design. Raises :class:`NoDhForm` where a pair parallel by design is tilted in ``robot``."""
    points, dirs, tcp = axis_lines(robot)
    parallel = _parallel_pairs(nominal or robot)
    size = 10.0 * (1.0 + float(np.abs(points).max()))
    lines = list(zip(points, dirs)) + [(tcp[:3, 3], tcp[:3, 2])]
    frames = [_first_frame(lines[0][0], lines[0][1])]
    for i in range(1, len(lines)):
        (p0, z0), (p1, z1) = (frames[-1][:3, 3], frames[-1][:3, 2]), lines[i]
        cross = np.cross(z0, z1)
        if np.linalg.norm(cross) > 1e-9:
            s, t = _closest(p0, z0, p1, z1)
            if abs(s) > size and i - 1 < len(parallel) and parallel[i - 1]:
                names = robot.joint_names
                second = names[i] if i < len(names) else "the TCP's z axis"
                raise NoDhForm(f"no DH table: the axes of {names[i - 1]} and {second} are parallel by design and "
                               f"{np.degrees(np.arcsin(min(1.0, np.linalg.norm(cross)))):.3g} deg apart as built, "
                               f"so their common normal lies {abs(s):.3g} m away; the MDH table (Hayati's beta) "
                               "carries them")
            x = cross / np.linalg.norm(cross)
            origin = p1 + t * z1
        else:
            x, origin = _perpendicular(p0, z0, p1, frames[-1][:3, 0])
        frames.append(_frame(origin, x, z1))
    params = []
    for i in range(len(robot.joint_names)):
        rel = np.linalg.inv(frames[i]) @ frames[i + 1]
        theta, alpha = np.arctan2(rel[1, 0], rel[0, 0]), np.arctan2(rel[2, 1], rel[2, 2])
        d, a = rel[2, 3], rel[0, 3] * np.cos(theta) + rel[1, 3] * np.sin(theta)
        params.append((a, alpha, d, theta, 0.0))
    return _finish("DH", robot, params, frames[0], np.linalg.inv(frames[-1]) @ tcp)


def mdh_table(robot: RobotModel, nominal: RobotModel | None = None) -> DhTable:
    """The modified DH table (Craig, Hayati's beta after pairs parallel by design in ``nominal``)."""
    points, dirs, tcp = axis_lines(robot)
    parallel = _parallel_pairs(nominal or robot) + [False]
    lines = list(zip(points, dirs)) + [(tcp[:3, 3], tcp[:3, 2])]
    frames, origin, x_previous = [], np.zeros(3), np.array([1.0, 0.0, 0.0])
    for i in range(len(points)):
        (p0, z0), (p1, z1) = lines[i], lines[i + 1]
        cross = np.cross(z0, z1)
        if not parallel[i] and np.linalg.norm(cross) > 1e-9:
            s, _ = _closest(p0, z0, p1, z1)
            o, x = p0 + s * z0, cross / np.linalg.norm(cross)
        else:  # Hayati: x in the plane normal to z0 through the origin, towards the next axis
            o = p0 + np.dot(origin - p0, z0) * z0
            crossing = p1 + (np.dot(o - p1, z0) / np.dot(z1, z0)) * z1
            x, o = _perpendicular(o, z0, crossing, x_previous)
            o = p0 + np.dot(origin - p0, z0) * z0
        frames.append(_frame(o, x, z0))
        origin, x_previous = o, x
    params = [(0.0, 0.0, 0.0, 0.0, 0.0)]
    for i in range(1, len(frames)):
        params.append(_mdh_row(np.linalg.inv(frames[i - 1]) @ frames[i]))
    return _finish("MDH", robot, params, frames[0], np.linalg.inv(frames[-1]) @ tcp)


# ---------------------------------------------------------------------------------------
def _mdh_row(rel: np.ndarray) -> tuple:
    """(a, alpha, d, theta, beta) of ``Rx(alpha) Tx(a) Ry(beta) Rz(theta) Tz(d)`` = rel."""
    r, t = rel[:3, :3], rel[:3, 3]
    beta = np.arcsin(np.clip(r[0, 2], -1.0, 1.0))
    alpha, theta = np.arctan2(-r[1, 2], r[2, 2]), np.arctan2(-r[0, 1], r[0, 0])
    u = _rx(alpha)[:3, :3].T @ t
    d = u[2] / np.cos(beta)
    return (u[0] - d * np.sin(beta), alpha, d, theta, beta)


def _finish(convention, robot, params, base, tool) -> DhTable:
    variable = tuple("d" if k == "prismatic" else "theta" for k in robot.joint_kinds)
    table = DhTable(convention, tuple(robot.joint_names), variable, np.array(params, dtype=float), base, tool)
    rng = np.random.default_rng(0)
    lo, hi = robot.joint_bounds(np.pi)
    for q in (np.zeros(robot.n_joints), *rng.uniform(lo, hi, (3, robot.n_joints))):
        if not np.allclose(table.tcp(q), _fk(robot, q), atol=1e-9):
            raise NoDhForm(f"no {convention} table: the chain of {robot.name} is not a product of "
                           f"{convention} rows (a joint that moves another, or a branch)")
    return table


def _fk(robot: RobotModel, q) -> np.ndarray:
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(np.asarray(q, dtype=float)))
    return data.oMf[robot.tool_frame_id].homogeneous


def _parallel_pairs(robot: RobotModel) -> list[bool]:
    _, dirs, tcp = axis_lines(robot)
    dirs = np.vstack([dirs, tcp[None, :3, 2]])
    return [bool(np.linalg.norm(np.cross(dirs[i], dirs[i + 1])) < PARALLEL_RAD) for i in range(len(dirs) - 1)]


def _closest(p0, z0, p1, z1) -> tuple[float, float]:
    """Parameters s, t of the closest points p0 + s z0 and p1 + t z1 of two skew lines."""
    w, b = p0 - p1, float(np.dot(z0, z1))
    denominator = float(np.dot(np.cross(z0, z1), np.cross(z0, z1)))  # 1 - b^2 without its cancellation
    s = (b * np.dot(z1, w) - np.dot(z0, w)) / denominator
    t = (np.dot(z1, w) - b * np.dot(z0, w)) / denominator
    return float(s), float(t)


def _perpendicular(p0, z0, p1, fallback_x):
    """x from the line (p0, z0) towards the point p1 (normal to z0) and the foot on that line's
    plane through p1; the fallback x (made normal to z0) when p1 lies on the line."""
    w = p1 - p0
    w = w - np.dot(w, z0) * z0
    if np.linalg.norm(w) < 1e-12:
        w = fallback_x - np.dot(fallback_x, z0) * z0
        return w / np.linalg.norm(w), p0 + 0.0 * w
    return w / np.linalg.norm(w), p1 - np.dot(p1 - p0, z0) * z0 + 0.0 * w


def _first_frame(point, z):
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    return _frame(point - np.dot(point, z) * z, x / np.linalg.norm(x), z)


def _frame(origin, x, z) -> np.ndarray:
    z = z / np.linalg.norm(z)
    x = x - np.dot(x, z) * z
    x = x / np.linalg.norm(x)
    out = np.eye(4)
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = x, np.cross(z, x), z, origin
    return out


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _tx(v):
    out = np.eye(4)
    out[0, 3] = v
    return out


def _tz(v):
    out = np.eye(4)
    out[2, 3] = v
    return out
