"""Denavit-Hartenberg tables of a robot's chain, read off its joint axes (for controllers).

The joint axes at q = 0 are lines in the base frame (Pinocchio's joint placements and motion
axes); the last "axis" is the TCP frame's z line. A table is a fixed base transform
``base_M_0`` (the robot's base to frame 0), one row per joint and a fixed tool transform (the
last frame to the TCP). Two conventions:

* **DH** (standard, Denavit-Hartenberg 1955): frame 0 on the first axis, frame i on axis i+1,
  row i ``Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)`` from frame i-1; the joint value
  adds to theta_i (revolute) or d_i (prismatic).
* **MDH** (modified, Craig 1986): frame i on axis i, row i
  ``Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(theta_i) Tz(d_i)`` from frame i-1.

**Parallel axes** (Hayati 1983). Two consecutive axes parallel by design (in the nominal robot)
and tilted by a calibration put their common normal metres or kilometres away: d jumps by that
much, and a millidegree more tilt moves it again. Where ``hayati=True`` (the default) such a row
takes Hayati's beta, a rotation about the row's y axis, and no d (DH) or no offset along the
first axis (MDH): the frame sits where the second axis crosses the plane normal to the first.
``hayati=False`` gives the plain table with its far common normal, which is what some makers'
controllers store (Universal Robots' own calibration does: d of hundreds of metres).

**Frame choices.** Where the rules leave a choice (the sign of x, the place of a common normal
between exactly parallel axes, frame 0), a ``reference`` table (the nominal robot's, or the
maker's published one) decides: the frame closest to the reference's. So the as-built table
and the nominal one differ by the calibration only, and a maker's published table is
reproduced exactly for the nominal robot.

Every table is checked against the robot's own forward kinematics (1e-9 m, 1e-9 rad) before it
is returned; :class:`NoDhForm` says why a chain has no table. Lengths in m, angles in rad
(tables for people: :mod:`tcr_accuracy.cli.export`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..model.robot import RobotModel

#: Axes closer than this angle [rad] in the nominal robot count as parallel.
PARALLEL_RAD = 1e-6
#: Axes whose directions differ by less than this [rad] are treated as exactly parallel (URDFs round
#: pi/2 to 1e-9: example-robot-data's UR tool0 is 2e-9 rad off its last axis).
EXACT_RAD = 1e-8
#: Largest miss a table may have against the robot's forward kinematics [m, rad].
TABLE_TOLERANCE = 1e-9


class NoDhForm(InputError):
    """The robot's axes admit no (useful) table of this kind; the message says which and why."""


@dataclass(frozen=True)
class DhTable:
    """A chain as DH or MDH rows.

    convention : "DH" or "MDH"
    joints : joint names, one row each
    variable : "theta" or "d" per row (what the joint value adds to)
    params : (n, 5) rows of (a [m], alpha [rad], d [m], theta [rad], beta [rad]); beta is 0 except
        in Hayati rows
    base : (4, 4) base_M_0; tool : (4, 4) n_M_tcp
    frames : (n + 1, 4, 4) the table's frames 0..n at q = 0 in the base frame (the reference for
        another table of the same chain)
    """

    convention: str
    joints: tuple
    variable: tuple
    params: np.ndarray
    base: np.ndarray
    tool: np.ndarray
    frames: np.ndarray

    def row_transform(self, i: int, value: float) -> np.ndarray:
        """(4, 4) transform of row i at joint value ``value`` [rad or m]."""
        a, alpha, d, theta, beta = self.params[i]
        if self.variable[i] == "theta":
            theta = theta + value
        else:
            d = d + value
        if self.convention == "DH":
            return rot_z(theta) @ trans(z=d) @ trans(x=a) @ rot_x(alpha) @ rot_y(beta)
        return rot_x(alpha) @ trans(x=a) @ rot_y(beta) @ rot_z(theta) @ trans(z=d)

    def tcp(self, q) -> np.ndarray:
        """(4, 4) base_M_tcp at joint values q (n,) [SI]: the product of the rows."""
        out = self.base.copy()
        for i, value in enumerate(np.asarray(q, dtype=float)):
            out = out @ self.row_transform(i, value)
        return out @ self.tool

    @classmethod
    def from_rows(cls, convention: str, joints, variable, params, base, tool) -> "DhTable":
        """A table given by its rows (a published one); its frames follow from the rows at q = 0."""
        table = cls(convention, tuple(joints), tuple(variable), np.asarray(params, dtype=float),
                    np.asarray(base, dtype=float), np.asarray(tool, dtype=float), np.zeros((0, 4, 4)))
        frames = [table.base]
        for i in range(len(table.joints)):
            frames.append(frames[-1] @ table.row_transform(i, 0.0))
        return cls(*[getattr(table, f) for f in ("convention", "joints", "variable", "params", "base", "tool")],
                   np.array(frames))


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


def dh_table(robot: RobotModel, nominal: RobotModel | None = None, *, reference: DhTable | None = None,
             hayati: bool = True) -> DhTable:
    """The standard DH table of ``robot``.

    Parameters
    ----------
    robot : RobotModel
        The chain to tabulate (nominal or as built).
    nominal : RobotModel, optional
        Says which consecutive axes are parallel by design (default: robot).
    reference : DhTable, optional
        A DH table of the same chain whose frames decide the free choices (default: the rules'
        own: frame 0 nearest the base origin, x along ``z_{i-1} x z_i``).
    hayati : bool, default=True
        Hayati's beta (and no d) for pairs parallel by design; False: the plain table.

    Returns
    -------
    DhTable
        Checked against the robot's forward kinematics (1e-9 m); NoDhForm otherwise.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> table = tcr.dh_table(tcr.load_robot("ur5"))
    >>> table.convention, len(table.joints)
    ('DH', 6)
    """
    lines, tcp = _lines(robot)
    parallel = _parallel_pairs(nominal or robot)
    ref = None if reference is None else reference.frames
    frames = [_frame_zero(lines[0], None if ref is None else ref[0])]
    hayati_rows = []
    for i in range(1, len(lines)):
        previous = frames[-1]
        target = None if ref is None else ref[i]
        use_beta = hayati and parallel[i - 1]
        frames.append(_next_dh_frame(previous, lines[i], target, use_beta))
        hayati_rows.append(use_beta)
    params = [_dh_row(np.linalg.inv(frames[i]) @ frames[i + 1], hayati_rows[i])
              for i in range(len(robot.joint_names))]
    table = _finish("DH", robot, params, frames[0], np.linalg.inv(frames[-1]) @ tcp)
    return _checked(table, robot, parallel, hayati)


def mdh_table(robot: RobotModel, nominal: RobotModel | None = None, *, reference: DhTable | None = None,
              hayati: bool = True) -> DhTable:
    """The modified DH table of ``robot`` (Craig; Hayati's beta after pairs parallel by design).

    Frame 0 lies on the first axis, nearest the reference's frame 0 (default: the base origin),
    so the first row is ``Rz(theta) Tz(d)``; frame i on axis i, its x towards axis i+1.

    Parameters
    ----------
    robot : RobotModel
        The chain to tabulate (nominal or as built).
    nominal : RobotModel, optional
        Says which consecutive axes are parallel by design (default: robot).
    reference : DhTable, optional
        An MDH table of the same chain whose frames decide the free choices.
    hayati : bool, default=True
        Hayati's beta after pairs parallel by design; False: the plain table.

    Returns
    -------
    DhTable
        Checked against the robot's forward kinematics (1e-9 m); NoDhForm otherwise.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> table = tcr.mdh_table(tcr.load_robot("ur5"))
    >>> table.convention, len(table.joints)
    ('MDH', 6)
    """
    lines, tcp = _lines(robot)
    parallel = _parallel_pairs(nominal or robot) + [False]
    ref = None if reference is None else reference.frames
    frames = [_frame_zero(lines[0], None if ref is None else ref[0])]
    for i in range(len(robot.joint_names)):
        target = None if ref is None else ref[i + 1]
        frames.append(_next_mdh_frame(frames[-1], lines[i], lines[i + 1], target, hayati and parallel[i]))
    params = [_mdh_row(np.linalg.inv(frames[i]) @ frames[i + 1]) for i in range(len(robot.joint_names))]
    table = _finish("MDH", robot, params, frames[0], np.linalg.inv(frames[-1]) @ tcp)
    return _checked(table, robot, parallel, hayati)


# ---------------------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------------------
def _lines(robot: RobotModel) -> tuple[list, np.ndarray]:
    points, dirs, tcp = axis_lines(robot)
    return list(zip(points, dirs)) + [(tcp[:3, 3], tcp[:3, 2])], tcp


def _frame_zero(line, reference: np.ndarray | None) -> np.ndarray:
    """Frame 0 on the first axis: origin nearest the reference's origin (default the base
    origin), x the reference's x made normal to the axis (default the base x, else y)."""
    point, z = line
    ref_origin = np.zeros(3) if reference is None else reference[:3, 3]
    origin = point + np.dot(ref_origin - point, z) * z
    x = np.array([1.0, 0.0, 0.0]) if reference is None else reference[:3, 0]
    x = x - np.dot(x, z) * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    return _frame(origin, x, z)


def _next_dh_frame(previous: np.ndarray, line, reference: np.ndarray | None, use_beta: bool) -> np.ndarray:
    """DH frame i on ``line`` (axis i+1) after frame i-1 (z on axis i)."""
    o0, x0, z0 = previous[:3, 3], previous[:3, 0], previous[:3, 2]
    p1, z1 = line
    cross = np.cross(z0, z1)
    if use_beta:  # Hayati: the origin where the axis crosses the plane normal to z0 through o0
        if abs(np.dot(z1, z0)) < 1e-3:
            raise NoDhForm("no DH table: axes parallel by design are more than 89.9 deg apart as built")
        origin = p1 + (np.dot(o0 - p1, z0) / np.dot(z1, z0)) * z1
        x = _signed(_unit_or(origin - o0, x0, z0), reference)
        rotation = _hayati_rotation(previous[:3, :3], x, z1)
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = rotation, origin
        return out
    if np.linalg.norm(cross) > EXACT_RAD:
        s, t = _closest(o0, z0, p1, z1)
        return _frame(p1 + t * z1, _signed(cross / np.linalg.norm(cross), reference), z1)
    # exactly parallel: the common normal through the reference's origin (default: through o0)
    anchor = o0 if reference is None else reference[:3, 3]
    origin = p1 + np.dot(anchor - p1, z1) * z1
    foot = o0 + np.dot(origin - o0, z0) * z0
    return _frame(origin, _signed(_unit_or(origin - foot, x0, z0), reference), z1)


def _next_mdh_frame(previous: np.ndarray, line, next_line, reference: np.ndarray | None,
                    use_beta: bool) -> np.ndarray:
    """MDH frame i on ``line`` (axis i), x towards ``next_line`` (axis i+1 or the TCP's z)."""
    (p0, z0), (p1, z1) = line, next_line
    o_prev, x_prev = previous[:3, 3], previous[:3, 0]
    cross = np.cross(z0, z1)
    if not use_beta and np.linalg.norm(cross) > EXACT_RAD:
        s, _ = _closest(p0, z0, p1, z1)
        return _frame(p0 + s * z0, _signed(cross / np.linalg.norm(cross), reference), z0)
    # parallel (by design with Hayati, or exactly): origin on this axis nearest the reference's
    # origin (default: the previous frame's), x towards where the next axis crosses its normal plane
    anchor = o_prev if reference is None else reference[:3, 3]
    origin = p0 + np.dot(anchor - p0, z0) * z0
    if abs(np.dot(z1, z0)) < 1e-3:
        raise NoDhForm("no MDH table: axes parallel by design are more than 89.9 deg apart as built")
    crossing = p1 + (np.dot(origin - p1, z0) / np.dot(z1, z0)) * z1
    return _frame(origin, _signed(_unit_or(crossing - origin, x_prev, z0), reference), z0)


def _unit_or(vector, fallback, normal) -> np.ndarray:
    """``vector`` made normal to ``normal`` and unit; the fallback (made normal) when it vanishes."""
    w = vector - np.dot(vector, normal) * normal
    if np.linalg.norm(w) < 1e-12:
        w = fallback - np.dot(fallback, normal) * normal
    return w / np.linalg.norm(w)


def _signed(x: np.ndarray, reference: np.ndarray | None) -> np.ndarray:
    """x or -x, whichever is nearer the reference frame's x."""
    return -x if reference is not None and np.dot(x, reference[:3, 0]) < 0 else x


def _hayati_rotation(previous: np.ndarray, x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``R_prev Rz(theta) Rx(alpha) Ry(beta)`` whose first Rz turns x_prev onto x (normal to z_prev)
    and whose z is z: the frame of a Hayati row."""
    z_prev = previous[:, 2]
    turned = np.column_stack([x, np.cross(z_prev, x), z_prev])  # R_prev Rz(theta)
    local = turned.T @ z  # (sin b, -sin a cos b, cos a cos b)
    beta = np.arcsin(np.clip(local[0], -1.0, 1.0))
    alpha = np.arctan2(-local[1], local[2])
    return turned @ rot_x(alpha)[:3, :3] @ rot_y(beta)[:3, :3]


def _frame(origin, x, z) -> np.ndarray:
    z = z / np.linalg.norm(z)
    x = x - np.dot(x, z) * z
    x = x / np.linalg.norm(x)
    out = np.eye(4)
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = x, np.cross(z, x), z, origin
    return out


def _closest(p0, z0, p1, z1) -> tuple[float, float]:
    """Parameters s, t of the closest points p0 + s z0 and p1 + t z1 of two skew lines."""
    w, b = p0 - p1, float(np.dot(z0, z1))
    denominator = float(np.dot(np.cross(z0, z1), np.cross(z0, z1)))  # 1 - b^2 without its cancellation
    s = (b * np.dot(z1, w) - np.dot(z0, w)) / denominator
    t = (np.dot(z1, w) - b * np.dot(z0, w)) / denominator
    return float(s), float(t)


# ---------------------------------------------------------------------------------------
# Rows
# ---------------------------------------------------------------------------------------
def _dh_row(rel: np.ndarray, beta_row: bool) -> tuple:
    """(a, alpha, d, theta, beta) of ``Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta)`` = rel."""
    r, t = rel[:3, :3], rel[:3, 3]
    if beta_row:  # R = Rz(theta) Rx(alpha) Ry(beta), beta in (-90, 90) deg; its last row gives alpha, beta
        beta = np.arctan(-r[2, 0] / r[2, 2])
        cos_alpha = r[2, 2] / np.cos(beta)
        alpha = np.arctan2(r[2, 1], cos_alpha)
        sign = 1.0 if cos_alpha >= 0 else -1.0
        theta = np.arctan2(-r[0, 1] * sign, r[1, 1] * sign)
    else:
        beta, alpha, theta = 0.0, np.arctan2(r[2, 1], r[2, 2]), np.arctan2(r[1, 0], r[0, 0])
    a = t[0] * np.cos(theta) + t[1] * np.sin(theta)
    return (a, alpha, t[2], theta, beta)


def _mdh_row(rel: np.ndarray) -> tuple:
    """(a, alpha, d, theta, beta) of ``Rx(alpha) Tx(a) Ry(beta) Rz(theta) Tz(d)`` = rel."""
    r, t = rel[:3, :3], rel[:3, 3]
    beta = np.arcsin(np.clip(r[0, 2], -1.0, 1.0))
    alpha, theta = np.arctan2(-r[1, 2], r[2, 2]), np.arctan2(-r[0, 1], r[0, 0])
    u = rot_x(alpha)[:3, :3].T @ t
    d = u[2] / np.cos(beta)
    return (u[0] - d * np.sin(beta), alpha, d, theta, beta)


def _finish(convention, robot, params, base, tool) -> DhTable:
    variable = tuple("d" if k == "prismatic" else "theta" for k in robot.joint_kinds)
    return DhTable.from_rows(convention, robot.joint_names, variable, params, base, tool)


def _checked(table: DhTable, robot: RobotModel, parallel: list, hayati: bool) -> DhTable:
    """The table, if its product is the robot's forward kinematics at q = 0 and three random
    joint vectors (1e-9 m and rad); NoDhForm naming the likely cause otherwise."""
    rng = np.random.default_rng(0)
    lo, hi = robot.joint_bounds(np.pi)
    for q in (np.zeros(robot.n_joints), *rng.uniform(lo, hi, (3, robot.n_joints))):
        product, expected = table.tcp(q), _fk(robot, q)
        if np.abs(product - expected).max() <= TABLE_TOLERANCE:
            continue
        far = np.abs(table.params[:, 2]).max()
        if not hayati and any(parallel) and far > 100.0:
            joint = table.joints[int(np.argmax(np.abs(table.params[:, 2])))]
            raise NoDhForm(f"no plain {table.convention} table of {robot.name}: the axes parallel by design are "
                           f"tilted so little as built that the common normal at {joint} lies {far:.3g} m away "
                           f"(rounding exceeds {TABLE_TOLERANCE:g} m); the table with Hayati's beta carries them")
        raise NoDhForm(f"no {table.convention} table: the chain of {robot.name} is not a product of "
                       f"{table.convention} rows (a joint that moves another, or a branch)")
    return table


def _fk(robot: RobotModel, q) -> np.ndarray:
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, robot.to_pinocchio_q(np.asarray(q, dtype=float)))
    return data.oMf[robot.tool_frame_id].homogeneous


def _parallel_pairs(robot: RobotModel) -> list[bool]:
    """Whether each consecutive pair of axes (the last with the TCP's z) is parallel in ``robot``."""
    _, dirs, tcp = axis_lines(robot)
    dirs = np.vstack([dirs, tcp[None, :3, 2]])
    return [bool(np.linalg.norm(np.cross(dirs[i], dirs[i + 1])) < PARALLEL_RAD) for i in range(len(dirs) - 1)]


# ---------------------------------------------------------------------------------------
# Elementary transforms (4, 4)
# ---------------------------------------------------------------------------------------
def rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out
