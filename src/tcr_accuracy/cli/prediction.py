"""Commands ``predict`` and ``compensate``: the remaining error from measurements, and
joint commands that correct it (the second seed).

Input: measurement CSVs in the shared format (:mod:`tcr_accuracy.io.measurements`): joint
columns ``<joint>_deg|_rad|_mm|_m`` and, for training data, the measured TCP position
``x_mm, y_mm, z_mm`` (or ``_m``) in the tracker's own frame. The tracker frame and the
TCP offset are fitted on the training data first (:mod:`tcr_accuracy.frames.registration`;
``--frame base`` when the positions are in the robot's base frame already); the error,
real minus nominal TCP position, is then taken in the base frame. A query (or target)
file that also carries measured positions is mapped with the training data's frame and
scored: the held-out error of the prediction. Output joint values are in degrees and
millimetres.

Both commands end like the other analyses (:mod:`tcr_accuracy.cli.output`): ``--json``,
``--out DIR`` (report), ``--plots DIR``, ``--view``/``--serve``, ``--quiet``; their CSV
(``--csv FILE``) is written whole, once everything has been computed, just before the
view, JSON and report.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..prediction.methods import DEFAULT_METHOD, METHODS
from .common import (MAX_MM, add_robot_arguments, check_csv_memory, integer, number, output_file, seed_value,
                     status)
from .output import RunOutput, add_output_arguments

JSON_HELP = "write a JSON summary (mm, unit-suffixed keys) to FILE, or to stdout without FILE"

#: What ``predict``'s headline, summary table and plot call the error (the JSON says it too).
ERROR_DEFINITION = ("measured point minus where the nominal robot with the fitted TCP offset puts it, robot base "
                    "frame (the offset itself, e.g. a reflector off the flange, is not counted)")

#: most rows of the per-pose tables in the report (the CSV has them all)
REPORT_ROWS = 50


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "predict", help="predict the TCP error at given joint values from measured poses",
        description="Fit an error predictor to measured poses (--train) and predict the TCP "
                    "position error (real minus nominal, robot base frame) at the joint values of "
                    "--query. When --query also has measured positions, report the held-out error "
                    "of the prediction against them.",
    )
    _common(p, METHODS)
    p.add_argument("--query", required=True, metavar="CSV",
                   help="joint values to predict at (CSV); with x/y/z columns also scored against them")
    p.add_argument("--csv", type=output_file, metavar="FILE",
                   help="write the predictions: the query joints, ex_mm, ey_mm, ez_mm, e_norm_mm, their "
                        "standard deviations ex_std_mm ... (methods with one) and, for measured queries, "
                        "the measured error and the held-out miss")
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
    c.add_argument("--threshold-mm", type=number(low=0, low_open=True, high=MAX_MM, unit="mm"), default=0.001,
                   help="stop when the predicted miss is below this [mm] (default 0.001)")
    c.add_argument("--max-iter", type=integer(low=1, high=10_000), default=20,
                   help="most compensation cycles (default 20)")
    c.add_argument("--csv", type=output_file, metavar="FILE", help="write the compensated joint values [deg, mm], the "
                                                 "corrections and the predicted miss")
    add_output_arguments(c, plots=True, view=True, json_help=JSON_HELP)
    c.set_defaults(run=_run_compensate)


def _common(p: argparse.ArgumentParser, methods) -> None:
    add_robot_arguments(p)
    p.add_argument("--train", required=True, metavar="CSV", help="measured poses: joints and x/y/z (CSV)")
    p.add_argument("--method", default=DEFAULT_METHOD, choices=methods,
                   help=f"predictor (default {DEFAULT_METHOD}: the diagnosis' fitted effect model plus a "
                        "Gaussian process of what it leaves; kriging-pf is the seed's method; local-gp for "
                        "10,000 training poses and more; bayes: the whole effect vocabulary linearised, with "
                        "a prior fitted to the data, for few poses)")
    p.add_argument("--frame", default="fit", choices=("fit", "base"),
                   help="fit: the positions are in a tracker's own frame; fit it and the TCP offset on the "
                        "training data (default); base: they are in the robot's base frame already (only the "
                        "TCP offset is fitted)")
    p.add_argument("--seed", type=seed_value, default=0, help="random seed of the stochastic methods (default 0)")


def read_joint_csv(path: str, robot, *, need_positions: bool, rows: bool = False, repeats: bool = False):
    """Joint values (N, n) [SI], measured positions (N, 3) [m] (None when the file has none)
    and the rows' context (payload, joints outside the TCP chain, ...), read and validated by
    :func:`tcr_accuracy.io.measurements.read_measurements`; with ``rows``, also each row's
    line in the file (N,), for messages. ``repeats``: rows may repeat (poses to predict or
    compensate, where asking twice is legitimate)."""
    import numpy as np

    from ..io.measurements import read_measurements

    mset = read_measurements(path, robot, require_position=need_positions, repeats_allowed=repeats)
    has_positions = need_positions or not np.isnan(mset.position).all()
    out = mset.q, (mset.position if has_positions else None), mset.context
    return (*out, mset.rows) if rows else out


def _write_csv(args, what: str, header: list[str], rows) -> None:
    import io

    from .staging import write_text

    if args.csv is None:
        return
    buf = io.StringIO()
    buf.write(",".join(header) + "\n")
    for row in rows:
        buf.write(",".join(f"{v:.9g}" for v in row) + "\n")
    write_text(Path(args.csv), buf.getvalue())
    status(args, f"{what} written to {args.csv}")


def _check_training(path: str, q, lines, n_joints: int) -> None:
    """Enough distinct training poses; ``lines`` (N,): each row's line in the file, for messages."""
    import numpy as np

    from ..exceptions import InputError

    if q.shape[0] <= n_joints:
        raise InputError(f"{path}: {q.shape[0]} training poses for {n_joints} joints; need at least "
                         f"{n_joints + 1} (the seed used 160 for 6)")
    _, first, inverse, counts = np.unique(q, axis=0, return_index=True, return_inverse=True,
                                          return_counts=True)
    if (counts > 1).any():
        group = int(np.flatnonzero(counts > 1)[0])
        rows = np.asarray(lines)[np.flatnonzero(inverse.ravel() == group)[:2]]
        raise InputError(f"{path}: rows {rows[0]} and {rows[1]} have the same joint values (a singular "
                         "kriging covariance); average repeated measurements of a pose into one row")


#: Methods holding an n x n covariance of the n training rows (Gaussian processes, kriging).
_QUADRATIC = ("kriging", "kriging-pf", "gp", "calibration+gp", "diagnosis+gp")


def _training_row_bytes(method: str) -> float:
    """Memory [bytes] a method plans per training row (the diagnosis' Jacobians for diagnosis*)."""
    from .diagnose import DIAGNOSE_ROW_BYTES

    if method == "bayes":  # the columns of the linearised vocabulary, about 600 on a 6-joint arm, and their making
        return 4 * 3 * 600 * 8.0
    return DIAGNOSE_ROW_BYTES if method.startswith("diagnosis") else 3 * 64 * 8.0


def _training_pair_bytes(method: str):
    """Memory [bytes] for n training rows beyond the per-row part: a few n x n matrices."""
    return (lambda rows: 4 * 8.0 * rows * rows) if method in _QUADRATIC else (lambda rows: 0.0)


def _fit(args, robot):
    """Read the training file, fit the tracker frame and the predictor: (q_train, MeasuredErrorModel)."""
    import time
    import warnings

    from sklearn.exceptions import ConvergenceWarning

    from ..exceptions import InputError
    from ..prediction.composed import MeasuredErrorModel
    from ..prediction.methods import make_predictor

    check_csv_memory(args, args.train, f"--method {args.method} on --train", _training_row_bytes(args.method),
                     _training_pair_bytes(args.method), hint="use fewer training rows, or --method local-gp or "
                                                           "calibration+local-gp (memory linear in the rows)")
    q, pos, context, lines = read_joint_csv(args.train, robot, need_positions=True, rows=True)
    _check_training(args.train, q, lines, robot.n_joints)
    model = MeasuredErrorModel(robot=robot, estimator=make_predictor(args.method, robot, random_state=args.seed),
                               fit_frame=args.frame == "fit")
    # the fit is the long part (seconds to minutes): say what runs, so the terminal is not blank
    _progress(args, f"fitting {args.method} to {q.shape[0]} measured poses of {args.train} "
                 f"({'tracker frame and ' if args.frame == 'fit' else ''}TCP offset first) ...")
    started = time.perf_counter()
    try:
        with warnings.catch_warnings():
            # scikit-learn's optimisers warn at their iteration caps; the fit is still usable
            warnings.simplefilter("ignore", ConvergenceWarning)
            model.fit(q, pos, context=context)
    except InputError as exc:
        hint = "; or choose a --method that needs fewer poses (gp, kriging)" if args.method.startswith(
            "diagnosis") and "too few" in str(exc) else ""
        raise InputError(f"{args.train}: {exc}{hint}", parameter=exc.parameter, value=exc.value) from None
    _progress(args, f"fitted in {time.perf_counter() - started:.1f} s")
    return q, model


def _progress(args, message: str) -> None:
    """A progress line on stderr, as the progress bars: only on a terminal and without --quiet
    (a log or a pipe gets the results and the status lines, and bad input stays one line)."""
    import sys

    if not getattr(args, "quiet", False) and sys.stderr.isatty():
        sys.stderr.write(message + "\n")


def _frame_rows(model, args):
    reg = model.registration_
    info = reg.to_dict()
    rows = [("frame", "fitted on the training data" if args.frame == "fit" else "base frame (--frame base)"),
            ("rotation angle", f"{info['rotation_angle_deg']:.4f} deg"),
            ("translation", "({:.3f}, {:.3f}, {:.3f}) mm".format(*info["translation_mm"])),
            ("TCP offset (TCP frame)", "({:.4f}, {:.4f}, {:.4f}) mm".format(*info["tool_offset_mm"])),
            ("RMS after the frame fit", f"{info['residual_rms_mm']:.4f} mm")]
    return rows


def _frame_line(model, args) -> str:
    info = model.registration_.to_dict()
    where = ("tracker frame fitted on the training data: rotation {:.4f} deg, translation ({:.3f}, {:.3f}, {:.3f}) mm"
             .format(info["rotation_angle_deg"], *info["translation_mm"]) if args.frame == "fit"
             else "positions taken in the base frame (--frame base)")
    return (f"{where}; TCP offset ({info['tool_offset_mm'][0]:.4f}, {info['tool_offset_mm'][1]:.4f}, "
            f"{info['tool_offset_mm'][2]:.4f}) mm; RMS after the frame fit {info['residual_rms_mm']:.4f} mm")


def _start(args, title: str):
    """The robot and the run's outputs, checked before any work."""
    from .common import robot_from_args

    out = RunOutput(args, title)
    return robot_from_args(args), out


def _fit_table(out, robot, args, q_train, what: str, n: int) -> None:
    out.add_table("Predictor", ["setting", "value"],
                  [("robot", robot.name), ("method", args.method), ("training poses", int(q_train.shape[0])),
                   ("training file", str(args.train)), (what, n), ("seed", args.seed)])


def _joint_columns(robot, prefix: str = "") -> list[str]:
    return [f"{prefix}{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]


def _nominal_summary(nominal) -> dict:
    """The JSON's ``nominal`` of a :class:`~tcr_accuracy.prediction.nominal.NominalError` [mm]."""
    from ..prediction.nominal import NOMINAL_DEFINITION

    return {"mean_mm": nominal.mean * 1e3, "rms_mm": nominal.rms * 1e3, "max_mm": nominal.max * 1e3, "n": nominal.n,
            "definition": NOMINAL_DEFINITION}


def nominal_line(summary: dict, poses: str) -> str:
    """The printed line of the nominal figure (the same words in export, predict and compensate)."""
    return (f"nominal (the nominal robot, tracker frame and TCP offset fitted to the training poses) on the "
            f"{summary['n']} {poses}: mean {summary['mean_mm']:.4f} mm, RMS {summary['rms_mm']:.4f} mm, max "
            f"{summary['max_mm']:.4f} mm")


def _held_out_summary(held) -> dict:
    """The JSON's ``heldout`` of a :class:`~tcr_accuracy.prediction.held_out.HeldOutError` [mm]: mean, RMS and
    max of the miss, the count and, with a standard deviation, how well it covers the miss."""
    summary = {"mean_mm": held.mean * 1e3, "rms_mm": held.rms * 1e3, "max_mm": held.max * 1e3, "count": held.count}
    if held.std is not None:
        summary.update(within_2std=held.within_2std, z_rms=held.z_rms)
    return summary


# ---------------------------------------------------------------------------------------
# predict
# ---------------------------------------------------------------------------------------
def _refuse_training_poses(args, q_train, q, lines) -> None:
    """A measured query pose that is a training pose (the same joint values) has an in-sample error,
    not a held-out one: ``--query m.csv`` with ``--train m.csv`` printed 0.0000 mm as "held-out"."""
    import numpy as np

    from ..exceptions import InputError

    train = {tuple(row) for row in np.round(q_train, 12)}
    same = [k for k, row in enumerate(np.round(q, 12)) if tuple(row) in train]
    if same:
        raise InputError(f"--query {args.query}: row {lines[same[0]]} ({len(same)} of {len(q)} measured rows) is a pose "
                         f"of --train {args.train}: its error is in-sample, not held out; measure other poses, or "
                         "leave the positions out to predict there")


def _run_predict(args) -> int:
    import numpy as np

    from ..prediction.error_prediction import predict_errors
    from ..prediction.nominal import nominal_error
    from ..view.plots_prediction import plot_predicted_errors

    robot, out = _start(args, "Error prediction")
    q_train, model = _fit(args, robot)
    check_csv_memory(args, args.query, "--query", 3 * 64 * 8.0)
    q, measured, context, lines = read_joint_csv(args.query, robot, need_positions=False, repeats=True, rows=True)
    if measured is not None:
        _refuse_training_poses(args, q_train, q, lines)
    scale = robot.display_scale
    prediction = predict_errors(model, q, context=context, measured=measured, label=f"method {args.method}")
    pred, std, kind, held = prediction.predicted_error, prediction.std, prediction.uncertainty, prediction.held_out
    norm = np.linalg.norm(pred, axis=1)
    robot_error = prediction.robot_error
    robot_norm = np.linalg.norm(robot_error, axis=1)
    stats = prediction.robot_error_statistics()
    heldout = None if held is None else _held_out_summary(held)
    payload = {
        "robot": robot.name, "method": args.method, "frame": args.frame,
        "n_train": int(q_train.shape[0]), "n_query": int(q.shape[0]),
        "tracker_frame": model.registration_.to_dict(),
        "error_definition": ERROR_DEFINITION,
        "predicted_error_mean_mm": float(robot_norm.mean() * 1e3),
        "predicted_error_max_mm": float(robot_norm.max() * 1e3),
        "predicted_robot_errors_mm": (robot_error * 1e3).tolist(),
        "predicted_error_stats_mm": {k: dict(zip(("norm", "abs_ex", "abs_ey", "abs_ez"), (float(v * 1e3) for v in s)))
                                     for k, s in stats.items()},
        "predicted_errors_mm": (pred * 1e3).tolist(),
        "uncertainty": kind or "none",
        "predicted_std_mm": None if std is None else (std * 1e3).tolist(),
        "heldout": heldout,
    }
    if held is not None:
        payload["measured_errors_mm"] = (held.measured_error * 1e3).tolist()
        nominal = nominal_error(model.registration_, robot, q, measured)
        payload["nominal"] = _nominal_summary(nominal)
    _fit_table(out, robot, args, q_train, "query poses", int(q.shape[0]))
    out.add_table("Tracker frame", ["setting", "value"], _frame_rows(model, args),
                  note="p_tracker = R p_base + t, fitted with the TCP offset on the training data "
                       "(closed form, then the frames effect by least squares)")
    out.add_table("Predicted error at the query poses", ["statistic", "|e|", "|ex|", "|ey|", "|ez|"],
                  [(k, *(v * 1e3 for v in s)) for k, s in stats.items()], units=["", "mm", "mm", "mm", "mm"],
                  note=f"error = {ERROR_DEFINITION}")
    if heldout is not None:
        rows = [("mean", heldout["mean_mm"]), ("RMS", heldout["rms_mm"]), ("max", heldout["max_mm"]),
                ("count", heldout["count"])]
        if "within_2std" in heldout:
            rows += [("share of axis misses within 2 std", heldout["within_2std"]),
                     ("RMS of miss / std", heldout["z_rms"])]
        out.add_table("Held-out error at the measured query poses", ["statistic", "value"], rows,
                      note="|measured - predicted error|; the query's measured positions mapped with the "
                           "training data's tracker frame")
    shown = min(len(q), REPORT_ROWS)
    columns = ["row", *_joint_columns(robot), "ex", "ey", "ez", "|e|"]
    units = ["", *[""] * robot.n_joints, "mm", "mm", "mm", "mm"]
    if std is not None:
        columns += ["std x / y / z"]  # one column: the per-pose table stays within the page
        units += ["mm"]
    if measured is not None:
        columns += ["held-out miss"]
        units += ["mm"]
    per_pose = []
    for i in range(shown):
        row = [i + 2, *(q[i] * scale), *(robot_error[i] * 1e3), robot_norm[i] * 1e3]
        if std is not None:
            row.append(" / ".join(f"{v:.4g}" for v in std[i] * 1e3))
        if measured is not None:
            row.append(float(np.linalg.norm(held.residual[i]) * 1e3))
        per_pose.append(row)
    out.add_table("Predicted error per query pose", columns, per_pose, units=units,
                  note="error beyond the fitted TCP offset (the CSV's ex_mm ... are real minus nominal TCP, "
                       "the offset included)" + ("" if shown == len(q) else f"; first {shown} of {len(q)} (all in --csv)"))
    out.add_plots(lambda folder: [plot_predicted_errors(
                      robot_error, Path(folder) / "predicted_errors.png", std=std,
                      measured=None if held is None else held.measured_error - prediction.tcp_offset_error)],
                  {"predicted_errors.png": "Predicted error at each query pose beyond the fitted TCP offset "
                                           "(components and magnitude"
                                           + (", +-2 standard deviations" if std is not None else "")
                                           + (", the measured error" if measured is not None else "")
                                           + ") and its distribution"
                                           + ("; the held-out miss, measured - predicted error, per pose"
                                              if measured is not None else "")})
    if out.scene_wanted:
        from ..view.prediction_scenes import prediction_scene

        out.set_scene(*prediction_scene(robot, q, prediction, model, method=args.method, train=args.train,
                                        rows=lines, measured=measured))
    header = _joint_columns(robot) + ["ex_mm", "ey_mm", "ez_mm", "e_norm_mm"]
    blocks = [q * scale, pred * 1e3, norm[:, None] * 1e3]
    if std is not None:
        header += ["ex_std_mm", "ey_std_mm", "ez_std_mm"]
        blocks.append(std * 1e3)
    if measured is not None:
        header += ["measured_ex_mm", "measured_ey_mm", "measured_ez_mm", "heldout_miss_mm"]
        blocks += [held.measured_error * 1e3, np.linalg.norm(held.residual, axis=1)[:, None] * 1e3]
    _write_csv(args, "predictions", header, np.hstack(blocks))
    lines = [_frame_line(model, args),
             (f"predicted |error| at {q.shape[0]} query poses: mean {robot_norm.mean() * 1e3:.4f} mm, "
              f"max {robot_norm.max() * 1e3:.4f} mm (beyond the nominal robot with the fitted TCP offset, "
              "robot base frame)"),
             (f"uncertainty ({kind}): mean std per axis {np.mean(std) * 1e3:.4f} mm" if std is not None
              else f"uncertainty: none ({args.method} gives no standard deviation)")]
    if heldout is not None:
        lines.append(nominal_line(payload["nominal"], "measured query poses"))
        lines.append(f"held-out error against the {heldout['count']} measured query positions: mean "
                     f"{heldout['mean_mm']:.4f} mm, RMS {heldout['rms_mm']:.4f} mm, max {heldout['max_mm']:.4f} mm"
                     + (f"; {100 * heldout['within_2std']:.0f} % of axis misses within 2 std"
                        if "within_2std" in heldout else ""))
    return out.finish(payload, lambda: _print(robot, args, q_train, *lines))


def _print(robot, args, q_train, *lines: str) -> None:
    print(f"{robot.name}: {args.method} fitted to {q_train.shape[0]} measured poses ({args.train})")
    for line in lines:
        print(f"  {line}")


# ---------------------------------------------------------------------------------------
# compensate
# ---------------------------------------------------------------------------------------
def _run_compensate(args) -> int:
    import numpy as np

    from ..exceptions import InputError
    from ..prediction.nominal import nominal_error
    from ..prediction.target_compensation import compensate_targets
    from ..view.plots_prediction import plot_compensation

    robot, out = _start(args, "Joint compensation")
    q_train, model = _fit(args, robot)
    check_csv_memory(args, args.targets, "--targets", 3 * 64 * 8.0)
    q_all, measured_all, context_all, lines = read_joint_csv(args.targets, robot, need_positions=False, rows=True,
                                                      repeats=True)
    units, scale = robot.display_units, robot.display_scale
    done = compensate_targets(model, q_all, threshold=args.threshold_mm * 1e-3, max_iter=args.max_iter,
                              context=context_all, measured=measured_all, label=f"method {args.method}")
    result, solved = done.result, done.solved
    lines = np.asarray(lines)
    unsolved = [{"row": int(lines[i]), "reason": str(result.reason[i]), "detail": str(result.detail[i]),
                 "predicted_miss_mm": float(result.predicted_miss[i] * 1e3)}
                for i in np.flatnonzero(~result.converged)]
    if solved.size == 0:
        raise InputError(f"{args.targets}: none of the {len(q_all)} targets can be compensated ("
                         + "; ".join(f"row {u['row']}: {u['reason']}, {u['detail']}" for u in unsolved[:3])
                         + (" ..." if len(unsolved) > 3 else "") + ")")
    q, q_comp, measured = done.q, done.q_compensated, None if measured_all is None else measured_all[solved]
    dq = done.correction * scale
    before, after, iterations = done.error_before, done.miss_after, done.iterations
    cycles, counts = np.unique(iterations, return_counts=True)
    heldout = heldout_miss = None
    if done.held_out is not None:
        heldout, heldout_miss = _held_out_summary(done.held_out), done.held_out.miss
        heldout["measured_error_before_mean_mm"] = float(done.measured_before.mean() * 1e3)
        heldout["measured_error_before_max_mm"] = float(done.measured_before.max() * 1e3)
        # the nominal figure on every measured target, solved or not (it does not depend on the compensation)
        heldout["nominal"] = _nominal_summary(nominal_error(model.registration_, robot, q_all, measured_all))
    payload = {
        "robot": robot.name, "method": args.method, "frame": args.frame, "n_train": int(q_train.shape[0]),
        "n_targets": int(q.shape[0]), "tracker_frame": model.registration_.to_dict(), "heldout": heldout,
        "threshold_mm": args.threshold_mm, "iterations_max": int(iterations.max()),
        "n_converged": int(solved.size), "n_unsolved": len(unsolved), "unsolved": unsolved,
        "solved_rows": [int(v) for v in lines[solved]],
        "cycles_targets": {str(int(c)): int(n) for c, n in zip(cycles, counts)},
        "predicted_error_before_mean_mm": float(before.mean() * 1e3),
        "predicted_error_before_max_mm": float(before.max() * 1e3),
        "predicted_miss_mean_mm": float(after.mean() * 1e3),
        "predicted_miss_max_mm": float(after.max() * 1e3),
        "joint_units": units, "compensated_joints": (q_comp * scale).tolist(),
        "largest_correction": {n: float(np.abs(dq[:, j]).max()) for j, n in enumerate(robot.joint_names)},
        "largest_first_order_correction": {n: float(np.abs(result.first_order[solved, j]).max() * scale[j])
                                           for j, n in enumerate(robot.joint_names)},
    }
    _fit_table(out, robot, args, q_train, "targets", int(q.shape[0]))
    out.add_table("Tracker frame", ["setting", "value"], _frame_rows(model, args),
                  note="p_tracker = R p_base + t, fitted with the TCP offset on the training data")
    out.add_table("Predicted error at the targets, before and after compensation", ["command", "mean", "max"],
                  [("uncompensated (target joints)", before.mean() * 1e3, before.max() * 1e3),
                   ("compensated: the model's own miss", after.mean() * 1e3, after.max() * 1e3)],
                  units=["", "mm", "mm"],
                  note="|predicted real TCP - target|, robot base frame; the TCP is the measured point (nominal "
                       "FK with the fitted TCP offset); predicted real TCP = its FK + the predicted error beyond it. The "
                       "compensated row is the model's own miss (its prediction, not a measurement): what "
                       "compensation really leaves is about the prediction's held-out error (measured targets)")
    if heldout is not None:
        out.add_table("Measured targets (held out)", ["statistic", "mean", "max"],
                      [("measured error, uncompensated", heldout["measured_error_before_mean_mm"],
                        heldout["measured_error_before_max_mm"]),
                       ("|measured - predicted error|", heldout["mean_mm"], heldout["max_mm"])],
                      units=["", "mm", "mm"],
                      note="the targets' measured positions mapped with the training data's tracker frame; the "
                           "second row is about what compensation leaves")
    out.add_table("Convergence", ["cycles", "targets"], [(int(c), int(n)) for c, n in zip(cycles, counts)],
                  note=f"{solved.size} of {len(q_all)} targets converged (predicted miss below "
                       f"{args.threshold_mm:g} mm, joints inside their limits, at most {args.max_iter} cycles)")
    if unsolved:
        out.add_table("Targets not solved", ["row", "reason", "why", "predicted miss"],
                      [(u["row"], u["reason"], u["detail"], u["predicted_miss_mm"]) for u in unsolved],
                      units=["", "", "", "mm"], note="not in --csv; the other targets' commands are")
    out.add_table("Joint corrections", ["joint", "largest |correction|", "unit"],
                  [(n, np.abs(dq[:, j]).max(), u) for j, (n, u) in enumerate(zip(robot.joint_names, units))])
    out.add_plots(lambda folder: [plot_compensation(before, after, Path(folder) / "compensation.png",
                                                    heldout_miss=heldout_miss)],
                  {"compensation.png": "Error at the targets before and after compensation"
                                       + ("; what compensation is expected to leave (the prediction's held-out "
                                          "miss at the measured targets) first, the model's own miss second"
                                          if heldout_miss is not None else
                                          "; after: the model's own miss (measure some targets for a realistic "
                                          "figure)")})
    if out.scene_wanted:
        from ..view.prediction_scenes import compensation_scene

        out.set_scene(*compensation_scene(robot, done, model, method=args.method, targets=args.targets,
                                          rows=lines[solved], measured=measured))
    header = _joint_columns(robot) + _joint_columns(robot, "d") + ["predicted_miss_mm", "target_row"]
    _write_csv(args, "compensated joint values", header,
                          np.hstack([q_comp * scale, dq, after[:, None] * 1e3, lines[solved][:, None]]))
    if unsolved:
        counts_by = {r: sum(u["reason"] == r for u in unsolved) for r in dict.fromkeys(u["reason"] for u in unsolved)}
        import sys

        from .staging import hold_message

        # a warning of a run that succeeds: shown once its files are written, not at all if they are not
        hold_message(sys.stderr, f"tcr-accuracy: warning: {len(unsolved)} of {len(q_all)} targets not solved (rows "
                     + ", ".join(str(u["row"]) for u in unsolved[:10]) + (" ..." if len(unsolved) > 10 else "")
                     + "; " + ", ".join(f"{r} {k}" for r, k in counts_by.items())
                     + "): listed in the JSON's 'unsolved' and the report, left out of --csv\n", "warning")
    lines = [_frame_line(model, args),
             (f"{q.shape[0]} of {len(q_all)} targets compensated in at most {iterations.max()} cycles; largest joint "
              f"correction {np.abs(dq).max():.4g} ({', '.join(sorted(set(units)))})"),
             f"predicted error at the targets before compensation: mean {before.mean() * 1e3:.4f} mm, "
             f"max {before.max() * 1e3:.4f} mm"]
    if heldout is not None:  # the realistic figure first: what compensation is expected to leave
        lines.append(nominal_line(heldout["nominal"], "measured targets"))
        lines.append(f"measured at the targets (held out): |measured - predicted error| mean {heldout['mean_mm']:.4f} mm, "
                     f"max {heldout['max_mm']:.4f} mm (about what compensation leaves)")
    lines.append(f"the model's own miss after compensation (its prediction, not a measurement): mean "
                 f"{after.mean() * 1e3:.2g} mm, max {after.max() * 1e3:.2g} mm")
    return out.finish(payload, lambda: _print(robot, args, q_train, *lines))
