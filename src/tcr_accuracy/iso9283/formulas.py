"""ISO 9283:1998 pose and distance characteristics from repeated measurements (the formulas).

Written from the standard's definitions (clauses 7.2, 7.3, 7.4 and 7.5). Inputs are in the
robot's base frame, already registered (see
:mod:`tcr_accuracy.iso9283.evaluate`, which fits the measurement frame first).

For a pose j visited n times with measured positions (x_i, y_i, z_i) and commanded
(x_c, y_c, z_c):

- barycentre ``x̄ = Σ x_i / n`` (and ȳ, z̄);
- pose accuracy ``AP_P = sqrt((x̄ - x_c)² + (ȳ - y_c)² + (z̄ - z_c)²)``, components
  ``AP_x = x̄ - x_c``, ``AP_y``, ``AP_z``;
- pose repeatability ``RP_l = l̄ + 3 S_l`` with ``l_i = |p_i - barycentre|``, ``l̄`` their
  mean and ``S_l = sqrt(Σ (l_i - l̄)² / (n - 1))``; not given below 3 visits;
- orientation, where measured: angles a, b, c are the measured orientation's deviation from
  the commanded one, as a rotation vector about the base frame's x, y, z axes
  (``log(R_measured R_commanded^T)``; for the small deviations of a pose test this is the
  standard's angle differences to first order, free of Euler-angle wrap-around):
  ``AP_a = ā - a_c`` with ``a_c = 0`` and ``RP_a = ±3 S_a``, ``S_a`` the standard
  deviation (n - 1) of the a_i; the same for b and c;
- multi-directional pose accuracy variation (7.2.3), where a pose is approached from
  several labelled directions h: ``vAP_P = max over h, k of |barycentre_h - barycentre_k|``,
  ``vAP_a = max |ā_h - ā_k|`` and so for b, c;
- distance accuracy and repeatability (7.3) between two poses A, B measured in the same
  cycles k: ``D_k = |p_Ak - p_Bk|``, ``D_c = |c_A - c_B|``, ``AD_P = D̄ - D_c``, components
  ``AD_x = D̄_x - D_cx`` with ``D_xk = x_Ak - x_Bk``, and ``RD = ±3 S_D``,
  ``S_D = sqrt(Σ (D_k - D̄)² / (n - 1))``; for every pair of poses with at least 3 cycles in
  common (the standard's own pair is P2-P4, the cube's space diagonal on the test plane).

Lengths are metres, angles radians; nothing here prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from ..exceptions import InputError

#: Fewest visits of a pose (or cycles of a pair) for a repeatability figure.
MIN_REPEATS = 3


@dataclass(frozen=True)
class PoseFigures:
    """ISO 9283 figures of one pose (one approach direction when they are labelled).

    Attributes
    ----------
    pose_id : int
    approach : int or None
        The approach label, None when the data carry none.
    n : int
        Visits.
    commanded : ndarray of shape (3,)
        Commanded position [m].
    barycentre : ndarray of shape (3,)
        Mean measured position [m].
    ap : float
        AP_P [m].
    ap_xyz : ndarray of shape (3,)
        AP_x, AP_y, AP_z [m].
    rp : float or None
        RP_l [m]; None below :data:`MIN_REPEATS` visits.
    l_mean, l_std : float or None
        l̄ and S_l [m] (S_l None below 2 visits).
    ap_abc : ndarray of shape (3,) or None
        AP_a, AP_b, AP_c [rad]; None without orientations.
    rp_abc : ndarray of shape (3,) or None
        RP_a, RP_b, RP_c (the ± half-width, 3 S) [rad]; None without orientations or
        below :data:`MIN_REPEATS` visits.
    """

    pose_id: int
    approach: int | None
    n: int
    commanded: np.ndarray
    barycentre: np.ndarray
    ap: float
    ap_xyz: np.ndarray
    rp: float | None
    l_mean: float
    l_std: float | None
    ap_abc: np.ndarray | None = None
    rp_abc: np.ndarray | None = None


@dataclass(frozen=True)
class DirectionalVariation:
    """vAP of one pose approached from several directions: ``vap`` [m], ``vap_abc`` (3,) [rad] or None."""

    pose_id: int
    approaches: tuple
    vap: float
    vap_abc: np.ndarray | None = None


@dataclass(frozen=True)
class DistanceFigures:
    """AD and RD between poses ``pose_a`` and ``pose_b`` over ``n`` common cycles [m]."""

    pose_a: int
    pose_b: int
    n: int
    commanded: float
    mean: float
    ad: float
    ad_xyz: np.ndarray
    rd: float


@dataclass(frozen=True)
class IsoFigures:
    """Every figure of one evaluation: ``poses``, ``directional``, ``distances`` and ``notes``
    (what could not be computed and why)."""

    poses: list
    directional: list = field(default_factory=list)
    distances: list = field(default_factory=list)
    notes: list = field(default_factory=list)


def pose_figures(positions, commanded, deviations=None, *, pose_id: int = 0,
                 approach: int | None = None) -> PoseFigures:
    """AP and RP of one pose.

    Parameters
    ----------
    positions : array-like of shape (n, 3)
        Measured positions in the base frame [m].
    commanded : array-like of shape (3,)
        Commanded position [m].
    deviations : array-like of shape (n, 3), optional
        Orientation deviations a, b, c of each visit [rad] (see the module docstring).
    """
    positions = np.atleast_2d(np.asarray(positions, dtype=float))
    commanded = np.asarray(commanded, dtype=float)
    n = positions.shape[0]
    barycentre = positions.mean(axis=0)
    ap_xyz = barycentre - commanded
    distances = np.linalg.norm(positions - barycentre, axis=1)
    l_mean = float(distances.mean())
    l_std = float(distances.std(ddof=1)) if n >= 2 else None
    rp = l_mean + 3.0 * l_std if n >= MIN_REPEATS else None
    ap_abc = rp_abc = None
    if deviations is not None:
        deviations = np.atleast_2d(np.asarray(deviations, dtype=float))
        ap_abc = deviations.mean(axis=0)
        rp_abc = 3.0 * deviations.std(axis=0, ddof=1) if n >= MIN_REPEATS else None
    return PoseFigures(pose_id=pose_id, approach=approach, n=n, commanded=commanded, barycentre=barycentre,
                       ap=float(np.linalg.norm(ap_xyz)), ap_xyz=ap_xyz, rp=rp, l_mean=l_mean, l_std=l_std,
                       ap_abc=ap_abc, rp_abc=rp_abc)


def distance_figures(a_positions, b_positions, a_commanded, b_commanded, *, pose_a: int, pose_b: int
                     ) -> DistanceFigures:
    """AD and RD between two poses from their positions (n, 3) [m] in matching cycle order."""
    d_xyz = np.asarray(a_positions, dtype=float) - np.asarray(b_positions, dtype=float)
    c_xyz = np.asarray(a_commanded, dtype=float) - np.asarray(b_commanded, dtype=float)
    d = np.linalg.norm(d_xyz, axis=1)
    commanded = float(np.linalg.norm(c_xyz))
    return DistanceFigures(pose_a=pose_a, pose_b=pose_b, n=len(d), commanded=commanded, mean=float(d.mean()),
                           ad=float(d.mean()) - commanded, ad_xyz=d_xyz.mean(axis=0) - c_xyz,
                           rd=3.0 * float(d.std(ddof=1)))


def iso_figures(pose_id, positions, commanded, *, deviations=None, cycle=None, approach=None) -> IsoFigures:
    """Every ISO 9283 figure the data allow.

    Parameters
    ----------
    pose_id : array-like of shape (N,)
        Which commanded pose each reading belongs to (integers).
    positions : array-like of shape (N, 3)
        Measured positions in the base frame [m].
    commanded : array-like of shape (N, 3)
        Commanded position of each reading [m] (the same for every reading of a pose).
    deviations : array-like of shape (N, 3), optional
        Orientation deviations a, b, c [rad].
    cycle : array-like of shape (N,), optional
        Cycle of each reading: enables the distance figures.
    approach : array-like of shape (N,), optional
        Approach direction label: figures per (pose, approach), and vAP per pose.
    """
    pose_id = np.asarray(pose_id).astype(int)
    positions = np.asarray(positions, dtype=float)
    commanded = np.asarray(commanded, dtype=float)
    labels = np.zeros(len(pose_id), dtype=int) if approach is None else np.asarray(approach).astype(int)
    notes = []
    poses = []
    for pid in np.unique(pose_id):
        for label in np.unique(labels[pose_id == pid]):
            rows = np.flatnonzero((pose_id == pid) & (labels == label))
            fig = pose_figures(positions[rows], commanded[rows[0]],
                               None if deviations is None else np.asarray(deviations)[rows], pose_id=int(pid),
                               approach=None if approach is None else int(label))
            poses.append(fig)
            if fig.rp is None:
                where = f"pose {pid}" + ("" if approach is None else f" approach {label}")
                notes.append(f"{where}: {fig.n} readings, no RP (the standard needs at least {MIN_REPEATS}; "
                             "it uses 30)")
    directional = []
    if approach is not None:
        for pid in np.unique(pose_id):
            group = [f for f in poses if f.pose_id == pid]
            if len(group) < 2:
                continue
            pairs = list(combinations(group, 2))
            vap = max(float(np.linalg.norm(a.barycentre - b.barycentre)) for a, b in pairs)
            vap_abc = None
            if deviations is not None:
                vap_abc = np.max([np.abs(a.ap_abc - b.ap_abc) for a, b in pairs], axis=0)
            directional.append(DirectionalVariation(int(pid), tuple(f.approach for f in group), vap, vap_abc))
    distances = []
    if cycle is None:
        notes.append("no cycle column: no distance accuracy (AD, RD needs the poses paired by cycle)")
    else:
        cycle = np.asarray(cycle).astype(int)
        ids = list(np.unique(pose_id))
        for a, b in combinations(ids, 2):
            rows_a = _one_per_cycle(pose_id, cycle, a)
            rows_b = _one_per_cycle(pose_id, cycle, b)
            common = sorted(set(rows_a) & set(rows_b))
            if len(common) < MIN_REPEATS:
                continue
            ra, rb = [rows_a[c] for c in common], [rows_b[c] for c in common]
            distances.append(distance_figures(positions[ra], positions[rb], commanded[ra[0]], commanded[rb[0]],
                                              pose_a=int(a), pose_b=int(b)))
    return IsoFigures(poses=poses, directional=directional, distances=distances, notes=notes)


def _one_per_cycle(pose_id, cycle, pid) -> dict:
    """cycle -> row of pose pid in that cycle (cycles where it was read more than once are left out)."""
    rows = np.flatnonzero(pose_id == pid)
    values, counts = np.unique(cycle[rows], return_counts=True)
    single = set(values[counts == 1].tolist())
    return {int(cycle[r]): int(r) for r in rows if int(cycle[r]) in single}


def check_repeats(pose_id, rows, source: str) -> None:
    """InputError naming the first pose measured only once (no spread can be computed)."""
    pose_id = np.asarray(pose_id).astype(int)
    values, counts = np.unique(pose_id, return_counts=True)
    once = values[counts < 2]
    if len(once):
        r = int(np.asarray(rows)[np.flatnonzero(pose_id == once[0])[0]])
        raise InputError(f"{source}: row {r}, column pose_id: pose {once[0]} has 1 reading; a pose test "
                         "measures each pose several times (ISO 9283: 30 cycles)")


__all__ = ["DirectionalVariation", "DistanceFigures", "IsoFigures", "MIN_REPEATS", "PoseFigures",
           "check_repeats", "distance_figures", "iso_figures", "pose_figures"]
