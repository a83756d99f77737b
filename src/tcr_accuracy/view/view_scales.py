"""Sizes, factors and subsets a 3D view needs: how far to magnify, how large to draw, what to thin.

Pure functions of the data (positions [m], errors [m]); :class:`tcr_accuracy.view.viewer.Scene`
and the commands' views use them to choose a magnification that shows errors of tenths of a
millimetre on a 2 m robot (:func:`auto_magnification`, :func:`segment_magnification`,
:func:`ghost_magnification`), point and triad sizes that read at the data's extent
(:func:`point_size`, :func:`frame_axis_length`), the ground grid (:func:`grid_extent`), and an
evenly spread subset of thousands of points whose error segments would fill the page
(:func:`spread_subset`).
"""

from __future__ import annotations

import math

import numpy as np

from ..model.robot import RobotModel


def grid_extent(lo_m, hi_m, target_m) -> tuple[np.ndarray, np.ndarray, float]:
    """The ground grid around what a view frames: (lower corner (3,), upper corner (3,) [m],
    square side [m]). The side is 0.05, 0.1, 0.25, 0.5 or 1 m, the one giving at most 24
    squares along the longer side, and the grid reaches two squares beyond the bounds."""
    lo = np.minimum(np.asarray(lo_m, dtype=float), target_m)
    hi = np.maximum(np.asarray(hi_m, dtype=float), target_m)
    size = float(np.max((hi - lo)[:2]))
    step = next((s for s in (0.05, 0.1, 0.25, 0.5) if size / s <= 24), 1.0)
    return np.floor(lo / step - 2) * step, np.ceil(hi / step + 2) * step, step


def transform_points(matrix, points_m) -> np.ndarray:
    """Points (N, 3) [m] mapped by a (4, 4) homogeneous transform ``aMb`` (b -> a)."""
    matrix = np.asarray(matrix, dtype=float)
    return np.asarray(points_m, dtype=float) @ matrix[:3, :3].T + matrix[:3, 3]


def rotate_vectors(matrix, vectors_m) -> np.ndarray:
    """Displacements (N, 3) [m] turned by the rotation of a (4, 4) transform (no translation)."""
    return np.asarray(vectors_m, dtype=float) @ np.asarray(matrix, dtype=float)[:3, :3].T


def frame_axis_length(points_m) -> float:
    """A triad length [m] that reads next to points of this extent: a sixth of it, 5 cm to 0.5 m."""
    return float(np.clip(data_extent(points_m) / 6.0, 0.05, 0.5))


def ghost_magnification(robot: RobotModel, q, error_model, x, largest: float, drawn_m: float = 0.15) -> float:
    """The factor for an as-built ghost with error vector x (n_params,) at joint values q:
    at most ``largest`` (the view's factor) and small enough that the ghost's TCP moves at
    most about ``drawn_m`` [m] (its rotation counted at 1 m), so a ghost never leaves the view."""
    from ..model.kinematics import pose_error, tcp_poses

    x = np.asarray(x, dtype=float)
    if not np.any(x):
        return 1.0
    q = np.atleast_2d(np.asarray(q, dtype=float))
    error = pose_error(tcp_poses(robot, q), tcp_poses(robot, q, x[None], error_model))
    moved = float(error.position_norm[0] + np.linalg.norm(np.asarray(error.rotation_vector)[0]))
    return max(1.0, min(float(largest), auto_magnification(moved, drawn_m=drawn_m)))


def data_extent(points_m) -> float:
    """The largest side of the bounding box of (N, 3) points [m] (0 for fewer than two)."""
    points = np.asarray(points_m, dtype=float).reshape(-1, 3)
    return float(np.max(np.ptp(points, axis=0))) if len(points) > 1 else 0.0


def point_size(extent_m: float) -> float:
    """A point size [m] that reads at a glance when the view frames data of this extent
    (1/70 of it, between 3 mm and 8 cm)."""
    return float(np.clip(extent_m / 70.0, 0.003, 0.08))


def segment_magnification(largest_error_m: float, extent_m: float) -> float:
    """A round factor that draws the largest error segment about 15 % of the data's extent
    long (at least 5 cm), so the segments read against the spread of the points."""
    return auto_magnification(largest_error_m, drawn_m=max(0.15 * extent_m, 0.05))


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


def spread_subset(points_m, k: int, keep=()) -> np.ndarray:
    """Indices of at most ``k`` of the (N, 3) points [m], spread evenly over them: the points are
    binned into cubic cells, as small as leave at most ``k`` cells occupied, and each cell gives
    the point nearest the mean of its points; the indices of ``keep`` (e.g. the largest error)
    take their cell's place. All of them when N <= k. Sorted, deterministic.
    """
    points = np.asarray(points_m, dtype=float).reshape(-1, 3)
    n = len(points)
    if n <= k:
        return np.arange(n)
    low = points.min(axis=0)
    extent = max(float(np.max(np.ptp(points, axis=0))), 1e-9)

    def cells(side: float) -> np.ndarray:
        index = np.floor((points - low) / side).astype(np.int64)
        return np.unique(index, axis=0, return_inverse=True)[1].reshape(-1)

    small, large = extent / (4.0 * math.ceil(n ** (1 / 3)) + 1.0), extent * 1.01  # many cells .. one cell
    for _ in range(40):  # bisect the cell side for the most cells within k
        side = 0.5 * (small + large)
        if cells(side).max() + 1 > k:
            small = side
        else:
            large = side
    label = cells(large)
    chosen = {}
    for c in range(label.max() + 1):
        members = np.flatnonzero(label == c)
        centre = points[members].mean(axis=0)
        chosen[c] = int(members[np.argmin(np.linalg.norm(points[members] - centre, axis=1))])
    for i in keep:
        chosen[int(label[int(i)])] = int(i)
    return np.array(sorted(chosen.values()))
