"""3D views in meshcat: a scene of robots, TCP point clouds, error segments and a legend.

Build a :class:`Scene`, add what should be seen, then either take one self-contained
HTML page that opens in any browser with no server (:meth:`Scene.static_html`, for the caller
to write) or serve it live on localhost (:meth:`Scene.serve`)::

    scene = Scene("tool-changer at the working pose")
    scene.add_robot(robot, q, "nominal")
    scene.add_robot(error_model.perturbed_robot(x), q, "as_built", color=(0.9, 0.2, 0.2), opacity=0.35)
    scene.add_point_cloud(tcp_points_m, error_mm, "tcp_cloud", "|dP| [mm]")
    Path("view.html").write_text(scene.static_html(), encoding="utf-8")

This module owns what a view holds and how it is framed: robots, point clouds coloured
by a value, magnified error segments, trajectories, frames, the camera and ground grid,
and the legend's content (:class:`ColorBar`, :class:`LegendEntry`, notes). Robot bodies
come from the URDF visuals through :mod:`tcr_accuracy.view.robot_visuals`. The scene records
meshcat's drawing commands in memory, and :mod:`tcr_accuracy.view.meshcat_page` turns the
recording into a page: one static HTML file (no server, no port, no subprocess) or a
live meshcat server on 127.0.0.1, with the legend as an HTML overlay (meshcat draws no
text).

Units: positions in metres (SI) as everywhere inside the package; the values that
colour a point cloud are shown as given, with the unit in their label.

One concept, the scene with its legend, and so one class above 500 lines: its sizes and factors
live in :mod:`tcr_accuracy.view.view_scales`, where the camera stands in
:mod:`tcr_accuracy.view.view_framing`, the page in :mod:`tcr_accuracy.view.meshcat_page`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..exceptions import InputError
from ..model.robot import RobotModel
from .meshcat_page import (LiveView, RecordingWindow, import_meshcat, legend_html, meshcat_color, serve_page,
                           static_page)
from .robot_visuals import draw_robot
from .view_framing import CAMERA_FOV_DEG, VIEW_MARGIN, camera_placement, framed_box, page_fit  # noqa: F401
from .view_scales import (auto_magnification, data_extent, frame_axis_length, ghost_magnification,  # noqa: F401
                          grid_extent, point_size, rotate_vectors, segment_magnification, spread_subset,
                          transform_points)

#: Default colours (RGB in 0..1) for things the scene draws.
COLORS = {
    "as_built": (0.85, 0.15, 0.15),
    "measured": (0.10, 0.35, 0.95),
    "predicted": (0.95, 0.55, 0.05),
    "segment": (0.10, 0.10, 0.10),
    "trajectory": (0.00, 0.60, 0.30),
    "nominal_tcp": (1.0, 1.0, 1.0),
}

#: The ground grid's colour (RGB in 0..1).
GRID_COLOR = (0.60, 0.60, 0.60)

#: The ring that marks the measured point of the pose the robot is drawn at (RGB in 0..1).
MARKER_COLOR = (0.85, 0.0, 0.75)

#: Colours a legend entry takes when the one asked for is another entry's already: one colour
#: per entry (matplotlib's tab10, RGB in 0..1).
SPARE_COLORS = ((0.55, 0.34, 0.29), (0.09, 0.75, 0.81), (0.74, 0.74, 0.13), (0.89, 0.47, 0.76),
                (0.58, 0.40, 0.74), (0.17, 0.63, 0.17), (0.84, 0.15, 0.16), (0.12, 0.47, 0.71))

#: At most this many error segments are drawn (an even spread of them, the largest included):
#: a thousand segments fill the view and hide the robot.
MAX_SEGMENTS = 250


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

    The page fits the camera, when it opens, to the canvas it gets beside the legend: the robots'
    bodies and the outline of the data in view (:data:`CAMERA_FOV_DEG`, :data:`VIEW_MARGIN`).
    Each legend entry has a colour of its own (:data:`SPARE_COLORS` when one is taken).

    Parameters
    ----------
    title : str
        Shown above the view and as the page title.
    grid : bool
        Show a ground grid (z = 0 plane, squares of 5 cm to 1 m fitted to what is drawn: :func:`grid_extent`).
    frame : {"all", "data"}
        What the camera frames: everything drawn, or the data (point clouds, points, error
        segments, trajectories; without far outliers: :func:`framed_box`) and the robots
        drawn among them, so that far frames (a tracker's triad metres away) or a few far-out
        points do not shrink them to a speck.

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> scene = tcr.Scene("UR5 at its working pose")
    >>> scene.add_robot(robot, robot.working_pose)
    >>> scene.title
    'UR5 at its working pose'
    """

    def __init__(self, title: str = "tcr-accuracy", *, grid: bool = True, frame: str = "all"):
        if frame not in ("all", "data"):
            raise InputError(f"scene frame {frame!r}: use 'all' or 'data'")
        meshcat, self._mg = import_meshcat()
        self.title = title
        self._window = RecordingWindow()
        self.vis = meshcat.Visualizer(window=self._window)
        self.color_bars: list[ColorBar] = []
        self.legend: list[LegendEntry] = []
        self.notes: list[str] = []
        self._bounds = _Bounds()
        self._robot_bounds = _Bounds()  # the framed robots' bodies
        self._robot_points: list[np.ndarray] = []  # their joints and the corners of their bodies' boxes
        self._other_points: list[np.ndarray] = []  # markers, frames: in the view when it frames all
        self._data: list[np.ndarray] = []  # points, clouds, segments, trajectories: the data
        self._frame = frame
        self.fit_radius_m: float | None = None  # the sphere the camera holds, once finished
        self._camera: tuple[np.ndarray, np.ndarray] | None = None
        self._grid = grid
        self._finished = False
        # a light background makes coloured points and dark segments readable
        self.vis["/Background"].set_property("top_color", [0.97, 0.97, 0.98])
        self.vis["/Background"].set_property("bottom_color", [0.80, 0.82, 0.86])

    # -- content ---------------------------------------------------------------------
    def add_robot(self, robot: RobotModel, q, name: str = "robot", color=None,
                  opacity: float = 1.0, *, include_base: bool = True, framed: bool = True) -> None:
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
            Paint every body in this colour (default: the URDF's materials); another one when a
            legend entry has it already.
        opacity : float
            1 opaque; below 1 a transparent "ghost".
        include_base : bool
            Draw the bodies fixed to the base (a ghost without base error would only
            repaint the nominal robot's pedestal).
        framed : bool
            Count the bodies in what the camera and the ground grid fit (False for a
            ghost whose magnified errors may reach far from the robot and the data).
        """
        q = robot.check_joint_values(np.asarray(q, dtype=float), source=f"{name}: q")
        if not 0.0 < opacity <= 1.0:
            raise InputError(f"{name}: opacity {opacity} is outside (0, 1]")
        color = None if color is None else self._own_color(color)
        points, skeleton = draw_robot(self.vis, robot, q, _node(name), color, opacity, include_base=include_base)
        points = points[np.all(np.isfinite(points), axis=1)]
        if framed:
            self._bounds.add(points)
            self._robot_bounds.add(points)
            self._robot_points.append(points)
        what = f" (skeleton: {skeleton})" if skeleton else ""
        suffix = f", {round(opacity * 100)} % opaque" if opacity < 1.0 else ""
        self.legend.append(LegendEntry(f"robot: {name}{what}{suffix}", tuple(color) if color is not None else None))

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
            Point size [m] (default: 1/60 of the cloud's drawn extent, smaller as the cube root
            of the count beyond 500 points so that thousands do not merge into a blot; at least 2 mm).
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
            size_m = max(data_extent(points) / 60.0 / max(1.0, (len(points) / 500.0) ** (1 / 3)), 0.002)
        self.vis[_node(name)].set_object(
            self._mg.PointCloud(points.T.astype(np.float32), rgb.T.astype(np.float32), size=size_m))
        self._add_data(points)
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
                            magnify: float | None = None, ghost: bool = True, vmin_mm: float | None = None,
                            vmax_mm: float | None = None) -> float:
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
            Magnification of the cloud about the nominal TCP (default: :func:`auto_magnification`
            drawing the largest error at most 0.8 m long and 40 % of the robot's drawn size, so
            the cloud does not hide the robot).
        ghost : bool
            Also draw, transparent, the as-built robot of the sample with the largest |dP|,
            its error vector scaled by the same factor (so its TCP sits, to first order,
            on that sample's magnified point).
        vmin_mm, vmax_mm : float, optional
            The colour bar's range [mm] (default: that of the samples drawn), e.g. the least and
            largest |dP| of a whole Monte Carlo run of which ``x`` are the first samples.

        Returns
        -------
        float
            The magnification used (also written in the legend).
        """
        from ..model.errors import ErrorModel
        from ..model.kinematics import pose_error, tcp_poses

        error_model = error_model or ErrorModel(robot)
        x = np.atleast_2d(np.asarray(x, dtype=float))
        q = robot.check_joint_values(np.asarray(q, dtype=float), source=f"{name}: q")
        nominal = tcp_poses(robot, q)
        actual = tcp_poses(robot, q, x, error_model)
        error = pose_error(nominal, actual)
        worst = int(np.argmax(error.position_norm))
        if magnify is None:
            size = float(np.max(self._robot_bounds.hi - self._robot_bounds.lo)) if not self._robot_bounds.empty \
                else 2.0
            magnify = auto_magnification(float(error.position_norm[worst]), drawn_m=min(0.8, 0.4 * size))
        self.add_point_cloud(actual.position, error.position_norm * 1000.0, name, "TCP error |dP| [mm]",
                             center_m=nominal.position[0], magnify=magnify, center_label="the nominal TCP",
                             vmin=vmin_mm, vmax=vmax_mm)
        self.add_points(nominal.position, f"{name}_nominal", COLORS["nominal_tcp"], size_m=0.02,
                        label="nominal TCP")
        if ghost:
            as_built = error_model.perturbed_robot(magnify * x[worst], name="as_built")
            base_error = bool(np.any(x[worst][error_model.base_slice]))
            self.add_robot(as_built, q, f"{name}_worst_as_built", color=COLORS["as_built"], opacity=0.35,
                           include_base=base_error, framed=False)
            self.legend[-1] = LegendEntry(
                f"as-built robot of the worst sample drawn (|dP| = {error.position_norm[worst] * 1000:.3g} mm), "
                f"errors x {magnify:g}", self.legend[-1].color)
        return magnify

    def add_points(self, points_m, name: str, color=(0.1, 0.35, 0.95), size_m: float = 0.01,
                   label: str | None = None) -> None:
        """Points in one colour (e.g. measured TCP positions), (N, 3) [m]; another colour when
        ``color`` is another legend entry's already."""
        points = _as_points(points_m, name)
        color = self._own_color(color)
        rgb = np.tile(np.asarray(color, dtype=np.float32)[:3, None], (1, len(points)))
        self.vis[_node(name)].set_object(
            self._mg.PointCloud(points.T.astype(np.float32), rgb, size=size_m))
        self._add_data(points)
        self.legend.append(LegendEntry(label or name, tuple(color)))

    def add_marker(self, point_m, name: str, label: str, *, radius_m: float, color=MARKER_COLOR) -> None:
        """A ring (three circles about the axes, ``radius_m`` [m]) around one point (3,) [m]: the
        measured point of the pose the robot is drawn at, so that it is found among the others."""
        centre = _as_points(point_m, name)[0]
        if not (math.isfinite(radius_m) and radius_m > 0):
            raise InputError(f"{name}: marker radius {radius_m} must be a positive number")
        color = self._own_color(color)
        angle = np.linspace(0.0, 2.0 * np.pi, 49)
        circle = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=1) * radius_m
        rings = [circle, circle[:, [2, 0, 1]], circle[:, [1, 2, 0]]]  # about z, x and y
        pairs = np.concatenate([np.stack([r[:-1], r[1:]], axis=1).reshape(-1, 3) for r in rings]) + centre
        self.vis[_node(name)]["ring"].set_object(self._mg.LineSegments(
            self._mg.PointsGeometry(pairs.T.astype(np.float32)),
            self._mg.LineBasicMaterial(color=meshcat_color(color), linewidth=2)))
        self._bounds.add(pairs)
        self._other_points.append(pairs)
        self.legend.append(LegendEntry(label, tuple(color)))

    def _own_color(self, color) -> tuple:
        """``color``, or the first of :data:`SPARE_COLORS` no legend entry has when it is taken."""
        def key(c):
            return tuple(int(round(255 * float(v))) for v in c[:3])

        taken = {key(e.color) for e in self.legend if e.color is not None}
        if key(color) not in taken:
            return tuple(float(v) for v in color[:3])
        spare = next((c for c in SPARE_COLORS if key(c) not in taken), None)
        if spare is None:
            raise InputError(f"colour {tuple(color)}: every spare colour of the legend is taken")
        return spare

    def _add_data(self, points: np.ndarray) -> None:
        self._bounds.add(points)
        self._data.append(points)

    def add_error_segments(self, start_m, end_m, magnify: float = 1.0, name: str = "errors", *,
                           start_label: str = "measured", end_label: str = "predicted",
                           start_color=COLORS["measured"], end_color=COLORS["predicted"],
                           size_m: float | None = None, max_drawn: int | None = MAX_SEGMENTS) -> np.ndarray:
        """Pairs of points joined by segments, the gap magnified.

        Parameters
        ----------
        start_m, end_m : array-like of shape (N, 3)
            e.g. measured and predicted TCP positions [m].
        magnify : float
            Each end is drawn at ``start + magnify * (end - start)``; the factor is
            written in the legend.
        start_color, end_color : RGB triple in 0..1, or None
            Colour of the points at the starts and at the ends; None draws none there
            (another layer, e.g. a point cloud coloured by a value, marks them already).
        size_m : float, optional
            Size of the points at both ends [m] (default: :func:`point_size` of the start
            points' extent).
        max_drawn : int or None, default=MAX_SEGMENTS
            Draw the segments (and their end points) of at most this many pairs, spread evenly
            over the start points with the largest error among them (:func:`spread_subset`);
            the legend says how many. None: all.

        Returns
        -------
        ndarray of int
            The indices of the pairs drawn.
        """
        start = _as_points(start_m, f"{name}: start")
        end = _as_points(end_m, f"{name}: end")
        if start.shape != end.shape:
            raise InputError(f"{name}: {len(start)} start points but {len(end)} end points")
        if not (math.isfinite(magnify) and magnify > 0):
            raise InputError(f"{name}: magnification {magnify} must be a positive number")
        if size_m is None:
            size_m = point_size(data_extent(start))
        n_pairs = len(start)
        drawn = np.arange(n_pairs) if max_drawn is None else spread_subset(
            start, int(max_drawn), keep=[int(np.argmax(np.linalg.norm(end - start, axis=1)))] if n_pairs else [])
        start, end = start[drawn], end[drawn]
        drawn_end = start + magnify * (end - start)
        segments = np.empty((2 * len(start), 3))
        segments[0::2], segments[1::2] = start, drawn_end
        mg = self._mg
        node = self.vis[_node(name)]
        for key, pts, rgb, label in (("start", start, start_color, start_label),
                                     ("end", drawn_end, end_color, end_label)):
            if rgb is None:
                continue
            rgb = self._own_color(rgb)  # every colour drawn gets a legend line of its own
            colors = np.tile(np.asarray(rgb, dtype=np.float32)[:3, None], (1, len(pts)))
            node[key].set_object(mg.PointCloud(pts.T.astype(np.float32), colors, size=size_m))
            self.legend.append(LegendEntry(label, rgb))
        segment_color = self._own_color(COLORS["segment"])
        node["segments"].set_object(mg.LineSegments(
            mg.PointsGeometry(segments.T.astype(np.float32)),
            mg.LineBasicMaterial(color=meshcat_color(segment_color))))
        for pts in (start, drawn_end):
            self._add_data(pts)
        said = ([f"segments magnified x {magnify:g}"] if magnify != 1.0 else []) + (
            [f"drawn for {len(drawn)} of the {n_pairs}, spread evenly, the largest among them"]
            if len(drawn) < n_pairs else [])
        self.legend.append(LegendEntry(f"line to the {end_label}" + (f" ({'; '.join(said)})" if said else ""),
                                       segment_color))
        return drawn

    def add_trajectory(self, points_m, name: str = "trajectory", color=COLORS["trajectory"]) -> None:
        """A polyline through (N, 3) points [m], in order."""
        points = _as_points(points_m, name)
        if len(points) < 2:
            raise InputError(f"{name}: a trajectory needs at least 2 points, got {len(points)}")
        mg = self._mg
        self.vis[_node(name)].set_object(mg.Line(
            mg.PointsGeometry(points.T.astype(np.float32)),
            mg.LineBasicMaterial(color=meshcat_color(color), linewidth=2)))
        self._add_data(points)
        self.legend.append(LegendEntry(name, tuple(color)))

    def add_frame(self, placement, name: str, length_m: float = 0.15, label: str | None = None) -> None:
        """Axes of a frame (pin.SE3 or (4, 4) matrix, in the base frame [m]) in red/green/blue
        for x/y/z; ``label`` (default ``name``) goes to the legend with the frame's origin in mm
        (meshcat draws no text, so the legend names the triad)."""
        matrix = np.asarray(getattr(placement, "homogeneous", placement), dtype=float)
        if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
            raise InputError(f"{name}: a frame needs a finite (4, 4) placement, got shape {matrix.shape}")
        node = self.vis[_node(name)]
        node.set_object(self._mg.triad(length_m))
        node.set_transform(matrix)
        self._bounds.add(matrix[None, :3, 3])
        self._other_points.append(matrix[None, :3, 3])
        origin = ", ".join(f"{v:.0f}" for v in matrix[:3, 3] * 1e3)
        self.legend.append(LegendEntry(f"{label or name}: triad x/y/z = red/green/blue, {length_m * 1e3:.0f} mm "
                                       f"long, origin ({origin}) mm in the base frame"))

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
    def framed_bounds(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(lower, upper) corners (3,) [m] of what the camera frames (see ``frame``), or None when
        nothing is drawn."""
        if self._frame == "data" and self._data:
            return framed_box(np.concatenate(self._data), self._robot_bounds.lo, self._robot_bounds.hi)
        return None if self._bounds.empty else (self._bounds.lo, self._bounds.hi)

    def _view_target(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(target, camera position) [m]: the one set, or :func:`camera_placement` of what the view
        frames (the page moves the camera along the same line for the canvas it gets: :meth:`_fit`)."""
        if self._camera is not None:
            return self._camera
        bounds = self.framed_bounds()
        if bounds is None:
            return None
        target, position, self.fit_radius_m = camera_placement(*bounds)
        return target, position

    def _finish(self) -> None:
        """Camera, ground grid and base axes, set once before output.

        meshcat's orbit camera always turns about the world origin, so the whole scene
        (everything lives under ``/meshcat``) is shifted to put the view target there; the
        camera is then placed relative to it in its parent's axes (three.js, y up: the
        base frame's (x, z, -y)). meshcat's own grid and axes would not follow the shift,
        so they are hidden and drawn again under ``/meshcat``.
        """
        from meshcat.transformations import translation_matrix

        view = self._view_target()
        if view is None or self._finished:
            return
        self._finished = True
        target, position = view
        mg = self._mg
        self.vis["/Grid"].set_property("visible", False)
        self.vis["/Axes"].set_property("visible", False)
        if self._grid:
            lo, hi, step = grid_extent(self._bounds.lo, self._bounds.hi, target)
            grid_color = self._own_color(GRID_COLOR)
            self.legend.append(LegendEntry(f"ground grid: the base's z = 0 plane, {step * 1e3:.0f} mm squares",
                                           grid_color))
            xs, ys = np.arange(lo[0], hi[0] + 1e-9, step), np.arange(lo[1], hi[1] + 1e-9, step)
            lines = [((x, ys[0], 0.0), (x, ys[-1], 0.0)) for x in xs]
            lines += [((xs[0], y, 0.0), (xs[-1], y, 0.0)) for y in ys]
            self.vis["ground_grid"].set_object(mg.LineSegments(
                mg.PointsGeometry(np.array(lines, dtype=np.float32).reshape(-1, 3).T),
                mg.LineBasicMaterial(color=meshcat_color(grid_color))))
        self.vis["base_axes"].set_object(mg.triad(self._axes_length()))
        self.legend.append(LegendEntry(f"robot base frame: triad x/y/z = red/green/blue, "
                                       f"{self._axes_length() * 1e3:.0f} mm long"))
        self.vis.set_transform(translation_matrix(-target))
        offset = position - target
        self.vis["/Cameras/default/rotated/<object>"].set_property(
            "position", [float(offset[0]), float(offset[2]), float(-offset[1])])

    def _axes_length(self) -> float:
        """Length [m] of the base frame's triad: a fifth of what the view frames, 5 cm to 0.5 m."""
        size = float(np.max(self._bounds.hi - self._bounds.lo)) if not self._bounds.empty else 1.0
        return float(np.clip(0.2 * size, 0.05, 0.5))

    def static_html(self) -> str:
        """One self-contained HTML page (meshcat's viewer, the scene, the legend); no server needed."""
        self._finish()
        return static_page(self._window, self.title, self._legend(), self._fit())

    def serve(self, open_browser: bool = False) -> LiveView:
        """Serve the scene live on 127.0.0.1 (a meshcat server subprocess).

        Returns a :class:`~tcr_accuracy.view.meshcat_page.LiveView` with the page's ``url``; call
        ``close()`` (or use it as a context manager) to stop the server. Further ``add_*``
        calls are not sent to a live view: build the scene first.
        """
        self._finish()
        return serve_page(self._window, self.title, self._legend(), open_browser, self._fit())

    def _legend(self) -> str:
        return legend_html(self.title, self.color_bars, self.legend, self.notes)

    def _fit(self) -> dict | None:
        """What the page needs to fit the camera to its canvas (:func:`page_fit`); None when the
        camera was set by hand."""
        if self.fit_radius_m is None or self._camera is not None:
            return None
        lo, hi = self.framed_bounds()
        data = np.concatenate(self._data) if self._data else np.zeros((0, 3))
        return page_fit(lo, hi, data, self._robot_points + (self._other_points if self._frame == "all" else []))


def _node(name: str) -> str:
    name = str(name).strip().strip("/")
    if not name or any(c in name for c in "<>\"'"):
        raise InputError(f"scene node name {name!r} is empty or has characters meshcat cannot use")
    return name
