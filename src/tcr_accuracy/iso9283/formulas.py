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
  mean and ``S_l = sqrt(Σ (l_i - l̄)² / (n - 1))``; not given below 3 visits (l̄ and S_l
  from 2, AP alone from 1: a series may read most poses once; the standard's 30 cycles are
  said against each pose's n, not required);
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
  common (the standard's own pair is P2-P4, the cube's space diagonal on the test plane),
  within one approach direction;
- pose stabilisation time and overshoot (7.5, 7.6), where a visit is a stream of time-stamped
  readings ending at the attained pose p_end: with ``d(t) = |p(t) - p_end|`` and a limit band
  of radius r (the manufacturer's, else the pose's RP), the robot first enters the band at
  t_in (the first reading with d <= r); the stabilisation time is from t_in to the first
  reading after which d stays <= r (0 when it never leaves again), and the overshoot is the
  largest d after t_in when the robot leaves the band again, else 0; figures per pose are
  the mean and the largest over its visits. Times are the readings' own: the resolution is
  the sampling interval.

Poses, cycles and approach directions are labels (``P1``, ``S01.P1``, ``3``), compared as
text and ordered naturally (:func:`label_key`). Lengths are metres, angles radians, times
seconds; nothing here prints.
"""

from __future__ import annotations

from dataclasses import dataclass, field
import re
from itertools import combinations

import numpy as np

from ..exceptions import InputError

#: Fewest visits of a pose (or cycles of a pair) for a repeatability figure RP (RD): with two, both
#: readings lie the same distance from their barycentre, S_l is 0 by construction and l̄ + 3 S_l
#: would be half their distance, about a third of the spread the standard's RP describes.
MIN_REPEATS = 3
#: The standard's cycles per pose (ISO 9283, 7.2.1): a pose read fewer times is evaluated, and said.
STANDARD_CYCLES = 30



def label_key(label) -> tuple:
    """Sort key of a label: whole numbers by value first, then names with their digit runs
    compared as numbers (``P2`` before ``P10``, ``S01.P5`` before ``S02.P1``)."""
    text = str(label)
    if re.fullmatch(r"[+-]?\d+", text):
        return (0, int(text), ())
    return (1, 0, tuple((0, int(part), "") if part.isdigit() else (1, 0, part) for part in re.findall(r"\d+|\D+", text)))


def pose_name(label) -> str:
    """How a pose is named in tables: ``P3`` for the label ``3``, any other label as it is."""
    text = str(label)
    return f"P{text}" if re.fullmatch(r"\d+", text) else text


def ordered(labels) -> list:
    """The distinct labels in natural order (:func:`label_key`)."""
    return sorted(set(str(v) for v in labels), key=label_key)


def as_labels(values) -> np.ndarray:
    """(N,) object array of str labels from any labels (numbers, text)."""
    return np.array([str(v) for v in np.asarray(values, dtype=object).ravel()], dtype=object)


@dataclass(frozen=True)
class PoseFigures:
    """ISO 9283 figures of one pose (one approach direction when they are labelled).

    Attributes
    ----------
    pose_id : str
        The pose's label.
    approach : str or None
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
        l̄ [m] (None for one visit: no spread) and S_l [m] (None below :data:`MIN_REPEATS` visits:
        with two, both distances are equal and S_l is 0 by construction).
    ap_abc : ndarray of shape (3,) or None
        AP_a, AP_b, AP_c [rad]; None without orientations.
    rp_abc : ndarray of shape (3,) or None
        RP_a, RP_b, RP_c (the ± half-width, 3 S) [rad]; None without orientations or
        below :data:`MIN_REPEATS` visits.
    """

    pose_id: str
    approach: str | None
    n: int
    commanded: np.ndarray
    barycentre: np.ndarray
    ap: float
    ap_xyz: np.ndarray
    rp: float | None
    l_mean: float | None
    l_std: float | None
    ap_abc: np.ndarray | None = None
    rp_abc: np.ndarray | None = None


@dataclass(frozen=True)
class DirectionalVariation:
    """vAP of one pose approached from several directions: ``vap`` [m], ``vap_abc`` (3,) [rad] or None."""

    pose_id: str
    approaches: tuple
    vap: float
    vap_abc: np.ndarray | None = None


@dataclass(frozen=True)
class DistanceFigures:
    """AD and RD between poses ``pose_a`` and ``pose_b`` over ``n`` common cycles [m] (``approach``:
    the direction both were approached from, None when unlabelled)."""

    pose_a: str
    pose_b: str
    n: int
    commanded: float
    mean: float
    ad: float
    ad_xyz: np.ndarray
    rd: float
    approach: str | None = None


@dataclass(frozen=True)
class Stabilisation:
    """Pose stabilisation time and overshoot of one pose over its streamed visits.

    Attributes
    ----------
    pose_id : str
    approach : str or None
    n : int
        Visits with a stream of readings.
    band : float
        Radius of the limit band [m].
    time_mean, time_max : float or None
        Stabilisation time [s], mean and largest over the visits that entered the band.
    overshoot_mean, overshoot_max : float or None
        Overshoot [m], likewise.
    never_entered : int
        Visits whose readings never came within the band.
    """

    pose_id: str
    approach: str | None
    n: int
    band: float
    time_mean: float | None
    time_max: float | None
    overshoot_mean: float | None
    overshoot_max: float | None
    never_entered: int = 0


@dataclass(frozen=True)
class IsoFigures:
    """Every figure of one evaluation: ``poses``, ``directional``, ``distances``, ``stabilisation``
    and ``notes`` (what could not be computed and why)."""

    poses: list
    directional: list = field(default_factory=list)
    distances: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    stabilisation: list = field(default_factory=list)


def pose_figures(positions, commanded, deviations=None, *, pose_id="1", approach=None) -> PoseFigures:
    """AP and RP of one pose.

    Parameters
    ----------
    positions : array-like of shape (n, 3)
        Measured positions in the base frame [m].
    commanded : array-like of shape (3,)
        Commanded position [m].
    deviations : array-like of shape (n, 3), optional
        Orientation deviations a, b, c of each visit [rad] (see the module docstring).
    pose_id, approach : str
        Labels carried into the result.

    Returns
    -------
    PoseFigures
    """
    positions = np.atleast_2d(np.asarray(positions, dtype=float))
    commanded = np.asarray(commanded, dtype=float)
    n = positions.shape[0]
    barycentre = positions.mean(axis=0)
    ap_xyz = barycentre - commanded
    distances = np.linalg.norm(positions - barycentre, axis=1)
    l_mean = float(distances.mean()) if n >= 2 else None
    l_std = float(distances.std(ddof=1)) if n >= MIN_REPEATS else None
    rp = l_mean + 3.0 * l_std if n >= MIN_REPEATS else None
    ap_abc = rp_abc = None
    if deviations is not None:
        deviations = np.atleast_2d(np.asarray(deviations, dtype=float))
        ap_abc = deviations.mean(axis=0)
        rp_abc = 3.0 * deviations.std(axis=0, ddof=1) if n >= MIN_REPEATS else None
    return PoseFigures(pose_id=str(pose_id), approach=None if approach is None else str(approach), n=n,
                       commanded=commanded, barycentre=barycentre, ap=float(np.linalg.norm(ap_xyz)), ap_xyz=ap_xyz,
                       rp=rp, l_mean=l_mean, l_std=l_std, ap_abc=ap_abc, rp_abc=rp_abc)


def distance_figures(a_positions, b_positions, a_commanded, b_commanded, *, pose_a, pose_b, approach=None
                     ) -> DistanceFigures:
    """AD and RD between two poses from their positions (n, 3) [m] in matching cycle order."""
    d_xyz = np.asarray(a_positions, dtype=float) - np.asarray(b_positions, dtype=float)
    c_xyz = np.asarray(a_commanded, dtype=float) - np.asarray(b_commanded, dtype=float)
    d = np.linalg.norm(d_xyz, axis=1)
    commanded = float(np.linalg.norm(c_xyz))
    return DistanceFigures(pose_a=str(pose_a), pose_b=str(pose_b), n=len(d), commanded=commanded,
                           mean=float(d.mean()), ad=float(d.mean()) - commanded, ad_xyz=d_xyz.mean(axis=0) - c_xyz,
                           rd=3.0 * float(d.std(ddof=1)), approach=None if approach is None else str(approach))


def settling(times, positions, band: float) -> tuple[float | None, float | None]:
    """Stabilisation time [s] and overshoot [m] of one visit (see the module docstring).

    Parameters
    ----------
    times : array-like of shape (k,)
        Time of each reading [s], increasing; the last reading is the attained pose.
    positions : array-like of shape (k, 3)
        The readings [m].
    band : float
        Radius of the limit band [m].

    Returns
    -------
    tuple of (float or None, float or None)
        (None, None) when no reading came within the band.
    """
    times = np.asarray(times, dtype=float)
    positions = np.asarray(positions, dtype=float)
    d = np.linalg.norm(positions - positions[-1], axis=1)
    inside = d <= band
    first = int(np.argmax(inside))
    if not inside[first]:
        return None, None
    left = np.flatnonzero(~inside[first:])
    if not len(left):
        return 0.0, 0.0
    settled = first + int(left[-1]) + 1  # the first reading of the last run inside the band
    return float(times[settled] - times[first]), float(d[first:].max())


def iso_figures(pose_id, positions, commanded, *, deviations=None, cycle=None, approach=None) -> IsoFigures:
    """Every ISO 9283 figure the data allow.

    Parameters
    ----------
    pose_id : array-like of shape (N,)
        Which commanded pose each reading belongs to (labels: text or whole numbers).
    positions : array-like of shape (N, 3)
        Measured positions in the base frame [m].
    commanded : array-like of shape (N, 3)
        Commanded position of each reading [m] (the same for every reading of a pose).
    deviations : array-like of shape (N, 3), optional
        Orientation deviations a, b, c [rad].
    cycle : array-like of shape (N,), optional
        Cycle of each reading (labels): enables the distance figures.
    approach : array-like of shape (N,), optional
        Approach direction label: figures per (pose, approach), vAP per pose, distances per
        approach.

    Returns
    -------
    IsoFigures
    """
    pose_id = as_labels(pose_id)
    positions = np.asarray(positions, dtype=float)
    commanded = np.asarray(commanded, dtype=float)
    labels = as_labels(np.zeros(len(pose_id), dtype=int) if approach is None else approach)
    notes = []
    poses = []
    for pid in ordered(pose_id):
        for label in ordered(labels[pose_id == pid]):
            rows = np.flatnonzero((pose_id == pid) & (labels == label))
            poses.append(pose_figures(positions[rows], commanded[rows[0]],
                                      None if deviations is None else np.asarray(deviations)[rows], pose_id=pid,
                                      approach=None if approach is None else label))
    notes += cycle_notes(poses, approach is not None)
    directional = []
    if approach is not None:
        for pid in ordered(pose_id):
            group = [f for f in poses if f.pose_id == pid]
            if len(group) < 2:
                continue
            pairs = list(combinations(group, 2))
            vap = max(float(np.linalg.norm(a.barycentre - b.barycentre)) for a, b in pairs)
            vap_abc = None
            if deviations is not None:
                vap_abc = np.max([np.abs(a.ap_abc - b.ap_abc) for a, b in pairs], axis=0)
            directional.append(DirectionalVariation(pid, tuple(f.approach for f in group), vap, vap_abc))
    distances = []
    if cycle is None:
        notes.append("no cycle column: no distance accuracy (AD, RD needs the poses paired by cycle)")
    else:
        distances, said = _distances(pose_id, labels, as_labels(cycle), positions, commanded, approach is not None)
        notes += said
    return IsoFigures(poses=poses, directional=directional, distances=distances, notes=notes)


def cycle_notes(poses, labelled: bool = False) -> list:
    """What the poses' counts leave out, one note per count below :data:`MIN_REPEATS` (a few names
    each), and how many poses were read fewer than the standard's :data:`STANDARD_CYCLES` times."""
    def name(f):
        return pose_name(f.pose_id) + (f" ({f.approach})" if labelled else "")

    notes = []
    for n, words in ((1, "read once: AP only"), (2, "read twice: AP, l̄ and S_l, no RP")):
        few = [f for f in poses if f.n == n]
        if few:
            shown = ", ".join(name(f) for f in few[:5]) + (f" and {len(few) - 5} more" if len(few) > 5 else "")
            notes.append(f"{len(few)} pose(s) {words} (RP needs at least {MIN_REPEATS} readings): {shown}")
    short = [f.n for f in poses if f.n < STANDARD_CYCLES]
    if short:
        counts = f"{min(short)}-{max(short)} readings" if min(short) != max(short) else f"{short[0]} readings each"
        notes.append(f"{len(short)} of {len(poses)} pose(s) read fewer times than the standard's {STANDARD_CYCLES} "
                     f"cycles ({counts}): evaluated, their figures less certain than the standard's")
    return notes


def _distances(pose_id, labels, cycle, positions, commanded, labelled: bool) -> tuple[list, list]:
    """AD, RD of every pair of poses read in at least MIN_REPEATS common cycles (per approach), and
    notes on what was left out."""
    out, notes, repeated = [], [], []
    for label in ordered(labels):
        ids = ordered(pose_id[labels == label])
        single = {}
        for pid in ids:
            once, twice = _one_per_cycle(pose_id, labels, cycle, pid, label)
            repeated += [(pid, label, c) for c in twice]
            if len(once) >= MIN_REPEATS:  # a pose read in fewer cycles pairs with none
                single[pid] = once
        ids = [pid for pid in ids if pid in single]
        for a, b in combinations(ids, 2):
            common = sorted(set(single[a]) & set(single[b]), key=label_key)
            if len(common) < MIN_REPEATS:
                continue
            ra, rb = [single[a][c] for c in common], [single[b][c] for c in common]
            out.append(distance_figures(positions[ra], positions[rb], commanded[ra[0]], commanded[rb[0]],
                                        pose_a=a, pose_b=b, approach=label if labelled else None))
    if repeated:
        pid, label, c = repeated[0]
        notes.append(f"{len(repeated)} (pose, cycle) pair(s) read more than once, left out of AD and RD (first: "
                     f"pose {pose_name(pid)}" + (f" approach {label}" if labelled else "") + f", cycle {c})")
    if not out:
        notes.append("no AD, RD: no two poses" + (" of one approach" if labelled else "") +
                     f" were each read once in {MIN_REPEATS} or more common cycles")
    return out, notes


def _one_per_cycle(pose_id, labels, cycle, pid, label) -> tuple[dict, list]:
    """cycle -> row of pose pid (approach label) in that cycle, and the cycles where it was read
    more than once (left out)."""
    rows = np.flatnonzero((pose_id == pid) & (labels == label))
    values, counts = np.unique(cycle[rows].astype(str), return_counts=True)
    once = set(values[counts == 1].tolist())
    return {cycle[r]: int(r) for r in rows if cycle[r] in once}, sorted(set(values.tolist()) - once, key=label_key)


def stabilisation_figures(pose_id, approach, visits, band) -> list:
    """Stabilisation time and overshoot per (pose, approach).

    Parameters
    ----------
    pose_id, approach : sequence of str (approach entries may be None)
        Labels of each visit.
    visits : list of (times (k,) [s], positions (k, 3) [m])
        Each visit's stream of readings, the last one the attained pose.
    band : dict of (pose_id, approach) to float
        Radius of the limit band of each pose [m].

    Returns
    -------
    list of Stabilisation
    """
    groups = {}
    for pid, label, (times, positions) in zip(pose_id, approach, visits):
        groups.setdefault((pid, label), []).append(settling(times, positions, band[(pid, label)]))
    out = []
    for (pid, label), results in sorted(groups.items(), key=lambda kv: (label_key(kv[0][0]), str(kv[0][1]))):
        entered = [r for r in results if r[0] is not None]
        times = [r[0] for r in entered]
        overshoots = [r[1] for r in entered]
        out.append(Stabilisation(
            pose_id=pid, approach=label, n=len(results), band=float(band[(pid, label)]),
            time_mean=float(np.mean(times)) if times else None, time_max=max(times) if times else None,
            overshoot_mean=float(np.mean(overshoots)) if entered else None,
            overshoot_max=max(overshoots) if entered else None, never_entered=len(results) - len(entered)))
    return out


__all__ = ["DirectionalVariation", "DistanceFigures", "IsoFigures", "MIN_REPEATS", "PoseFigures", "STANDARD_CYCLES",
           "Stabilisation", "as_labels", "cycle_notes", "distance_figures", "iso_figures", "label_key", "ordered", "pose_figures",
           "pose_name", "settling", "stabilisation_figures"]
