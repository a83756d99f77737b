"""``tcr-accuracy iso9283 plan|evaluate``: the ISO 9283:1998 pose test, planned and evaluated.

``plan`` finds the test cube and writes the poses to run (the measurement CSV's joint
columns plus ``pose_id``, ``cycle`` and the commanded TCP ``target_x_mm`` ... in the base
frame); ``evaluate`` reads the measured test and prints AP, RP (and vAP, AD, RD where the
data allow), optionally also as predicted after compensation with a diagnosis' model.
"""

from __future__ import annotations

import argparse

from .common import (DEFAULT_MEMORY_GB, EXIT_OK, MAX_MM, Parser, add_quiet_argument, add_robot_arguments,
                     check_csv_memory, emit_json, integer, number, output_file, sample_bytes, seed_value, status)
from .output import add_output_arguments


def add_parsers(sub) -> None:
    p = sub.add_parser("iso9283", help="ISO 9283 pose accuracy and repeatability: plan the test, evaluate it",
                       description="ISO 9283:1998 pose accuracy (AP) and repeatability (RP) over the standard's "
                                   "test cube: 'plan' finds the cube and writes the poses to run, 'evaluate' "
                                   "computes the figures from the measured test.")
    steps = p.add_subparsers(dest="step", metavar="STEP", parser_class=Parser)
    steps.required = True
    plan = steps.add_parser(
        "plan", help="the largest ISO test cube, its five poses, joint solutions and cycle order, as a CSV",
        description="Find the largest cube (edges along the base axes) whose 8 corners and 5 ISO poses the robot "
                    "reaches at one TCP orientation, within its joint limits and free of self-collision (coal on "
                    "the URDF's collision geometry, where it has any), or take the cube given; P1 at its centre, "
                    "P2..P5 on the diagonal plane at 10 % of the diagonal from its corners. Writes the cycles "
                    "(P5, P4, P3, P2, P1 each) as a measurement CSV without positions: joint columns, pose_id, "
                    "cycle, target_x_mm, target_y_mm, target_z_mm (commanded TCP, base frame).")
    add_robot_arguments(plan)
    plan.add_argument("--cycles", type=integer(low=1, high=100_000), default=30,
                      help="cycles of the five poses (default 30, as the standard)")
    plan.add_argument("--cube-centre-mm", nargs=3, type=number(low=-MAX_MM, high=MAX_MM, unit="mm"), default=None,
                      metavar=("X", "Y", "Z"), help="plan this cube instead of searching (with --cube-size-mm)")
    plan.add_argument("--cube-size-mm", type=number(low=0, low_open=True, high=MAX_MM, unit="mm"), default=None,
                      metavar="S", help="edge of the given cube [mm]")
    plan.add_argument("--seed", type=seed_value, default=0, help="seed of the cube search (default 0)")
    plan.add_argument("--out", required=True, type=output_file, metavar="FILE.csv", help="the test to run")
    plan.add_argument("--json", nargs="?", const="-", default=None, type=output_file, metavar="FILE",
                      help="also write the plan as JSON (stdout without FILE)")
    add_quiet_argument(plan)
    plan.set_defaults(run=_run_plan)
    evaluate = steps.add_parser(
        "evaluate", help="AP, RP (vAP, AD, RD where the data allow) of a measured pose test",
        description="Per pose (pose_id column): AP_P and its components, RP_l, and with orientations (qw..qz) "
                    "AP_a/b/c and RP_a/b/c; vAP where an 'approach' column labels directions; AD and RD between "
                    "poses measured in the same cycles ('cycle' column). The measurement frame is fitted to the "
                    "poses' barycentres (Kabsch, TCP offset where identifiable) unless --frame base.")
    evaluate.add_argument("measurements", metavar="MEAS.csv", help="the measured pose test (see README)")
    add_robot_arguments(evaluate)
    evaluate.add_argument("--frame", choices=("fit", "base"), default="fit",
                          help="fit: register the instrument's frame to the poses (default); base: the readings "
                               "are already base-frame TCP positions")
    evaluate.add_argument("--frame-from", default=None, metavar="CAL.csv",
                          help="fit the instrument frame on these measurements instead (other poses measured in the "
                               "same instrument frame, e.g. a calibration set of the same session)")
    evaluate.add_argument("--model", default=None, metavar="DIAGNOSIS.json",
                          help="a 'diagnose --json' result: also the figures predicted after compensating with it")
    add_output_arguments(evaluate, plots=False)
    evaluate.set_defaults(run=_run_evaluate)
    for parser in (plan, evaluate):  # as main() adds them to every command, also after the step
        parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                            help="on an error, print the full Python traceback as well as the one-line message")
        parser.add_argument("--max-memory-gb", type=number(low=0, low_open=True, high=1e6, unit="GB"),
                            default=argparse.SUPPRESS, metavar="GB",  # keeps a value given before the step
                            help=f"refuse work estimated to need more memory than this (default "
                                 f"{DEFAULT_MEMORY_GB:g} GB)")


# ---------------------------------------------------------------------------------------
def _run_plan(args) -> int:
    import numpy as np

    from ..analysis.iso9283_plan import cycle_order, plan_iso_cube
    from .staging import write_text
    from ..exceptions import InputError
    from ..model.robot import load_robot

    if (args.cube_centre_mm is None) != (args.cube_size_mm is None):
        raise InputError("--cube-centre-mm and --cube-size-mm: give both, or neither to search the largest cube")
    robot = load_robot(args.robot, args.tool)
    centre = None if args.cube_centre_mm is None else np.asarray(args.cube_centre_mm) * 1e-3
    size = None if args.cube_size_mm is None else args.cube_size_mm * 1e-3
    plan = plan_iso_cube(robot, np.random.default_rng(args.seed), centre=centre, size=size)
    pose_id, cycle = cycle_order(args.cycles)
    from pathlib import Path

    write_text(Path(args.out), _plan_csv(robot, plan, pose_id, cycle))
    payload = {"robot": robot.name, "tool": robot.tool_frame, "cube_centre_mm": (plan.centre * 1e3).tolist(),
               "cube_size_mm": plan.size * 1e3, "searched": plan.searched, "candidate_centres": plan.n_centres,
               "orientation": plan.orientation, "collision": plan.collision, "cycles": args.cycles,
               "order": "P5, P4, P3, P2, P1 in every cycle",
               "poses": [{"pose_id": k + 1, "target_mm": (plan.positions[k] * 1e3).tolist(),
                          "q_display": (plan.q[k] * robot.display_scale).tolist()} for k in range(5)],
               "joint_units": robot.display_units, "out": str(args.out)}
    if args.json:
        emit_json(payload, args.json)
    if args.json != "-":
        print(_plan_text(robot, plan, args))
    status(args, f"plan written to {args.out}")
    return EXIT_OK


def _plan_csv(robot, plan, pose_id, cycle) -> str:
    import io

    joints = [f"{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]
    out = io.StringIO()
    out.write(f"# ISO 9283 pose test of {robot.name} (TCP {robot.tool_frame}), written by tcr-accuracy iso9283 plan\n")
    out.write(f"# cube centre {', '.join(f'{v * 1e3:.3f}' for v in plan.centre)} mm, edge {plan.size * 1e3:.3f} mm; "
              "run the rows in order, add the measured x_mm,y_mm,z_mm (and qw,qx,qy,qz) columns\n")
    out.write(",".join(joints + ["pose_id", "cycle", "target_x_mm", "target_y_mm", "target_z_mm"]) + "\n")
    for pid, c in zip(pose_id, cycle):
        row = [format(v, ".10g") for v in plan.q[pid - 1] * robot.display_scale]
        row += [str(pid), str(c)] + [format(v, ".10g") for v in plan.positions[pid - 1] * 1e3]
        out.write(",".join(row) + "\n")
    return out.getvalue()


def _plan_text(robot, plan, args) -> str:
    how = (f"the largest found over {plan.n_centres} candidate centres" if plan.searched else "as given")
    lines = [f"{robot.name}: ISO 9283 test cube ({how})",
             f"  centre [mm]      {', '.join(f'{v * 1e3:.1f}' for v in plan.centre)}",
             f"  edge             {plan.size * 1e3:.1f} mm",
             "  orientation      " + ("one TCP orientation at every pose" if plan.orientation == "exact" else
                                     "positions exact, orientation as close as the robot can (rank < 6)"),
             f"  self-collision   {plan.collision}",
             f"  {'pose':<5}" + "".join(f"{a + ' [mm]':>12}" for a in "xyz") + "  joints [" +
             ", ".join(robot.display_units) + "]"]
    for k in range(5):
        lines.append(f"  P{k + 1:<4}" + "".join(f"{v * 1e3:12.1f}" for v in plan.positions[k]) + "  " +
                     " ".join(f"{v:.2f}" for v in plan.q[k] * robot.display_scale))
    lines.append(f"  {args.cycles} cycles of P5, P4, P3, P2, P1 ({5 * args.cycles} rows) -> {args.out}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------
def _run_evaluate(args) -> int:
    import warnings

    from ..io.measurements import MeasurementWarning, read_measurements
    from ..model.robot import load_robot
    from ..prediction.iso9283_evaluation import compensated_readings, evaluate_measurements, register_from
    from .output import RunOutput

    robot = load_robot(args.robot, args.tool)
    check_csv_memory(args, args.measurements, "MEAS.csv", sample_bytes(robot))
    model = _read_model(robot, args.model) if args.model else None
    with warnings.catch_warnings():  # a pose test repeats its poses on purpose, labelled or not
        warnings.filterwarnings("ignore", message=".*repeated pose", category=MeasurementWarning)
        mset = read_measurements(args.measurements, robot)
    given = {}
    if args.frame_from:
        given = {"registration": register_from(robot, read_measurements(args.frame_from, robot, min_rows=3)),
                 "registration_source": args.frame_from}
    result = evaluate_measurements(robot, mset, frame=args.frame, **given)
    after = None
    if model is not None:
        after = evaluate_measurements(robot, compensated_readings(robot, mset, result.registration, *model),
                                      frame=args.frame, **given)
    from .diagnose import robot_source

    out = RunOutput(args, f"ISO 9283 pose test: {robot.name}")
    text = format_evaluation(robot, args, result, after)
    payload = {"measurements": str(args.measurements), "robot": robot.name, "robot_source": robot_source(args.robot),
               "tool_frame": robot.tool_frame, **evaluation_dict(result)}
    if after is not None:
        payload["compensated"] = {"model": str(args.model), "kind": "predicted: the model's displacement removed "
                                  "from each reading (first order, positions only)", **evaluation_dict(after)}
    if out.report is not None:
        _calibration_page(out.report, args, robot, payload)
    out.add_preformatted(text, "ISO 9283 figures")
    return out.finish(payload, lambda: print(text))


def _calibration_page(report, args, robot, payload: dict) -> None:
    """The report opens with the calibration report's first page (with the diagnosis of --model, if given),
    then the per-pose tables."""
    from ..view.calibration_report import Campaign, RobotFacts, add_iso_tables, kind_or_none as kind_or_none
    from .report import add_calibration_page
    from .result_files import PAGE_KEYS, read_result, validate_result

    documents = [(str(args.measurements), payload)]
    files = [("ISO 9283 JSON", args.json)] if args.json not in (None, "-") else []
    if args.model:  # read and checked already (_read_model); one of ours written before the report: shown
        model = read_result(args.model, "diagnosis")[1]
        if kind_or_none(model) == "diagnosis":  # on the page: with what the page reads
            documents.insert(0, (str(args.model), validate_result(model, "diagnosis", args.model, PAGE_KEYS)))
        files.append(("diagnosis JSON (--model)", args.model))
    add_calibration_page(report, args.out, Campaign(RobotFacts.of_robot(robot, payload["robot_source"]), documents),
                         files)
    add_iso_tables(report, str(args.measurements), payload)


def _read_model(robot, path: str):
    from ..prediction.iso9283_evaluation import diagnosis_model
    from .result_files import check_physics, read_result

    payload = read_result(path, "diagnosis", hint="give the JSON that 'diagnose --json FILE' wrote")[1]
    check_physics(payload, robot, path)
    return diagnosis_model(robot, payload, path)


def _pose_dict(f) -> dict:
    import numpy as np

    out = {"pose_id": f.pose_id, "n": f.n, "ap_mm": f.ap * 1e3,
           **{f"ap_{a}_mm": float(v * 1e3) for a, v in zip("xyz", f.ap_xyz)},
           "rp_mm": None if f.rp is None else f.rp * 1e3, "l_mean_mm": f.l_mean * 1e3,
           "s_l_mm": None if f.l_std is None else f.l_std * 1e3,
           "barycentre_mm": (f.barycentre * 1e3).tolist(), "commanded_mm": (f.commanded * 1e3).tolist()}
    if f.approach is not None:
        out["approach"] = f.approach
    if f.ap_abc is not None:
        out.update({f"ap_{a}_deg": float(np.degrees(v)) for a, v in zip("abc", f.ap_abc)})
        out.update({f"rp_{a}_deg": None if f.rp_abc is None else float(np.degrees(f.rp_abc[k]))
                    for k, a in enumerate("abc")})
    return out


def evaluation_dict(result) -> dict:
    """JSON-ready figures of an :class:`~tcr_accuracy.prediction.iso9283_evaluation.IsoEvaluation` (mm, deg)."""
    import numpy as np

    fig = result.figures
    rps = [f.rp for f in fig.poses if f.rp is not None]
    return {
        "n_readings": result.n_readings, "frame": result.frame, "frame_fit": result.how,
        "registration": None if result.registration is None else result.registration.to_dict(),
        "poses": [_pose_dict(f) for f in fig.poses],
        "summary": {"ap_max_mm": max(f.ap for f in fig.poses) * 1e3,
                    "rp_max_mm": max(rps) * 1e3 if rps else None},
        "directional": [{"pose_id": d.pose_id, "approaches": list(d.approaches), "vap_mm": d.vap * 1e3,
                         **({} if d.vap_abc is None else
                            {f"vap_{a}_deg": float(np.degrees(v)) for a, v in zip("abc", d.vap_abc)})}
                        for d in fig.directional],
        "distances": [{"pose_a": d.pose_a, "pose_b": d.pose_b, "n": d.n, "commanded_mm": d.commanded * 1e3,
                       "mean_mm": d.mean * 1e3, "ad_mm": d.ad * 1e3,
                       **{f"ad_{a}_mm": float(v * 1e3) for a, v in zip("xyz", d.ad_xyz)}, "rd_mm": d.rd * 1e3}
                      for d in fig.distances],
        "notes": list(fig.notes),
    }


def format_evaluation(robot, args, result, after=None) -> str:
    """The printed figures: the per-pose table, the summary, and what could not be computed."""
    lines = [f"{robot.name}: ISO 9283 pose test {args.measurements} ({result.n_readings} readings, "
             f"{len(result.pose_q)} poses)", f"  measurement frame {result.how}"]
    lines += _figures_lines(result)
    if after is not None:
        lines += [f"after compensation with {args.model} (predicted: the model's displacement removed from "
                  "each reading, first order, positions only):"] + _figures_lines(after, table_only=True)
    return "\n".join(lines)


def _figures_lines(result, table_only: bool = False) -> list:
    import numpy as np

    fig = result.figures
    angles = any(f.ap_abc is not None for f in fig.poses)
    labelled = any(f.approach is not None for f in fig.poses)
    head = f"  {'pose':<5}" + (f"{'appr':>5}" if labelled else "") + f"{'n':>4}" + \
        "".join(f"{h:>10}" for h in ("AP_P", "AP_x", "AP_y", "AP_z", "RP_l")) + "  [mm]"
    if angles:
        head += "".join(f"{h:>9}" for h in ("AP_a", "AP_b", "AP_c", "RP_a", "RP_b", "RP_c")) + "  [deg]"
    lines = [head]
    for f in fig.poses:
        row = f"  P{f.pose_id:<4}" + (f"{f.approach:>5}" if labelled else "") + f"{f.n:>4}" + \
            "".join(f"{v * 1e3:10.4f}" for v in (f.ap, *f.ap_xyz)) + \
            (f"{f.rp * 1e3:10.4f}" if f.rp is not None else f"{'-':>10}")
        if f.ap_abc is not None:
            row += "       " + "".join(f"{np.degrees(v):9.4f}" for v in f.ap_abc)
            row += "".join(f"{np.degrees(v):9.4f}" for v in f.rp_abc) if f.rp_abc is not None else f"{'-':>27}"
        lines.append(row)
    rps = [f.rp for f in fig.poses if f.rp is not None]
    lines.append(f"  largest AP_P {max(f.ap for f in fig.poses) * 1e3:.4f} mm, largest RP_l "
                 + (f"{max(rps) * 1e3:.4f} mm" if rps else "- (no pose with 3 readings)"))
    for d in fig.directional:
        lines.append(f"  vAP P{d.pose_id} over approaches {', '.join(map(str, d.approaches))}: {d.vap * 1e3:.4f} mm")
    if fig.distances and not table_only:
        lines.append(f"  distance {'poses':<8}{'n':>4}{'D_c':>11}{'AD_P':>10}{'RD':>10}  [mm]")
        for d in fig.distances:
            lines.append(f"           P{d.pose_a}-P{d.pose_b}   {d.n:>4}{d.commanded * 1e3:11.3f}{d.ad * 1e3:10.4f}"
                         f"{d.rd * 1e3:10.4f}")
    lines += [f"  note: {n}" for n in fig.notes]
    return lines
