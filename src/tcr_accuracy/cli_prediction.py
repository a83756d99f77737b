"""Commands ``predict`` and ``compensate``: the remaining error from measurements, and
joint commands that correct it (the second seed).

Input: measurement CSVs in the shared format (:mod:`tcr_accuracy.measurements`): joint
columns ``<joint>_deg|_rad|_mm|_m`` and, for training data, the measured TCP position
``x_mm, y_mm, z_mm`` (or ``_m``). The error is measured minus nominal TCP position, so
positions in a tracker frame other than the base frame make the frame offset part of
the predicted error. Output joint values are in degrees and millimetres.
"""

from __future__ import annotations

import argparse

from .cli import EXIT_OK, add_robot_arguments, emit_json

#: names of prediction.METHODS, repeated here so that --help does not import scikit-learn
#: (a test checks that the two lists agree)
METHODS = ("kriging", "kriging-pf", "gp", "idw-joint", "idw-cartesian", "mlp-cartesian", "calibration",
           "calibration+gp")

def add_parsers(sub) -> None:
    p = sub.add_parser(
        "predict", help="predict the TCP error at given joint values from measured poses",
        description="Fit an error predictor to measured poses (--train) and predict the TCP "
                    "position error (real minus nominal) at the joint values of --query.",
    )
    _common(p, METHODS)
    p.add_argument("--query", required=True, metavar="CSV", help="joint values to predict at (CSV)")
    p.add_argument("--out", metavar="CSV", help="write predictions: the query joints and ex_mm, ey_mm, ez_mm")
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
    c.add_argument("--out", metavar="CSV", help="write compensated joint values [deg, mm]")
    c.set_defaults(run=_run_compensate)


def _common(p: argparse.ArgumentParser, methods) -> None:
    add_robot_arguments(p)
    p.add_argument("--train", required=True, metavar="CSV", help="measured poses: joints and x/y/z (CSV)")
    p.add_argument("--method", default="gp", choices=methods,
                   help="predictor (default gp; kriging-pf is the seed's method)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the stochastic methods (default 0)")
    p.add_argument("--json", nargs="?", const="-", default=None, metavar="FILE",
                   help="write a JSON summary to FILE, or to stdout without FILE")


def read_joint_csv(path: str, robot, *, need_positions: bool):
    """Joint values (N, n) [SI] and measured positions (N, 3) [m] (None for a pose list),
    read and validated by :func:`tcr_accuracy.measurements.read_measurements`."""
    from .measurements import read_measurements

    mset = read_measurements(path, robot, require_position=need_positions)
    return mset.q, (mset.position if need_positions else None)


def _write_csv_atomically(path: str, header: list[str], rows) -> None:
    import io
    from pathlib import Path

    from .asbuilt import write_text_atomically

    buf = io.StringIO()
    buf.write(",".join(header) + "\n")
    for row in rows:
        buf.write(",".join(f"{v:.9g}" for v in row) + "\n")
    write_text_atomically(Path(path), buf.getvalue())


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


def _fit(args):
    import warnings

    import numpy as np
    from sklearn.exceptions import ConvergenceWarning

    from .kinematics import tcp_poses
    from .prediction import make_predictor
    from .robot import load_robot

    robot = load_robot(args.robot, args.tool)
    q, pos = read_joint_csv(args.train, robot, need_positions=True)
    _check_training(args.train, q, robot.n_joints)
    errors = pos - tcp_poses(robot, q).position
    estimator = make_predictor(args.method, robot, random_state=args.seed)
    with warnings.catch_warnings():
        # scikit-learn's optimisers warn at their iteration caps; the fit is still usable
        warnings.simplefilter("ignore", ConvergenceWarning)
        estimator.fit(q, errors)
    return robot, q, errors, estimator


def _run_predict(args) -> int:
    import numpy as np

    from .exceptions import AnalysisError

    robot, q_train, _, estimator = _fit(args)
    q, _ = read_joint_csv(args.query, robot, need_positions=False)
    units, scale = robot.display_units, robot.display_scale
    pred = np.asarray(estimator.predict(q)).reshape(-1, 3)
    if not np.all(np.isfinite(pred)):
        raise AnalysisError(f"method {args.method} predicted non-finite errors")
    norm = np.linalg.norm(pred, axis=1)
    if args.out:
        header = [f"{n}_{u}" for n, u in zip(robot.joint_names, units)] + ["ex_mm", "ey_mm", "ez_mm", "e_norm_mm"]
        _write_csv_atomically(args.out, header, np.hstack([q * scale, pred * 1e3, norm[:, None] * 1e3]))
    payload = {
        "robot": robot.name, "method": args.method, "n_train": int(q_train.shape[0]), "n_query": int(q.shape[0]),
        "predicted_error_mean_mm": float(norm.mean() * 1e3), "predicted_error_max_mm": float(norm.max() * 1e3),
        "predicted_errors_mm": (pred * 1e3).tolist(),
    }
    return _report(args, robot, q_train, payload,
                   f"predicted |error| at {q.shape[0]} query poses: mean {norm.mean() * 1e3:.4f} mm, "
                   f"max {norm.max() * 1e3:.4f} mm")


def _report(args, robot, q_train, payload: dict, line: str) -> int:
    """JSON to a file or stdout (then nothing else on stdout), and the human summary."""
    if args.json is not None:
        emit_json(payload, args.json)
        if args.json == "-":
            return EXIT_OK
    print(f"{robot.name}: {args.method} fitted to {q_train.shape[0]} measured poses ({args.train})")
    print(f"  {line}" + (f"; written to {args.out}" if args.out else ""))
    return EXIT_OK


def _run_compensate(args) -> int:
    import numpy as np

    from .compensation import compensate_joints
    from .exceptions import InputError

    if args.threshold_mm <= 0:
        raise InputError(f"--threshold-mm {args.threshold_mm}: must be > 0")
    if args.max_iter < 1:
        raise InputError(f"--max-iter {args.max_iter}: must be >= 1")
    robot, q_train, _, estimator = _fit(args)
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
    if args.out:
        header = ([f"{n}_{u}" for n, u in zip(robot.joint_names, units)]
                  + [f"d{n}_{u}" for n, u in zip(robot.joint_names, units)] + ["predicted_miss_mm"])
        _write_csv_atomically(args.out, header, np.hstack([result.q * scale, dq, result.predicted_miss[:, None] * 1e3]))
    payload = {
        "robot": robot.name, "method": args.method, "n_train": int(q_train.shape[0]), "n_targets": int(q.shape[0]),
        "threshold_mm": args.threshold_mm, "iterations_max": int(result.iterations.max()),
        "predicted_miss_max_mm": float(result.predicted_miss.max() * 1e3),
        "joint_units": units, "compensated_joints": (result.q * scale).tolist(),
    }
    return _report(args, robot, q_train, payload,
                   f"{q.shape[0]} targets compensated in at most {result.iterations.max()} cycles; largest joint "
                   f"correction {np.abs(dq).max():.4g} ({', '.join(sorted(set(units)))}); predicted miss below "
                   f"{result.predicted_miss.max() * 1e3:.2g} mm")
