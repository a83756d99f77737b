"""The ISO 9283:1998 test cube of a robot: where it fits, its five poses, their joints, the order
of the cycles and the test conditions.

ISO 9283 (clause 6.8) measures pose accuracy and repeatability at five poses on a diagonal
plane of a cube whose edges are parallel to the base frame's axes, placed in the working
space with the largest volume the robot can serve. Here:

- the diagonal plane is the one through the cube's corners C1 = (-,-,-), C2 = (+,-,-),
  C3 = (+,+,+), C4 = (-,+,+) (signs: cube centre -/+ half the edge along x, y, z); it
  holds two opposite edges parallel to x and two space diagonals of the cube;
- P1 is the cube's centre; P2..P5 lie on the plane's diagonals at 10 % of the diagonal's
  length from C1..C4: ``P = C + 0.2 (centre - C)`` (the corner is half a diagonal from the
  centre);
- all poses share one TCP orientation (the one given, ``tool_rotation``, else the one of the
  configuration found at the centre), so that a tool or reflector offset is the same
  translation everywhere; a robot that cannot hold an orientation while it moves (a frame
  Jacobian of rank < 6, like the tool-changer) gets its positions exactly and the orientation
  as close as it can;
- a cube is accepted when its 8 corners and the 5 poses are reached by inverse kinematics
  (:func:`tcr_accuracy.analysis.sampling.inverse_kinematics`) within the joint limits, with
  every revolute joint within half a turn of a home configuration (the robot's usual ready
  pose unless given, :func:`ready_pose`: the maker's for robots known by name, the UR's
  upright pose, else the robot's ``working_pose``; of the joint values that place the TCP
  alike, those one or more full turns apart, the one nearest home is taken), with the
  instrument's line of sight to P1..P5 free of the robot's bodies when its position is given
  (``tracker``; the collision geometry's), with every point above the mounting plane
  (the base frame's z = 0, or a floor given) and inside a cell box when one is given, with no
  body of the robot below the mounting plane, or the floor when it is lower (coal's half-space
  against the URDF's collision geometry; without it, the joint origins) and none of those
  configurations in
  self-collision (:mod:`tcr_accuracy.analysis.collision`; not checked, and said, for a URDF
  without collision geometry). Bodies fixed to the base, and those of the first joint that
  reach below the floor at home (a base flange turning on it), are not held to the floor;
- the largest cube is searched over centres taken from random joint configurations within
  half a turn of home with the best-conditioned Jacobians, each grown by bisection on the
  edge length; the cube found is solved again from home and that solution kept when its
  joints are nearer home.

The cycle order of the test (clause 7.2.1): the robot starts at P1, then ``cycles`` times P5,
P4, P3, P2, P1. The test conditions (clause 6 and its table of tests): rated load at 100 %,
50 % and 10 % of the rated speed, and 10 % of the rated load at 100 % speed; each condition
is one block of cycles. :meth:`IsoPlan.series` gives the test as a :class:`MeasurementSet`
in that order, its labels set (pose ids ``P1``..``P5`` as the plan names them), ready to be
measured or simulated. Lengths are metres, angles radians; nothing here prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..analysis.collision import collision_checker
from ..analysis.sampling import inverse_kinematics
from ..exceptions import InputError
from ..io.measurements import MeasurementSet
from ..model.jacobians import tcp_jacobian
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel
from ..random_state import renamed_keyword
from .reach import MAX_SWING, Reach, Workspace

#: P2..P5 sit this fraction of the diagonal's length from the plane's corners (ISO 9283: 10 %).
CORNER_OFFSET = 0.10
#: The standard's number of cycles.
DEFAULT_CYCLES = 30
#: Signs of the diagonal plane's corners C1..C4 (x, y, z), those nearest P2..P5.
PLANE_CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1]], dtype=float)
#: Signs of the cube's eight corners.
CUBE_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
#: The smallest cube edge planned [m]: below it the five poses lie within the instrument's reach of
#: one another and the measurement reader's unit check (which needs a spread of a millimetre) is blind.
MIN_CUBE_SIZE = 0.01
#: The standard's test conditions: (load, speed) in % of the rated load and of the rated speed.
STANDARD_CONDITIONS = ((100.0, 100.0), (100.0, 50.0), (100.0, 10.0), (10.0, 100.0))
#: Rated payloads [kg] from the makers' data sheets, for the robots known by name.
RATED_LOAD_KG = {"ur3": 3.0, "ur5": 5.0, "ur10": 10.0, "panda": 3.0}
#: The makers' ready (home) poses [deg] of the robots known by name, from which a test starts: the
#: UR's upright pose (the teach pendant's home, the arm pointing up), Franka's ready pose. The URDFs'
#: zero (a UR stretched out level) is no pose a test starts from.
READY_POSE_DEG = {"ur3": (0.0, -90.0, 0.0, -90.0, 0.0, 0.0), "ur5": (0.0, -90.0, 0.0, -90.0, 0.0, 0.0),
                  "ur10": (0.0, -90.0, 0.0, -90.0, 0.0, 0.0), "panda": (0.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0)}


def ready_pose(robot: RobotModel) -> np.ndarray:
    """(n_joints,) the robot's usual ready pose [rad, m]: :data:`READY_POSE_DEG` for the robots known by
    name (when its joints are theirs and within the limits), else the robot's ``working_pose``."""
    known = READY_POSE_DEG.get(robot.name)
    if known is not None and len(known) == robot.n_joints and all(k == "revolute" for k in robot.joint_kinds):
        q = np.radians(known)
        if robot.within_limits(q[None])[0]:
            return q
    return np.asarray(robot.working_pose, dtype=float).copy()


def iso_points(centre, size: float) -> np.ndarray:
    """(5, 3) positions [m] of P1..P5 for a cube of edge ``size`` [m] centred at ``centre`` (3,)."""
    centre = np.asarray(centre, dtype=float)
    corners = centre + 0.5 * size * PLANE_CORNERS
    # 10 % of the diagonal from a corner = 20 % of the way from the corner to the centre
    return np.vstack([centre, corners + 2 * CORNER_OFFSET * (centre - corners)])


def cube_corners(centre, size: float) -> np.ndarray:
    """(8, 3) corner positions [m] of the cube."""
    return np.asarray(centre, dtype=float) + 0.5 * size * CUBE_CORNERS


def cycle_order(cycles: int = DEFAULT_CYCLES) -> tuple[np.ndarray, np.ndarray]:
    """The visits of a pose test in the standard's order (clause 7.2.1): the robot starts at P1, then
    every cycle P5, P4, P3, P2, P1.

    Parameters
    ----------
    cycles : int, default=30
        Cycles (the standard's 30).

    Returns
    -------
    tuple of (ndarray of shape (5 * cycles,), ndarray of shape (5 * cycles,))
        The pose number (1..5, P1..P5) and the cycle (1..cycles) of each visit.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> pose, cycle = tcr.cycle_order(2)
    >>> [f"P{p}" for p in pose], cycle.tolist()
    (['P5', 'P4', 'P3', 'P2', 'P1', 'P5', 'P4', 'P3', 'P2', 'P1'], [1, 1, 1, 1, 1, 2, 2, 2, 2, 2])
    """
    if isinstance(cycles, bool) or not isinstance(cycles, (int, np.integer)) or cycles < 1:
        raise InputError(f"cycles={cycles!r}: need a whole number of at least 1 (the standard uses "
                         f"{DEFAULT_CYCLES})", parameter="cycles", value=cycles)
    pose_id = np.tile(np.arange(5, 0, -1), int(cycles))
    cycle = np.repeat(np.arange(1, int(cycles) + 1), 5)
    return pose_id, cycle


# ---------------------------------------------------------------------------------------
# Test conditions
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Condition:
    """One block of cycles: ``load_pct`` of the rated load (``payload_kg`` [kg], None when the rated
    load is unknown) at ``speed_pct`` of the rated speed."""

    load_pct: float
    speed_pct: float
    payload_kg: float | None

    def words(self) -> str:
        load = f"{self.load_pct:g} % rated load" + ("" if self.payload_kg is None else f" ({self.payload_kg:g} kg)")
        return f"{load}, {self.speed_pct:g} % rated speed"


def plan_conditions(robot: RobotModel, conditions=STANDARD_CONDITIONS,
                    rated_load_kg: float | None = None) -> tuple[list, str]:
    """The test conditions with their payloads, and where the rated load came from.

    Parameters
    ----------
    robot : RobotModel
    conditions : sequence of (float, float)
        (load, speed) in % of the rated ones; default the standard's four.
    rated_load_kg : float, optional
        The rated load [kg]; default the maker's for robots known by name (:data:`RATED_LOAD_KG`),
        the tool-changer's disc cutter, else unknown (payloads left out, said).

    Returns
    -------
    tuple of (list of Condition, str)
    """
    for load, speed in conditions:
        if not (0 <= load <= 100 and 0 < speed <= 100):
            raise InputError(f"test condition {load:g} % load, {speed:g} % speed: want a load of 0-100 % and a "
                             "speed of (0, 100] % of the rated ones")
    if rated_load_kg is not None:
        if not (np.isfinite(rated_load_kg) and rated_load_kg > 0):
            raise InputError(f"rated load {rated_load_kg!r} kg: want a positive load")
        source = f"rated load {rated_load_kg:g} kg (given)"
    elif robot.name in RATED_LOAD_KG:
        rated_load_kg = RATED_LOAD_KG[robot.name]
        source = f"rated load {rated_load_kg:g} kg ({robot.name}'s data sheet)"
    elif robot.payload_kg is not None:
        rated_load_kg = float(robot.payload_kg)
        source = f"rated load {rated_load_kg:g} kg (the robot's design payload)"
    else:
        source = "rated load unknown (give it): the loads are percentages only, no payload_kg column"
    out = [Condition(float(load), float(speed), None if rated_load_kg is None else rated_load_kg * load / 100.0)
           for load, speed in conditions]
    return out, source


# ---------------------------------------------------------------------------------------
# The cube
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class IsoPlan:
    """An ISO 9283 test cube and its five poses.

    Attributes
    ----------
    centre : ndarray of shape (3,)
        Cube centre in the base frame [m] (= P1).
    size : float
        Edge length [m].
    positions : ndarray of shape (5, 3)
        Commanded TCP positions of P1..P5 in the base frame [m] (``q`` reaches them within
        1e-7 m).
    q : ndarray of shape (5, n_joints)
        Joint values of P1..P5 [rad, m].
    rotation : ndarray of shape (5, 3, 3)
        TCP orientation of each pose (all equal unless ``orientation`` is ``best_effort``).
    corner_q : ndarray of shape (8, n_joints)
        Joint values at the cube's corners (checked, not measured).
    orientation : str
        ``exact`` (one orientation held) or ``best_effort`` (position exact, orientation as
        close as the robot can: its frame Jacobian has rank < 6).
    collision : str
        How self-collision was checked, or why it was not.
    searched : bool
        True: the largest cube found; False: the cube the caller gave.
    n_centres : int
        Candidate centres tried.
    home : ndarray of shape (n_joints,)
        The home configuration [rad, m].
    max_swing : float
        The largest turn of a revolute joint from home over the poses and corners [rad].
    workspace : str
        Where the test was kept, in words (floor, box, the bodies above the floor).
    tracker : ndarray of shape (3,) or None
        The instrument's position in the base frame [m], when given.
    tracker_distance : ndarray of shape (5,) or None
        Distance of P1..P5 from the instrument [m] (its MPE grows with it), when given.
    sight : str
        How the instrument's line of sight to P1..P5 was checked, or why it was not.
    robot : RobotModel or None
        The robot planned for (:meth:`series` writes its joints and rated load).
    """

    centre: np.ndarray
    size: float
    positions: np.ndarray
    q: np.ndarray
    rotation: np.ndarray
    corner_q: np.ndarray
    orientation: str
    collision: str
    searched: bool
    n_centres: int
    home: np.ndarray | None = None
    max_swing: float = 0.0
    workspace: str = ""
    tracker: np.ndarray | None = None
    tracker_distance: np.ndarray | None = None
    sight: str = ""
    robot: RobotModel | None = field(default=None, repr=False, compare=False)

    @property
    def pose_ids(self) -> list:
        """The poses' names, ``P1``..``P5`` (rows of :attr:`positions` and :attr:`q`)."""
        return [f"P{k}" for k in range(1, 6)]

    def series(self, cycles: int = DEFAULT_CYCLES, conditions=((100.0, 100.0),), *,
               rated_load_kg: float | None = None) -> MeasurementSet:
        """The test to run: every condition a block of ``cycles`` cycles in the standard's order
        (:func:`cycle_order`), as a measurement set whose positions are to be measured.

        Parameters
        ----------
        cycles : int, default=30
            Cycles per condition (the standard's 30).
        conditions : sequence of (float, float), default=((100.0, 100.0),)
            (load, speed) in % of the rated ones: the rated load at the rated speed; give
            :data:`STANDARD_CONDITIONS` for the standard's four (then evaluate each block:
            :func:`tcr_accuracy.iso9283.evaluate.evaluate_conditions`).
        rated_load_kg : float, optional
            The rated load [kg] (default as :func:`plan_conditions`): sets each row's ``payload_kg``.

        Returns
        -------
        MeasurementSet
            ``q`` (5 * cycles * len(conditions), n_joints) the commanded joints, ``position`` NaN
            until measured (replace it with the instrument's readings, or a simulation's:
            ``dataclasses.replace(series, position=...)``), ``payload_kg`` where the rated load is
            known, and ``annotations`` ``pose_id`` (``P1``..``P5``), ``cycle``, ``load_pct``,
            ``speed_pct`` and the commanded TCP ``target_x_mm``, ``target_y_mm``, ``target_z_mm``
            (base frame, mm as the CSV names them).

        Examples
        --------
        >>> import tcr_accuracy as tcr
        >>> robot = tcr.load_robot("ur5")
        >>> plan = tcr.plan_iso_cube(robot, random_state=0, centre=[-0.13, -0.44, 0.32], size=0.2)
        >>> series = plan.series(cycles=2)
        >>> series.annotations["pose_id"].tolist()
        ['P5', 'P4', 'P3', 'P2', 'P1', 'P5', 'P4', 'P3', 'P2', 'P1']
        """
        if self.robot is None:
            raise InputError("this plan does not hold its robot: plan it with plan_iso_cube")
        blocks, _ = plan_conditions(self.robot, tuple(conditions), rated_load_kg)
        pose, cycle = cycle_order(cycles)
        k = pose - 1
        n = len(k) * len(blocks)
        payload = None
        if all(b.payload_kg is not None for b in blocks):
            payload = np.repeat([b.payload_kg for b in blocks], len(k))
        targets = np.tile(self.positions[k] * 1e3, (len(blocks), 1))
        annotations = {
            "pose_id": np.array([f"P{v}" for v in np.tile(pose, len(blocks))], dtype=object),
            "cycle": np.array([str(v) for v in np.tile(cycle, len(blocks))], dtype=object),
            "load_pct": np.repeat([b.load_pct for b in blocks], len(k)),
            "speed_pct": np.repeat([b.speed_pct for b in blocks], len(k)),
            "target_x_mm": targets[:, 0], "target_y_mm": targets[:, 1], "target_z_mm": targets[:, 2]}
        return MeasurementSet(joint_names=list(self.robot.joint_names), q=np.tile(self.q[k], (len(blocks), 1)),
                              position=np.full((n, 3), np.nan), payload_kg=payload,
                              source=f"ISO 9283 plan of {self.robot.name}", annotations=annotations)


@renamed_keyword("rng", "random_state")
def plan_iso_cube(robot: RobotModel, random_state=None, *, centre=None, size: float | None = None,
                  home=None, tool_rotation=None, tracker=None, workspace: Workspace | None = None,
                  n_samples: int = 1000, n_centres: int = 60, bisections: int = 10) -> IsoPlan:
    """The largest ISO test cube the robot serves (see the module docstring), or the one given.

    Parameters
    ----------
    robot : RobotModel
    random_state : int, numpy.random.Generator or None, default=None
        Draws the candidate configurations (formerly ``rng``).
    centre : array-like of shape (3,), optional
        A cube centre [m] (with ``size``): plan that cube instead of searching.
    size : float, optional
        Its edge [m], at least :data:`MIN_CUBE_SIZE`.
    home : array-like of shape (n_joints,), optional
        The home configuration [rad, m]; default the robot's usual ready pose (:func:`ready_pose`).
    tool_rotation : array-like of shape (3, 3), optional
        The TCP orientation every pose holds, in the base frame (``baseRtool``); default the one
        found at the cube's centre.
    tracker : array-like of shape (3,), optional
        The instrument's position in the base frame [m]: P1..P5 must be in its line of sight (no
        collision body on it; needs the URDF's collision geometry), and their distances from it
        are kept.
    workspace : Workspace, optional
        Floor and cell box; default above the mounting plane (z = 0 of the base frame).
    n_samples : int, default=1000
        Random joint configurations the candidate centres are chosen from.
    n_centres : int, default=60
        Candidate centres grown into cubes.
    bisections : int, default=10
        Bisection steps on each candidate's edge length.

    Returns
    -------
    IsoPlan

    Raises
    ------
    InputError
        The given cube does not fit (naming the points that fail and why), or no cube was found.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> plan = tcr.plan_iso_cube(robot, random_state=0, centre=[-0.13, -0.44, 0.32], size=0.2)
    >>> plan.pose_ids, plan.positions.shape
    (['P1', 'P2', 'P3', 'P4', 'P5'], (5, 3))
    """
    rng = np.random.default_rng(random_state)
    workspace = workspace or Workspace()
    home = _home(robot, home)
    rotation = _tool_rotation(tool_rotation)
    reach = Reach(robot, collision_checker(robot), workspace, home, _orientation_mode(robot, rng),
                  tracker=_tracker(tracker))
    if centre is not None:
        if size is None or not np.isfinite(size) or size < MIN_CUBE_SIZE:
            raise InputError(f"a given cube needs its centre and an edge of at least {MIN_CUBE_SIZE * 1e3:g} mm "
                             f"(got size={size!r} m)", parameter="size", value=size)
        return _given_cube(reach, np.asarray(centre, dtype=float), float(size), rng, rotation)
    candidates = _candidate_configurations(reach, rng, n_samples, n_centres)
    if not len(candidates):
        raise InputError(f"{robot.name}: none of {n_samples} random configurations within half a turn of home puts "
                         f"the TCP {workspace.words()} free of collision; check the floor, box and home")
    poses = tcp_poses(robot, candidates)
    far = float(np.max(np.linalg.norm(poses.position, axis=1))) + 1e-3
    best = (0.0, None)
    for k in range(len(candidates)):
        q_c, p_c, r_c = candidates[k], poses.position[k], poses.rotation[k]
        if rotation is not None:  # the given orientation at this candidate's TCP position
            r_c = rotation
            solved = reach.solve(p_c[None], r_c, q_c, sighted=1)
            if solved is None:
                continue
            q_c = solved[0]
        low, high = best[0], min(2.0 * far / np.sqrt(3.0), workspace.room(p_c))
        if high <= low or (best[1] is not None and reach.solve(_targets(p_c, low * 1.01), r_c, q_c,
                                                               sighted=5) is None):
            continue  # cannot beat the best cube so far
        for _ in range(bisections):
            mid = 0.5 * (low + high)
            if reach.solve(_targets(p_c, mid), r_c, q_c, sighted=5) is not None:
                low = mid
            else:
                high = mid
        if low > best[0] and reach.solve(_targets(p_c, low), r_c, q_c, sighted=5) is not None:
            best = (low, (p_c, r_c, q_c))
    if best[1] is None or best[0] < MIN_CUBE_SIZE:
        raise InputError(f"{robot.name}: no ISO test cube of {MIN_CUBE_SIZE * 1e3:g} mm or more found among "
                         f"{len(candidates)} candidate centres {workspace.words()}"
                         + ("" if rotation is None else " at the tool orientation given")
                         + ("" if reach.tracker is None else " in sight of the tracker")
                         + "; give one with the cube's centre and size, or another floor, box, home, orientation "
                           "or tracker position")
    p_c, r_c, q_c = best[1]
    solved = reach.solve(_targets(p_c, best[0]), r_c, q_c, sighted=5)
    return _plan(reach, p_c, best[0], _nearer_home(reach, p_c, best[0], r_c, solved), searched=True,
                 n_centres=len(candidates))


def _tool_rotation(rotation):
    """The given TCP orientation (3, 3), checked, or None."""
    if rotation is None:
        return None
    rotation = np.asarray(rotation, dtype=float)
    if rotation.shape != (3, 3) or not np.all(np.isfinite(rotation)) or \
            not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6) or np.linalg.det(rotation) < 0:
        raise InputError("tool_rotation: want a (3, 3) rotation matrix (orthonormal, determinant +1)",
                         parameter="tool_rotation")
    return rotation


def _tracker(tracker):
    """The instrument's position (3,) [m], checked, or None."""
    if tracker is None:
        return None
    tracker = np.asarray(tracker, dtype=float).ravel()
    if tracker.shape != (3,) or not np.all(np.isfinite(tracker)):
        raise InputError("tracker: want its position x, y, z [m] in the base frame, three finite numbers",
                         parameter="tracker")
    return tracker


def _home(robot: RobotModel, home) -> np.ndarray:
    if home is None:
        return ready_pose(robot)
    home = np.asarray(home, dtype=float).ravel()
    if home.shape != (robot.n_joints,) or not np.all(np.isfinite(home)):
        raise InputError(f"home: want {robot.n_joints} finite joint values ({', '.join(robot.joint_names)})")
    if not robot.within_limits(home[None])[0]:
        raise InputError(f"home: outside the joint limits of {robot.name}")
    return home


def _targets(centre, size) -> np.ndarray:
    """(13, 3) P1..P5 then the 8 corners [m]."""
    return np.vstack([iso_points(centre, size), cube_corners(centre, size)])


def _nearer_home(reach: Reach, centre, size, rotation, solved) -> np.ndarray:
    """The cube solved again from home; kept when its joints are nearer home than ``solved``."""
    again = reach.solve(centre[None], rotation, reach.home, sighted=1)
    if again is not None:
        again = reach.solve(_targets(centre, size), rotation, again[0], sighted=5)
    if again is not None and np.sum(reach.swing(again)) < np.sum(reach.swing(solved)):
        return again
    return solved


def _orientation_mode(robot: RobotModel, rng: np.random.Generator) -> str:
    """``exact`` when the TCP frame Jacobian has rank 6 (at 20 random configurations), else
    ``best_effort``."""
    spectra = _jacobian_spectra(robot, rng.uniform(*robot.joint_bounds(np.pi), (20, robot.n_joints)))
    return "exact" if _generic_rank(spectra) >= 6 else "best_effort"


def _jacobian_spectra(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """(N, min(6, n_joints)) singular values of the TCP frame Jacobian at each configuration."""
    data = robot.model.createData()
    spectra = []
    for row in q:
        jac = tcp_jacobian(robot, row, data)[1]
        spectra.append(np.linalg.svd(jac, compute_uv=False)[:6])
    return np.array(spectra)


def _generic_rank(spectra: np.ndarray) -> int:
    return int(np.max(np.sum(spectra > 1e-6 * spectra[:, :1], axis=1)))


def _candidate_configurations(reach: Reach, rng, n_samples, n_centres) -> np.ndarray:
    """Random configurations within half a turn of home, TCP in the workspace, free of collision and
    the floor, with the best-conditioned Jacobians, spread out."""
    robot = reach.robot
    q = rng.uniform(*reach.bounds(), (n_samples, robot.n_joints))
    q = q[reach.workspace.inside(tcp_poses(robot, q).position)]
    if reach.checker is not None and len(q):
        q = q[reach.checker.is_free(q)]
    q = q[[not reach.below(row) for row in q]] if len(q) else q
    if not len(q):
        return q
    spectra = _jacobian_spectra(robot, q)
    score = spectra[:, _generic_rank(spectra) - 1]  # the smallest singular value of the generic rank
    top = np.argsort(-score)[: max(n_centres * 4, n_centres)]
    positions = tcp_poses(robot, q[top]).position
    chosen = [0]  # the best; then the farthest from those chosen (spread over the workspace)
    while len(chosen) < min(n_centres, len(top)):
        gap = np.min(np.linalg.norm(positions[:, None] - positions[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(gap)))
    return q[top[chosen]]


def _given_cube(reach: Reach, centre, size, rng, rotation=None) -> IsoPlan:
    """The caller's cube: an orientation (the one given, else one found at its centre) that serves
    every point, or InputError."""
    robot = reach.robot
    failures = []
    starts = [reach.home] + list(rng.uniform(*reach.bounds(), (16, robot.n_joints)))
    for start in starts:
        ik = inverse_kinematics(robot, centre[None], None if rotation is None else rotation[None], start,
                                orientation=reach.mode if rotation is not None else "exact", max_iter=200)
        q_centre = reach.nearest_home(ik.q)
        if not ik.success[0] or reach.swing(q_centre)[0] > MAX_SWING + 1e-9 or \
                (reach.checker is not None and not reach.checker.is_free(q_centre).all()):
            continue
        held = tcp_poses(robot, q_centre).rotation[0] if rotation is None else rotation
        solved = reach.solve(_targets(centre, size), held, q_centre[0], sighted=5)
        if solved is not None:
            return _plan(reach, centre, size, _nearer_home(reach, centre, size, held, solved), searched=False,
                         n_centres=1)
        failures.append(_failing_points(reach, centre, size, held, q_centre[0]))
    said = failures[0] if failures else ("the centre itself (not reachable within half a turn of home"
                                         + ("" if rotation is None else " at the tool orientation given") + ")")
    raise InputError(f"cube centre ({', '.join(f'{v * 1e3:.1f}' for v in centre)}) mm, edge {size * 1e3:.1f} mm: "
                     f"{said}; the test must be reachable collision-free within the joint limits at one orientation, "
                     f"{reach.workspace.words()}: give a smaller cube or omit the centre and size to search the "
                     "largest")


def _failing_points(reach: Reach, centre, size, rotation, q_start) -> str:
    names = [f"P{k}" for k in range(1, 6)] + [f"corner ({', '.join('+' if s > 0 else '-' for s in c)})"
                                               for c in CUBE_CORNERS]
    words = reach.failures(_targets(centre, size), rotation, q_start, sighted=5)
    failing = [f"{n} {w}" for n, w in zip(names, words) if w]
    return "; ".join(failing[:4]) + (f" (and {len(failing) - 4} more)" if len(failing) > 4 else "") or "a point"


def _plan(reach: Reach, centre, size, solved, *, searched, n_centres) -> IsoPlan:
    robot, checker = reach.robot, reach.checker
    poses = tcp_poses(robot, solved[:5])
    if checker is None:
        collision = f"not checked: the URDF of {robot.name} has no collision geometry"
    else:
        collision = (f"checked with coal on the URDF's collision geometry: {checker.n_pairs} body pairs "
                     f"(ignored: {', '.join(f'{n} {k}' for k, n in checker.ignored.items() if n) or 'none'})")
    positions = iso_points(centre, size)
    distance = None if reach.tracker is None else np.linalg.norm(positions - reach.tracker, axis=1)
    return IsoPlan(centre=np.asarray(centre, dtype=float), size=float(size), positions=positions,
                   q=solved[:5], rotation=poses.rotation, corner_q=solved[5:], orientation=reach.mode,
                   collision=collision, searched=searched, n_centres=n_centres, home=reach.home.copy(),
                   max_swing=float(np.max(reach.swing(solved))),
                   workspace=f"{reach.workspace.words()}; {reach.floor_words()}",
                   tracker=None if reach.tracker is None else reach.tracker.copy(), tracker_distance=distance,
                   sight=reach.sight_words(), robot=robot)


__all__ = ["CORNER_OFFSET", "Condition", "DEFAULT_CYCLES", "IsoPlan", "MIN_CUBE_SIZE", "RATED_LOAD_KG",
           "READY_POSE_DEG", "STANDARD_CONDITIONS", "cube_corners", "cycle_order", "iso_points", "plan_conditions",
           "plan_iso_cube", "ready_pose"]
