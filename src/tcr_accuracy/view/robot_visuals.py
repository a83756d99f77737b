"""Robot bodies in a meshcat tree: the URDF's visuals at given joint values, or a skeleton.

Robots are loaded by Pinocchio's ``MeshcatVisualizer`` from Pinocchio's visual
``GeometryModel`` of the URDF (:func:`visual_geometry`), attached to the joints of the
robot's kinematic model, so an as-built robot (same joints, other placements) carries
the same bodies. A URDF without ``<visual>`` elements is drawn as its kinematic skeleton.
A painted robot (a colour or transparency of its own, e.g. an as-built "ghost") gets its
meshes as plain meshcat geometry so that the colour shows. What else a view holds, and
its legend, is :class:`tcr_accuracy.view.viewer.Scene`'s.

Units: positions in metres, joint values in SI.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .meshcat_page import meshcat_color
from ..model.robot import RobotModel


def visual_geometry(robot: RobotModel):
    """Pinocchio's visual ``GeometryModel`` of the robot, attached to ``robot.model``'s joints.

    The robot builds it from its own URDF and whole-tree model (``RobotModel.visual_model``):
    the bodies of joints outside the TCP chain (another arm, a head) are drawn at their
    neutral pose, and the geometry fits ``robot.model`` and any as-built copy of it.

    Raises
    ------
    InputError
        The URDF's visuals cannot be read (missing mesh file, ...).
    """
    return robot.visual_model()


def draw_robot(vis, robot: RobotModel, q: np.ndarray, node: str, color=None, opacity: float = 1.0, *,
               include_base: bool = True) -> tuple[np.ndarray, bool]:
    """Draw the robot at joint values q under ``vis[node]``.

    Parameters
    ----------
    vis : meshcat.Visualizer
    robot : RobotModel
        Nominal or as-built: the bodies hang on the robot's own joint placements.
    q : ndarray of shape (n_joints,)
        Joint values [rad, m], already checked against the robot.
    node : str
        A node name meshcat can use.
    color : RGB triple in 0..1, optional
        Paint every body in this colour (default: the URDF's materials).
    opacity : float
        In (0, 1]; below 1 a transparent "ghost".
    include_base : bool
        Draw the bodies fixed to the base.

    Returns
    -------
    points : ndarray of shape (n_pinocchio_joints + 1, 3)
        The joint origins (Pinocchio's, the universe first) and the TCP [m], to frame the view.
    skeleton : bool
        Whether the URDF had no visuals and the skeleton was drawn instead.
    """
    from pinocchio.visualize import MeshcatVisualizer

    geometry = visual_geometry(robot)
    if geometry.ngeoms == 0:  # a URDF without <visual> elements: draw the kinematic skeleton
        return _draw_skeleton(vis, robot, q, node, color, opacity), True
    if not include_base:
        for obj in [o for o in geometry.geometryObjects if o.parentJoint == 0]:
            geometry.removeGeometryObject(obj.name)
    if color is not None or opacity < 1.0:
        for obj in geometry.geometryObjects:
            rgba = np.array(obj.meshColor, dtype=float)
            if color is not None:
                rgba[:3] = np.asarray(color, dtype=float)[:3]
            rgba[3] = opacity
            obj.meshColor = rgba
            obj.overrideMaterial = True  # meshes keep their own material otherwise
    viz_class = _painted_visualizer_class() if color is not None or opacity < 1.0 else MeshcatVisualizer
    viz = viz_class(robot.model, None, geometry)
    viz.initViewer(viewer=vis)
    viz.loadViewerModel(rootNodeName=node)
    viz.display(robot.to_pinocchio_q(q))
    origins, tool = _joint_origins(robot, q)
    return np.vstack([origins, tool[None]]), False


def _joint_origins(robot: RobotModel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n_pinocchio_joints, 3) joint origins, the universe first, and the (3,) TCP [m] at q."""
    import pinocchio as pin

    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, robot.to_pinocchio_q(q))
    pin.updateFramePlacements(model, data)
    origins = np.array([data.oMi[j].translation for j in range(model.njoints)])
    return origins, data.oMf[robot.tool_frame_id].translation


def _draw_skeleton(vis, robot: RobotModel, q: np.ndarray, node: str, color, opacity: float) -> np.ndarray:
    """Joint origins as spheres joined by links (parent to child) and the TCP, for a URDF
    that has no visuals (point-mass models such as calibration data sets ship).
    Returns the (n_pinocchio_joints + 1, 3) points drawn [m]."""
    import meshcat.geometry as mg
    from meshcat.transformations import translation_matrix

    model = robot.model
    origins, tool = _joint_origins(robot, q)
    segments = [(origins[model.parents[j]], origins[j]) for j in range(1, model.njoints)]
    segments.append((origins[model.frames[robot.tool_frame_id].parentJoint], tool))
    rgb = tuple(color) if color is not None else (0.35, 0.38, 0.45)
    root = vis[node]
    pairs = np.array([p for segment in segments for p in segment], dtype=np.float32)
    root["links"].set_object(mg.LineSegments(mg.PointsGeometry(pairs.T), mg.LineBasicMaterial(
        color=meshcat_color(rgb), linewidth=4, transparent=opacity < 1.0, opacity=opacity)))
    reach = float(np.max(np.linalg.norm(origins - origins[0], axis=1), initial=0.0)) or 1.0
    for j, origin in enumerate(list(origins[1:]) + [tool]):
        sphere = root[f"joint_{j}"]
        sphere.set_object(mg.Sphere(0.02 * reach), mg.MeshLambertMaterial(
            color=meshcat_color(rgb), transparent=opacity < 1.0, opacity=opacity))
        sphere.set_transform(translation_matrix(origin))
    return np.vstack([origins, tool[None]])


def _painted_visualizer_class():
    """Pinocchio's MeshcatVisualizer, loading meshes as plain geometry with our material.

    Pinocchio sends meshes as meshcat "mesh file objects", and meshcat's browser side
    draws those with the file's own materials, ignoring the one sent along. A ghost needs
    its colour and transparency, so the meshes of a painted robot go as meshcat mesh
    geometries, which take Pinocchio's material (colour from ``meshColor``).
    """
    import meshcat.geometry as mg
    from pinocchio.visualize import MeshcatVisualizer

    class PaintedMeshcatVisualizer(MeshcatVisualizer):
        def loadMeshFromFile(self, geometry_object):  # noqa: N802 - Pinocchio's name
            suffix = Path(geometry_object.meshPath).suffix.lower()
            loaders = {".dae": mg.DaeMeshGeometry, ".stl": mg.StlMeshGeometry, ".obj": mg.ObjMeshGeometry}
            if suffix in loaders:
                return loaders[suffix].from_file(geometry_object.meshPath)
            return super().loadMeshFromFile(geometry_object)

    return PaintedMeshcatVisualizer
