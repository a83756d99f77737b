"""Robot bodies in a meshcat tree: the URDF's visuals at given joint values, or a skeleton.

Robots are loaded by Pinocchio's ``MeshcatVisualizer`` from Pinocchio's visual
``GeometryModel`` of the URDF (:func:`visual_geometry`), attached to the joints of the
robot's kinematic model, so an as-built robot (same joints, other placements) carries
the same bodies. A URDF without ``<visual>`` elements is drawn as its kinematic skeleton, and
so is, over the bodies that were found, a robot some of whose meshes are missing (a ROS
package not given: :mod:`tcr_accuracy.model.ros_packages`).
A painted robot (a colour or transparency of its own, e.g. an as-built "ghost") gets its
meshes as plain meshcat geometry so that the colour shows. What else a view holds, and
its legend, is :class:`tcr_accuracy.view.viewer.Scene`'s.

Nothing is read into a view that was not checked: every mesh Pinocchio resolved, and every
file it references, must lie in the URDF's folder or a package folder
(:mod:`tcr_accuracy.model.mesh_resources`), and a COLLADA file's images are embedded from
that checked list alone, never by the loader's own reading.

Units: positions in metres, joint values in SI.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .meshcat_page import meshcat_color
from ..exceptions import InputError
from ..model.mesh_resources import check_mesh_references, inside
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
               include_base: bool = True) -> tuple[np.ndarray, str | None]:
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
    points : ndarray of shape (n, 3)
        The joint origins (Pinocchio's, the universe first), the TCP and the corners of each
        body's bounding box [m], to frame the view.
    skeleton : str or None
        Why the kinematic skeleton was drawn (the URDF has no visuals, or meshes are
        missing), for the legend; None when it was not.
    """
    geometry = visual_geometry(robot)
    missing = robot.missing_meshes(("visual",))
    if geometry.ngeoms == 0:  # no <visual> elements, or none whose mesh was found: the kinematic skeleton
        why = "the URDF has no visuals" if not missing else _missing_links(missing)
        return _draw_skeleton(vis, robot, q, node, color, opacity), why
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
    checked = checked_mesh_files(robot, geometry)
    viz = _confined_visualizer_class(checked, painted=color is not None or opacity < 1.0)(robot.model, None, geometry)
    viz.initViewer(viewer=vis)
    viz.loadViewerModel(rootNodeName=node)
    viz.display(robot.to_pinocchio_q(q))
    if missing:  # the bodies found, and the skeleton where the others would be
        return _draw_skeleton(vis, robot, q, node, color, opacity), _missing_links(missing)
    origins, tool = _joint_origins(robot, q)
    return np.vstack([origins, tool[None], _body_corners(robot, geometry, q)]), None


def _body_corners(robot: RobotModel, geometry, q: np.ndarray) -> np.ndarray:
    """(8 n_bodies, 3) corners of each drawn body's bounding box (coal's local AABB of its shape,
    placed by Pinocchio) [m]: what the view must hold to show the whole robot."""
    import pinocchio as pin

    data, geometry_data = robot.model.createData(), geometry.createData()
    pin.forwardKinematics(robot.model, data, robot.to_pinocchio_q(q))
    pin.updateGeometryPlacements(robot.model, data, geometry, geometry_data)
    corners = []
    for k, obj in enumerate(geometry.geometryObjects):
        shape = obj.geometry
        shape.computeLocalAABB()
        low, high = np.asarray(shape.aabb_local.min_), np.asarray(shape.aabb_local.max_)
        box = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])])
        placement = geometry_data.oMg[k]
        corners.append(box @ placement.rotation.T + placement.translation)
    return np.vstack(corners) if corners else np.zeros((0, 3))


def _missing_links(missing) -> str:
    """For the legend: the links whose meshes are missing (``MeshPlace`` records)."""
    links = list(dict.fromkeys(place.link for place in missing))
    shown = ", ".join(links[:5]) + (f" and {len(links) - 5} more" if len(links) > 5 else "")
    return f"meshes missing for link{'s' if len(links) > 1 else ''} {shown}"


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
    that has no visuals (point-mass models such as calibration data sets ship) or whose meshes
    are missing.
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


def checked_mesh_files(robot: RobotModel, geometry) -> dict[str, list[tuple[str, Path]]]:
    """The files each mesh of ``geometry`` references, by mesh path, all checked to lie in the
    robot's mesh folders; only these meshes and files are read into a view.

    Raises
    ------
    InputError
        A mesh as Pinocchio resolved it, or a file it references, lies outside the URDF's
        folder and the package folders (one line naming the URDF, the mesh and the file).
    """
    roots = [Path(r).resolve() for r in robot.mesh_roots()]
    checked = {}
    for obj in geometry.geometryObjects:
        if not obj.meshPath or obj.meshPath in checked or _is_primitive(obj):
            continue
        mesh = Path(obj.meshPath)
        if not inside(mesh, roots):
            raise InputError(f"{robot.urdf_source}: mesh {obj.meshPath!r} lies outside the URDF's folder "
                             "and package folders; refused")
        checked[obj.meshPath] = check_mesh_references(mesh, roots, robot.urdf_source, obj.meshPath)
    return checked


def _is_primitive(obj) -> bool:
    """Whether a geometry object is a box, cylinder, sphere, ... (its ``meshPath`` a word like 'BOX')."""
    try:
        import coal
    except ImportError:  # Pinocchio without coal has no primitives
        return False
    return isinstance(obj.geometry, coal.ShapeBase)


def _confined_visualizer_class(checked: dict, painted: bool):
    """Pinocchio's MeshcatVisualizer, loading only the meshes in ``checked`` and embedding only
    the checked files they reference.

    A painted robot (``painted``, e.g. an as-built ghost) gets its meshes as plain meshcat
    geometry: Pinocchio sends meshes as meshcat "mesh file objects", and meshcat's browser
    side draws those with the file's own materials, ignoring the one sent along; a ghost needs
    its colour and transparency, which plain mesh geometries take from Pinocchio's material.
    A COLLADA file otherwise goes with its images as data URLs, read from the checked list, and each
    of its meshes of several materials split in one mesh per material
    (:func:`one_material_per_mesh`).
    """
    import base64

    import meshcat.geometry as mg

    from ..input_files import SIZE_LIMITS, read_input_bytes
    from pinocchio.visualize import MeshcatVisualizer
    from pinocchio.visualize.meshcat_visualizer import DaeMeshGeometry

    class CheckedDae(DaeMeshGeometry):
        """Pinocchio's COLLADA scene element, its images taken from a checked list."""

        def __init__(self, path: Path, references: list[tuple[str, Path]]):  # noqa: D107
            mg.ReferenceSceneElement.__init__(self)  # Pinocchio's own __init__ reads the images itself
            self.path, self.material, self.intrinsic_transform = None, None, mg.tf.identity_matrix()
            self.dae_raw = one_material_per_mesh(
                read_input_bytes(path, "mesh", limit=SIZE_LIMITS["mesh"]).decode("utf-8", "replace"))
            self.img_resources = {
                str(Path(name)): "data:image/png;base64," + base64.b64encode(
                    read_input_bytes(file, "mesh image", limit=SIZE_LIMITS["mesh"])).decode("ascii")
                for name, file in references if file.is_file()}

    class ConfinedMeshcatVisualizer(MeshcatVisualizer):
        def loadMeshFromFile(self, geometry_object):  # noqa: N802 - Pinocchio's name
            if geometry_object.meshPath not in checked:
                return None  # never read: Pinocchio warns that it cannot draw it
            path = Path(geometry_object.meshPath)
            suffix = path.suffix.lower()
            if suffix == ".dae":
                if painted:
                    return mg.DaeMeshGeometry.from_file(path)
                return CheckedDae(path, checked[geometry_object.meshPath])
            if suffix == ".obj":
                return mg.ObjMeshGeometry.from_file(path)
            if suffix == ".stl":
                return mg.StlMeshGeometry.from_file(path)
            return None

    return ConfinedMeshcatVisualizer


#: The COLLADA 1.4 namespace, and the elements of a ``<mesh>`` that draw with one material each.
_COLLADA = "http://www.collada.org/2005/11/COLLADASchema"
_PRIMITIVES = ("triangles", "polylist", "polygons", "trifans", "tristrips", "lines", "linestrips")


def one_material_per_mesh(text: str) -> str:
    """A COLLADA document in which every ``<geometry>`` holds one primitive element (one material):
    a geometry of several (the UR5's housings: ``<triangles>`` of the grey metal and of the dark
    ring, in one mesh) becomes one geometry per element, each with its own copy of the sources, and
    every ``<instance_geometry>`` of it one instance per part, with the same material bindings.

    Why: meshcat's browser side (``merge_geometries`` in its ``index.js``) merges a COLLADA file's
    meshes into one geometry with one group per *mesh*, and hands it the meshes' materials as a
    list; a mesh of several materials puts a list inside that list, which three.js cannot draw, and
    the whole mesh vanishes (the UR5's housings did, leaving its blue caps and wrist parts floating
    in the air). One material per mesh is drawn whole. Placements, vertices and materials are
    unchanged. A document that does not parse, or has none to split, is returned as it is (the
    loader reports what it cannot read); so is a geometry a skin controller uses.
    """
    import copy
    from xml.etree import ElementTree

    ns = {"c": _COLLADA}
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError:
        return text
    if root.tag != f"{{{_COLLADA}}}COLLADA":
        return text
    skinned = {c.get("source", "").lstrip("#") for c in root.iterfind(".//c:library_controllers//c:skin", ns)}
    parts: dict[str, list[str]] = {}
    for library in root.iterfind("c:library_geometries", ns):
        for geometry in list(library.iterfind("c:geometry", ns)):
            mesh = geometry.find("c:mesh", ns)
            gid = geometry.get("id", "")
            if mesh is None or not gid or gid in skinned:
                continue
            primitives = [e for e in mesh if e.tag.split("}")[-1] in _PRIMITIVES]
            if len(primitives) < 2:
                continue
            position = list(library).index(geometry)
            library.remove(geometry)
            parts[gid] = []
            for k, primitive in enumerate(primitives):
                part = copy.deepcopy(geometry)
                part.set("id", f"{gid}-part{k}")
                if part.get("name"):
                    part.set("name", f"{part.get('name')}-part{k}")
                part_mesh = part.find("c:mesh", ns)
                for other in [e for e in part_mesh if e.tag.split("}")[-1] in _PRIMITIVES]:
                    part_mesh.remove(other)
                part_mesh.append(copy.deepcopy(primitive))
                _rename_ids(part, f"-part{k}")
                library.insert(position + k, part)
                parts[gid].append(part.get("id"))
    if not parts:
        return text
    for parent in list(root.iter()):
        for k, child in reversed(list(enumerate(parent))):
            url = child.get("url", "").lstrip("#") if child.tag == f"{{{_COLLADA}}}instance_geometry" else ""
            if url in parts:
                parent.remove(child)
                for j, part in enumerate(parts[url]):
                    instance = copy.deepcopy(child)
                    instance.set("url", f"#{part}")
                    parent.insert(k + j, instance)
    ElementTree.register_namespace("", _COLLADA)
    return ElementTree.tostring(root, encoding="unicode")


def _rename_ids(element, suffix: str) -> None:
    """Give every ``id`` inside ``element`` (but its own) ``suffix``, and the ``#id`` references to
    them inside it (``source``, ``url`` and ``<accessor source>``), so copies of one geometry stay
    apart in the document."""
    renamed = {e.get("id"): e.get("id") + suffix for e in element.iter() if e is not element and e.get("id")}
    for e in element.iter():
        if e is not element and e.get("id") in renamed:
            e.set("id", renamed[e.get("id")])
        for attribute in ("source", "url"):
            value = e.get(attribute, "")
            if value.startswith("#") and value[1:] in renamed:
                e.set(attribute, "#" + renamed[value[1:]])
