"""The ISO 9283:1998 test paths of a robot, in the test cube's plane, with their joints and timing.

The path characteristics (clause 8) are measured on paths in the same diagonal plane of the
test cube as the pose test (:mod:`tcr_accuracy.iso9283.plan`), at one TCP orientation:

- ``line``: the straight line from P2 to P4, the plane's diagonal less 10 % at each end
  (80 % of the diagonal);
- ``circle_large``: a circle about P1 in the plane, of a diameter 80 % of the cube's edge;
- ``circle_small``: a circle about P1 of a tenth of the large one's diameter;
- ``rectangle``: P2 -> P3 -> P4 -> P5 -> P2, whose corners at P3, P4 and P5 are right angles
  that the robot passes at speed (the corner deviations).

The circles start on the plane's x direction from P1 and run counter-clockwise seen from the
plane's normal (0, -1, 1)/sqrt(2). Each path is sampled every millimetre (at least 200 points)
and solved by inverse kinematics point after point from the cube's P1 solution (a robot that
cannot hold an orientation, positions only: each step the smallest joint motion), every sample
held to the plan's :class:`~tcr_accuracy.iso9283.plan.Reach` (limits, half a turn from home,
workspace; self-collision and the floor at every tenth sample). Each path runs at a set of
speeds (the standard's 100, 50 and 10 % of the rated path speed): a trapezoidal profile with
the acceleration that ramps over 10 % of the path at each end, written as the commanded time of
each sample. The rated path speed, unless given, is the largest at which no joint exceeds its
URDF velocity limit anywhere on any path (``|dq/ds| v <= v_max`` per joint). Lengths are
metres, times seconds; nothing here prints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError
from ..analysis.collision import collision_checker
from ..model.robot import RobotModel
from ..random_state import renamed_keyword
from .plan import IsoPlan, cube_corners, iso_points, plan_iso_cube
from .reach import Reach, Workspace

#: The standard's cycles of a path test.
PATH_CYCLES = 10
#: Largest sample spacing along a path [m], and fewest samples per path.
SAMPLE_STEP = 1e-3
MIN_SAMPLES = 200
#: Fraction of a path's length over which its speed ramps up (and down).
RAMP_FRACTION = 0.10
#: A change of direction larger than this between neighbouring samples is a corner [rad].
CORNER_ANGLE = np.radians(30.0)
#: Largest joint step between neighbouring samples [rad or m]: more is a jump to another branch.
MAX_JOINT_STEP = 0.05
#: IK tolerance of a path sample [m, rad]: the commanded path is the nominal TCP of the joints written,
#: so a sample a micrometre off its ideal place changes nothing the evaluation computes.
IK_TOL = 1e-6
#: Every this many samples is checked for collisions and the floor.
COLLISION_STRIDE = 10
#: The plane of the test: its x direction, its in-plane diagonal direction, its normal.
PLANE_U = np.array([1.0, 0.0, 0.0])
PLANE_W = np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0)
PLANE_NORMAL = np.array([0.0, -1.0, 1.0]) / np.sqrt(2.0)


@dataclass(frozen=True)
class TestPath:
    """One commanded path.

    Attributes
    ----------
    name : str
        ``line``, ``circle_large``, ``circle_small`` or ``rectangle``.
    points : ndarray of shape (N, 3)
        Commanded TCP positions in the base frame [m].
    s : ndarray of shape (N,)
        Arc length from the start [m].
    q : ndarray of shape (N, n_joints) or None
        Joint values [rad, m] (None before the path is solved).
    corners : tuple of int
        Sample indices of the corners passed at speed.
    """

    __test__ = False  # a path, not a pytest class

    name: str
    points: np.ndarray
    s: np.ndarray
    q: np.ndarray | None = None
    corners: tuple = ()

    @property
    def length(self) -> float:
        return float(self.s[-1])


def arc_length(points) -> np.ndarray:
    """(N,) cumulative length [m] along a polyline (N, 3)."""
    points = np.asarray(points, dtype=float)
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def corners_of(points, angle: float = CORNER_ANGLE) -> tuple:
    """Indices of the interior samples where the direction turns by more than ``angle`` [rad]."""
    d = np.diff(np.asarray(points, dtype=float), axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    turn = np.arccos(np.clip(np.sum(d[:-1] * d[1:], axis=1), -1.0, 1.0))
    return tuple(int(i) + 1 for i in np.flatnonzero(turn > angle))


def _polyline(vertices, step) -> np.ndarray:
    """Samples (N, 3) along straight segments through ``vertices``, each vertex a sample."""
    out = [np.asarray(vertices[0], dtype=float)[None]]
    for a, b in zip(vertices[:-1], vertices[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.append(a + np.outer(np.arange(1, n + 1) / n, b - a))
    return np.vstack(out)


def standard_paths(centre, size: float) -> list:
    """The four test paths (see the module docstring) of the cube at ``centre`` (3,) [m] with edge
    ``size`` [m], sampled, without joints."""
    centre = np.asarray(centre, dtype=float)
    p = iso_points(centre, size)
    diagonal = float(np.linalg.norm(p[3] - p[1]))
    rectangle = 2 * (np.linalg.norm(p[2] - p[1]) + np.linalg.norm(p[3] - p[2]))
    out = []
    for name, vertices, total in (("line", [p[1], p[3]], diagonal),
                                  ("rectangle", [p[1], p[2], p[3], p[4], p[1]], rectangle)):
        points = _polyline(vertices, min(SAMPLE_STEP, total / MIN_SAMPLES))
        out.append(TestPath(name, points, arc_length(points), corners=corners_of(points)))
    for name, diameter in (("circle_large", 0.8 * size), ("circle_small", 0.08 * size)):
        radius = diameter / 2
        n = max(MIN_SAMPLES, int(np.ceil(np.pi * diameter / SAMPLE_STEP)))
        angle = np.linspace(0.0, 2 * np.pi, n + 1)
        points = centre + radius * (np.outer(np.cos(angle), PLANE_U) + np.outer(np.sin(angle), PLANE_W))
        out.append(TestPath(name, points, arc_length(points)))
    return sorted(out, key=lambda path: ("line", "circle_large", "circle_small", "rectangle").index(path.name))


def solve_path(reach: Reach, path: TestPath, rotation, q_start, anchors=None, chunk: int = 20) -> TestPath:
    """The path with its joints: IK sample after sample (in chunks started from the last solved
    sample, else from the ``anchors`` (positions (k, 3) [m], joints (k, n)) nearest the chunk) at
    ``rotation`` (3, 3), then held to ``reach``; InputError naming the first sample that fails and why."""
    n = len(path.points)
    q = np.empty((n, reach.robot.n_joints))
    start = np.asarray(q_start, dtype=float)
    if reach.mode != "exact":  # no orientation to hold: positions only, each step the smallest joint motion
        rotation = None
    for first in range(0, n, chunk):
        block = slice(first, min(first + chunk, n))
        solved = reach.solve_raw(path.points[block], rotation, start, IK_TOL)
        if solved is None and anchors is not None:
            near = np.argsort(np.linalg.norm(anchors[0] - path.points[first], axis=1))
            for k in near[:3]:
                solved = reach.solve_raw(path.points[block], rotation, anchors[1][k], IK_TOL)
                if solved is not None:
                    break
        if solved is None:
            _refuse(reach, path, first, rotation, start, "not reachable at the test's orientation")
        q[block] = solved
        start = solved[-1]
    q = reach.nearest_home(q)
    step = np.abs(np.diff(q, axis=0)).max(axis=1)
    if step.max() > MAX_JOINT_STEP:
        _refuse(reach, path, int(np.argmax(step)) + 1, rotation, q[int(np.argmax(step))],
                f"a joint jumps {step.max():.3g} rad or m between neighbouring samples (another branch)")
    swung = np.flatnonzero(reach.swing(q) > np.pi + 1e-9)
    if len(swung):
        _refuse(reach, path, int(swung[0]), rotation, q[swung[0]], "a joint more than half a turn from home")
    checked = np.unique(np.append(np.arange(0, n, COLLISION_STRIDE), n - 1))
    for k in checked:
        if (reach.checker is not None and not reach.checker.is_free(q[k:k + 1])[0]) or reach.below(q[k]):
            _refuse(reach, path, int(k), rotation, q[k], "self-collision or a body below the floor")
    outside = np.flatnonzero(~reach.workspace.inside(path.points))
    if len(outside):
        _refuse(reach, path, int(outside[0]), rotation, q[outside[0]], "outside the workspace")
    return TestPath(path.name, path.points, path.s, q, path.corners)


def _refuse(reach, path, k, rotation, q, why):
    at = ", ".join(f"{v * 1e3:.1f}" for v in path.points[k])
    raise InputError(f"{reach.robot.name}: the {path.name} test path at {path.s[k] * 1e3:.1f} mm from its start "
                     f"({at} mm): {why}; plan a smaller cube")


@dataclass(frozen=True)
class PathPlan:
    """The test paths of a cube, solved, with the rated path speed.

    Attributes
    ----------
    cube : IsoPlan
    paths : list of TestPath
    rotation : ndarray of shape (3, 3)
        The TCP orientation held along every path.
    rated_speed : float
        The rated path speed [m/s].
    speed_source : str
        Where it came from, in words.
    """

    cube: IsoPlan
    paths: list
    rotation: np.ndarray
    rated_speed: float
    speed_source: str


def plan_test_paths(reach: Reach, cube: IsoPlan, rated_speed: float | None = None) -> PathPlan:
    """The standard's test paths in the cube's plane, solved (see the module docstring).

    Parameters
    ----------
    reach : Reach
        What every sample must satisfy (the cube's).
    cube : IsoPlan
        The test cube (its P1 solution starts each path's IK).
    rated_speed : float, optional
        The rated path speed [m/s]; default the largest the joints' velocity limits allow.

    Returns
    -------
    PathPlan
    """
    rotation = cube.rotation[0]
    anchors = (np.vstack([cube.positions, cube_corners(cube.centre, cube.size)]), np.vstack([cube.q, cube.corner_q]))
    paths = []
    for path in standard_paths(cube.centre, cube.size):
        start = reach.solve_raw(path.points[:1], rotation, cube.q[0], IK_TOL)
        if start is None:
            _refuse(reach, path, 0, rotation, cube.q[0], "not reachable at the test's orientation")
        paths.append(solve_path(reach, path, rotation, start[0], anchors))
    if rated_speed is not None:
        if not (np.isfinite(rated_speed) and rated_speed > 0):
            raise InputError(f"rated path speed {rated_speed!r} m/s: want a positive speed")
        source = f"given: {rated_speed * 1e3:g} mm/s"
    else:
        rated_speed, source = _joint_limited_speed(reach.robot, paths)
    return PathPlan(cube=cube, paths=paths, rotation=rotation, rated_speed=float(rated_speed), speed_source=source)


@renamed_keyword("rng", "random_state")
def plan_path_test(robot: RobotModel, random_state=None, *, centre=None, size: float | None = None,
                   home=None, tool_rotation=None, tracker=None, workspace: Workspace | None = None,
                   rated_speed: float | None = None) -> PathPlan:
    """The test cube (:func:`tcr_accuracy.iso9283.plan.plan_iso_cube`, same arguments) and its test paths.

    Parameters
    ----------
    robot : RobotModel
    random_state : int, numpy.random.Generator or None, default=None
        Draws the cube search's candidates (formerly ``rng``).
    centre, size, home, tool_rotation, tracker, workspace
        As for :func:`~tcr_accuracy.iso9283.plan.plan_iso_cube` (the tracker's line of sight checked at
        the cube's five poses, not along the paths between them).
    rated_speed : float, optional
        The rated path speed [m/s]; default the largest the joints' velocity limits allow.

    Returns
    -------
    PathPlan

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> plan = tcr.plan_path_test(tcr.load_robot("ur5"), random_state=0)
    >>> len(plan.paths) > 0
    True
    """
    workspace = workspace or Workspace()
    cube = plan_iso_cube(robot, random_state, centre=centre, size=size, home=home, tool_rotation=tool_rotation,
                         tracker=tracker, workspace=workspace)
    reach = Reach(robot, collision_checker(robot), workspace, cube.home, cube.orientation)
    return plan_test_paths(reach, cube, rated_speed)


def _joint_limited_speed(robot, paths) -> tuple[float, str]:
    limits = np.asarray(robot.model.velocityLimit, dtype=float)
    if limits.shape != (robot.n_joints,) or not np.all(np.isfinite(limits) & (limits > 0)):
        raise InputError(f"{robot.name}: the URDF gives no velocity limit for every joint; give the rated path speed")
    worst, where = np.inf, ""
    for path in paths:
        rate = np.abs(np.diff(path.q, axis=0)) / np.diff(path.s)[:, None]  # |dq/ds| [rad/m or 1]
        speed = np.min(limits / np.maximum(rate, 1e-12), axis=1)
        k = int(np.argmin(speed))
        if speed[k] < worst:
            joint = int(np.argmin(limits / np.maximum(rate[k], 1e-12)))
            worst, where = float(speed[k]), f"{robot.joint_names[joint]} on the {path.name}"
    return worst, f"the largest the joints' velocity limits allow: {where} at its limit"


def trapezoid_times(s, speed: float, ramp: float = RAMP_FRACTION) -> np.ndarray:
    """(N,) time [s] at each arc length ``s`` (N,) [m] of a path run at ``speed`` [m/s], ramping up
    and down with the constant acceleration that takes ``ramp`` of the length at each end."""
    s = np.asarray(s, dtype=float)
    length = s[-1]
    d = ramp * length
    accel = speed ** 2 / (2 * d)
    t_ramp = speed / accel
    t_cruise = (length - 2 * d) / speed
    t = np.where(s <= d, np.sqrt(2 * s / accel), t_ramp + (s - d) / speed)
    tail = s > length - d
    t[tail] = t_ramp + t_cruise + t_ramp - np.sqrt(2 * np.maximum(length - s[tail], 0.0) / accel)
    return t


def commanded_speed(s, t) -> np.ndarray:
    """(N,) speed [m/s] of a commanded path at each sample from its arc length and times (centred
    differences)."""
    return np.gradient(np.asarray(s, dtype=float), np.asarray(t, dtype=float))


__all__ = ["CORNER_ANGLE", "PATH_CYCLES", "PathPlan", "TestPath", "arc_length", "commanded_speed",
           "corners_of", "plan_path_test", "plan_test_paths", "solve_path", "standard_paths", "trapezoid_times"]
