"""Where a 3D view's camera stands: what the view frames, and the camera that holds it on the canvas.

A view frames the robot drawn and its data, without the few far-out points that would shrink them
to a speck (:func:`framed_box`). Python places the camera on a fixed line of sight at the distance
that holds that box's sphere (:func:`camera_placement`); the page then moves it along the same line
to the nearest distance at which every point it must hold (:func:`page_fit`: the robots' joints
and body corners, the outline of the data) lies in the field of view of the canvas it gets,
whatever the window's shape (``meshcat_page``'s fitting script). Positions in metres, base frame.
"""

from __future__ import annotations

import math

import numpy as np

from .view_scales import spread_subset

#: meshcat's camera: its vertical field of view [deg] (``PerspectiveCamera(75, ...)`` in its main.js).
CAMERA_FOV_DEG = 75.0
#: The view holds what it frames with this margin (1: the outermost point touches the canvas' edge).
VIEW_MARGIN = 1.08
#: Where the camera looks from, in the base frame: in front, to the right, above.
VIEW_DIRECTION = (1.0, -0.55, 0.45)
#: The share of the data points (per axis, the central quantiles) and how far beyond them, as a
#: share of their extent, the view holds the data: a few far-out measurements do not shrink the
#: robot and the rest to a speck, and the outer layer of a grid of poses stays in view.
DATA_SHARE = 0.98
DATA_REACH = 0.25
#: The page fits the camera to at most this many of the data points besides their outline.
FIT_POINTS = 400


def framed_box(data_m, robot_lo_m, robot_hi_m) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners (3,) [m] of the data (N, 3) without far outliers (beyond the central
    :data:`DATA_SHARE` per axis by more than :data:`DATA_REACH` of its extent) and of the robots'
    box (``robot_lo_m``, ``robot_hi_m``; infinite when no robot is framed)."""
    data = np.asarray(data_m, dtype=float).reshape(-1, 3)
    low, high = np.quantile(data, [(1 - DATA_SHARE) / 2, (1 + DATA_SHARE) / 2], axis=0)
    reach = DATA_REACH * (high - low)  # the edge of a grid of points is no outlier
    lo = np.maximum(data.min(axis=0), low - reach)
    hi = np.minimum(data.max(axis=0), high + reach)
    robot_lo, robot_hi = np.asarray(robot_lo_m, dtype=float), np.asarray(robot_hi_m, dtype=float)
    if np.all(np.isfinite(robot_lo)):
        lo, hi = np.minimum(lo, robot_lo), np.maximum(hi, robot_hi)
    return lo, hi


def camera_placement(lo_m, hi_m) -> tuple[np.ndarray, np.ndarray, float]:
    """(target, camera position (3,) [m], radius [m]): looking at the box's centre along
    :data:`VIEW_DIRECTION` from the distance that holds the sphere about the box (radius: half its
    diagonal, at least 5 cm) in meshcat's vertical field of view with :data:`VIEW_MARGIN`."""
    lo, hi = np.asarray(lo_m, dtype=float), np.asarray(hi_m, dtype=float)
    target = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.05)
    distance = VIEW_MARGIN * radius / math.sin(math.radians(CAMERA_FOV_DEG) / 2)
    direction = np.asarray(VIEW_DIRECTION, dtype=float)
    return target, target + distance * direction / np.linalg.norm(direction), radius


def page_fit(lo_m, hi_m, data_m, held_m) -> dict:
    """What the page's fitting script needs: ``points_m``, the points the view must hold relative
    to the box's centre in three.js's axes (the base frame's (x, z, -y)) [m] (the data within the
    box, outlined by :func:`outline`, and every point of ``held_m``, a list of (N, 3) arrays: the
    robots' joints and body corners, and the frames and markers when the view frames all),
    ``margin`` and ``fov_deg``."""
    lo, hi = np.asarray(lo_m, dtype=float), np.asarray(hi_m, dtype=float)
    centre = 0.5 * (lo + hi)
    data = np.asarray(data_m, dtype=float).reshape(-1, 3)
    data = data[np.all((data >= lo - 1e-9) & (data <= hi + 1e-9), axis=1)]
    data = data[outline(data, FIT_POINTS)] if len(data) else data
    points = np.concatenate([data, *[np.asarray(h, dtype=float).reshape(-1, 3) for h in held_m]]) - centre
    if not len(points):
        points = np.array([lo, hi]) - centre
    return {"points_m": np.round(np.stack([points[:, 0], points[:, 2], -points[:, 1]], axis=1), 5).tolist(),
            "margin": VIEW_MARGIN, "fov_deg": CAMERA_FOV_DEG}


def outline(points_m, k: int) -> np.ndarray:
    """Indices of the points that outline (N, 3) points [m]: the vertices of their convex hull
    (qhull, through scipy), else the extremes along each axis and diagonal when they lie in a
    plane or a line, and an even spread of the others (:func:`spread_subset`) up to ``k``."""
    from scipy.spatial import ConvexHull, QhullError

    points = np.asarray(points_m, dtype=float).reshape(-1, 3)
    try:
        hull = ConvexHull(points).vertices if len(points) > 4 else np.arange(len(points))
    except QhullError:  # flat or too few: the extremes along each axis and each diagonal
        directions = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [1, -1, 1], [1, 1, -1], [-1, 1, 1]])
        along = points @ directions.T
        hull = np.unique(np.concatenate([along.argmin(axis=0), along.argmax(axis=0)]))
    return np.union1d(hull, spread_subset(points, k))
