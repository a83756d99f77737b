"""Self-collision of a robot from its URDF's collision geometry (Pinocchio + coal).

The collision bodies are read with Pinocchio's ``buildGeomFromUrdfString`` on the whole
tree (joints outside the TCP chain stay at their neutral value) and checked with
``computeCollisions``. Pairs that are never tested:

- bodies on the same joint or on joints next to each other in the tree (their meshes
  touch at the axis by design);
- pairs the robot's SRDF disables, when the URDF sits in ``.../urdf/`` with an SRDF of the
  same name in ``.../srdf/`` (example-robot-data's layout);
- pairs already in contact at the robot's working pose (a design contact, as a MoveIt setup
  ignores them).

A robot whose URDF has no ``<collision>`` element has no checker (:func:`collision_checker`
returns None), and the callers say so. Nothing here prints.

The same bodies tell whether a straight line is free: :meth:`CollisionChecker.blocking_bodies`
tests a thin coal ``Capsule`` laid along a segment (a tracker's beam) against every body of
the posed robot, with no pair left out.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin

from ..model.robot import RobotModel


@dataclass
class CollisionChecker:
    """Self-collision tests of one robot.

    Attributes
    ----------
    geometry : pin.GeometryModel
        The collision bodies on the robot's whole tree, with the pairs that are tested.
    ignored : dict of str to int
        How many pairs were left out, by reason (``adjacent``, ``srdf``, ``working pose``).
    """

    robot: RobotModel
    geometry: pin.GeometryModel
    ignored: dict

    @property
    def n_pairs(self) -> int:
        return len(self.geometry.collisionPairs)

    def colliding_pairs(self, q) -> list[tuple[str, str]]:
        """Names of the body pairs in contact at chain joint values q (n_joints,) [rad, m]."""
        full_q = self.robot.full_configurations(np.atleast_2d(np.asarray(q, dtype=float)))[0]
        model = self.robot.full_model
        data, geometry_data = model.createData(), self.geometry.createData()
        pin.computeCollisions(model, data, self.geometry, geometry_data, full_q, False)
        out = []
        for pair, result in zip(self.geometry.collisionPairs, geometry_data.collisionResults):
            if result.isCollision():
                out.append((self.geometry.geometryObjects[pair.first].name,
                            self.geometry.geometryObjects[pair.second].name))
        return out

    def blocking_bodies(self, q, start, end, radius: float = 1e-3) -> list[str]:
        """Names of the bodies that a segment from ``start`` to ``end`` (3,) [m], in the base
        frame, passes through or within ``radius`` [m] of, at chain joint values q (n_joints,)."""
        start, end = np.asarray(start, dtype=float), np.asarray(end, dtype=float)
        length = float(np.linalg.norm(end - start))
        if length == 0.0:
            return []
        full_q = self.robot.full_configurations(np.atleast_2d(np.asarray(q, dtype=float)))[0]
        model = self.robot.full_model
        data, geometry_data = model.createData(), self.geometry.createData()
        pin.updateGeometryPlacements(model, data, self.geometry, geometry_data, full_q)
        # coal's capsule lies along its own z axis, centred: turn z onto the segment
        axis = (end - start) / length
        rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis).matrix()
        beam = coal.Capsule(radius, length)
        beam_placement = coal.Transform3s(rotation, 0.5 * (start + end))
        out = []
        for body, placement in zip(self.geometry.geometryObjects, geometry_data.oMg):
            result = coal.CollisionResult()
            if coal.collide(beam, beam_placement, body.geometry,
                            coal.Transform3s(placement.rotation, placement.translation),
                            coal.CollisionRequest(), result):
                out.append(body.name)
        return out

    def bodies_below(self, q, height: float) -> list[str]:
        """Names of the bodies that reach below the plane z = ``height`` [m] of the base frame (a
        floor or mounting plane: coal's ``Halfspace``) at chain joint values q (n_joints,)."""
        full_q = self.robot.full_configurations(np.atleast_2d(np.asarray(q, dtype=float)))[0]
        model = self.robot.full_model
        data, geometry_data = model.createData(), self.geometry.createData()
        pin.updateGeometryPlacements(model, data, self.geometry, geometry_data, full_q)
        floor, at_origin = coal.Halfspace(np.array([0.0, 0.0, 1.0]), float(height)), coal.Transform3s()
        out = []
        for body, placement in zip(self.geometry.geometryObjects, geometry_data.oMg):
            if coal.collide(floor, at_origin, body.geometry, coal.Transform3s(placement.rotation, placement.translation),
                            coal.CollisionRequest(), coal.CollisionResult()):
                out.append(body.name)
        return out

    def is_free(self, q) -> np.ndarray:
        """(N,) True where the configuration q (N, n_joints) has no self-collision."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return np.array([not self.colliding_pairs(row) for row in q], dtype=bool)


def collision_checker(robot: RobotModel) -> CollisionChecker | None:
    """The robot's self-collision checker, or None when its URDF has no collision geometry.

    Raises
    ------
    InputError
        The collision meshes cannot be read (a missing one is left out: the robot is checked
        without that body, as :func:`tcr_accuracy.model.robot.load_robot` warned).
    """
    if "<collision" not in robot.urdf_text:
        return None
    model = robot.full_model
    # a copy: the pairs below are this checker's, the robot's own model stays as the URDF says
    geometry = robot.geometry_model("collision").copy()  # bodies whose mesh is missing left out (load_robot warned)
    if geometry.ngeoms < 2:
        return None
    geometry.addAllCollisionPairs()
    ignored = {"adjacent": 0, "srdf": 0, "working pose": 0}
    for pair in list(geometry.collisionPairs):
        a = geometry.geometryObjects[pair.first].parentJoint
        b = geometry.geometryObjects[pair.second].parentJoint
        if a == b or model.parents[a] == b or model.parents[b] == a:
            geometry.removeCollisionPair(pair)
            ignored["adjacent"] += 1
    srdf = _srdf_path(robot)
    if srdf is not None:
        before = len(geometry.collisionPairs)
        pin.removeCollisionPairs(model, geometry, str(srdf))
        ignored["srdf"] = before - len(geometry.collisionPairs)
    checker = CollisionChecker(robot, geometry, ignored)
    touching = set(checker.colliding_pairs(robot.working_pose))
    for pair in list(geometry.collisionPairs):
        names = (geometry.geometryObjects[pair.first].name, geometry.geometryObjects[pair.second].name)
        if names in touching:
            geometry.removeCollisionPair(pair)
            ignored["working pose"] += 1
    return checker


def _srdf_path(robot: RobotModel) -> Path | None:
    """``.../srdf/<name>.srdf`` beside the URDF's ``.../urdf/`` folder, if it exists."""
    if robot.urdf_path is None:
        return None
    candidate = robot.urdf_path.parent.parent / "srdf" / f"{robot.urdf_path.stem}.srdf"
    return candidate if candidate.is_file() else None


__all__ = ["CollisionChecker", "collision_checker"]
