"""The ISO 9283:1998 test cube of a robot: where it fits, its five poses and their joints.

ISO 9283 (clause 6.8) measures pose accuracy and repeatability at five poses on a diagonal
plane of a cube whose edges are parallel to the base frame's axes, placed in the working
space with the largest volume the robot can serve. Here:

- the diagonal plane is the one through the cube's corners C1 = (-,-,-), C2 = (+,-,-),
  C3 = (+,+,+), C4 = (-,+,+) (signs: cube centre -/+ half the edge along x, y, z); it
  holds two opposite edges parallel to x and two space diagonals of the cube;
- P1 is the cube's centre; P2..P5 lie on the plane's diagonals at 10 % of the diagonal's
  length from C1..C4: ``P = C + 0.2 (centre - C)`` (the corner is half a diagonal from the
  centre);
- all poses share one TCP orientation (the one of the configuration found at the centre),
  so that a tool or reflector offset is the same translation everywhere; a robot that
  cannot hold an orientation while it moves (a frame Jacobian of rank < 6, like the
  tool-changer) gets its positions exactly and the orientation as close as it can;
- a cube is accepted when its 8 corners and the 5 poses are reached by inverse
  kinematics (:func:`tcr_accuracy.analysis.sampling.inverse_kinematics`, started from the
  centre's configuration) within the joint limits, and none of those configurations is in
  self-collision (:mod:`tcr_accuracy.analysis.collision`; not checked, and said, for a URDF
  without collision geometry);
- the largest cube is searched over centres taken from random joint configurations with
  the best-conditioned Jacobians (the robot's whole joint range, collision-free), each
  grown by bisection on the edge length.

The cycle order of the test (clause 7.2.1): ``cycles`` times P5, P4, P3, P2, P1.
Lengths are metres, angles radians; nothing here prints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..exceptions import InputError
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel
from ..analysis.collision import CollisionChecker, collision_checker
from ..analysis.sampling import inverse_kinematics

#: P2..P5 sit this fraction of the diagonal's length from the plane's corners (ISO 9283: 10 %).
CORNER_OFFSET = 0.10
#: The standard's number of cycles.
DEFAULT_CYCLES = 30
#: Signs of the diagonal plane's corners C1..C4 (x, y, z), those nearest P2..P5.
PLANE_CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1]], dtype=float)
#: Signs of the cube's eight corners.
CUBE_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)


def iso_points(centre, size: float) -> np.ndarray:
    """(5, 3) positions [m] of P1..P5 for a cube of edge ``size`` [m] centred at ``centre`` (3,)."""
    centre = np.asarray(centre, dtype=float)
    corners = centre + 0.5 * size * PLANE_CORNERS
    # 10 % of the diagonal from a corner = 20 % of the way from the corner to the centre
    return np.vstack([centre, corners + 2 * CORNER_OFFSET * (centre - corners)])


def cube_corners(centre, size: float) -> np.ndarray:
    """(8, 3) corner positions [m] of the cube."""
    return np.asarray(centre, dtype=float) + 0.5 * size * CUBE_CORNERS


def cycle_order(cycles: int) -> tuple[np.ndarray, np.ndarray]:
    """(pose_id, cycle) of each visit, (5 * cycles,) each: every cycle P5, P4, P3, P2, P1."""
    if cycles < 1:
        raise InputError(f"cycles {cycles}: need at least 1 (the standard uses {DEFAULT_CYCLES})")
    pose_id = np.tile(np.arange(5, 0, -1), cycles)
    cycle = np.repeat(np.arange(1, cycles + 1), 5)
    return pose_id, cycle


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


def plan_iso_cube(robot: RobotModel, rng: np.random.Generator, *, centre=None, size: float | None = None,
                  n_samples: int = 1000, n_centres: int = 60, bisections: int = 10) -> IsoPlan:
    """The largest ISO test cube in the reachable, collision-free workspace, or the one given.

    Parameters
    ----------
    robot : RobotModel
    rng : numpy.random.Generator
        Draws the candidate configurations.
    centre : array-like of shape (3,), optional
        A cube centre [m] (with ``size``): plan that cube instead of searching.
    size : float, optional
        Its edge [m].
    n_samples : int, default=1000
        Random joint configurations the candidate centres are chosen from.
    n_centres : int, default=60
        Candidate centres grown into cubes.
    bisections : int, default=10
        Bisection steps on each candidate's edge length.

    Raises
    ------
    InputError
        The given cube does not fit (naming the points that fail), or no cube was found.
    """
    checker = collision_checker(robot)
    mode = _orientation_mode(robot, rng)
    if centre is not None:
        if size is None or not size > 0:
            raise InputError("a given cube needs its centre and a size > 0")
        return _given_cube(robot, np.asarray(centre, dtype=float), float(size), checker, mode, rng)
    candidates = _candidate_configurations(robot, checker, rng, n_samples, n_centres)
    poses = tcp_poses(robot, candidates)
    reach = float(np.max(np.linalg.norm(poses.position, axis=1))) + 1e-3
    best = (0.0, None)
    for k in range(len(candidates)):
        q_c, p_c, r_c = candidates[k], poses.position[k], poses.rotation[k]
        low, high = best[0], 2.0 * reach / np.sqrt(3.0)
        if best[1] is not None and _solve(robot, p_c, low * 1.01, r_c, q_c, checker, mode) is None:
            continue  # cannot beat the best cube so far
        for _ in range(bisections):
            mid = 0.5 * (low + high)
            if _solve(robot, p_c, mid, r_c, q_c, checker, mode) is not None:
                low = mid
            else:
                high = mid
        if low > best[0] and _solve(robot, p_c, low, r_c, q_c, checker, mode) is not None:
            best = (low, (p_c, r_c, q_c))
    if best[1] is None:
        raise InputError(f"{robot.name}: no ISO test cube found among {len(candidates)} candidate centres; "
                         "give one with --cube-centre-mm and --cube-size-mm")
    p_c, r_c, q_c = best[1]
    solved = _solve(robot, p_c, best[0], r_c, q_c, checker, mode)
    return _plan(robot, p_c, best[0], solved, checker, mode, searched=True, n_centres=len(candidates))


def _orientation_mode(robot: RobotModel, rng: np.random.Generator) -> str:
    """``exact`` when the TCP frame Jacobian has rank 6 (at 20 random configurations), else
    ``best_effort``."""
    spectra = _jacobian_spectra(robot, rng.uniform(*robot.joint_bounds(np.pi), (20, robot.n_joints)))
    return "exact" if _generic_rank(spectra) >= 6 else "best_effort"


def _jacobian_spectra(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """(N, min(6, n_joints)) singular values of the TCP frame Jacobian at each configuration."""
    model, data = robot.model, robot.model.createData()
    spectra = []
    for row in q:
        pin.computeJointJacobians(model, data, robot.to_pinocchio_q(row))
        pin.updateFramePlacements(model, data)
        jac = pin.getFrameJacobian(model, data, robot.tool_frame_id, pin.LOCAL_WORLD_ALIGNED)
        spectra.append(np.linalg.svd(jac, compute_uv=False)[:6])
    return np.array(spectra)


def _generic_rank(spectra: np.ndarray) -> int:
    return int(np.max(np.sum(spectra > 1e-6 * spectra[:, :1], axis=1)))


def _candidate_configurations(robot, checker, rng, n_samples, n_centres) -> np.ndarray:
    """Collision-free random configurations with the best-conditioned Jacobians, spread out."""
    lo, hi = robot.joint_bounds(np.pi)
    q = rng.uniform(lo, hi, (n_samples, robot.n_joints))
    if checker is not None:
        q = q[checker.is_free(q)]
    spectra = _jacobian_spectra(robot, q)
    score = spectra[:, _generic_rank(spectra) - 1]  # the smallest singular value of the generic rank
    top = np.argsort(-score)[: max(n_centres * 4, n_centres)]
    positions = tcp_poses(robot, q[top]).position
    chosen = [0]  # the best; then the farthest from those chosen (spread over the workspace)
    while len(chosen) < min(n_centres, len(top)):
        gap = np.min(np.linalg.norm(positions[:, None] - positions[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(gap)))
    return q[top[chosen]]


def _solve(robot, centre, size, rotation, q_start, checker: CollisionChecker | None, mode):
    """Joint values (13, n) of P1..P5 then the 8 corners, or None when one fails."""
    targets = np.vstack([iso_points(centre, size), cube_corners(centre, size)])
    ik = inverse_kinematics(robot, targets, np.broadcast_to(rotation, (13, 3, 3)), q_start,
                            orientation=mode, max_iter=150, tol_position=1e-7, tol_rotation=1e-7)
    if not ik.success.all():
        return None
    if checker is not None and not checker.is_free(ik.q).all():
        return None
    return ik.q


def _given_cube(robot, centre, size, checker, mode, rng) -> IsoPlan:
    """The caller's cube: an orientation found at its centre that serves every point, or InputError."""
    failures = []
    starts = [robot.working_pose] + list(rng.uniform(*robot.joint_bounds(np.pi), (16, robot.n_joints)))
    for start in starts:
        ik = inverse_kinematics(robot, centre[None], None, start, max_iter=200)
        if not ik.success[0] or (checker is not None and not checker.is_free(ik.q).all()):
            continue
        rotation = tcp_poses(robot, ik.q).rotation[0]
        solved = _solve(robot, centre, size, rotation, ik.q[0], checker, mode)
        if solved is not None:
            return _plan(robot, centre, size, solved, checker, mode, searched=False, n_centres=1)
        failures.append(_failing_points(robot, centre, size, rotation, ik.q[0], checker, mode))
    said = failures[0] if failures else "the centre itself"
    raise InputError(f"cube centre ({', '.join(f'{v * 1e3:.1f}' for v in centre)}) mm, edge {size * 1e3:.1f} mm: "
                     f"{said} not reachable collision-free within the joint limits at one orientation; "
                     "give a smaller cube or omit --cube-centre-mm/--cube-size-mm to search the largest")


def _failing_points(robot, centre, size, rotation, q_start, checker, mode) -> str:
    names = [f"P{k}" for k in range(1, 6)] + [f"corner ({', '.join('+' if s > 0 else '-' for s in c)})"
                                               for c in CUBE_CORNERS]
    targets = np.vstack([iso_points(centre, size), cube_corners(centre, size)])
    ik = inverse_kinematics(robot, targets, np.broadcast_to(rotation, (13, 3, 3)), q_start, orientation=mode,
                            max_iter=150)
    bad = ~ik.success
    if checker is not None:
        bad |= ~checker.is_free(ik.q)
    return ", ".join(n for n, b in zip(names, bad) if b) or "a point"


def _plan(robot, centre, size, solved, checker, mode, *, searched, n_centres) -> IsoPlan:
    poses = tcp_poses(robot, solved[:5])
    if checker is None:
        collision = f"not checked: the URDF of {robot.name} has no collision geometry"
    else:
        collision = (f"checked with coal on the URDF's collision geometry: {checker.n_pairs} body pairs "
                     f"(ignored: {', '.join(f'{n} {k}' for k, n in checker.ignored.items() if n) or 'none'})")
    return IsoPlan(centre=np.asarray(centre, dtype=float), size=float(size), positions=iso_points(centre, size),
                   q=solved[:5], rotation=poses.rotation, corner_q=solved[5:], orientation=mode,
                   collision=collision, searched=searched, n_centres=n_centres)


__all__ = ["CORNER_OFFSET", "DEFAULT_CYCLES", "IsoPlan", "cube_corners", "cycle_order", "iso_points",
           "plan_iso_cube"]
