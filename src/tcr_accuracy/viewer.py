"""3D views in meshcat: robots from their URDF visuals, TCP point clouds, error segments.

Build a :class:`Scene`, add what should be seen, then either write one self-contained
HTML file that opens in any browser with no server (:meth:`Scene.write_static_html`)
or serve it live on localhost (:meth:`Scene.serve`)::

    scene = Scene("tool-changer at the working pose")
    scene.add_robot(robot, q, "nominal")
    scene.add_robot(error_model.perturbed_robot(x), q, "as_built", color=(0.9, 0.2, 0.2), opacity=0.35)
    scene.add_point_cloud(tcp_points_m, error_mm, "tcp_cloud", "|dP| [mm]")
    scene.write_static_html("view.html")

How it works. meshcat's Python client sends drawing commands to a window object; its
own window talks ZeroMQ to a server subprocess, which keeps the scene tree and is the
only thing that can export a static page. Here the commands go to a recording window
that keeps the same scene tree (meshcat's own ``SceneTree``) in memory, so a static
page needs no server, no port and no subprocess; :meth:`Scene.serve` starts meshcat's
server bridge bound to 127.0.0.1 only (meshcat's own ``meshcat-server`` listens on all
interfaces) and replays the tree into it. Robots are loaded by Pinocchio's
``MeshcatVisualizer`` from Pinocchio's visual ``GeometryModel`` of the URDF, reduced to
the robot's TCP chain exactly as :func:`tcr_accuracy.robot.robot_from_urdf_text`
reduces the kinematic model, so an as-built robot (same joints, other placements)
carries the same bodies.

meshcat draws no text, so legends (colour bars, magnification factors) are HTML
overlays in the page this module writes around meshcat's viewer.

Units: positions in metres (SI) as everywhere inside the package; the values that
colour a point cloud are shown as given, with the unit in their label.
"""

from __future__ import annotations

import atexit
import base64
import html
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .exceptions import InputError
from .robot import RobotModel

INSTALL_HINT = "the 3D viewer needs meshcat: pip install meshcat (or pip install tcr-accuracy)"

#: Default colours (RGB in 0..1) for things the scene draws.
COLORS = {
    "as_built": (0.85, 0.15, 0.15),
    "measured": (0.10, 0.35, 0.95),
    "predicted": (0.95, 0.55, 0.05),
    "segment": (0.10, 0.10, 0.10),
    "trajectory": (0.00, 0.60, 0.30),
    "nominal_tcp": (1.0, 1.0, 1.0),
}


def _import_meshcat():
    """meshcat and its geometry module, or an InputError with the install hint."""
    try:
        import meshcat
        import meshcat.geometry as mg
    except ImportError as exc:  # pragma: no cover - meshcat is a declared dependency
        raise InputError(f"{INSTALL_HINT} ({exc})") from None
    return meshcat, mg


def _rgb_int(rgb) -> int:
    r, g, b = (int(round(255 * min(max(float(c), 0.0), 1.0))) for c in rgb[:3])
    return (r << 16) + (g << 8) + b


def _css_rgb(rgb) -> str:
    r, g, b = (int(round(255 * min(max(float(c), 0.0), 1.0))) for c in rgb[:3])
    return f"rgb({r},{g},{b})"


def _as_points(points, what: str) -> np.ndarray:
    points = np.asarray(points, dtype=float)
    if points.ndim == 1 and points.shape == (3,):
        points = points[None]
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"{what}: expected points of shape (N, 3) [m], got {points.shape}")
    if not np.isfinite(points).all():
        raise InputError(f"{what}: points contain NaN or infinite values")
    return points


# ---------------------------------------------------------------------------------------
# Recording window: meshcat's command stream kept in memory
# ---------------------------------------------------------------------------------------
class _RecordingWindow:
    """Stands in for ``meshcat.visualizer.ViewerWindow``: keeps every command in a scene tree.

    The tree update rules are those of meshcat's server bridge
    (``meshcat.servers.zmqserver.ZMQWebSocketBridge.handle_zmq``), so the page built from
    it shows what a live meshcat server would show.
    """

    web_url = None

    def __init__(self):
        from meshcat.servers.tree import SceneTree

        self.tree = SceneTree()

    def send(self, command) -> None:
        import umsgpack
        from meshcat.servers.tree import SceneTree, find_node

        data = command.lower()
        kind = data["type"]
        path = [p for p in data["path"].split("/") if p]
        packed = umsgpack.packb(data)
        if kind == "set_transform":
            find_node(self.tree, path).transform = packed
        elif kind == "set_object":
            node = find_node(self.tree, path)
            node.object = packed
            node.properties = []
        elif kind == "set_property":
            find_node(self.tree, path).properties.append(packed)
        elif kind == "set_animation":
            find_node(self.tree, path).animation = packed
        elif kind == "delete":
            if path:
                parent = find_node(self.tree, path[:-1])
                parent.pop(path[-1], None)
            else:
                self.tree = SceneTree()

    def packed_commands(self) -> list[bytes]:
        """All commands (msgpack bytes) in the order meshcat's server replays them."""
        from meshcat.servers.tree import walk

        out: list[bytes] = []
        for node in walk(self.tree):
            if node.object is not None:
                out.append(node.object)
            out.extend(node.properties)
            if node.transform is not None:
                out.append(node.transform)
            if node.animation is not None:
                out.append(node.animation)
        return out

    # meshcat API the Pinocchio visualizer may probe
    def get_image(self):  # pragma: no cover - never called for a recording
        raise NotImplementedError("a recorded scene has no image; open its static HTML in a browser")


# ---------------------------------------------------------------------------------------
# Robot bodies from the URDF visuals
# ---------------------------------------------------------------------------------------
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


# ---------------------------------------------------------------------------------------
# Legends shown next to the 3D view
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ColorBar:
    """A colour scale: ``label`` (with unit) from ``vmin`` to ``vmax``, sampled colours."""

    label: str
    vmin: float
    vmax: float
    colors: tuple  # RGB triples, low to high


@dataclass(frozen=True)
class LegendEntry:
    """A swatch and a text line (e.g. "error segments x 100")."""

    text: str
    color: tuple | None = None


@dataclass
class _Bounds:
    lo: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))
    hi: np.ndarray = field(default_factory=lambda: np.full(3, -np.inf))

    def add(self, points: np.ndarray) -> None:
        if len(points):
            self.lo = np.minimum(self.lo, points.min(axis=0))
            self.hi = np.maximum(self.hi, points.max(axis=0))

    @property
    def empty(self) -> bool:
        return not np.all(np.isfinite(self.lo))


# ---------------------------------------------------------------------------------------
# The scene
# ---------------------------------------------------------------------------------------
class Scene:
    """A meshcat scene under construction (see the module docstring).

    Parameters
    ----------
    title : str
        Shown above the view and as the page title.
    grid : bool
        Show meshcat's ground grid (z = 0 plane, 0.5 m squares).
    """

    def __init__(self, title: str = "tcr-accuracy", *, grid: bool = True):
        meshcat, self._mg = _import_meshcat()
        self.title = title
        self._window = _RecordingWindow()
        self.vis = meshcat.Visualizer(window=self._window)
        self.color_bars: list[ColorBar] = []
        self.legend: list[LegendEntry] = []
        self.notes: list[str] = []
        self._bounds = _Bounds()
        self._camera: tuple[np.ndarray, np.ndarray] | None = None
        self._grid = grid
        self._finished = False
        # a light background makes coloured points and dark segments readable
        self.vis["/Background"].set_property("top_color", [0.97, 0.97, 0.98])
        self.vis["/Background"].set_property("bottom_color", [0.80, 0.82, 0.86])

    # -- content ---------------------------------------------------------------------
    def add_robot(self, robot: RobotModel, q, name: str = "robot", color=None,
                  opacity: float = 1.0, *, include_base: bool = True) -> None:
        """Draw the robot's URDF visuals at joint values q.

        Parameters
        ----------
        robot : RobotModel
            Nominal or as-built (e.g. ``ErrorModel.perturbed_robot(x)``): the bodies hang
            on the robot's own joint placements.
        q : array-like of shape (n_joints,)
            Joint values [rad, m].
        name : str
            Node name in the meshcat tree (also the legend text).
        color : RGB triple in 0..1, optional
            Paint every body in this colour (default: the URDF's materials).
        opacity : float
            1 opaque; below 1 a transparent "ghost".
        include_base : bool
            Draw the bodies fixed to the base (a ghost without base error would only
            repaint the nominal robot's pedestal).
        """
        import pinocchio as pin
        from pinocchio.visualize import MeshcatVisualizer

        q = robot.check_joint_values(np.asarray(q, dtype=float), source=f"{name}: q")
        if not 0.0 < opacity <= 1.0:
            raise InputError(f"{name}: opacity {opacity} is outside (0, 1]")
        geometry = visual_geometry(robot)
        if geometry.ngeoms == 0:  # a URDF without <visual> elements: draw the kinematic skeleton
            self._add_skeleton(robot, q, name, color, opacity)
            return
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
        viz.initViewer(viewer=self.vis)
        viz.loadViewerModel(rootNodeName=_node(name))
        viz.display(robot.to_pinocchio_q(q))
        data = robot.model.createData()
        pin.forwardKinematics(robot.model, data, robot.to_pinocchio_q(q))
        pin.updateFramePlacements(robot.model, data)
        joints = np.array([data.oMi[j].translation for j in range(robot.model.njoints)]
                          + [data.oMf[robot.tool_frame_id].translation])
        self._bounds.add(joints)
        swatch = tuple(color) if color is not None else None
        suffix = f", {round(opacity * 100)} % opaque" if opacity < 1.0 else ""
        self.legend.append(LegendEntry(f"robot: {name}{suffix}", swatch))

    def _add_skeleton(self, robot: RobotModel, q, name: str, color, opacity: float) -> None:
        """Joint origins as spheres joined by links (parent to child) and the TCP, for a URDF
        that has no visuals (point-mass models such as calibration data sets ship)."""
        import pinocchio as pin

        model = robot.model
        data = model.createData()
        pin.forwardKinematics(model, data, robot.to_pinocchio_q(q))
        pin.updateFramePlacements(model, data)
        origins = np.array([data.oMi[j].translation for j in range(model.njoints)])
        tool = data.oMf[robot.tool_frame_id].translation
        segments = [(origins[model.parents[j]], origins[j]) for j in range(1, model.njoints)]
        segments.append((origins[model.frames[robot.tool_frame_id].parentJoint], tool))
        rgb = tuple(color) if color is not None else (0.35, 0.38, 0.45)
        mg = self._mg
        node = self.vis[_node(name)]
        pairs = np.array([p for segment in segments for p in segment], dtype=np.float32)
        node["links"].set_object(mg.LineSegments(mg.PointsGeometry(pairs.T), mg.LineBasicMaterial(
            color=_rgb_int(rgb), linewidth=4, transparent=opacity < 1.0, opacity=opacity)))
        reach = float(np.max(np.linalg.norm(origins - origins[0], axis=1), initial=0.0)) or 1.0
        for j, origin in enumerate(list(origins[1:]) + [tool]):
            sphere = node[f"joint_{j}"]
            sphere.set_object(mg.Sphere(0.02 * reach), mg.MeshLambertMaterial(
                color=_rgb_int(rgb), transparent=opacity < 1.0, opacity=opacity))
            sphere.set_transform(_translation(origin))
        self._bounds.add(np.vstack([origins, tool[None]]))
        suffix = f", {round(opacity * 100)} % opaque" if opacity < 1.0 else ""
        self.legend.append(LegendEntry(f"robot: {name} (skeleton: the URDF has no visuals){suffix}",
                                       rgb if color is not None else None))

    def add_point_cloud(self, points_m, values, name: str, label: str, *, cmap: str = "viridis",
                        vmin: float | None = None, vmax: float | None = None,
                        center_m=None, magnify: float = 1.0, size_m: float | None = None,
                        center_label: str = "its centre") -> ColorBar:
        """Points coloured by a value, with a colour bar in the legend.

        Parameters
        ----------
        points_m : array-like of shape (N, 3)
            Positions [m].
        values : array-like of shape (N,)
            What the colour shows (e.g. |dP| in mm), in the unit named by ``label``.
        name : str
            Node name.
        label : str
            Colour-bar label with its unit, e.g. ``"|dP| [mm]"``.
        cmap : str
            A matplotlib colormap name.
        vmin, vmax : float, optional
            Colour range (default: the values' range).
        center_m : array-like of shape (3,), optional
            With ``magnify``: points are drawn at ``center + magnify * (p - center)``
            (errors of tenths of a millimetre become visible on a 2 m robot). The factor
            is written in the legend.
        magnify : float
            Magnification about ``center_m`` (1: true positions).
        center_label : str
            What the centre is, for the legend ("the nominal TCP").
        size_m : float, optional
            Point size [m] (default: 1/60 of the cloud's drawn extent, at least 2 mm).
        """
        import matplotlib

        points = _as_points(points_m, name)
        values = np.asarray(values, dtype=float).reshape(-1)
        if values.shape != (len(points),):
            raise InputError(f"{name}: {values.size} values for {len(points)} points")
        if not np.isfinite(values).all():
            raise InputError(f"{name}: values contain NaN or infinite entries")
        points = self._magnified(points, center_m, magnify, name)
        lo = float(values.min()) if vmin is None else float(vmin)
        hi = float(values.max()) if vmax is None else float(vmax)
        if hi <= lo:
            hi = lo + 1.0 if lo == 0 else lo + abs(lo) * 1e-6
        try:
            colormap = matplotlib.colormaps[cmap]
        except KeyError:
            raise InputError(f"colormap {cmap!r} is not a matplotlib colormap") from None
        rgb = colormap(np.clip((values - lo) / (hi - lo), 0.0, 1.0))[:, :3]
        if size_m is None:
            extent = float(np.max(np.ptp(points, axis=0))) if len(points) > 1 else 0.0
            size_m = max(extent / 60.0, 0.002)
        self.vis[_node(name)].set_object(
            self._mg.PointCloud(points.T.astype(np.float32), rgb.T.astype(np.float32), size=size_m))
        self._bounds.add(points)
        bar = ColorBar(label, lo, hi, tuple(tuple(float(c) for c in colormap(t)[:3])
                                           for t in np.linspace(0.0, 1.0, 11)))
        self.color_bars.append(bar)
        if magnify != 1.0:
            self.legend.append(LegendEntry(f"{name}: magnified x {magnify:g} about {center_label}"))
        return bar

    @staticmethod
    def _magnified(points: np.ndarray, center_m, magnify: float, name: str) -> np.ndarray:
        if not (math.isfinite(magnify) and magnify > 0):
            raise InputError(f"{name}: magnification {magnify} must be a positive number")
        if center_m is None:
            if magnify != 1.0:
                raise InputError(f"{name}: a magnification needs the centre to magnify about")
            return points
        center = _as_points(center_m, f"{name}: centre")[0]
        return center + magnify * (points - center)

    def add_tcp_error_cloud(self, robot: RobotModel, q, x, error_model=None, *, name: str = "tcp_cloud",
                            magnify: float | None = None, ghost: bool = True) -> float:
        """The TCP positions of as-built robots at joint values q, coloured by |dP| [mm].

        Parameters
        ----------
        robot : RobotModel
            The nominal robot (drawn by the caller with :meth:`add_robot`).
        q : array-like of shape (n_joints,)
            Joint values [rad, m].
        x : array-like of shape (N, n_params)
            Error vectors, e.g. ``ErrorBudget.sample(N, rng)``.
        error_model : ErrorModel, optional
            Layout of x (built from the robot when omitted).
        magnify : float, optional
            Magnification of the cloud about the nominal TCP (default:
            :func:`auto_magnification` of the largest error).
        ghost : bool
            Also draw, transparent, the as-built robot of the sample with the largest |dP|,
            its error vector scaled by the same factor (so its TCP sits, to first order,
            on that sample's magnified point).

        Returns
        -------
        float
            The magnification used (also written in the legend).
        """
        from .errors import ErrorModel
        from .kinematics import pose_error, tcp_poses

        error_model = error_model or ErrorModel(robot)
        x = np.atleast_2d(np.asarray(x, dtype=float))
        q = robot.check_joint_values(np.asarray(q, dtype=float), source=f"{name}: q")
        nominal = tcp_poses(robot, q)
        actual = tcp_poses(robot, q, x, error_model)
        error = pose_error(nominal, actual)
        worst = int(np.argmax(error.position_norm))
        if magnify is None:
            magnify = auto_magnification(float(error.position_norm[worst]))
        self.add_point_cloud(actual.position, error.position_norm * 1000.0, name, "TCP error |dP| [mm]",
                             center_m=nominal.position[0], magnify=magnify, center_label="the nominal TCP")
        self.add_points(nominal.position, f"{name}_nominal", COLORS["nominal_tcp"], size_m=0.02,
                        label="nominal TCP")
        if ghost:
            as_built = error_model.perturbed_robot(magnify * x[worst], name="as_built")
            base_error = bool(np.any(x[worst][error_model.base_slice]))
            self.add_robot(as_built, q, f"{name}_worst_as_built", color=COLORS["as_built"], opacity=0.35,
                           include_base=base_error)
            self.legend[-1] = LegendEntry(
                f"as-built robot of the worst sample (|dP| = {error.position_norm[worst] * 1000:.3g} mm), "
                f"errors x {magnify:g}", COLORS["as_built"])
        return magnify

    def add_points(self, points_m, name: str, color=(0.1, 0.35, 0.95), size_m: float = 0.01,
                   label: str | None = None) -> None:
        """Points in one colour (e.g. measured TCP positions), (N, 3) [m]."""
        points = _as_points(points_m, name)
        rgb = np.tile(np.asarray(color, dtype=np.float32)[:3, None], (1, len(points)))
        self.vis[_node(name)].set_object(
            self._mg.PointCloud(points.T.astype(np.float32), rgb, size=size_m))
        self._bounds.add(points)
        self.legend.append(LegendEntry(label or name, tuple(color)))

    def add_error_segments(self, start_m, end_m, magnify: float = 1.0, name: str = "errors", *,
                           start_label: str = "measured", end_label: str = "predicted",
                           start_color=COLORS["measured"], end_color=COLORS["predicted"],
                           size_m: float = 0.01) -> None:
        """Pairs of points joined by segments, the gap magnified.

        Parameters
        ----------
        start_m, end_m : array-like of shape (N, 3)
            e.g. measured and predicted TCP positions [m].
        magnify : float
            Each end is drawn at ``start + magnify * (end - start)``; the factor is
            written in the legend.
        """
        start = _as_points(start_m, f"{name}: start")
        end = _as_points(end_m, f"{name}: end")
        if start.shape != end.shape:
            raise InputError(f"{name}: {len(start)} start points but {len(end)} end points")
        if not (math.isfinite(magnify) and magnify > 0):
            raise InputError(f"{name}: magnification {magnify} must be a positive number")
        drawn_end = start + magnify * (end - start)
        segments = np.empty((2 * len(start), 3))
        segments[0::2], segments[1::2] = start, drawn_end
        mg = self._mg
        node = self.vis[_node(name)]
        node["segments"].set_object(mg.LineSegments(
            mg.PointsGeometry(segments.T.astype(np.float32)),
            mg.LineBasicMaterial(color=_rgb_int(COLORS["segment"]))))
        for key, pts, rgb in (("start", start, start_color), ("end", drawn_end, end_color)):
            colors = np.tile(np.asarray(rgb, dtype=np.float32)[:3, None], (1, len(pts)))
            node[key].set_object(mg.PointCloud(pts.T.astype(np.float32), colors, size=size_m))
        self._bounds.add(start)
        self._bounds.add(drawn_end)
        self.legend.append(LegendEntry(start_label, tuple(start_color)))
        self.legend.append(LegendEntry(
            f"{end_label} (segments magnified x {magnify:g})" if magnify != 1.0 else end_label,
            tuple(end_color)))

    def add_trajectory(self, points_m, name: str = "trajectory", color=COLORS["trajectory"]) -> None:
        """A polyline through (N, 3) points [m], in order."""
        points = _as_points(points_m, name)
        if len(points) < 2:
            raise InputError(f"{name}: a trajectory needs at least 2 points, got {len(points)}")
        mg = self._mg
        self.vis[_node(name)].set_object(mg.Line(
            mg.PointsGeometry(points.T.astype(np.float32)),
            mg.LineBasicMaterial(color=_rgb_int(color), linewidth=2)))
        self._bounds.add(points)
        self.legend.append(LegendEntry(name, tuple(color)))

    def add_frame(self, placement, name: str, length_m: float = 0.15) -> None:
        """Axes of a frame (pin.SE3 or (4, 4) matrix) in red/green/blue for x/y/z."""
        matrix = np.asarray(getattr(placement, "homogeneous", placement), dtype=float)
        node = self.vis[_node(name)]
        node.set_object(self._mg.triad(length_m))
        node.set_transform(matrix)
        self._bounds.add(matrix[None, :3, 3])

    def add_note(self, text: str) -> None:
        """A line of text under the legend (settings, units, what the view shows)."""
        self.notes.append(text)

    def set_camera(self, target_m, position_m) -> None:
        """Look at ``target_m`` (3,) from ``position_m`` (3,) [m], base frame (z up)."""
        target = np.asarray(target_m, dtype=float).reshape(3)
        position = np.asarray(position_m, dtype=float).reshape(3)
        self._camera = (target, position)

    def recorded_commands(self) -> list[dict]:
        """The meshcat commands of the scene as dicts (``type``, ``path``, ...), in replay order."""
        import umsgpack

        return [umsgpack.unpackb(c) for c in self._window.packed_commands()]

    # -- output ----------------------------------------------------------------------
    def _view_target(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(target, camera position) [m]: the one set, or one framing everything drawn."""
        if self._camera is not None:
            return self._camera
        if self._bounds.empty:
            return None
        lo, hi = self._bounds.lo, self._bounds.hi
        target = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.3)
        direction = np.array([1.0, -0.55, 0.45])
        return target, target + 2.2 * radius * direction / np.linalg.norm(direction)

    def _finish(self) -> None:
        """Camera, ground grid and base axes, set once before output.

        meshcat's orbit camera always turns about the world origin, so the whole scene
        (everything lives under ``/meshcat``) is shifted to put the view target there; the
        camera is then placed relative to it in its parent's axes (three.js, y up: the
        base frame's (x, z, -y)). meshcat's own grid and axes would not follow the shift,
        so they are hidden and drawn again under ``/meshcat``.
        """
        view = self._view_target()
        if view is None or self._finished:
            return
        self._finished = True
        target, position = view
        mg = self._mg
        self.vis["/Grid"].set_property("visible", False)
        self.vis["/Axes"].set_property("visible", False)
        if self._grid:
            lo = np.floor(np.minimum(self._bounds.lo, target) / 0.5 - 2) * 0.5
            hi = np.ceil(np.maximum(self._bounds.hi, target) / 0.5 + 2) * 0.5
            xs, ys = np.arange(lo[0], hi[0] + 1e-9, 0.5), np.arange(lo[1], hi[1] + 1e-9, 0.5)
            lines = [((x, ys[0], 0.0), (x, ys[-1], 0.0)) for x in xs]
            lines += [((xs[0], y, 0.0), (xs[-1], y, 0.0)) for y in ys]
            self.vis["ground_grid"].set_object(mg.LineSegments(
                mg.PointsGeometry(np.array(lines, dtype=np.float32).reshape(-1, 3).T),
                mg.LineBasicMaterial(color=0x9a9a9a)))
        self.vis["base_axes"].set_object(mg.triad(0.5))
        self.vis.set_transform(_translation(-target))
        offset = position - target
        self.vis["/Cameras/default/rotated/<object>"].set_property(
            "position", [float(offset[0]), float(offset[2]), float(-offset[1])])

    def _legend_html(self) -> str:
        parts = [f'<div class="tcr-title">{html.escape(self.title)}</div>']
        for bar in self.color_bars:
            stops = ", ".join(_css_rgb(c) for c in bar.colors)
            parts.append(
                '<div class="tcr-bar">'
                f'<div class="tcr-bar-label">{html.escape(bar.label)}</div>'
                f'<div class="tcr-bar-gradient" style="background: linear-gradient(to right, {stops});"></div>'
                f'<div class="tcr-bar-ticks"><span>{bar.vmin:.4g}</span>'
                f'<span>{0.5 * (bar.vmin + bar.vmax):.4g}</span><span>{bar.vmax:.4g}</span></div>'
                "</div>")
        for entry in self.legend:
            swatch = (f'<span class="tcr-swatch" style="background:{_css_rgb(entry.color)}"></span>'
                      if entry.color is not None else '<span class="tcr-swatch tcr-none"></span>')
            parts.append(f'<div class="tcr-entry">{swatch}{html.escape(entry.text)}</div>')
        for note in self.notes:
            parts.append(f'<div class="tcr-note">{html.escape(note)}</div>')
        return '<div id="tcr-legend">' + "".join(parts) + "</div>"

    def _page(self, scene_script: str, meshcat_script: str) -> str:
        return _PAGE.format(
            title=html.escape(self.title),
            css=_CSS,
            legend=self._legend_html(),
            meshcat_script=meshcat_script,
            scene_script=scene_script,
        )

    def static_html(self) -> str:
        """One self-contained HTML page (meshcat's viewer, the scene, the legend); no server needed."""
        from meshcat.servers.zmqserver import VIEWER_ROOT

        self._finish()
        main_js = (Path(VIEWER_ROOT) / "main.min.js").read_text(encoding="utf-8")
        commands = [base64.b64encode(c).decode("ascii") for c in self._window.packed_commands()]
        scene_script = _STATIC_LOADER.format(commands=json.dumps(commands))
        # "</script" inside the inlined bundle would end the script element early
        main_js = main_js.replace("</script", "<\\/script")
        return self._page(scene_script, f"<script>{main_js}</script>")

    def write_static_html(self, path) -> Path:
        """Write :meth:`static_html` to path atomically (temporary file + rename)."""
        from .atomic import write_text_atomically

        path = Path(path)
        write_text_atomically(path, self.static_html())
        return path

    def serve(self, open_browser: bool = False) -> "LiveView":
        """Serve the scene live on 127.0.0.1 (a meshcat server subprocess).

        Returns a :class:`LiveView` with the page's ``url``; call ``close()`` (or use it
        as a context manager) to stop the server. Further ``add_*`` calls are not sent
        to a live view: build the scene first.
        """
        self._finish()
        live = LiveView.start(self._page(_LIVE_LOADER, '<script src="static/main.min.js"></script>'))
        live.replay(self._window)
        if open_browser:
            import webbrowser

            webbrowser.open(live.url, new=2)
        return live


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


def auto_magnification(largest_error_m: float, drawn_m: float = 0.8) -> float:
    """A round factor (1, 2 or 5 times a power of ten, at least 1) that draws the largest
    error at most about ``drawn_m`` long."""
    if not (largest_error_m > 0 and math.isfinite(largest_error_m)):
        return 1.0
    raw = drawn_m / largest_error_m
    if raw <= 1.0:
        return 1.0
    decade = 10.0 ** math.floor(math.log10(raw))
    return max(m * decade for m in (1.0, 2.0, 5.0) if m * decade <= raw)


def _node(name: str) -> str:
    name = str(name).strip().strip("/")
    if not name or any(c in name for c in "<>\"'"):
        raise InputError(f"scene node name {name!r} is empty or has characters meshcat cannot use")
    return name


def _translation(p: np.ndarray) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, 3] = p
    return matrix


# ---------------------------------------------------------------------------------------
# Live server on localhost
# ---------------------------------------------------------------------------------------
class LiveView:
    """A meshcat server subprocess bound to 127.0.0.1 holding one scene."""

    def __init__(self, process: subprocess.Popen, zmq_url: str, url: str):
        self.process = process
        self.zmq_url = zmq_url
        self.url = url

    @classmethod
    def start(cls, page: str, timeout_s: float = 20.0) -> "LiveView":
        _import_meshcat()
        env = dict(os.environ)
        src = str(Path(__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join(p for p in (src, env.get("PYTHONPATH", "")) if p)
        process = subprocess.Popen(
            [sys.executable, "-u", "-m", "tcr_accuracy._meshcat_server"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
            start_new_session=True)
        assert process.stdin is not None and process.stdout is not None
        process.stdin.write(page.encode("utf-8"))
        process.stdin.close()
        deadline = time.monotonic() + timeout_s
        zmq_url = web_url = None
        while time.monotonic() < deadline and (zmq_url is None or web_url is None):
            line = process.stdout.readline().decode("utf-8").strip()
            if not line and process.poll() is not None:
                break
            if line.startswith("zmq_url="):
                zmq_url = line.split("=", 1)[1]
            elif line.startswith("web_url="):
                web_url = line.split("=", 1)[1]
        if zmq_url is None or web_url is None:
            process.kill()
            process.wait()
            process.stdout.close()
            from .exceptions import AnalysisError

            raise AnalysisError("the meshcat server did not start")
        live = cls(process, zmq_url, web_url)
        atexit.register(live.close)
        return live

    def replay(self, window: _RecordingWindow) -> None:
        import zmq

        socket = zmq.Context.instance().socket(zmq.REQ)
        socket.connect(self.zmq_url)
        try:
            from meshcat.servers.tree import walk

            for node_path, packed in _walk_with_paths(window.tree, walk):
                kind = _command_type(packed)
                socket.send_multipart([kind.encode(), node_path.encode(), packed])
                socket.recv()
        finally:
            socket.close(linger=0)

    def close(self) -> None:
        """Stop the server (it ends with this process anyway)."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.process.stdout is not None:
            self.process.stdout.close()

    def __enter__(self) -> "LiveView":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _command_type(packed: bytes) -> str:
    import umsgpack

    return umsgpack.unpackb(packed)["type"]


def _walk_with_paths(tree, walk):
    """(path, packed command) pairs of a recorded tree, in replay order."""
    import umsgpack

    for node in walk(tree):
        for packed in ([node.object] if node.object is not None else []) + list(node.properties) + \
                [c for c in (node.transform, node.animation) if c is not None]:
            yield umsgpack.unpackb(packed).get("path", ""), packed


# ---------------------------------------------------------------------------------------
# Page template
# ---------------------------------------------------------------------------------------
_CSS = """
body { margin: 0; font-family: system-ui, -apple-system, "Segoe UI", sans-serif; }
#meshcat-pane { width: 100vw; height: 100vh; overflow: hidden; }
#tcr-legend { position: absolute; left: 10px; top: 10px; max-width: 330px; padding: 8px 10px;
  background: rgba(255, 255, 255, 0.88); border: 1px solid #bbb; border-radius: 4px;
  font-size: 13px; color: #222; line-height: 1.35; }
.tcr-title { font-weight: 600; margin-bottom: 4px; }
.tcr-bar { margin: 4px 0 6px 0; }
.tcr-bar-gradient { height: 12px; border: 1px solid #777; }
.tcr-bar-ticks { display: flex; justify-content: space-between; font-size: 11px; }
.tcr-swatch { display: inline-block; width: 11px; height: 11px; margin-right: 6px;
  border: 1px solid #555; vertical-align: -1px; }
.tcr-none { background: repeating-linear-gradient(45deg, #ddd, #ddd 2px, #fff 2px, #fff 4px); }
.tcr-note { font-size: 11px; color: #444; margin-top: 3px; }
"""

_PAGE = """<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>{css}</style>
</head>
<body>
<div id="meshcat-pane"></div>
{legend}
{meshcat_script}
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
{scene_script}
</script>
</body>
</html>
"""

# The commands are the msgpack blobs meshcat's server would send over its websocket;
# decoding them synchronously (not through fetch() of data: URLs as meshcat's own export
# does) keeps their order and lets a page screenshot see the finished scene.
_STATIC_LOADER = """var tcrCommands = {commands};
for (var i = 0; i < tcrCommands.length; i++) {{
  var raw = atob(tcrCommands[i]);
  var bytes = new Uint8Array(raw.length);
  for (var k = 0; k < raw.length; k++) {{ bytes[k] = raw.charCodeAt(k); }}
  viewer.handle_command_bytearray(bytes);
}}
document.body.setAttribute("data-tcr-scene", "loaded");
"""

_LIVE_LOADER = """try { viewer.connect(); } catch (e) { console.info("no meshcat server: ", e); }
"""
