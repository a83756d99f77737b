"""Poses a robot can take and a tracker can see: the one filter of random and planned poses.

A configuration is kept when, in this order (a rejected one is counted under the first
test it fails):

1. ``limits``: every chain joint is within its URDF limits, a ``<mimic>`` joint at the
   value its rule gives (drawn poses are made to follow it; a given pose that breaks it is
   an input error, :func:`check_given_poses`);
2. ``box``: the nominal TCP lies in the task box (base frame), when one is given;
2b. ``mounting plane``: the nominal TCP and every joint origin lie on or above the plane the robot
   stands on (``z = floor_z`` of the base frame), when one is given (a robot bolted to a floor or a
   table reaches no point below it);
3. ``self-collision``: no two bodies of the URDF's collision geometry touch
   (:mod:`tcr_accuracy.analysis.collision`, with its excluded pairs), when it has any;
4. ``line of sight``: the segment from the tracker to the TCP, stopped
   :data:`REFLECTOR_CLEARANCE_M` short of it, meets no collision body, when a tracker
   position is given (and the URDF has collision geometry).

A robot without collision geometry is *unchecked* for 3 and 4; :attr:`PoseFilter.checks`
says so, for the commands to print. Nothing here prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..exceptions import InputError
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel
from .collision import CollisionChecker, collision_checker

#: How far short of the TCP the tracker's line of sight is tested [m]: the reflector (a 1.5 in
#: sphere-mounted retroreflector has a 19 mm radius) and its nest sit on the TCP, in contact
#: with the last link's body, so the last few centimetres of the beam are the reflector's own.
REFLECTOR_CLEARANCE_M = 0.025

#: Radius of the capsule standing for the tracker's beam [m] (a laser tracker's beam is a few mm wide).
BEAM_RADIUS_M = 1e-3

#: Largest difference [rad or m] between a given ``<mimic>`` joint's value and its rule's that
#: is taken as rounding (0.0006 deg, 0.01 mm): a CSV written with a few decimals still follows it.
MIMIC_TOLERANCE = 1e-5

REASONS = ("limits", "box", "mounting plane", "self-collision", "line of sight")


@dataclass
class Screened:
    """Configurations that passed the filter, and what happened to the others.

    q : (M, n_joints) [rad, m] the kept configurations, in the order drawn or given
    tried : how many were drawn or given
    rejected : dict of reason (:data:`REASONS`) to count, each rejected pose under the first test it failed
    """

    q: np.ndarray
    tried: int
    rejected: dict = field(default_factory=lambda: dict.fromkeys(REASONS, 0))

    def rejections(self) -> str:
        """'1650 outside the box, 400 in self-collision' (the reasons that rejected any), or 'none rejected'."""
        words = {"limits": "outside the joint limits", "box": "with the TCP outside the box",
                 "mounting plane": "below the mounting plane",
                 "self-collision": "in self-collision", "line of sight": "hidden from the tracker"}
        parts = [f"{n} {words[reason]}" for reason, n in self.rejected.items() if n]
        return ", ".join(parts) or "none rejected"


@dataclass
class PoseFilter:
    """The tests a configuration must pass (see the module docstring).

    Build it with :meth:`for_robot`, which reads the collision geometry once.

    box : (3, 2) [[xmin, xmax], [ymin, ymax], [zmin, zmax]] [m] in the base frame, or None
    tracker : (3,) the tracker's position [m] in the base frame, or None
    checker : the robot's collision checker, or None when its URDF has no collision geometry
    floor_z : the mounting plane's height [m] in the base frame (the TCP and every joint origin on or
        above it), or None: no plane
    """

    robot: RobotModel
    checker: CollisionChecker | None = None
    box: np.ndarray | None = None
    tracker: np.ndarray | None = None
    floor_z: float | None = None

    @classmethod
    def for_robot(cls, robot: RobotModel, *, box=None, tracker=None, collision: bool = True,
                  floor_z: float | None = None) -> "PoseFilter":
        """The filter of ``robot``: joint limits and ``<mimic>`` rules always; the task box, the
        mounting plane (``floor_z`` [m], base frame) and the tracker's line of sight when given;
        self-collision when ``collision`` and the URDF has collision geometry.

        Raises
        ------
        InputError
            A box whose minimum is not below its maximum on some axis, a tracker position that
            is not 3 finite numbers, or collision meshes that cannot be read.
        """
        if box is not None:
            box = np.asarray(box, dtype=float)
            if box.shape != (3, 2) or not np.isfinite(box).all() or np.any(box[:, 0] >= box[:, 1]):
                raise InputError("task box: give xmin xmax ymin ymax zmin zmax with min < max")
        if tracker is not None:
            tracker = np.asarray(tracker, dtype=float)
            if tracker.shape != (3,) or not np.isfinite(tracker).all():
                raise InputError("tracker position: give x y z, three finite numbers")
        if floor_z is not None and not np.isfinite(floor_z):
            raise InputError(f"mounting plane: z = {floor_z} is not a finite number")
        return cls(robot, collision_checker(robot) if collision else None, box, tracker,
                   None if floor_z is None else float(floor_z))

    @property
    def rejects_any(self) -> bool:
        """Whether a uniform draw within the limits may be rejected (else it is kept as drawn)."""
        return (self.robot.has_chain_mimic or self.box is not None or self.checker is not None
                or self.floor_z is not None)

    @property
    def tests(self) -> str:
        """What a kept pose passed: 'within the joint limits, TCP in the box ..., free of self-collision ...'."""
        done = ["within the joint limits" + (" (<mimic> rules kept)" if self.robot.has_chain_mimic else "")]
        if self.box is not None:
            done.append("TCP in the box " + " ".join(f"{axis} [{lo:g}, {hi:g}]" for axis, (lo, hi)
                                                      in zip("xyz", self.box * 1e3)) + " mm")
        if self.floor_z is not None:
            done.append(f"TCP and joints above the mounting plane (z >= {self.floor_z * 1e3:g} mm)")
        if self.checker is not None:
            done.append(f"free of self-collision (coal, {self.checker.n_pairs} body pairs of the URDF's collision "
                        "geometry)")
            if self.tracker is not None:
                done.append("in sight of the tracker at (" + ", ".join(f"{v:g}" for v in self.tracker * 1e3)
                            + ") mm")
        return ", ".join(done)

    @property
    def unchecked(self) -> str:
        """What could not be checked and why ('' when nothing was left out)."""
        if self.checker is not None:
            return ""
        what = "self-collision" + (" and line of sight" if self.tracker is not None else "")
        return f"{what} not checked: the URDF of {self.robot.name} has no collision geometry"

    @property
    def checks(self) -> str:
        """One line: what a kept pose was checked for, and what was not checked and why."""
        return self.tests + (f"; {self.unchecked}" if self.unchecked else "")

    def screen(self, q: np.ndarray) -> tuple[np.ndarray, dict]:
        """(N,) True where configuration q (N, n_joints) [rad, m] passes every test, and the
        rejections by reason (each counted under the first test it failed)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        rejected = dict.fromkeys(REASONS, 0)
        keep = self.robot.within_limits(q) & _follows_mimic(self.robot, q)
        rejected["limits"] = int(np.sum(~keep))
        if self.box is not None and keep.any():
            position = tcp_poses(self.robot, q[keep]).position
            inside = np.all((position >= self.box[:, 0]) & (position <= self.box[:, 1]), axis=1)
            rejected["box"] = int(np.sum(~inside))
            keep[np.flatnonzero(keep)[~inside]] = False
        if self.floor_z is not None and keep.any():
            above = self.above_floor(q[keep])
            rejected["mounting plane"] = int(np.sum(~above))
            keep[np.flatnonzero(keep)[~above]] = False
        if self.checker is not None and keep.any():
            index = np.flatnonzero(keep)
            free = self.checker.is_free(q[index])
            rejected["self-collision"] = int(np.sum(~free))
            keep[index[~free]] = False
            if self.tracker is not None and keep.any():
                index = np.flatnonzero(keep)
                seen = self.in_sight(q[index])
                rejected["line of sight"] = int(np.sum(~seen))
                keep[index[~seen]] = False
        return keep, rejected

    def above_floor(self, q: np.ndarray) -> np.ndarray:
        """(N,) True where the TCP and every joint origin of the chain at q (N, n_joints) lie on or
        above the mounting plane (1e-9 m of rounding allowed; True throughout without a plane)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if self.floor_z is None:
            return np.ones(len(q), dtype=bool)
        import pinocchio as pin

        model = self.robot.model
        data = model.createData()
        lowest = np.empty(len(q))
        for k, row in enumerate(q):
            pin.forwardKinematics(model, data, self.robot.to_pinocchio_q(row))
            lowest[k] = min(data.oMi[j].translation[2] for j in range(1, model.njoints))
        lowest = np.minimum(lowest, tcp_poses(self.robot, q).position[:, 2])
        return lowest >= self.floor_z - 1e-9

    def in_sight(self, q: np.ndarray) -> np.ndarray:
        """(N,) True where the tracker sees the TCP at q (N, n_joints): the segment from the
        tracker to :data:`REFLECTOR_CLEARANCE_M` short of the TCP meets no collision body
        (True throughout without a tracker or collision geometry)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if self.tracker is None or self.checker is None:
            return np.ones(len(q), dtype=bool)
        position = tcp_poses(self.robot, q).position
        out = np.empty(len(q), dtype=bool)
        for k, (row, point) in enumerate(zip(q, position)):
            distance = float(np.linalg.norm(point - self.tracker))
            if distance <= REFLECTOR_CLEARANCE_M:
                out[k] = True  # the tracker at the reflector: nothing between them
                continue
            end = point + (self.tracker - point) * (REFLECTOR_CLEARANCE_M / distance)
            out[k] = not self.checker.blocking_bodies(row, self.tracker, end, BEAM_RADIUS_M)
        return out


def _follows_mimic(robot: RobotModel, q: np.ndarray) -> np.ndarray:
    """(N,) whether every chain ``<mimic>`` joint of q (N, n_joints) is at its rule's value
    (within :data:`MIMIC_TOLERANCE`)."""
    if not robot.has_chain_mimic:
        return np.ones(len(q), dtype=bool)
    return np.all(np.abs(robot.follow_mimic(q) - q) <= MIMIC_TOLERANCE, axis=1)


def draw_poses(pose_filter: PoseFilter, n: int, rng: np.random.Generator, *, max_tried: int | None = None
               ) -> Screened:
    """Up to n configurations drawn uniformly within the joint limits (+-pi where a revolute
    joint has none), ``<mimic>`` joints set by their rule, kept where they pass the filter.

    Draws in batches of max(4 n, 2000) until n are kept or ``max_tried`` (default 200 batches)
    were drawn; fewer than n kept is for the caller to judge (:class:`Screened` has the counts).
    A filter that can reject nothing takes n draws as they come.

    Raises
    ------
    InputError
        A prismatic joint without limits (it cannot be drawn).
    """
    robot = pose_filter.robot
    lo, hi = robot.joint_bounds()
    for j, kind in enumerate(robot.joint_kinds):
        if kind != "revolute" and (np.isnan(robot.lower_limits[j]) or np.isnan(robot.upper_limits[j])):
            raise InputError(f"joint {robot.joint_names[j]} is prismatic without limits: its values cannot be "
                             "drawn; give the poses")
    if not pose_filter.rejects_any:
        return Screened(rng.uniform(lo, hi, size=(n, robot.n_joints)), n)
    batch = max(4 * n, 2000)
    max_tried = 200 * batch if max_tried is None else max_tried
    kept, screened = [], Screened(np.empty((0, robot.n_joints)), 0)
    while sum(len(k) for k in kept) < n and screened.tried < max_tried:
        q = robot.follow_mimic(rng.uniform(lo, hi, size=(min(batch, max_tried - screened.tried), robot.n_joints)))
        keep = np.zeros(len(q), dtype=bool)
        # screen a slice at a time, so that the costly tests stop once n are kept
        for start in range(0, len(q), 500):
            part = slice(start, start + 500)
            keep[part], rejected = pose_filter.screen(q[part])
            screened.tried += len(q[part])
            for reason, count in rejected.items():
                screened.rejected[reason] += count
            if sum(len(k) for k in kept) + int(keep.sum()) >= n:
                break
        kept.append(q[keep])
    screened.q = np.concatenate(kept)[:n]
    return screened


def check_given_poses(robot: RobotModel, q: np.ndarray, source: str, rows=None) -> None:
    """Refuse given configurations q (N, n_joints) [rad, m] the robot cannot take: a joint
    outside its limits or a ``<mimic>`` joint off its rule, naming ``source`` and the row
    (``rows``: the file's row numbers, default 1..N).

    Raises
    ------
    InputError
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    with np.errstate(invalid="ignore"):  # NaN limits: an unbounded joint
        outside = (q < robot.lower_limits - 1e-12) | (q > robot.upper_limits + 1e-12)
    off_rule = np.abs(robot.follow_mimic(q) - q) > MIMIC_TOLERANCE
    scale, unit = robot.display_scale, robot.display_units
    for bad, what in ((outside, "outside"), (off_rule, "mimic")):
        if not bad.any():
            continue
        r, j = np.argwhere(bad)[0]
        row = rows[r] if rows is not None else r + 1
        name, value = robot.joint_names[j], q[r, j] * scale[j]
        count = f"({int(bad.any(axis=1).sum())} such row(s))"
        if what == "outside":
            raise InputError(f"{source}: row {row}: joint {name} = {value:.6g} {unit[j]} is outside its limits "
                             f"[{robot.lower_limits[j] * scale[j]:.6g}, {robot.upper_limits[j] * scale[j]:.6g}] "
                             f"{unit[j]}; a candidate must be a pose the robot can take {count}")
        rule = robot.mimic[name]
        raise InputError(f"{source}: row {row}: joint {name} = {value:.6g} {unit[j]} breaks its <mimic> rule "
                         f"{rule.multiplier:g} x {rule.joint} + {rule.offset:g} = "
                         f"{robot.follow_mimic(q[r:r + 1])[0, j] * scale[j]:.6g} {unit[j]}; a candidate must be a "
                         f"pose the robot can take {count}")


__all__ = ["BEAM_RADIUS_M", "MIMIC_TOLERANCE", "PoseFilter", "REFLECTOR_CLEARANCE_M", "REASONS", "Screened",
           "check_given_poses", "draw_poses"]
