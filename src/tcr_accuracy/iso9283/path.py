"""ISO 9283:1998 path characteristics from a measured path (the formulas, clause 8).

A path test runs one commanded path n times (cycles); the instrument streams the TCP position
with time stamps. Inputs here are in the robot's base frame, already registered
(:mod:`tcr_accuracy.iso9283.path_evaluate` does that). Written from the standard's definitions:

- the path is cut by m planes normal to the commanded path at evenly spaced arc lengths
  ``s_i = L (i - 1/2) / m`` (planes within 5 % of the path's length of a corner are left out:
  there the normal planes of the two edges cross); the attained point of cycle j in plane i is
  where the measured stream crosses that plane going forward (linear interpolation between the
  two readings on either side; of several crossings the one nearest the commanded point, and
  none farther than a tenth of the path's length);
- path accuracy ``AT_P = max_i |bar_i - c_i|`` with ``bar_i`` the barycentre of the attained
  points of plane i and ``c_i`` the commanded point;
- path repeatability ``RT_P = max_i (l̄_i + 3 S_li)`` with ``l_ij = |p_ij - bar_i|``, ``l̄_i``
  their mean and ``S_li = sqrt(Σ_j (l_ij - l̄_i)² / (n - 1))``;
- corner deviations at each corner K passed at speed (incoming direction a, outgoing b: the
  chords of its straight edges, from the corner or path end before it and to the one after): the
  cornering round-off error ``CR`` is the smallest distance from K to the attained path, the
  cornering overshoot ``CO`` the largest excursion beyond K in the incoming direction after
  turning, ``max((p - K)·a)`` over the readings past the corner (``(p - K)·b > 0``), 0 when the
  robot cuts the corner; both per cycle, reported as mean and largest over the cycles;
- path velocity characteristics over the part of the path commanded at constant speed
  ``v_c`` (where the commanded speed is within 0.1 % of it; without commanded times, the middle
  half of the path): the speed between neighbouring planes (not across a corner's zone) ``v_ij = |p_{i+1,j} - p_ij| /
  (t_{i+1,j} - t_ij)``; path velocity accuracy ``AV = (v̄ - v_c) / v_c`` (in %) with ``v̄``
  the mean of all v_ij, repeatability ``RV = 3 S_v / v_c`` (in %) with ``S_v`` the standard
  deviation (n - 1) of the cycles' mean speeds, fluctuation ``FV = max_j (max_i v_ij - min_i
  v_ij)``.

Lengths are metres, times seconds, speeds m/s; nothing here prints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import InputError

#: Planes nearer a corner than this fraction of the path's length are left out.
CORNER_ZONE = 0.05
#: A crossing farther from the commanded point than this fraction of the path's length is no crossing.
CROSSING_LIMIT = 0.10
#: The commanded speed is constant where it is within this fraction of the path speed.
CONSTANT_SPEED = 0.001
#: Fewest cycles for a repeatability figure.
MIN_CYCLES = 2


@dataclass(frozen=True)
class Corner:
    """Corner deviations at one corner: ``point`` (3,) [m]; ``cr``, ``co`` (n_cycles,) [m] per cycle
    (NaN where a cycle did not pass it)."""

    point: np.ndarray
    cr: np.ndarray
    co: np.ndarray


@dataclass(frozen=True)
class PathFigures:
    """The path characteristics of one commanded path at one speed.

    Attributes
    ----------
    n_cycles : int
    s : ndarray of shape (m,)
        Arc length of each normal plane [m].
    commanded : ndarray of shape (m, 3)
        Commanded point of each plane [m].
    attained : ndarray of shape (n_cycles, m, 3)
        Attained points [m] (NaN where a cycle did not cross the plane).
    times : ndarray of shape (n_cycles, m)
        Crossing times [s] (NaN likewise).
    at : float
        AT_P [m]; ``at_s`` the arc length of its plane [m].
    rt : float or None
        RT_P [m] (None below :data:`MIN_CYCLES` cycles); ``rt_s`` its plane's arc length.
    deviation : ndarray of shape (m,)
        |bar_i - c_i| [m] per plane.
    rt_planes : ndarray of shape (m,)
        l̄_i + 3 S_li [m] per plane (NaN below MIN_CYCLES crossings).
    corners : list of Corner
    speed : float or None
        v_c, the commanded path speed [m/s].
    av, rv : float or None
        AV and RV [fraction of v_c] (None without a commanded speed, or RV below MIN_CYCLES).
    fv : float or None
        FV [m/s].
    v_mean : float or None
        v̄ [m/s].
    missed : int
        (cycle, plane) pairs without a crossing.
    """

    n_cycles: int
    s: np.ndarray
    commanded: np.ndarray
    attained: np.ndarray
    times: np.ndarray
    at: float
    at_s: float
    rt: float | None
    rt_s: float | None
    deviation: np.ndarray
    rt_planes: np.ndarray
    corners: list
    speed: float | None
    av: float | None
    rv: float | None
    fv: float | None
    v_mean: float | None
    missed: int


def normal_planes(points, s, m: int, corners=()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(s_i (k,), c_i (k, 3), unit tangents (k, 3)) of the normal planes along a sampled path, the
    ones near a corner left out (see the module docstring).

    Parameters
    ----------
    points : array-like of shape (N, 3)
        The commanded path [m], densely sampled.
    s : array-like of shape (N,)
        Its arc length [m].
    m : int
        Planes before the corners' are left out.
    corners : sequence of int
        Sample indices of the corners.
    """
    points, s = np.asarray(points, dtype=float), np.asarray(s, dtype=float)
    length = s[-1]
    s_i = length * (np.arange(m) + 0.5) / m
    if len(corners):
        near = np.min(np.abs(s_i[:, None] - s[list(corners)][None]), axis=1) < CORNER_ZONE * length
        s_i = s_i[~near]
    seg = np.clip(np.searchsorted(s, s_i, side="right") - 1, 0, len(s) - 2)
    frac = (s_i - s[seg]) / (s[seg + 1] - s[seg])
    c = points[seg] + frac[:, None] * (points[seg + 1] - points[seg])
    # the tangent: the chord over the neighbouring samples (exact on a straight edge, second order on a curve)
    lo, hi = np.maximum(seg - 1, 0), np.minimum(seg + 2, len(s) - 1)
    lo = np.where(np.isin(seg, list(corners)), seg, lo)
    hi = np.where(np.isin(seg + 1, list(corners)), seg + 1, hi)
    tangent = points[hi] - points[lo]
    return s_i, c, tangent / np.linalg.norm(tangent, axis=1, keepdims=True)


def plane_crossings(positions, times, centres, tangents, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """Where and when one cycle's stream crosses each normal plane going forward.

    Parameters
    ----------
    positions : array-like of shape (K, 3)
        The cycle's readings in time order [m].
    times : array-like of shape (K,)
        Their times [s].
    centres, tangents : array-like of shape (k, 3)
        The planes' commanded points [m] and unit normals (the path's tangents).
    limit : float
        Farthest a crossing may lie from its commanded point [m].

    Returns
    -------
    points : ndarray of shape (k, 3)
        The crossing points [m], NaN where none.
    when : ndarray of shape (k,)
        The crossing times [s], NaN where none.
    """
    x, t = np.asarray(positions, dtype=float), np.asarray(times, dtype=float)
    centres, tangents = np.asarray(centres, dtype=float), np.asarray(tangents, dtype=float)
    points = np.full((len(centres), 3), np.nan)
    when = np.full(len(centres), np.nan)
    block = max(1, PLANE_BLOCK // max(len(x), 1))  # planes per block: memory bounded whatever --planes is
    for start in range(0, len(centres), block):
        rows = slice(start, start + block)
        _crossings_into(x, t, centres[rows], tangents[rows], limit, points[rows], when[rows])
    return points, when


#: Plane-to-reading distances held at once by :func:`plane_crossings` (32 MB of float64).
PLANE_BLOCK = 4_000_000


def _crossings_into(x, t, centres, tangents, limit, points, when) -> None:
    """:func:`plane_crossings` for one block of planes, written into ``points`` and ``when``."""
    d = tangents @ x.T - np.sum(centres * tangents, axis=1)[:, None]  # (k, K) signed distances to the planes
    plane, k = np.nonzero((d[:, :-1] < 0) & (d[:, 1:] >= 0))
    if not len(plane):
        return
    w = -d[plane, k] / (d[plane, k + 1] - d[plane, k])
    y = x[k] + w[:, None] * (x[k + 1] - x[k])
    ty = t[k] + w * (t[k + 1] - t[k])
    gap = np.linalg.norm(y - centres[plane], axis=1)
    order = np.lexsort((gap, plane))  # per plane, nearest first
    first = order[np.r_[True, plane[order][1:] != plane[order][:-1]]]
    keep = first[gap[first] <= limit]
    points[plane[keep]], when[plane[keep]] = y[keep], ty[keep]


def corner_deviations(points, corners, cycles) -> list:
    """CR and CO per corner and cycle (see the module docstring).

    Parameters
    ----------
    points : array-like of shape (N, 3)
        The commanded path [m].
    corners : sequence of int
        Sample indices of its corners.
    cycles : list of ndarray of shape (K, 3)
        Each cycle's readings in time order [m].

    Returns
    -------
    list of Corner
    """
    points = np.asarray(points, dtype=float)
    marks = [0, *corners, len(points) - 1]
    out = []
    for n, k in enumerate(corners):
        corner = points[k]
        a = corner - points[marks[n]]  # the edges' directions over their whole length (the samples are IK
        b = points[marks[n + 2]] - corner  # solutions: a neighbour's chord turns by their error)
        reach = 0.5 * min(np.linalg.norm(a), np.linalg.norm(b))
        a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
        cr, co = np.full(len(cycles), np.nan), np.full(len(cycles), np.nan)
        for j, x in enumerate(cycles):
            near = np.flatnonzero(np.linalg.norm(x - corner, axis=1) < reach)
            if len(near) < 2:
                continue
            run = np.split(near, np.flatnonzero(np.diff(near) > 1) + 1)
            seg = max(run, key=len)  # the pass by the corner (not a later visit of the same place)
            p = x[seg]
            cr[j] = _distance_to_polyline(corner, p)
            past = (p - corner) @ b > 0
            co[j] = max(0.0, float(np.max((p[past] - corner) @ a))) if past.any() else 0.0
        out.append(Corner(corner, cr, co))
    return out


def _distance_to_polyline(point, polyline) -> float:
    """Smallest distance [m] from ``point`` (3,) to the segments of ``polyline`` (K, 3)."""
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    w = np.clip(np.einsum("kc,kc->k", point - a, ab) / np.maximum(np.einsum("kc,kc->k", ab, ab), 1e-300), 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + w[:, None] * ab - point, axis=1)))


def path_figures(points, s, cycles, *, planes: int = 100, corners=(), commanded_times=None,
                 speed: float | None = None) -> PathFigures:
    """Every path characteristic of one commanded path at one speed (see the module docstring).

    Parameters
    ----------
    points : array-like of shape (N, 3)
        The commanded path [m], densely sampled.
    s : array-like of shape (N,)
        Its arc length [m].
    cycles : list of (ndarray of shape (K,), ndarray of shape (K, 3))
        Each cycle's reading times [s] and positions [m], in time order.
    planes : int, default=100
        Normal planes along the path (before those near corners are left out).
    corners : sequence of int
        Sample indices of the corners passed at speed.
    commanded_times : array-like of shape (N,), optional
        The commanded time of each sample [s]: where the commanded speed is constant.
    speed : float, optional
        The commanded path speed v_c [m/s]; default the largest commanded speed, if times are given.

    Returns
    -------
    PathFigures

    Raises
    ------
    InputError
        No plane was crossed by any cycle.
    """
    points, s = np.asarray(points, dtype=float), np.asarray(s, dtype=float)
    s_i, c, tangent = normal_planes(points, s, planes, corners)
    limit = CROSSING_LIMIT * s[-1]
    found = [plane_crossings(x, t, c, tangent, limit) for t, x in cycles]
    attained = np.array([f[0] for f in found]).reshape(len(cycles), len(c), 3)
    times = np.array([f[1] for f in found]).reshape(len(cycles), len(c))
    crossed = np.isfinite(times)
    if not crossed.any():
        raise InputError("no cycle of the measured path crosses the commanded path's normal planes (another path, "
                         "another frame, or the stream does not follow the path)")
    count = crossed.sum(axis=0)
    with np.errstate(invalid="ignore"):
        bar = np.nanmean(np.where(crossed[..., None], attained, np.nan), axis=0)
    deviation = np.linalg.norm(bar - c, axis=1)
    at_k = int(np.nanargmax(deviation))
    l = np.linalg.norm(attained - bar[None], axis=2)
    rt_planes = np.full(len(c), np.nan)
    for i in np.flatnonzero(count >= MIN_CYCLES):
        li = l[crossed[:, i], i]
        rt_planes[i] = li.mean() + 3.0 * li.std(ddof=1)
    rt_k = int(np.nanargmax(rt_planes)) if np.isfinite(rt_planes).any() else None
    speed, av, rv, fv, v_mean = _velocity(s, s_i, attained, times, commanded_times, speed)
    return PathFigures(
        n_cycles=len(cycles), s=s_i, commanded=c, attained=attained, times=times, at=float(deviation[at_k]),
        at_s=float(s_i[at_k]), rt=None if rt_k is None else float(rt_planes[rt_k]),
        rt_s=None if rt_k is None else float(s_i[rt_k]), deviation=deviation, rt_planes=rt_planes,
        corners=corner_deviations(points, corners, [x for _, x in cycles]), speed=speed, av=av, rv=rv, fv=fv,
        v_mean=v_mean, missed=int((~crossed).sum()))


def _velocity(s, s_i, attained, times, commanded_times, speed):
    """(v_c, AV, RV, FV, v̄) over the planes commanded at constant speed (see the module docstring)."""
    if commanded_times is not None:
        commanded_times = np.asarray(commanded_times, dtype=float)
        v = np.gradient(s, commanded_times)
        speed = float(np.max(v)) if speed is None else speed
        steady = np.interp(s_i, s, v) >= (1 - CONSTANT_SPEED) * speed
    elif speed is not None:
        steady = (s_i > 0.25 * s[-1]) & (s_i < 0.75 * s[-1])
    else:
        return None, None, None, None, None
    adjacent = np.diff(s_i) < 1.5 * np.min(np.diff(s_i))  # no plane left out between (a corner's zone)
    pair = steady[:-1] & steady[1:] & adjacent
    dt = np.diff(times, axis=1)[:, pair]
    dp = np.linalg.norm(np.diff(attained, axis=1), axis=2)[:, pair]
    with np.errstate(invalid="ignore", divide="ignore"):
        v_ij = np.where(dt > 0, dp / dt, np.nan)
    if not np.isfinite(v_ij).any():
        return speed, None, None, None, None
    v_mean = float(np.nanmean(v_ij))
    cycle_means = np.array([np.nanmean(row) for row in v_ij if np.isfinite(row).any()])
    rv = 3.0 * float(cycle_means.std(ddof=1)) / speed if len(cycle_means) >= MIN_CYCLES else None
    fv = float(max(np.nanmax(row) - np.nanmin(row) for row in v_ij if np.isfinite(row).any()))
    return speed, (v_mean - speed) / speed, rv, fv, v_mean


__all__ = ["CORNER_ZONE", "CROSSING_LIMIT", "Corner", "MIN_CYCLES", "PathFigures", "corner_deviations",
           "normal_planes", "path_figures", "plane_crossings"]
