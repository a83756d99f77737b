"""ISO 9283 evaluation of a measured pose test: the measurement frame registered, then the figures.

A pose test's CSV (``tcr-accuracy iso9283 plan`` writes its joints) holds, per reading, the
commanded joints, a ``pose_id`` (and optionally ``cycle``, ``approach`` and the commanded TCP
``target_x_mm`` ...) and the position the instrument measured in its own frame. Before the
standard's formulas (:mod:`tcr_accuracy.iso9283.formulas`) apply, the readings must be in the
robot's base frame:

- ``frame="auto"`` (default): a frame given (``registration=``, fitted beforehand on other
  poses measured in the same instrument frame: ``iso9283 evaluate --frame-from CAL.csv``, a
  calibration set of the same session) is used, so that the test's own poses do not place the
  frame and AP keeps all it measures. Without one, the frame is fitted to the test's poses (as
  ``frame="fit"``); when that frame moves no pose by more than :data:`BASE_FRAME_TOL` (the
  readings already lie in the robot's base frame: a real instrument's own frame is metres
  away), the readings are taken as base-frame positions (as ``frame="base"``) and AP is the
  standard's, the barycentre against the command pose; else AP is relative to the fitted
  frame, and :attr:`IsoEvaluation.absolute` is False. (The test's poses cannot tell the
  frame's offset from the robot's own error: a robot off by more than that bound, its readings
  in the base frame, is evaluated with ``frame="base"``.)
- ``frame="fit"``: the barycentre of each pose is matched to the robot's nominal TCP at the
  commanded joints by :func:`tcr_accuracy.frames.registration.register_tracker` (Kabsch, then
  a least-squares refinement with the measured point's offset from the TCP frame fitted where
  the poses' orientations tell it apart from the frame's translation, held at 0 and said where
  they do not). The commanded position of a pose is then the nominal TCP with that fitted
  offset. With orientations, the measured frame's rotation relative to the TCP frame is fitted
  too (the mean of ``R_commanded^T R_measured`` over the readings). What the fit takes up (6 to
  9 of the 3 x poses coordinates: on the five poses of a cube most of the robot's absolute
  error) is not seen in AP, which is then relative to that frame, not the standard's: the
  standard assumes the base frame known.
- ``frame="base"``: the readings are base-frame TCP positions (and orientations); nothing is
  fitted.

A pose may be read once (AP only), twice (AP, l̄ and S_l) or three times and more (RP too);
the standard's 30 cycles are said against each pose's count, not required.

Pose ids, cycles and approach directions are labels (``P1``, ``S01.P1``, ``+x``; whole numbers
name the same pose however written). A visit is one reading, or, where the readings carry
``time_s`` and a ``cycle`` column and a (pose, approach, cycle) was read several times, the
stream of readings of that visit: its last reading is the attained pose (every figure uses
it) and the readings before it give the pose stabilisation time and overshoot
(:func:`tcr_accuracy.iso9283.formulas.settling`), with the limit band ``band`` or else the
pose's RP.

:func:`diagnosis_model` reads a ``diagnose --json`` result and :func:`compensated_readings`
removes what that model predicts at each reading's joints and context, which is what a
compensation with it would leave to first order (positions only; the session's tracker frame
of the diagnosis is not used). Lengths are metres, angles radians; nothing here prints.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from .formulas import IsoFigures, as_labels, iso_figures, ordered, stabilisation_figures
from ..effects import predict_positions
from ..effects.file_values import checked_effect, parameter_vector
from ..exceptions import InputError
from ..io.measurement_checks import MIN_UNIT_SPREAD, rms_spread
from ..io.measurements import MeasurementSet
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel
from ..frames.registration import Registration, register_tracker
from ..frames.rigid import rigid_fit

#: Joint values of the readings of one pose may differ by this much [rad, m] (CSV rounding).
SAME_POSE_TOL = 1e-6
#: Readings whose joint values all agree within this [rad or m] visit one pose: joint values
#: logged from the encoders scatter by a few counts (~1e-5 rad) about the commanded ones, and
#: the five ISO poses lie tenths of a radian apart.
POSE_GROUP_TOL = 1e-3
#: A target column farther than this from the nominal TCP at the pose's joints warns [m].
TARGET_TOL = 1e-5
#: ``frame="auto"``: a frame fitted on the test's poses that moves none of them by more than this
#: [m] is taken for the robot's base frame (the readings are base-frame positions, their AP the
#: standard's). What the fit moves is the frame's offset and the robot's own error together, which
#: the test's poses cannot tell apart: the bound is a robot's usual absolute error (the UR5's ~2-3
#: mm), below what an instrument's own frame is off (metres; a frame set up near the base, as
#: ``simulate`` draws one, centimetres). Beyond it the frame is fitted and AP said relative.
BASE_FRAME_TOL = 5e-3
#: A position column whose values, multiplied (or divided) by 1000, bring the rigid fit of the nominal
#: TCP to the readings this many times closer is in the other unit (m under ``_mm`` or mm under ``_m``):
#: a robot's own errors cannot be undone by scaling one axis of the instrument's frame.
COLUMN_UNIT_GAIN = 10.0
#: What ``frame_source`` says of AP relative to a frame fitted on the test's own poses.
RELATIVE_SOURCE = "fitted on the test poses (relative)"
#: The words printed beside every AP figure relative to such a frame.
RELATIVE_WORDS = "AP relative to a frame fitted on the test poses"


@dataclass(frozen=True)
class IsoEvaluation:
    """An evaluated pose test.

    Attributes
    ----------
    figures : IsoFigures
    frame : str
        ``fit`` (fitted on the test's poses), ``base`` or ``given`` (a registration from other
        poses).
    registration : Registration or None
        The measurement frame and TCP offset fitted (``fit``) or given (``given``).
    how : str
        How the readings were brought into the base frame, in words.
    orientation_offset : ndarray of shape (3, 3) or None
        Fitted rotation of the measured frame relative to the TCP frame.
    n_readings : int
        Readings in the file.
    pose_q : dict of str to ndarray of shape (n_joints,)
        Commanded joints [rad, m] of each pose, by label.
    n_visits : int
        Visits (one reading each, or one stream each: the attained readings the figures use).
    frame_source : str
        Where the base frame came from, in words: ``base`` (given, or found: the readings lie in
        it), ``calibration set (N poses)`` (other poses of the session), or
        :data:`RELATIVE_SOURCE` (fitted on the test's own poses: AP relative).
    absolute : bool
        True: AP is the standard's, in the robot's base frame; False: relative to a frame fitted
        on the test's own poses, which takes up most of the robot's absolute error.
    instrument_distance : dict of str to float, or None
        Each pose's distance from the origin of the instrument's frame [m] (its barycentre as
        read: a laser tracker's frame has its origin at the tracker, and its error grows with
        the distance); None when the readings are taken as base-frame positions.

    Examples
    --------
    >>> import dataclasses
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> series = tcr.plan_iso_cube(robot, random_state=0, n_centres=10).series(cycles=10)
    >>> readings = tcr.tcp_poses(robot, series.q).position + np.random.default_rng(1).normal(0, 1e-5, (50, 3))
    >>> evaluation = tcr.evaluate_pose_test(robot, dataclasses.replace(series, position=readings), frame="base")
    >>> evaluation.frame, evaluation.absolute, evaluation.n_readings
    ('base', True, 50)
    """

    figures: IsoFigures
    frame: str
    registration: Registration | None
    how: str
    orientation_offset: np.ndarray | None
    n_readings: int
    pose_q: dict
    n_visits: int
    frame_source: str = "base"
    absolute: bool = True
    instrument_distance: dict | None = None

    def frame_dict(self) -> dict:
        """JSON-ready account of the frame (mm): ``frame_source``, ``ap_absolute``, and the frame
        registration's ``frame_residual_rms_mm`` and ``frame_n_points`` (None where nothing was
        fitted), for the report's first page and its uncertainty budget."""
        fitted = self.registration is not None
        return {"frame_source": self.frame_source, "ap_absolute": self.absolute,
                "frame_residual_rms_mm": self.registration.residual_rms * 1e3 if fitted else None,
                "frame_n_points": self.registration.n_points if fitted else None}


@dataclass(frozen=True)
class PoseLabels:
    """``pose_id``, ``cycle`` (or None) and ``approach`` (or None), (N,) object arrays of str labels;
    ``grouped``: the pose ids were read off the joint values (no ``pose_id`` column)."""

    pose_id: np.ndarray
    cycle: np.ndarray | None
    approach: np.ndarray | None
    grouped: bool = False


def group_by_joints(q: np.ndarray, tol: float = POSE_GROUP_TOL) -> np.ndarray:
    """Pose ids 1, 2, ... (in order of first visit) of readings q (N, n_joints) [rad, m]: a
    reading belongs to the first pose whose first reading it matches within ``tol`` on every
    joint. Hand-written: a clustering by distance threshold (scipy's fcluster) would chain
    nearby readings of different poses together; the first-visit rule cannot."""
    firsts: list[np.ndarray] = []
    out = np.empty(len(q), dtype=int)
    for i, row in enumerate(q):
        for k, first in enumerate(firsts):
            if np.abs(row - first).max() <= tol:
                out[i] = k + 1
                break
        else:
            firsts.append(row)
            out[i] = len(firsts)
    return out


def pose_labels(mset: MeasurementSet) -> PoseLabels:
    """The pose test's labels of each reading, checked (InputError naming file, row, column)."""
    labels = dict(mset.annotations or {})
    grouped = "pose_id" not in labels
    if grouped:
        pose_id = group_by_joints(mset.q)
        if pose_id.max() == len(mset):
            raise InputError(f"{mset.source}: no pose_id column, and no two readings at the same joint values "
                             f"(within {POSE_GROUP_TOL:g} rad or m): a pose test measures each pose several times "
                             "(tcr-accuracy iso9283 plan writes the poses with their pose_id)")
        labels["pose_id"] = pose_id

    def named(name):
        return None if name not in labels else as_labels(labels[name])

    return PoseLabels(named("pose_id"), named("cycle"), named("approach"), grouped)


def pose_joints(mset: MeasurementSet, pose_id: np.ndarray) -> dict:
    """pose label -> its commanded joints (n_joints,): the mean of its readings' joint values, which
    may scatter by up to POSE_GROUP_TOL (encoder readings); InputError when they differ more."""
    out = {}
    for pid in ordered(pose_id):
        rows = np.flatnonzero(pose_id == pid)
        q = mset.q[rows]
        far = np.abs(q - q[0]).max(axis=1) > POSE_GROUP_TOL
        if far.any():
            r = rows[np.argmax(far)]
            j = int(np.argmax(np.abs(mset.q[r] - q[0])))
            raise InputError(f"{mset.source}: row {mset.rows[r]}, column {mset.joint_names[j]}: pose {pid} is "
                             f"commanded with other joint values than in row {mset.rows[rows[0]]}; one pose_id "
                             "is one commanded pose")
        out[pid] = q.mean(axis=0)
    return out


@dataclass(frozen=True)
class Visits:
    """How the readings group into visits: ``attained`` (V,) row of each visit's attained reading,
    ``streams`` a list of (V,) row arrays in time order (None: one reading per visit)."""

    attained: np.ndarray
    streams: list | None = None


def visits_of(mset: MeasurementSet, labels: PoseLabels) -> Visits:
    """One visit per reading, or, with ``time_s`` and ``cycle`` and a (pose, approach, cycle) read
    several times, one per such group (InputError when a stream's times repeat)."""
    n = len(mset)
    if mset.time_s is None or labels.cycle is None:
        return Visits(np.arange(n))
    approach = labels.approach if labels.approach is not None else np.full(n, "", dtype=object)
    keys = list(zip(labels.pose_id, approach, labels.cycle))
    groups = {}
    for r, key in enumerate(keys):
        groups.setdefault(key, []).append(r)
    if all(len(rows) == 1 for rows in groups.values()):
        return Visits(np.arange(n))
    streams = []
    for rows in groups.values():
        rows = np.array(rows)[np.argsort(mset.time_s[rows], kind="stable")]
        same = np.flatnonzero(np.diff(mset.time_s[rows]) <= 0)
        if len(same):
            r = rows[same[0] + 1]
            raise InputError(f"{mset.source}: row {mset.rows[r]}, column time_s: {mset.time_s[r]:g} s repeats a "
                             f"time of the same visit (pose {labels.pose_id[r]}, cycle {labels.cycle[r]}); the "
                             "readings of one visit are a stream in time")
        streams.append(rows)
    streams.sort(key=lambda rows: rows[-1])
    return Visits(np.array([rows[-1] for rows in streams]), streams)


def evaluate_pose_test(robot: RobotModel, mset: MeasurementSet, *, frame: str = "auto",
                       registration: Registration | None = None, registration_source: str = "",
                       band: float | None = None) -> IsoEvaluation:
    """Register the readings (see the module docstring) and compute every ISO 9283 figure.

    Parameters
    ----------
    robot : RobotModel
    mset : MeasurementSet
        With ``annotations["pose_id"]`` (and optionally ``cycle``, ``approach``,
        ``target_x_mm`` ...; ``time_s`` for streamed visits); of one test condition (see
        :func:`evaluate_conditions` for several).
    frame : {"auto", "fit", "base"}, default="auto"
        How the readings are brought into the base frame when no ``registration`` is given:
        ``auto`` takes them as base-frame positions when they lie in the base frame, else fits
        the frame on the test's poses (AP relative, said in :attr:`IsoEvaluation.frame_source`).
    registration : Registration, optional
        The instrument frame (and TCP offset) fitted on other poses (:func:`register_from`);
        not with ``frame="base"`` or ``"fit"``.
    registration_source : str
        Where that registration came from, for the record.
    band : float, optional
        Radius of the limit band for stabilisation time and overshoot [m]; default each pose's RP.

    Returns
    -------
    IsoEvaluation

    Raises
    ------
    InputError
        Several test conditions in ``mset``, a pose commanded at two joint values, a visit's
        stream with a repeated time, a position column in the other unit, or fewer than 3 poses
        to fit a frame on.

    Examples
    --------
    >>> import dataclasses
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> plan = tcr.plan_iso_cube(robot, random_state=0, centre=[-0.13, -0.44, 0.32], size=0.2)
    >>> series = plan.series(cycles=3)
    >>> simulated, _ = tcr.simulate_measurements(robot, {"noise_mm": 0.02}, len(series), random_state=1,
    ...                                          q=series.q, context=series.context)
    >>> result = tcr.evaluate_pose_test(robot, dataclasses.replace(series, position=simulated.position))
    >>> result.frame_source, [(f.pose_id, f.n) for f in result.figures.poses]
    ('base', [('P1', 3), ('P2', 3), ('P3', 3), ('P4', 3), ('P5', 3)])
    """
    if registration is not None and frame in ("base", "fit"):
        raise InputError(f"frame {frame!r} and a registration from other poses: the readings are either in the "
                         "base frame already, or in the instrument's with the frame fitted on the test or on "
                         "other poses; give one")
    return _evaluate(robot, mset, frame, registration, registration_source, band, relative=False)


def _evaluate(robot, mset, frame, registration, registration_source, band, relative: bool) -> IsoEvaluation:
    """:func:`evaluate_pose_test`; ``relative``: the registration given was fitted on this test's own
    poses (another condition's block), so AP is relative."""
    if frame not in ("auto", "fit", "base"):
        raise InputError(f"frame {frame!r}: use 'auto', 'fit' or 'base'")
    if band is not None and not (np.isfinite(band) and band > 0):
        raise InputError(f"band {band!r} m: want a positive limit band radius")
    _check_one_condition(mset)
    labels = pose_labels(mset)
    visits = visits_of(mset, labels)
    attained = visits.attained
    joints = pose_joints(mset, labels.pose_id)
    ids = list(joints)
    q_poses = np.array([joints[i] for i in ids])
    index = {pid: k for k, pid in enumerate(ids)}
    row_pose = np.array([index[p] for p in labels.pose_id])
    nominal = tcp_poses(robot, q_poses)
    _check_targets(mset, labels.pose_id, nominal.position, index)
    barycentres = np.array([mset.position[attained][row_pose[attained] == k].mean(axis=0) for k in range(len(ids))])
    check_column_units(barycentres, nominal.position, mset.source)
    source, absolute = "base", True
    if registration is not None:
        frame = "given"
        if relative:
            source, absolute = RELATIVE_SOURCE, False
            how = (f"fitted on {registration_source}: {registration.n_points} poses of this test "
                   f"(fit residual RMS {registration.residual_rms * 1e3:.4f} mm); {RELATIVE_WORDS}")
        else:
            source = f"calibration set ({registration.n_points} poses)"
            how = (f"from {registration_source or 'other poses'}: fitted on its "
                   f"{registration.n_points} poses (Kabsch, then least squares with the TCP offset; fit residual "
                   f"RMS {registration.residual_rms * 1e3:.4f} mm)")
    elif frame in ("auto", "fit"):
        if len(ids) < 3:
            raise InputError(f"{mset.source}: {len(ids)} poses; fitting the measurement frame needs at least 3 "
                             "(or readings already in the robot's base frame, evaluated with frame 'base')")
        registration = register_tracker(robot, q_poses, barycentres)
        moved = np.linalg.norm(registration.to_tracker(nominal.position) - nominal.position, axis=1).max()
        if frame == "auto" and moved <= BASE_FRAME_TOL:
            frame, registration = "base", None
            how = (f"found: the readings lie in the robot's base frame (a frame fitted on the test poses would move "
                   f"them by {moved * 1e3:.3g} mm at most, an instrument's own frame by centimetres to metres): AP "
                   "absolute, each pose's barycentre against its command pose (frame 'fit' fits it instead)")
        else:
            frame, source, absolute = "fit", RELATIVE_SOURCE, False
            how = f"fitted on the test poses: {_fit_words(registration, len(ids))}; {RELATIVE_WORDS}"
    else:
        how = "not fitted: the readings are taken as base-frame TCP positions (frame base)"
    if registration is None:
        commanded, positions = nominal.position, mset.position
    else:
        commanded = registration.tcp_positions(robot, q_poses)
        positions = registration.to_base(mset.position)
    deviations = offset = None
    if mset.quaternion is not None:
        deviations, offset = _orientation_deviations(mset.quaternion[attained], nominal.rotation[row_pose[attained]],
                                                     registration)

    def pick(values):
        return None if values is None else values[attained]

    figures = iso_figures(labels.pose_id[attained], positions[attained], commanded[row_pose[attained]],
                          deviations=deviations, cycle=pick(labels.cycle), approach=pick(labels.approach))
    if visits.streams is not None:
        figures.stabilisation.extend(_stabilisation(mset, labels, visits, positions, figures, band))
        figures.notes.insert(0, f"{len(mset)} time-stamped readings in {len(attained)} visits (pose, cycle): the "
                                "last reading of each is its attained pose; the readings before it give the "
                                "stabilisation time and overshoot (band: "
                                + ("the pose's RP" if band is None else f"{band * 1e3:g} mm") + ")")
    if labels.grouped:
        figures.notes.insert(0, f"no pose_id column: the readings grouped by their joint values (within "
                                f"{POSE_GROUP_TOL:g} rad or m) into {len(ids)} poses, numbered in order of first "
                                "visit")
    if rms_spread(nominal.position[row_pose]) < MIN_UNIT_SPREAD:
        figures.notes.append(f"the poses lie within {rms_spread(nominal.position[row_pose]) * 1e3:.3g} mm (RMS) of "
                             f"one another: too close for the measurement reader's unit check (it needs "
                             f"{MIN_UNIT_SPREAD * 1e3:g} mm), which did not run; make sure the position columns' "
                             "unit is the file's")
    spread = max(float(np.abs(mset.q[row_pose == k] - q_poses[k]).max()) for k in range(len(ids)))
    if spread > SAME_POSE_TOL:
        figures.notes.append(f"the joint values of one pose scatter by up to {spread:.2g} rad or m (encoder "
                             "readings?): each pose's commanded joints taken as their mean")
    distance = None if frame == "base" else dict(zip(ids, np.linalg.norm(barycentres, axis=1).tolist()))
    return IsoEvaluation(figures=figures, frame=frame, registration=registration, how=how,
                         orientation_offset=offset, n_readings=len(mset), pose_q=joints, n_visits=len(attained),
                         frame_source=source, absolute=absolute, instrument_distance=distance)


def _check_one_condition(mset: MeasurementSet) -> None:
    """InputError when ``mset`` holds several test conditions (``load_pct``, ``speed_pct``): their
    figures are per condition (:func:`evaluate_conditions`), not mixed."""
    blocks = condition_blocks(mset)
    if len(blocks) > 1:
        raise InputError(f"{mset.source}: {len(blocks)} test conditions ({'; '.join(b.words() for b in blocks)}); "
                         "each has its own figures: evaluate them with evaluate_conditions")


def _fit_words(registration: Registration, n_poses: int) -> str:
    tool = [n.rpartition(".")[2] for n in registration.fitted if n.startswith("frames.tool.")]
    if len(tool) == 3:
        offset = "with the measured point's offset from the TCP frame fitted"
    elif tool:
        offset = (f"with the measured point's offset from the TCP frame fitted along {', '.join(tool)} "
                  "(the rest is not identifiable from these poses, held at 0)")
    else:
        offset = ("the measured point's offset from the TCP frame is not identifiable from these poses (one "
                  "orientation: it moves the frame) and held at 0")
    return (f"Kabsch on the barycentres of the {n_poses} poses against the nominal TCP, refined by least squares; "
            f"{offset}; fit residual RMS {registration.residual_rms * 1e3:.4f} mm")


def _stabilisation(mset, labels, visits, positions, figures, band) -> list:
    """Stabilisation time and overshoot of each (pose, approach) from its streamed visits (band: the
    given radius, else the pose's RP; poses without RP are left out and said)."""
    rp = {(f.pose_id, f.approach): f.rp for f in figures.poses}
    chosen, said = [], []
    for rows in visits.streams:
        r = rows[-1]
        key = (labels.pose_id[r], None if labels.approach is None else labels.approach[r])
        radius = band if band is not None else rp.get(key)
        if radius is None or radius <= 0:
            said.append(key)
            continue
        chosen.append((key, radius, (mset.time_s[rows], positions[rows])))
    if said:
        figures.notes.append(f"no stabilisation time for {len(set(said))} pose(s) without RP to take as the limit "
                             "band (give one)")
    return stabilisation_figures([k[0] for k, _, _ in chosen], [k[1] for k, _, _ in chosen],
                                 [v for _, _, v in chosen], {k: radius for k, radius, _ in chosen})


@dataclass(frozen=True)
class ConditionBlock:
    """The readings of one test condition: ``load_pct``, ``speed_pct`` (None when the file has no such
    column) and ``rows`` (indices into the measurement set)."""

    load_pct: float | None
    speed_pct: float | None
    rows: np.ndarray

    def words(self) -> str:
        parts = ([] if self.load_pct is None else [f"{self.load_pct:g} % rated load"]) + \
                ([] if self.speed_pct is None else [f"{self.speed_pct:g} % rated speed"])
        return ", ".join(parts) or "one condition"


def condition_blocks(mset: MeasurementSet) -> list:
    """The test conditions of a pose test (``load_pct``, ``speed_pct`` columns), the reference one
    (100 % load and speed, else the first in the file) first, then in file order; one block of
    every row without those columns."""
    labels = mset.annotations or {}
    load, speed = labels.get("load_pct"), labels.get("speed_pct")
    if load is None and speed is None:
        return [ConditionBlock(None, None, np.arange(len(mset)))]
    for name, values, low_open in (("load_pct", load, False), ("speed_pct", speed, True)):
        if values is None:
            continue
        values = np.asarray(values, dtype=float)
        bad = ~(((values > 0) if low_open else (values >= 0)) & (values <= 100))
        if bad.any():
            r = int(np.argmax(bad))
            raise InputError(f"{mset.source}: row {mset.rows[r]}, column {name}: {values[r]:g} %; a test condition "
                             f"is a {'speed of (0, 100]' if low_open else 'load of 0-100'} % of the rated one")
    keys = list(zip(*(np.asarray(v, dtype=float).tolist() if v is not None else [None] * len(mset)
                      for v in (load, speed))))
    order = list(dict.fromkeys(keys))
    order.sort(key=lambda k: k != (100.0, 100.0) and k != (100.0, None) and k != (None, 100.0))
    return [ConditionBlock(k[0], k[1], np.array([i for i, key in enumerate(keys) if key == k])) for k in order]


def evaluate_conditions(robot: RobotModel, mset: MeasurementSet, *, frame: str = "auto",
                        registration: Registration | None = None, registration_source: str = "",
                        band: float | None = None) -> list:
    """:func:`evaluate_pose_test` per test condition: the measurement frame of the reference
    condition (fitted on its poses, or found to be the base frame) is used for the others, so that
    what changes with load and speed shows in their AP.

    Parameters
    ----------
    robot : RobotModel
    mset : MeasurementSet
        A pose test with ``load_pct`` and ``speed_pct`` annotations (one block per condition).
    frame, registration, registration_source, band
        As for :func:`evaluate_pose_test`.

    Returns
    -------
    list of (ConditionBlock, IsoEvaluation)

    Examples
    --------
    >>> import dataclasses
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> plan = tcr.plan_iso_cube(robot, random_state=0, centre=[-0.13, -0.44, 0.32], size=0.2)
    >>> series = plan.series(cycles=3, conditions=[(100, 100), (10, 100)])
    >>> nominal = tcr.tcp_poses(robot, series.q).position
    >>> blocks = tcr.evaluate_conditions(robot, dataclasses.replace(series, position=nominal))
    >>> [(block.words(), round(result.figures.poses[0].ap, 9)) for block, result in blocks]
    [('100 % rated load, 100 % rated speed', 0.0), ('10 % rated load, 100 % rated speed', 0.0)]
    """
    if registration is not None and frame in ("base", "fit"):
        raise InputError(f"frame {frame!r} and a registration from other poses: give one")
    out, relative = [], False
    for block in condition_blocks(mset):
        part = mset.subset(block.rows)
        result = _evaluate(robot, part, frame, registration, registration_source, band, relative)
        if not out and result.frame == "fit":  # the reference block's frame, fitted on its poses, for all
            frame, registration, relative = "auto", result.registration, True
            registration_source = f"the {block.words()} block"
        elif not out and result.frame == "base":  # found (or given) to be the base frame: for all
            frame = "base"
        out.append((block, result))
    return out


def register_from(robot: RobotModel, other: MeasurementSet) -> Registration:
    """The instrument frame and TCP offset fitted on other measured poses of the same session (each
    position column's unit checked first, :func:`check_column_units`)."""
    check_column_units(other.position, tcp_poses(robot, other.q).position, other.source)
    return register_tracker(robot, other.q, other.position, context=other.context)


def check_column_units(measured, nominal, source: str) -> None:
    """InputError naming the file and the position column whose values are in the other unit.

    The measurement reader checks the spread of all three columns together (metres under every
    ``_mm`` header); one column alone in metres changes the spread little but bends the point cloud,
    which no rigid motion maps onto the nominal TCP: the rigid fit's residual falls
    :data:`COLUMN_UNIT_GAIN` times or more when that column is scaled back by 1000.

    Parameters
    ----------
    measured : array-like of shape (N, 3)
        The measured points, as read [m], in the instrument's frame.
    nominal : array-like of shape (N, 3)
        The nominal TCP at the same joints, base frame [m].
    source : str
        The file, for the message.
    """
    measured, nominal = np.asarray(measured, dtype=float), np.asarray(nominal, dtype=float)
    if len(measured) < 4 or rms_spread(nominal) < MIN_UNIT_SPREAD:
        return

    def residual(points) -> float:
        try:
            rotation, translation = rigid_fit(nominal, points)
        except InputError:  # points on one line: no frame, no comparison
            return np.nan
        return float(np.sqrt(np.mean(np.sum((nominal @ rotation.T + translation - points) ** 2, axis=1))))

    as_read = residual(measured)
    if not np.isfinite(as_read):
        return
    for axis, name in enumerate("xyz"):
        for factor, header, words in ((1e3, f"{name}_mm", "m"), (1e-3, f"{name}_m", "mm")):
            scaled = measured.copy()
            scaled[:, axis] *= factor
            better = residual(scaled)
            if np.isfinite(better) and better * COLUMN_UNIT_GAIN < as_read:
                raise InputError(f"{source}: column {header}: its values look like {words} (no rigid frame maps the "
                                 f"nominal TCP onto the readings closer than {as_read * 1e3:.4g} mm RMS; with this "
                                 f"column times {factor:g}, {better * 1e3:.4g} mm); write the column in the unit its "
                                 "header names")


def _check_targets(mset, pose_id, nominal_positions, index) -> None:
    labels = mset.annotations or {}
    names = ("target_x_mm", "target_y_mm", "target_z_mm")
    if not all(n in labels for n in names):
        return
    target = np.stack([labels[n] for n in names], axis=1) * 1e-3
    expected = nominal_positions[[index[p] for p in pose_id]]
    gap = np.linalg.norm(target - expected, axis=1)
    if gap.max() > TARGET_TOL:
        r = int(np.argmax(gap))
        warnings.warn(f"{mset.source}: row {mset.rows[r]}, columns target_x_mm..target_z_mm: {gap[r] * 1e3:.4g} mm "
                      f"from the robot's nominal TCP at the commanded joints (another "
                      "robot or tool?); the figures use the nominal TCP", UserWarning, stacklevel=3)


def _orientation_deviations(quaternion, commanded_rotation, registration):
    """(N, 3) deviations a, b, c [rad] and the fitted measured-frame offset (3, 3) (identity in base frame)."""
    measured = Rotation.from_quat(quaternion[:, [1, 2, 3, 0]]).as_matrix()  # scipy: x, y, z, w
    if registration is None:
        offset = np.eye(3)
    else:
        measured = registration.rotation.T @ measured
        offset = Rotation.from_matrix(np.transpose(commanded_rotation, (0, 2, 1)) @ measured).mean().as_matrix()
    target = commanded_rotation @ offset
    deviation = Rotation.from_matrix(measured @ np.transpose(target, (0, 2, 1))).as_rotvec()
    return deviation, (None if registration is None else offset)


# ---------------------------------------------------------------------------------------
# After compensation with a diagnosis' model
# ---------------------------------------------------------------------------------------
def diagnosis_model(robot: RobotModel, payload: dict, source: str) -> tuple[list, list]:
    """The effects and parameter vectors of a ``diagnose --json`` result (its ``frames`` left out:
    they belong to that session's instrument). InputError naming what does not fit the robot."""
    parameters = payload.get("parameters") if isinstance(payload, dict) else None
    if not isinstance(parameters, dict):
        raise InputError(f"{source}: no 'parameters' object; give the JSON that tcr-accuracy diagnose writes")
    if payload.get("robot") not in (None, robot.name):
        raise InputError(f"{source}: a diagnosis of {payload.get('robot')}, not of {robot.name}; give robot=",
                         parameter="robot", value=robot.name)
    options = payload.get("effect_options") or {}
    if not isinstance(options, dict):
        raise InputError(f"{source}: effect_options: must map effect names to {{option: value}}")
    effects, params = [], []
    for name, values in parameters.items():
        if name == "frames":
            continue
        effect = checked_effect(name, robot, options.get(name), f"{source}: effect_options")
        params.append(parameter_vector(effect, values or {}, f"{source}: parameters.{name}"))
        effects.append(effect)
    return effects, params


def compensated_readings(robot: RobotModel, mset: MeasurementSet, registration: Registration | None,
                         effects: list, params: list) -> MeasurementSet:
    """The readings with the model's predicted TCP displacement removed (what compensating with it
    leaves, to first order); positions only, orientations dropped."""
    context = mset.context
    shift = predict_positions(robot, effects, params, mset.q, context) - tcp_poses(robot, mset.q).position
    if registration is not None:
        shift = shift @ registration.rotation.T  # base-frame displacement into the tracker frame
    return replace(mset, position=mset.position - shift, quaternion=None)


__all__ = ["ConditionBlock", "IsoEvaluation", "condition_blocks", "evaluate_conditions", "PoseLabels", "Visits", "check_column_units", "compensated_readings", "diagnosis_model", "evaluate_pose_test",
           "pose_joints", "pose_labels", "register_from", "visits_of"]
