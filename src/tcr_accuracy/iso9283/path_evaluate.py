"""ISO 9283 evaluation of a measured path test: the commanded paths, the tracker's stream cut into
runs and cycles, the stream registered into the base frame, then the path characteristics.

- The commanded paths come as a measurement CSV without positions (``iso9283 plan --path``
  writes it): the joints of each sample, and per row ``path``, ``speed_pct``, ``speed_mm_s`` and
  the commanded ``time_s``. The commanded point of a sample is the nominal TCP at its joints (a
  ``target_x_mm`` ... column farther than 10 um from it warns), with the measured point's offset
  from the TCP when a registration from poses fitted one; a run is one (path, speed).
- The stream (:func:`tcr_accuracy.io.tracker_stream.read_tracker_stream`) is matched to the runs
  by its ``path`` and ``speed_pct`` labels (either may be left out where the commanded file has
  one value of it) and cut into cycles by its ``cycle`` labels (without them, one cycle: no RT
  nor RV, said). Its spread is checked against the commanded paths' with the measurement
  reader's unit check (:func:`tcr_accuracy.io.measurement_checks.check_spread_units`).
- The stream is brought into the base frame by a registration fitted beforehand on poses
  measured in the same instrument frame (``registration=``), taken as already in it
  (``frame="base"``), or fitted to the commanded paths (``frame="fit"``): a start from the runs'
  first cycles matched by fraction of their length (Kabsch), then iterative closest points on
  the commanded paths (projection on the polyline) with Kabsch each step. The fit takes up any
  constant offset and rotation of the attained paths, which AT then does not show: say it.
- ``model=`` (a diagnosis' effects and parameters) gives the figures predicted after
  compensation: each reading moved by minus the model's TCP displacement at the commanded joints
  of its nearest commanded point (first order, positions only).

Lengths are metres, times seconds; nothing here prints.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..effects import predict_positions
from ..exceptions import InputError
from ..frames.registration import Registration
from ..frames.rigid import rigid_fit
from ..io.measurement_checks import check_spread_units
from ..io.measurements import MeasurementSet
from ..io.tracker_stream import TrackerStream
from ..model.kinematics import tcp_poses
from ..model.robot import RobotModel
from .formulas import label_key
from .path import path_figures
from .path_plan import arc_length, corners_of

#: A target column farther than this from the nominal TCP at the sample's joints warns [m].
TARGET_TOL = 1e-5
#: Iterations and readings per run of the closest-point frame fit.
ICP_ITERATIONS = 50
ICP_SAMPLES = 2000
#: Fewest readings of one cycle of a path: a run along it is a stream.
MIN_CYCLE_READINGS = 3
#: A measured path speed more than this many times the commanded one, or less than its inverse, is
#: no robot's: the time column is in another unit (AV would read -99.9 % for milliseconds).
SPEED_RATIO_LIMIT = 30.0


@dataclass(frozen=True)
class CommandedRun:
    """One commanded path at one speed.

    Attributes
    ----------
    path : str
    speed_pct : float or None
    points : ndarray of shape (N, 3)
        Nominal TCP of each sample [m].
    s : ndarray of shape (N,)
        Arc length [m].
    q : ndarray of shape (N, n_joints)
        Commanded joints [rad, m].
    times : ndarray of shape (N,) or None
        Commanded time of each sample [s].
    speed : float or None
        Commanded path speed [m/s] (``speed_mm_s``), else None (then the largest commanded speed).
    corners : tuple of int
    context : MeasurementContext
        Payload, temperature ... of each sample (for a model's prediction).
    """

    path: str
    speed_pct: float | None
    points: np.ndarray
    s: np.ndarray
    q: np.ndarray
    times: np.ndarray | None
    speed: float | None
    corners: tuple
    context: object = None

    def words(self) -> str:
        return self.path + ("" if self.speed_pct is None else f" at {self.speed_pct:g} %")


def commanded_runs(robot: RobotModel, commanded: MeasurementSet, registration: Registration | None = None) -> list:
    """The runs of a commanded path file, in file order (InputError naming file and row); with a
    ``registration``, the commanded points are the measured point's (the TCP with its fitted offset)."""
    labels = commanded.annotations or {}
    n = len(commanded)
    path = np.asarray(labels.get("path", np.full(n, "path", dtype=object)), dtype=object)
    speed = labels.get("speed_pct")
    keys = list(zip(path, [None] * n if speed is None else np.asarray(speed, dtype=float).tolist()))
    points = tcp_poses(robot, commanded.q).position
    _check_targets(commanded, points)
    if registration is not None:
        points = registration.tcp_positions(robot, commanded.q, commanded.context)
    out = []
    for key in dict.fromkeys(keys):
        rows = np.array([i for i, k in enumerate(keys) if k == key])
        if len(rows) < 3:
            raise InputError(f"{commanded.source}: row {commanded.rows[rows[0]]}: the {key[0]} path has "
                             f"{len(rows)} point(s); a commanded path needs at least 3")
        if len(rows) > 1 and np.any(np.diff(rows) != 1):
            r = rows[int(np.argmax(np.diff(rows) != 1)) + 1]
            raise InputError(f"{commanded.source}: row {commanded.rows[r]}: the {key[0]} path continues after "
                             "other rows; write each path (and speed) as one block of rows in order")
        s = arc_length(points[rows])
        steps = np.diff(s)
        if np.any(steps <= 0):
            r = rows[int(np.argmax(steps <= 0)) + 1]
            raise InputError(f"{commanded.source}: row {commanded.rows[r]}: the same commanded point as the row "
                             "before; a path moves from sample to sample")
        times = None if commanded.time_s is None else commanded.time_s[rows]
        if times is not None and np.any(np.diff(times) <= 0):
            r = rows[int(np.argmax(np.diff(times) <= 0)) + 1]
            raise InputError(f"{commanded.source}: row {commanded.rows[r]}, column time_s: the commanded time "
                             "does not increase")
        v = labels.get("speed_mm_s")
        out.append(CommandedRun(path=str(key[0]), speed_pct=key[1], points=points[rows], s=s, q=commanded.q[rows],
                                times=times, speed=None if v is None else float(np.asarray(v)[rows[0]]) * 1e-3,
                                corners=corners_of(points[rows]), context=commanded.context.subset(rows)))
    return out


def _check_targets(commanded: MeasurementSet, points) -> None:
    labels = commanded.annotations or {}
    names = ("target_x_mm", "target_y_mm", "target_z_mm")
    if not all(n in labels for n in names):
        return
    gap = np.linalg.norm(np.stack([labels[n] for n in names], axis=1) * 1e-3 - points, axis=1)
    if gap.max() > TARGET_TOL:
        r = int(np.argmax(gap))
        warnings.warn(f"{commanded.source}: row {commanded.rows[r]}, columns target_x_mm..target_z_mm: "
                      f"{gap[r] * 1e3:.4g} mm from the robot's nominal TCP at the commanded joints (another robot or "
                      "tool?); the figures use the nominal TCP", UserWarning, stacklevel=3)


def stream_cycles(stream: TrackerStream, runs: list) -> tuple[dict, list]:
    """run index -> list of (times (K,), row indices (K,)) per cycle, in cycle order; and notes.

    Each reading is matched to a run by its ``path`` and ``speed_pct``; a label the stream lacks
    must have one value in the commanded file."""
    n = len(stream)
    notes = []
    path = stream.labels.get("path")
    if path is None:
        names = sorted({r.path for r in runs})
        if len(names) > 1:
            raise InputError(f"{stream.source}: no path column, and the commanded file holds {len(names)} paths "
                             f"({', '.join(names)}); label each reading with its path")
        path = np.full(n, names[0], dtype=object)
    speed = stream.speed_pct
    if speed is None:
        speeds = sorted({r.speed_pct for r in runs if r.speed_pct is not None})
        if len(speeds) > 1:
            per = {p: {r.speed_pct for r in runs if r.path == p} for p in set(path)}
            if any(len(v) > 1 for v in per.values()):
                raise InputError(f"{stream.source}: no speed_pct column, and the commanded file runs its paths at "
                                 f"{', '.join(f'{v:g}' for v in speeds)} %; label each reading with its speed")
        speed = np.array([next(r.speed_pct for r in runs if r.path == p) for p in path], dtype=object)
    index = {(r.path, r.speed_pct): k for k, r in enumerate(runs)}
    cycle = stream.labels.get("cycle")
    if cycle is None:
        notes.append("no cycle column: each run is one cycle (no RT, RV)")
        cycle = np.full(n, "1", dtype=object)
    out = {}
    for i in range(n):
        key = (path[i], None if speed[i] is None else float(speed[i]))
        if key not in index:
            raise InputError(f"{stream.source}: row {stream.rows[i]}: path {key[0]}"
                             + ("" if key[1] is None else f" at {key[1]:g} %") + " is not in the commanded file")
        out.setdefault(index[key], {}).setdefault(cycle[i], []).append(i)
    cycles = {}
    for k, by_cycle in out.items():
        cycles[k] = []
        for label in sorted(by_cycle, key=label_key):
            rows = np.array(by_cycle[label])
            rows = rows[np.argsort(stream.time_s[rows], kind="stable")]
            same = np.flatnonzero(np.diff(stream.time_s[rows]) <= 0)
            if len(same):
                r = rows[same[0] + 1]
                raise InputError(f"{stream.source}: row {stream.rows[r]}, column time_s: {stream.time_s[r]:g} s "
                                 f"repeats a time of the same cycle ({runs[k].words()}, cycle {label})")
            if len(rows) < MIN_CYCLE_READINGS:
                raise InputError(f"{stream.source}: row {stream.rows[rows[0]]}, column cycle: cycle {label} of the "
                                 f"{runs[k].words()} holds {len(rows)} reading(s); a cycle is one run along the "
                                 "path, its readings labelled alike (a label per run, not per reading)")
            cycles[k].append(rows)
        _check_apart(stream, runs[k], [(label, rows) for label, rows in
                                       zip(sorted(by_cycle, key=label_key), cycles[k])])
    unmeasured = [runs[k].words() for k in range(len(runs)) if k not in cycles]
    if unmeasured:
        notes.append(f"not measured: {', '.join(unmeasured)}")
    return cycles, notes


def _check_apart(stream: TrackerStream, run: CommandedRun, labelled: list) -> None:
    """InputError when two cycles of a run interleave in time: each cycle is one run along the path,
    one block of readings in time (labels given reading by reading in turn mix the runs)."""
    spans = sorted(labelled, key=lambda item: stream.time_s[item[1][0]])
    for (label_a, a), (label_b, b) in zip(spans, spans[1:]):
        if stream.time_s[b[0]] < stream.time_s[a[-1]]:
            inside = b[0]
            raise InputError(f"{stream.source}: row {stream.rows[inside]}, column cycle: cycle {label_b} of the "
                             f"{run.words()} starts at {stream.time_s[inside]:g} s, before cycle {label_a} ends "
                             f"({stream.time_s[a[-1]]:g} s): a cycle is one run along the path, one block of readings "
                             "in time; label each run's readings with its cycle")


def _check_speed(stream: TrackerStream, run: CommandedRun, figures) -> None:
    """InputError when the stream moves along the path at a speed no robot runs a commanded one at
    (beyond :data:`SPEED_RATIO_LIMIT` either way): the time column in another unit."""
    if figures.v_mean is None or not figures.speed:
        return
    ratio = figures.v_mean / figures.speed
    if 1.0 / SPEED_RATIO_LIMIT < ratio < SPEED_RATIO_LIMIT:
        return
    hint = ("the times look like ms: give time_s in seconds" if 0.3e-3 <= ratio <= 3e-3 else
            "the times look like s where the commanded file's are ms" if 0.3e3 <= ratio <= 3e3 else
            "check the unit of time_s here and in the commanded file (seconds)")
    raise InputError(f"{stream.source}: column time_s: the {run.words()} is measured moving at "
                     f"{figures.v_mean * 1e3:.4g} mm/s where it is commanded at {figures.speed * 1e3:.4g} mm/s "
                     f"({ratio:.3g} times); {hint}")


def project_on_path(points, path_points, s, tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Foot points (N, 3) [m] of points (N, 3) on a sampled path (M, 3), and their arc lengths (N,)
    [m]: the two nearest samples, then the nearest of their neighbouring segments (two: a closed path's
    last sample is its first, and a reading just past the start is on the first segment, not the last)."""
    tree = tree or cKDTree(path_points)
    _, nearest = tree.query(points, k=min(2, len(path_points)))
    nearest = np.asarray(nearest).reshape(len(points), -1)  # a path of one sample has one nearest
    best_foot, best_s, best_d = None, None, None
    for a in [start for k in nearest.T for start in (np.maximum(k - 1, 0), k)]:
        b = np.minimum(a + 1, len(path_points) - 1)
        ab = path_points[b] - path_points[a]
        w = np.clip(np.einsum("nc,nc->n", points - path_points[a], ab) /
                    np.maximum(np.einsum("nc,nc->n", ab, ab), 1e-300), 0.0, 1.0)
        foot = path_points[a] + w[:, None] * ab
        d = np.linalg.norm(points - foot, axis=1)
        s_foot = s[a] + w * (s[b] - s[a])
        if best_d is None:
            best_foot, best_s, best_d = foot, s_foot, d
        else:
            closer = d < best_d
            best_foot[closer], best_s[closer], best_d[closer] = foot[closer], s_foot[closer], d[closer]
    return best_foot, best_s


@dataclass(frozen=True)
class StreamFrame:
    """The instrument frame fitted to the commanded paths: ``rotation`` (3, 3) and ``translation`` (3,)
    [m] with ``tracker = rotation @ base + translation``, ``residual_rms`` [m] of the readings from
    the paths, ``n_points`` readings used."""

    rotation: np.ndarray
    translation: np.ndarray
    residual_rms: float
    n_points: int

    def to_base(self, points) -> np.ndarray:
        return (np.atleast_2d(points) - self.translation) @ self.rotation


def fit_stream_frame(runs: list, stream: TrackerStream, cycles: dict) -> StreamFrame:
    """The instrument frame from the stream and the commanded paths (see the module docstring)."""
    nominal, measured = [], []
    for k, rows_of in cycles.items():
        run, x = runs[k], stream.position[rows_of[0]]
        f = arc_length(x) / max(arc_length(x)[-1], 1e-300)
        grid = np.linspace(0.0, 1.0, 200)
        measured.append(np.stack([np.interp(grid, f, x[:, a]) for a in range(3)], axis=1))
        nominal.append(np.stack([np.interp(grid * run.s[-1], run.s, run.points[:, a]) for a in range(3)], axis=1))
    rotation, translation = rigid_fit(np.vstack(nominal), np.vstack(measured))
    rng = np.random.default_rng(0)
    picked = {k: np.concatenate(rows_of) for k, rows_of in cycles.items()}
    picked = {k: rows if len(rows) <= ICP_SAMPLES else np.sort(rng.choice(rows, ICP_SAMPLES, replace=False))
              for k, rows in picked.items()}
    trees = {k: cKDTree(runs[k].points) for k in picked}
    for _ in range(ICP_ITERATIONS):
        feet = [project_on_path((stream.position[rows] - translation) @ rotation, runs[k].points, runs[k].s,
                                trees[k])[0] for k, rows in picked.items()]
        x = np.vstack([stream.position[rows] for rows in picked.values()])
        new_rotation, new_translation = rigid_fit(np.vstack(feet), x)
        moved = np.linalg.norm(new_translation - translation) + np.linalg.norm(new_rotation - rotation)
        rotation, translation = new_rotation, new_translation
        if moved < 1e-10:
            break
    feet = np.vstack([project_on_path((stream.position[rows] - translation) @ rotation, runs[k].points, runs[k].s,
                                      trees[k])[0] for k, rows in picked.items()])
    residual = np.linalg.norm((x - translation) @ rotation - feet, axis=1)
    return StreamFrame(rotation, translation, float(np.sqrt(np.mean(residual ** 2))), len(x))


@dataclass(frozen=True)
class PathEvaluation:
    """An evaluated path test: ``runs`` a list of (CommandedRun, PathFigures); ``frame`` (``fit``,
    ``base``, ``given``), ``how`` in words, ``notes``."""

    runs: list
    frame: str
    how: str
    notes: list


def evaluate_path_test(robot: RobotModel, commanded: MeasurementSet, stream: TrackerStream, *, frame: str = "fit",
                       registration: Registration | None = None, registration_source: str = "",
                       planes: int = 100, model=None, registration_after: Registration | None = None
                       ) -> tuple[PathEvaluation, PathEvaluation | None]:
    """Every path characteristic of a measured path test (see the module docstring).

    Parameters
    ----------
    robot : RobotModel
    commanded : MeasurementSet
        The commanded paths (joints; ``path``, ``speed_pct``, ``speed_mm_s`` annotations,
        ``time_s``).
    stream : TrackerStream
        The measured stream.
    frame : {"fit", "base"}, default="fit"
    registration : Registration, optional
        The instrument frame fitted on poses of the same session; not with ``frame="base"``.
    registration_source : str
    planes : int, default=100
        Normal planes per path.
    model : tuple of (list, list), optional
        Effects and parameter vectors of a diagnosis (:func:`tcr_accuracy.iso9283.evaluate.diagnosis_model`).
    registration_after : Registration, optional
        With ``registration`` and ``model``: the frame fitted on the same poses with the model's
        displacement removed from them (the frame the compensated robot is seen in); default
        ``registration``.

    Returns
    -------
    tuple of (PathEvaluation, PathEvaluation or None)
        As measured, and predicted after compensation with ``model``.

    Examples
    --------
    >>> import pathlib
    >>> import tempfile
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> path = tcr.plan_path_test(robot, np.random.default_rng(0)).paths[0]  # the first standard path
    >>> times = np.linspace(0.0, 2.0, len(path.q))
    >>> commanded = tcr.MeasurementSet(joint_names=list(robot.joint_names), q=path.q, position=path.points,
    ...                                time_s=times, annotations={"path": np.full(len(path.q), path.name, dtype=object)})
    >>> rows = ["time_s,x_mm,y_mm,z_mm,path,cycle"]
    >>> for cycle in (1, 2, 3):  # the robot runs the path three times; the tracker logs at 200 Hz
    ...     t = np.linspace(0.0, 2.0, 401)
    ...     p = np.stack([np.interp(t, times, path.points[:, a]) for a in range(3)], axis=1) * 1e3
    ...     rows += [f"{10 * cycle + tk:.3f},{x:.4f},{y:.4f},{z:.4f},{path.name},{cycle}" for tk, (x, y, z) in zip(t, p)]
    >>> stream_file = tempfile.mkdtemp() + "/stream.csv"
    >>> _ = pathlib.Path(stream_file).write_text("\\n".join(rows) + "\\n")
    >>> measured, compensated = tcr.evaluate_path_test(robot, commanded, tcr.read_tracker_stream(stream_file), frame="base",
    ...                                              planes=20)
    >>> len(measured.runs), measured.runs[0][1].at < 1e-4  # AT_P [m]: the robot follows its path
    (1, True)
    """
    if frame not in ("fit", "base"):
        raise InputError(f"frame {frame!r}: use 'fit' or 'base'")
    if registration is not None and frame == "base":
        raise InputError("frame 'base' and a registration from other poses: give one")
    if planes < 3:
        raise InputError(f"planes {planes}: want at least 3 normal planes per path")
    runs = commanded_runs(robot, commanded, registration)
    cycles, notes = stream_cycles(stream, runs)
    measured_runs = sorted(cycles)
    check_spread_units(stream.position, np.vstack([runs[k].points for k in measured_runs]), stream.position_columns,
                       stream.source, "check the stream's position unit and that it measures these paths")
    if registration is not None:
        base, used = registration.to_base(stream.position), "given"
        how = (f"from {registration_source or 'other poses'}: fitted on its {registration.n_points} poses "
               f"(fit residual RMS {registration.residual_rms * 1e3:.4f} mm)")
    elif frame == "fit":
        fitted = fit_stream_frame(runs, stream, cycles)
        base, used = fitted.to_base(stream.position), "fit"
        how = (f"fitted to the commanded paths (arc-length start, then closest points on the paths, Kabsch) on "
               f"{fitted.n_points} readings, residual RMS {fitted.residual_rms * 1e3:.4f} mm; a constant offset or "
               "rotation of the attained paths is taken up and not seen in AT")
    else:
        base, used, how = stream.position, "base", "not fitted: the readings are taken as base-frame positions"
    before = _figures(runs, measured_runs, cycles, stream, base, planes, used, how, notes)
    after = None
    if model is not None:
        if registration is not None and registration_after is not None:  # the compensated robot's frame
            base = registration_after.to_base(stream.position)
            runs = commanded_runs(robot, commanded, registration_after)
        shifted = base - _model_shift(robot, runs, cycles, base, *model)
        after = _figures(runs, measured_runs, cycles, stream, shifted, planes, used, how, notes)
    return before, after


def _figures(runs, measured_runs, cycles, stream, base, planes, frame, how, notes) -> PathEvaluation:
    out = []
    for k in measured_runs:
        run = runs[k]
        try:
            figures = path_figures(run.points, run.s, [(stream.time_s[rows], base[rows]) for rows in cycles[k]],
                                   planes=planes, corners=run.corners, commanded_times=run.times, speed=run.speed)
        except InputError as exc:  # the formulas know no file: say which and which run
            raise InputError(f"{stream.source}: the {run.words()}: {exc}") from None
        _check_speed(stream, run, figures)
        out.append((run, figures))
    said = list(notes)
    missed = [(run.words(), f.missed) for run, f in out if f.missed]
    if missed:
        said.append("normal planes a cycle did not cross (left out of that plane's figures): " +
                    ", ".join(f"{w} {m}" for w, m in missed))
    no_speed = [run.words() for run, f in out if f.speed is None]
    if no_speed:
        said.append(f"no commanded time or speed: no AV, RV, FV for {', '.join(no_speed)}")
    return PathEvaluation(runs=out, frame=frame, how=how, notes=said)


def _model_shift(robot, runs, cycles, base, effects, params) -> np.ndarray:
    """(N, 3) the model's TCP displacement [m] at the commanded joints nearest each reading."""
    shift = np.zeros_like(base)
    for k, rows_of in cycles.items():
        run = runs[k]
        delta = predict_positions(robot, effects, params, run.q, run.context) - tcp_poses(robot, run.q).position
        rows = np.concatenate(rows_of)
        _, s_foot = project_on_path(base[rows], run.points, run.s)
        shift[rows] = np.stack([np.interp(s_foot, run.s, delta[:, a]) for a in range(3)], axis=1)
    return shift


__all__ = ["CommandedRun", "PathEvaluation", "StreamFrame", "commanded_runs", "evaluate_path_test",
           "fit_stream_frame", "project_on_path", "stream_cycles"]
