"""Where an ISO 9283 test may go and what each of its configurations must satisfy.

:class:`Workspace` is the room (above the mounting plane or a floor, inside a cell box);
:class:`Reach` holds a robot to it: inverse kinematics within the joint limits, every revolute
joint within half a turn of a home configuration (whole turns taken off jointly, see
:meth:`Reach.nearest_home`), no self-collision, no body below the mounting plane (coal's
half-space; the joint origins without collision geometry), and, when the instrument's position is
given, its line of sight to the measured points free of the robot's bodies (as
:mod:`tcr_accuracy.analysis.reachable` checks it). The pose test's cube
(:mod:`tcr_accuracy.iso9283.plan`) and the test paths (:mod:`tcr_accuracy.iso9283.path_plan`)
both use it. Lengths are metres, angles radians; nothing here prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..analysis.collision import CollisionChecker
from ..analysis.reachable import BEAM_RADIUS_M, REFLECTOR_CLEARANCE_M
from ..analysis.sampling import inverse_kinematics
from ..exceptions import InputError
from ..model.robot import RobotModel
from ..units import REVOLUTE

#: How far a revolute joint may turn from home [rad].
MAX_SWING = np.pi


@dataclass(frozen=True)
class Workspace:
    """The room the test has: above ``floor`` (z of the base frame [m]; the mounting plane by
    default) and, when given, inside ``box`` ((2, 3) lower and upper corners [m])."""

    floor: float = 0.0
    box: np.ndarray | None = None

    def __post_init__(self):
        if not np.isfinite(self.floor):
            raise InputError(f"floor {self.floor!r} m: want a finite height")
        if self.box is not None:
            box = np.asarray(self.box, dtype=float).reshape(2, 3)
            if not np.all(np.isfinite(box)) or np.any(box[1] <= box[0]):
                raise InputError("cell box: want finite lower < upper bounds on x, y and z")
            object.__setattr__(self, "box", box)

    @property
    def lowest(self) -> float:
        """The plane the robot's bodies must stay above [m]: the mounting plane, or the floor when it
        is lower (a robot on a pedestal); a floor above the mounting plane (a table top the test is
        above) holds the test's points, not the arm that rises through it."""
        return min(self.floor, 0.0)

    def inside(self, points) -> np.ndarray:
        """(N,) True where the points (N, 3) [m] are above the floor (and in the box)."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        ok = points[:, 2] >= self.floor
        if self.box is not None:
            ok &= np.all((points >= self.box[0]) & (points <= self.box[1]), axis=1)
        return ok

    def room(self, centre) -> float:
        """The largest cube edge [m] centred at ``centre`` (3,) that fits the floor and the box."""
        centre = np.asarray(centre, dtype=float)
        half = centre[2] - self.floor
        if self.box is not None:
            half = min(half, float(np.min(centre - self.box[0])), float(np.min(self.box[1] - centre)))
        return 2.0 * max(half, 0.0)

    def words(self) -> str:
        out = f"above z = {self.floor * 1e3:g} mm" + (" (the mounting plane)" if self.floor == 0 else "")
        if self.box is not None:
            out += ", inside the cell box " + " x ".join(f"[{lo * 1e3:g}, {hi * 1e3:g}]"
                                                       for lo, hi in zip(self.box[0], self.box[1])) + " mm"
        return out


@dataclass
class Reach:
    """What a configuration of the test must satisfy (see the module docstring), and the checks.

    Attributes
    ----------
    robot : RobotModel
    checker : CollisionChecker or None
    workspace : Workspace
    home : ndarray of shape (n_joints,)
        The home configuration [rad, m].
    mode : str
        ``exact`` or ``best_effort`` (see :func:`tcr_accuracy.analysis.sampling.inverse_kinematics`).
    tracker : ndarray of shape (3,) or None
        The instrument's position in the base frame [m]: the measured points must be in its sight.
    """

    robot: RobotModel
    checker: CollisionChecker | None
    workspace: Workspace
    home: np.ndarray
    mode: str
    floor_exempt: set = field(default_factory=set)
    tracker: np.ndarray | None = None

    def __post_init__(self):
        self.revolute = np.array([k == REVOLUTE for k in self.robot.joint_kinds])
        self.floor_exempt = self._floor_exempt()

    # -- joints ---------------------------------------------------------------------------
    def nearest_home(self, q) -> np.ndarray:
        """q (N, n_joints), one set of configurations the robot moves between, with each revolute joint
        moved by the same whole turns in every row to the values nearest home that its limits allow
        (the TCP does not move, and a move between two rows keeps its short way)."""
        q = np.array(np.atleast_2d(q), dtype=float)
        lo, hi = self.robot.joint_bounds(np.inf)
        for j in np.flatnonzero(self.revolute):
            best, far = q[:, j], np.max(np.abs(q[:, j] - self.home[j]))
            for turns in (-2, -1, 1, 2):
                shifted = q[:, j] + 2 * np.pi * turns
                if np.all(shifted >= lo[j] - 1e-12) and np.all(shifted <= hi[j] + 1e-12) and \
                        np.max(np.abs(shifted - self.home[j])) < far:
                    best, far = shifted, np.max(np.abs(shifted - self.home[j]))
            q[:, j] = best
        return q

    def swing(self, q) -> np.ndarray:
        """(N,) the largest turn of a revolute joint from home [rad]."""
        q = np.atleast_2d(q)
        if not self.revolute.any():
            return np.zeros(len(q))
        return np.max(np.abs(q[:, self.revolute] - self.home[self.revolute]), axis=1)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Joint ranges to draw candidates from: the limits, revolute joints within half a turn of home."""
        lo, hi = self.robot.joint_bounds(np.pi)
        lo = np.where(self.revolute, np.maximum(lo, self.home - MAX_SWING), lo)
        hi = np.where(self.revolute, np.minimum(hi, self.home + MAX_SWING), hi)
        return lo, hi

    # -- the floor ------------------------------------------------------------------------
    def _floor_exempt(self) -> set:
        """Bodies (or joint origins) not held to the floor: fixed to the base, or on the first joint
        and below the floor already at home."""
        below_home = set(self.below(self.home, exempt=False))
        if self.checker is None:
            return {name for name in below_home if name == self.robot.joint_names[0]}
        first = self.robot.chain_joint_ids[0] if self.robot.chain_joint_ids else -1
        out = set()
        for body in self.checker.geometry.geometryObjects:
            if body.parentJoint == 0 or (body.parentJoint == first and body.name in below_home):
                out.add(body.name)
        return out

    def below(self, q, exempt: bool = True) -> list:
        """Names of the bodies (joint origins without collision geometry) below the floor at q (n_joints,)."""
        lowest = self.workspace.lowest
        if self.checker is not None:
            names = self.checker.bodies_below(q, lowest)
        else:  # no geometry: the kinematic skeleton's joint origins
            model, data = self.robot.model, self.robot.model.createData()
            pin.forwardKinematics(model, data, self.robot.to_pinocchio_q(np.asarray(q, dtype=float)))
            names = [model.names[j] for j in range(1, model.njoints) if data.oMi[j].translation[2] < lowest]
        return [n for n in names if not (exempt and n in self.floor_exempt)]

    def floor_words(self) -> str:
        what = "collision bodies (coal half-space)" if self.checker is not None else "joint origins"
        exempt = ", ".join(sorted(self.floor_exempt)) or "none"
        return f"the robot's {what} above z = {self.workspace.lowest * 1e3:g} mm (not held: {exempt})"

    # -- the instrument's line of sight -----------------------------------------------------
    def hidden(self, q, points) -> np.ndarray:
        """(k,) True where a body of the robot at q (k, n_joints) stands between the instrument and the
        point (k, 3) [m] (the beam stopped short of it by the reflector's size); False throughout
        without an instrument position or collision geometry."""
        q, points = np.atleast_2d(q), np.atleast_2d(points)
        out = np.zeros(len(points), dtype=bool)
        if self.tracker is None or self.checker is None:
            return out
        for k, (row, point) in enumerate(zip(q, points)):
            distance = float(np.linalg.norm(point - self.tracker))
            if distance > REFLECTOR_CLEARANCE_M:
                end = point + (self.tracker - point) * (REFLECTOR_CLEARANCE_M / distance)
                out[k] = bool(self.checker.blocking_bodies(row, self.tracker, end, BEAM_RADIUS_M))
        return out

    def sight_words(self) -> str:
        if self.tracker is None:
            return "not checked: no tracker position given"
        where = "(" + ", ".join(f"{v * 1e3:.0f}" for v in self.tracker) + ") mm"
        if self.checker is None:
            return f"not checked: the URDF of {self.robot.name} has no collision geometry (tracker at {where})"
        return f"the tracker at {where} sees every measured pose (coal: no collision body on the beam)"

    # -- a set of targets -------------------------------------------------------------------
    def solve(self, targets, rotation, q_start, sighted: int = 0):
        """Joint values (k, n) reaching every target (k, 3) [m] at ``rotation`` (3, 3), or None; the
        first ``sighted`` targets (the measured ones) in the instrument's sight."""
        q, bad = self._attempt(targets, rotation, q_start, sighted=sighted)
        return None if bad.any() else q

    def solve_raw(self, targets, rotation, q_start, tol: float = 1e-7):
        """Joint values (k, n) reaching every target (k, 3) [m] at ``rotation`` (None: positions only)
        by IK within the joint limits and ``tol`` [m, rad], or None; nothing else checked."""
        targets = np.atleast_2d(targets)
        rotations = None if rotation is None else np.broadcast_to(rotation, (len(targets), 3, 3))
        ik = inverse_kinematics(self.robot, targets, rotations, q_start, orientation=self.mode, max_iter=150,
                                tol_position=tol, tol_rotation=tol)
        return ik.q if ik.success.all() else None

    def failures(self, targets, rotation, q_start, sighted: int = 0) -> list[str]:
        """Why each target fails, in words ('' where it does not), in target order."""
        return self._attempt(targets, rotation, q_start, reasons=True, sighted=sighted)[1]

    def _attempt(self, targets, rotation, q_start, reasons: bool = False, sighted: int = 0):
        """(q, bad): bad a (k,) mask, or with ``reasons`` a list of words per target ('' where fine);
        without reasons, the checks stop at the first that fails (q None when before IK)."""
        targets = np.atleast_2d(targets)
        k = len(targets)
        checks = {"outside the workspace": ~self.workspace.inside(targets)}
        if not reasons and checks["outside the workspace"].any():
            return None, checks["outside the workspace"]
        ik = inverse_kinematics(self.robot, targets, np.broadcast_to(rotation, (k, 3, 3)), q_start,
                                orientation=self.mode, max_iter=150, tol_position=1e-7, tol_rotation=1e-7)
        q = self.nearest_home(ik.q)
        steps = (("not reachable", lambda: ~ik.success),
                 ("a joint more than half a turn from home", lambda: self.swing(q) > MAX_SWING + 1e-9),
                 ("self-collision", lambda: np.zeros(k, bool) if self.checker is None else ~self.checker.is_free(q)),
                 ("a body below the floor", lambda: np.array([bool(self.below(row)) for row in q])),
                 ("hidden from the tracker", lambda: np.concatenate([self.hidden(q[:sighted], targets[:sighted]),
                                                                     np.zeros(k - min(sighted, k), bool)])))
        for word, check in steps:
            checks[word] = check()
            if not reasons and checks[word].any():
                return q, checks[word]
        if not reasons:
            return q, np.zeros(k, dtype=bool)
        unreachable = checks["not reachable"]
        return q, [", ".join(w for w, flags in checks.items()
                             if flags[i] and (w in ("outside the workspace", "not reachable") or not unreachable[i]))
                   for i in range(k)]


__all__ = ["MAX_SWING", "Reach", "Workspace"]
