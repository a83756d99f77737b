"""Commands ``predict`` and ``compensate``: the remaining error from measurements, and
joint commands that correct it (the second seed).

Input: measurement CSVs in the shared format (:mod:`tcr_accuracy.measurements`): joint
columns ``<joint>_deg|_rad|_mm|_m`` and, for training data, the measured TCP position
``x_mm, y_mm, z_mm`` (or ``_m``). The error is measured minus nominal TCP position, so
positions in a tracker frame other than the base frame make the frame offset part of
the predicted error. Output joint values are in degrees and millimetres.

Both commands end like the other analyses (:mod:`tcr_accuracy.cli_output`): ``--json``,
``--out DIR`` (report), ``--plots DIR``, ``--view``/``--serve``, ``--quiet``; their CSV
(``--csv FILE``) is written whole, once everything has been computed, just before the
view, JSON and report.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .cli import add_robot_arguments, status
from .cli_output import RunOutput, add_output_arguments

#: names of prediction.METHODS, repeated here so that --help does not import scikit-learn
#: (a test checks that the two lists agree)
METHODS = ("kriging", "kriging-pf", "gp", "idw-joint", "idw-cartesian", "mlp-cartesian", "calibration",
           "calibration+gp")

JSON_HELP = "write a JSON summary (mm, unit-suffixed keys) to FILE, or to stdout without FILE"

#: most rows of the per-pose tables in the report (the CSV has them all)
REPORT_ROWS = 50


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "predict", help="predict the TCP error at given joint values from measured poses",
        description="Fit an error predictor to measured poses (--train) and predict the TCP "
                    "position error (real minus nominal) at the joint values of --query.",
    )
    _common(p, METHODS)
    p.add_argument("--query", required=True, metavar="CSV", help="joint values to predict at (CSV)")
    p.add_argument("--csv", metavar="FILE",
                   help="write the predictions: the query joints and ex_mm, ey_mm, ez_mm, e_norm_mm")
    add_output_arguments(p, plots=True, view=True, json_help=JSON_HELP)
    p.set_defaults(run=_run_predict)

    c = sub.add_parser(
        "compensate", help="corrected joint commands so the predicted real TCP lands on target",
        description="Fit an error predictor to measured poses (--train), then for every target "
                    "(joint values whose nominal TCP is where the tool should go) search the "
                    "joint command whose predicted real TCP reaches it (cyclic search, IK steps).",
    )
    _common(c, METHODS)
    c.add_argument("--targets", required=True, metavar="CSV", help="target joint values (CSV)")
    c.add_argument("--threshold-mm", type=float, default=0.001,
                   help="stop when the predicted miss is below this [mm] (default 0.001)")
    c.add_argument("--max-iter", type=int, default=20, help="most compensation cycles (default 20)")
    c.add_argument("--csv", metavar="FILE", help="write the compensated joint values [deg, mm], the "
                                                 "corrections and the predicted miss")
    add_output_arguments(c, plots=True, view=True, json_help=JSON_HELP)
    c.set_defaults(run=_run_compensate)


def _common(p: argparse.ArgumentParser, methods) -> None:
    add_robot_arguments(p)
    p.add_argument("--train", required=True, metavar="CSV", help="measured poses: joints and x/y/z (CSV)")
    p.add_argument("--method", default="gp", choices=methods,
                   help="predictor (default gp; kriging-pf is the seed's method)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the stochastic methods (default 0)")


def read_joint_csv(path: str, robot, *, need_positions: bool):
    """Joint values (N, n) [SI] and measured positions (N, 3) [m] (None for a pose list),
    read and validated by :func:`tcr_accuracy.measurements.read_measurements`."""
    from .measurements import read_measurements

    mset = read_measurements(path, robot, require_position=need_positions)
    return mset.q, (mset.position if need_positions else None)


def _check_csv_target(path: str | None) -> None:
    """Fail before the computation when the --csv folder does not exist."""
    if path is not None and not Path(path).resolve().parent.is_dir():
        from .exceptions import InputError

        raise InputError(f"--csv {path}: the folder {Path(path).parent} does not exist")


def _write_csv_atomically(args, what: str, header: list[str], rows) -> None:
    import io

    from .atomic import write_text_atomically

    if args.csv is None:
        return
    buf = io.StringIO()
    buf.write(",".join(header) + "\n")
    for row in rows:
        buf.write(",".join(f"{v:.9g}" for v in row) + "\n")
    write_text_atomically(Path(args.csv), buf.getvalue())
    status(args, f"{what} written to {args.csv}")


def _check_training(path: str, q, n_joints: int) -> None:
    import numpy as np

    from .exceptions import InputError

    if q.shape[0] <= n_joints:
        raise InputError(f"{path}: {q.shape[0]} training poses for {n_joints} joints; need at least "
                         f"{n_joints + 1} (the seed used 160 for 6)")
    _, first, inverse, counts = np.unique(q, axis=0, return_index=True, return_inverse=True,
                                          return_counts=True)
    if (counts > 1).any():
        group = int(np.flatnonzero(counts > 1)[0])
        rows = np.flatnonzero(inverse.ravel() == group)[:2] + 2
        raise InputError(f"{path}: rows {rows[0]} and {rows[1]} have the same joint values (a singular "
                         "kriging covariance); average repeated measurements of a pose into one row")


def _fit(args, robot):
    import warnings

    from sklearn.exceptions import ConvergenceWarning

    from .kinematics import tcp_poses
    from .prediction import make_predictor

    q, pos = read_joint_csv(args.train, robot, need_positions=True)
    _check_training(args.train, q, robot.n_joints)
    errors = pos - tcp_poses(robot, q).position
    estimator = make_predictor(args.method, robot, random_state=args.seed)
    with warnings.catch_warnings():
        # scikit-learn's optimisers warn at their iteration caps; the fit is still usable
        warnings.simplefilter("ignore", ConvergenceWarning)
        estimator.fit(q, errors)
    return q, estimator


def _predict(args, estimator, q):
    """Predicted errors (N, 3) [m], checked finite."""
    import numpy as np

    from .exceptions import AnalysisError

    pred = np.asarray(estimator.predict(q), dtype=float).reshape(-1, 3)
    if not np.all(np.isfinite(pred)):
        raise AnalysisError(f"method {args.method} predicted non-finite errors")
    return pred


def _start(args, title: str):
    """The robot and the run's outputs, checked before any work."""
    from .robot import load_robot

    _check_csv_target(args.csv)
    out = RunOutput(args, title)
    return load_robot(args.robot, args.tool), out


def _fit_table(out, robot, args, q_train, what: str, n: int) -> None:
    out.add_table("Predictor", ["setting", "value"],
                  [("robot", robot.name), ("method", args.method), ("training poses", int(q_train.shape[0])),
                   ("training file", str(args.train)), (what, n), ("seed", args.seed)])


def _joint_columns(robot, prefix: str = "") -> list[str]:
    return [f"{prefix}{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]


def _median_index(values) -> int:
    """Index of the value nearest the median: the pose the 3D view shows the robot at."""
    import numpy as np

    return int(np.argmin(np.abs(values - np.median(values))))


# ---------------------------------------------------------------------------------------
# predict
# ---------------------------------------------------------------------------------------
def _run_predict(args) -> int:
    import numpy as np

    from .plots_prediction import plot_predicted_errors

    robot, out = _start(args, "Error prediction")
    q_train, estimator = _fit(args, robot)
    q, _ = read_joint_csv(args.query, robot, need_positions=False)
    scale = robot.display_scale
    pred = _predict(args, estimator, q)
    norm = np.linalg.norm(pred, axis=1)
    stats = {
        "mean": (norm.mean(), *np.abs(pred).mean(axis=0)),
        "RMS": (np.sqrt(np.mean(norm ** 2)), *np.sqrt(np.mean(pred ** 2, axis=0))),
        "max": (norm.max(), *np.abs(pred).max(axis=0)),
    }
    payload = {
        "robot": robot.name, "method": args.method, "n_train": int(q_train.shape[0]), "n_query": int(q.shape[0]),
        "predicted_error_mean_mm": float(norm.mean() * 1e3), "predicted_error_max_mm": float(norm.max() * 1e3),
        "predicted_error_stats_mm": {k: dict(zip(("norm", "abs_ex", "abs_ey", "abs_ez"), (float(v * 1e3) for v in s)))
                                     for k, s in stats.items()},
        "predicted_errors_mm": (pred * 1e3).tolist(),
    }
    _fit_table(out, robot, args, q_train, "query poses", int(q.shape[0]))
    out.add_table("Predicted error at the query poses", ["statistic", "|e|", "|ex|", "|ey|", "|ez|"],
                  [(k, *(v * 1e3 for v in s)) for k, s in stats.items()], units=["", "mm", "mm", "mm", "mm"],
                  note="error = real minus nominal TCP position, base frame")
    shown = min(len(q), REPORT_ROWS)
    out.add_table("Predicted error per query pose", ["row", *_joint_columns(robot), "ex", "ey", "ez", "|e|"],
                  [(i + 2, *(q[i] * scale), *(pred[i] * 1e3), norm[i] * 1e3) for i in range(shown)],
                  units=["", *[""] * robot.n_joints, "mm", "mm", "mm", "mm"],
                  note=None if shown == len(q) else f"first {shown} of {len(q)} (all in --csv)")
    out.add_plots(lambda folder: [plot_predicted_errors(pred, Path(folder) / "predicted_errors.png")],
                  {"predicted_errors.png": "Predicted TCP error at each query pose (components and magnitude) "
                                           "and its distribution"})
    if out.scene_wanted:
        out.set_scene(*_predict_scene(robot, q, pred, norm, args))
    header = _joint_columns(robot) + ["ex_mm", "ey_mm", "ez_mm", "e_norm_mm"]
    _write_csv_atomically(args, "predictions", header, np.hstack([q * scale, pred * 1e3, norm[:, None] * 1e3]))
    return out.finish(payload, lambda: _print(robot, args, q_train,
                                              f"predicted |error| at {q.shape[0]} query poses: mean "
                                              f"{norm.mean() * 1e3:.4f} mm, max {norm.max() * 1e3:.4f} mm"))


def _print(robot, args, q_train, *lines: str) -> None:
    print(f"{robot.name}: {args.method} fitted to {q_train.shape[0]} measured poses ({args.train})")
    for line in lines:
        print(f"  {line}")


def _predict_scene(robot, q, pred, norm, args):
    from .kinematics import tcp_poses
    from .viewer import Scene, auto_magnification

    nominal = tcp_poses(robot, q).position
    magnify = auto_magnification(float(norm.max()), drawn_m=0.3)
    scene = Scene(f"{robot.name}: error predicted by {args.method}")
    shown = _median_index(norm)
    scene.add_robot(robot, q[shown], name="nominal robot", opacity=0.5)  # the TCP points sit in the tool
    scene.add_point_cloud(nominal, norm * 1e3, name="query TCP", label="predicted TCP error |e| [mm]",
                          size_m=0.025)
    scene.add_error_segments(nominal, nominal + pred, magnify=magnify, name="predicted error",
                             start_label="nominal TCP at the query joints",
                             end_label="predicted real TCP", size_m=0.015)
    scene.add_note(f"{len(q)} query poses, {args.method} fitted to {args.train}; robot at query row {shown + 2} "
                   f"(median |e|); segments magnified x {magnify:g}")
    return scene, (f"Query TCP points coloured by the predicted |e|; segments to the predicted real TCP, "
                   f"magnified x {magnify:g}")


# ---------------------------------------------------------------------------------------
# compensate
# ---------------------------------------------------------------------------------------
def _run_compensate(args) -> int:
    import numpy as np

    from .compensation import compensate_joints
    from .exceptions import InputError
    from .kinematics import tcp_poses
    from .plots_prediction import plot_compensation

    if args.threshold_mm <= 0:
        raise InputError(f"--threshold-mm {args.threshold_mm}: must be > 0")
    if args.max_iter < 1:
        raise InputError(f"--max-iter {args.max_iter}: must be >= 1")
    robot, out = _start(args, "Joint compensation")
    q_train, estimator = _fit(args, robot)
    q, _ = read_joint_csv(args.targets, robot, need_positions=False)
    units, scale = robot.display_units, robot.display_scale
    result = compensate_joints(robot, estimator, q, threshold=args.threshold_mm * 1e-3, max_iter=args.max_iter)
    failed = np.flatnonzero(~result.converged)
    if failed.size:
        rows = ", ".join(str(i + 2) for i in failed[:10]) + (" ..." if failed.size > 10 else "")
        raise InputError(f"{args.targets}: {failed.size} target(s) not reachable within the joint limits or "
                         f"{args.max_iter} cycles (rows {rows}; predicted miss up to "
                         f"{result.predicted_miss[failed].max() * 1e3:.4g} mm)")
    dq = (result.q - q) * scale
    # the real TCP the uncompensated command is predicted to reach, and the compensated one
    before_tcp = result.target + _predict(args, estimator, q)
    after_tcp = tcp_poses(robot, result.q).position + _predict(args, estimator, result.q)
    before = np.linalg.norm(before_tcp - result.target, axis=1)
    after = result.predicted_miss
    cycles, counts = np.unique(result.iterations, return_counts=True)
    payload = {
        "robot": robot.name, "method": args.method, "n_train": int(q_train.shape[0]), "n_targets": int(q.shape[0]),
        "threshold_mm": args.threshold_mm, "iterations_max": int(result.iterations.max()),
        "n_converged": int(result.converged.sum()),
        "cycles_targets": {str(int(c)): int(n) for c, n in zip(cycles, counts)},
        "predicted_error_before_mean_mm": float(before.mean() * 1e3),
        "predicted_error_before_max_mm": float(before.max() * 1e3),
        "predicted_miss_mean_mm": float(after.mean() * 1e3),
        "predicted_miss_max_mm": float(after.max() * 1e3),
        "joint_units": units, "compensated_joints": (result.q * scale).tolist(),
    }
    _fit_table(out, robot, args, q_train, "targets", int(q.shape[0]))
    out.add_table("Predicted error at the targets, before and after compensation", ["command", "mean", "max"],
                  [("uncompensated (target joints)", before.mean() * 1e3, before.max() * 1e3),
                   ("compensated", after.mean() * 1e3, after.max() * 1e3)], units=["", "mm", "mm"],
                  note="|predicted real TCP - target|; predicted real TCP = nominal FK + predicted error")
    out.add_table("Convergence", ["cycles", "targets"], [(int(c), int(n)) for c, n in zip(cycles, counts)],
                  note=f"{int(result.converged.sum())} of {len(q)} targets converged (predicted miss below "
                       f"{args.threshold_mm:g} mm, joints inside their limits, at most {args.max_iter} cycles)")
    out.add_table("Joint corrections", ["joint", "largest |correction|", "unit"],
                  [(n, np.abs(dq[:, j]).max(), u) for j, (n, u) in enumerate(zip(robot.joint_names, units))])
    out.add_plots(lambda folder: [plot_compensation(before, after, Path(folder) / "compensation.png")],
                  {"compensation.png": "Predicted error at the targets before and after compensation"})
    if out.scene_wanted:
        out.set_scene(*_compensate_scene(robot, q, result, before_tcp, after_tcp, before, args))
    header = _joint_columns(robot) + _joint_columns(robot, "d") + ["predicted_miss_mm"]
    _write_csv_atomically(args, "compensated joint values", header,
                          np.hstack([result.q * scale, dq, result.predicted_miss[:, None] * 1e3]))
    return out.finish(payload, lambda: _print(
        robot, args, q_train,
        f"{q.shape[0]} targets compensated in at most {result.iterations.max()} cycles; largest joint "
        f"correction {np.abs(dq).max():.4g} ({', '.join(sorted(set(units)))})",
        f"predicted error at the targets: mean {before.mean() * 1e3:.4f} mm, max {before.max() * 1e3:.4f} mm "
        f"before; mean {after.mean() * 1e3:.2g} mm, max {after.max() * 1e3:.2g} mm after"))


def _compensate_scene(robot, q, result, before_tcp, after_tcp, before, args):
    from .viewer import COLORS, Scene, auto_magnification

    magnify = auto_magnification(float(before.max()), drawn_m=0.3)
    scene = Scene(f"{robot.name}: compensation with {args.method}")
    shown = _median_index(before)
    scene.add_robot(robot, result.q[shown], name="compensated command", opacity=0.5)
    scene.add_error_segments(result.target, before_tcp, magnify=magnify, name="before",
                             start_label="target TCP", end_label="predicted real TCP, uncompensated command",
                             size_m=0.02)
    scene.add_error_segments(result.target, after_tcp, magnify=magnify, name="after",
                             start_label="target TCP", end_label="predicted real TCP, compensated command",
                             end_color=COLORS["trajectory"], size_m=0.02)
    del scene.legend[-2]  # the targets' entry, already in the legend once
    scene.add_note(f"{len(q)} targets of {args.targets}; robot at target row {shown + 2} (median error before); "
                   f"segments magnified x {magnify:g}")
    return scene, f"Targets and the predicted real TCP before and after compensation, magnified x {magnify:g}"
