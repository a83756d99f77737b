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
from .iso9283_inputs import condition, plan_inputs, read_model, tool_rotation
from .output import add_output_arguments
from .report import add_campaign_arguments, read_campaign_arguments


def add_parsers(sub) -> None:
    p = sub.add_parser("iso9283", help="ISO 9283 pose and path tests: plan the test, evaluate it",
                       description="ISO 9283:1998 pose accuracy (AP) and repeatability (RP) over the standard's "
                                   "test cube, and the path tests (AT, RT, corner deviations, path velocity) in its "
                                   "plane: 'plan' finds the cube and writes the poses (--path: the paths) to run, "
                                   "'evaluate' computes the figures from the measured test.")
    steps = p.add_subparsers(dest="step", metavar="STEP", parser_class=Parser)
    steps.required = True
    plan = steps.add_parser(
        "plan", help="the largest ISO test cube, its five poses, joint solutions, cycle order and test conditions, "
                     "as a CSV (--path: the test paths)",
        description="Find the largest cube (edges along the base axes) whose 8 corners and 5 ISO poses the robot "
                    "reaches at one TCP orientation, within its joint limits, every revolute joint within half a "
                    "turn of --home (of the equivalent joint values the nearest), above the mounting plane (or "
                    "--floor-mm) and inside --box, no body below that floor and free of self-collision (coal on "
                    "the URDF's collision geometry, where it has any), or take the cube given; P1 at its centre, "
                    "P2..P5 on the diagonal plane at 10 % of the diagonal from its corners. Writes, for each test "
                    "condition (% of the rated load and speed), the cycles (start at P1, then P5, P4, P3, P2, P1 "
                    "each) as a measurement CSV without positions: joint columns, payload_kg (when the rated load "
                    "is known), pose_id, cycle, load_pct, speed_pct, target_x_mm, target_y_mm, target_z_mm "
                    "(commanded TCP, base frame). With --path: the standard's test paths in the cube's plane "
                    "instead (see docs/iso9283.md).")
    add_robot_arguments(plan)
    plan.add_argument("--cycles", type=integer(low=1, high=100_000), default=None,
                      help="cycles (default 30 for the pose test, 10 for --path, as the standard)")
    plan.add_argument("--cube-centre-mm", nargs=3, type=number(low=-MAX_MM, high=MAX_MM, unit="mm"), default=None,
                      metavar=("X", "Y", "Z"), help="plan this cube instead of searching (with --cube-size-mm)")
    plan.add_argument("--cube-size-mm", type=number(low=10, high=MAX_MM, unit="mm"), default=None,
                      metavar="S", help="edge of the given cube [mm], at least 10")
    plan.add_argument("--home", nargs="+", type=number(low=-MAX_MM, high=MAX_MM), default=None, metavar="Q",
                      help="the home configuration, one value per joint [deg, mm for prismatic joints]; default the "
                           "robot's usual ready pose (the UR's upright pose, 0 -90 0 -90 0 0; else its reference "
                           "pose)")
    plan.add_argument("--tool-rpy", nargs=3, type=number(low=-360, high=360, unit="deg"), default=None,
                      metavar=("ROLL", "PITCH", "YAW"),
                      help="the TCP orientation every pose holds, roll-pitch-yaw of the TCP frame in the base frame "
                           "[deg] (URDF convention: R = Rz(yaw) Ry(pitch) Rx(roll)); default the one found at the "
                           "cube's centre")
    plan.add_argument("--tracker-mm", nargs=3, type=number(low=-MAX_MM, high=MAX_MM, unit="mm"), default=None,
                      metavar=("X", "Y", "Z"),
                      help="the instrument's position [mm] in the base frame: the poses must be in its line of sight "
                           "(no collision body on the beam; needs the URDF's collision geometry), their distances "
                           "from it written")
    plan.add_argument("--floor-mm", type=number(low=-MAX_MM, high=MAX_MM, unit="mm"), default=0.0, metavar="Z",
                      help="keep the test and the robot's bodies above z = Z of the base frame (default 0, the "
                           "mounting plane)")
    plan.add_argument("--box", nargs=6, type=number(low=-MAX_MM, high=MAX_MM, unit="mm"), default=None,
                      metavar=("XMIN", "XMAX", "YMIN", "YMAX", "ZMIN", "ZMAX"),
                      help="a cell box [mm], base frame: keep the test's points inside")
    plan.add_argument("--rated-load-kg", type=number(low=0, low_open=True, high=1e6, unit="kg"), default=None,
                      metavar="M", help="the rated load (default: the maker's for ur3, ur5, ur10, panda; the disc "
                                        "cutter for the tool-changer)")
    plan.add_argument("--conditions", nargs="+", type=condition, default=None, metavar="LOAD/SPEED",
                      help="test conditions as %% of the rated load / %% of the rated speed (default the "
                           "standard's: 100/100 100/50 100/10 10/100)")
    plan.add_argument("--path", action="store_true",
                      help="write the path tests instead: a straight line, two circles and a rectangle in the "
                           "cube's plane, at 100, 50 and 10 %% of the rated path speed")
    plan.add_argument("--path-speed-mm-s", type=number(low=0, low_open=True, high=MAX_MM, unit="mm/s"), default=None,
                      metavar="V", help="the rated path speed [mm/s] (default: the largest every joint's velocity "
                                        "limit allows on every path)")
    plan.add_argument("--seed", type=seed_value, default=0, help="seed of the cube search (default 0)")
    plan.add_argument("--out", required=True, type=output_file, metavar="FILE.csv", help="the test to run")
    plan.add_argument("--json", nargs="?", const="-", default=None, type=output_file, metavar="FILE",
                      help="also write the plan as JSON (stdout without FILE)")
    add_quiet_argument(plan)
    plan.set_defaults(run=_run_plan)
    evaluate = steps.add_parser(
        "evaluate", help="AP, RP (vAP, AD, RD, stabilisation where the data allow) of a measured pose test; "
                         "--path: AT, RT, corners, path velocity of a measured path",
        description="Per pose (pose_id column, labels such as P1 or S01.P1): AP_P and its components, RP_l, and "
                    "with orientations (qw..qz) AP_a/b/c and RP_a/b/c; vAP where an 'approach' column labels "
                    "directions; AD and RD between poses measured in the same cycles ('cycle' column); pose "
                    "stabilisation time and overshoot where a visit is a time-stamped stream; per test condition "
                    "(load_pct, speed_pct columns). AP needs the robot's base frame: from --frame-from (other poses "
                    "of the session), --frame base, or found (readings within 5 mm of it); else the frame is "
                    "fitted to the poses' barycentres (Kabsch, TCP offset where identifiable) and AP is relative "
                    "to it, said on every line. With --path "
                    "COMMANDED.csv, MEAS.csv is the tracker's stream of a path test (see docs/iso9283.md).")
    evaluate.add_argument("measurements", metavar="MEAS.csv",
                          help="the measured pose test, or with --path the tracker's stream (see docs/iso9283.md)")
    add_robot_arguments(evaluate)
    evaluate.add_argument("--frame", choices=("fit", "base"), default=None,
                          help="fit: register the instrument's frame to the test's poses (AP then relative to it, "
                               "said on every line); base: the readings are already base-frame TCP positions "
                               "(AP absolute). Default: --frame-from when given, else base when the readings lie "
                               "in the robot's base frame (a frame fitted on the poses moves none by more than "
                               "5 mm), else fit")
    evaluate.add_argument("--frame-from", default=None, metavar="CAL.csv",
                          help="fit the instrument frame on these measurements instead (other poses measured in the "
                               "same instrument frame, e.g. a calibration set of the same session); not with --frame")
    evaluate.add_argument("--band-mm", type=number(low=1e-6, high=MAX_MM, unit="mm"), default=None,
                          metavar="R", help="limit band radius for the pose stabilisation time and overshoot of "
                                            "time-stamped visits (default: each pose's RP)")
    evaluate.add_argument("--model", default=None, metavar="DIAGNOSIS.json",
                          help="a 'diagnose --json' result: also the figures predicted after compensating with it")
    evaluate.add_argument("--path", default=None, metavar="COMMANDED.csv",
                          help="evaluate a path test: MEAS.csv is the tracker's stream (time_s, x_mm, y_mm, z_mm; "
                               "path, speed_pct and cycle labels), COMMANDED.csv the commanded path ('iso9283 plan "
                               "--path' writes it; or the joints of its points): AT, RT, corner deviations CR, CO "
                               "and the path velocity figures AV, RV, FV")
    evaluate.add_argument("--planes", type=integer(low=3, high=100_000), default=None, metavar="M",
                          help="--path: normal planes along each path (default 100)")
    add_output_arguments(evaluate, plots=False)
    add_campaign_arguments(evaluate)
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

    from ..iso9283.plan import DEFAULT_CYCLES, plan_iso_cube
    from .staging import write_text

    if args.path:
        from .iso9283_path import run_path_plan

        return run_path_plan(args)
    _pose_test_only(args)
    robot, home, workspace, conditions, rated = plan_inputs(args)
    centre = None if args.cube_centre_mm is None else np.asarray(args.cube_centre_mm) * 1e-3
    size = None if args.cube_size_mm is None else args.cube_size_mm * 1e-3
    plan = plan_iso_cube(robot, args.seed, centre=centre, size=size, home=home, workspace=workspace,
                         tool_rotation=tool_rotation(args), tracker=_tracker(args))
    cycles = args.cycles or DEFAULT_CYCLES
    series = plan.series(cycles, [(c.load_pct, c.speed_pct) for c in conditions], rated_load_kg=args.rated_load_kg)
    from pathlib import Path

    write_text(Path(args.out), _plan_csv(robot, plan, series, conditions, rated))
    payload = {"robot": robot.name, "tool": robot.tool_frame, "cube_centre_mm": (plan.centre * 1e3).tolist(),
               "cube_size_mm": plan.size * 1e3, "searched": plan.searched, "candidate_centres": plan.n_centres,
               "orientation": plan.orientation, "tool_rpy_deg": np.degrees(pin_rpy(plan.rotation[0])).tolist(),
               "collision": plan.collision, "workspace": plan.workspace, "sight": plan.sight,
               "tracker_mm": None if plan.tracker is None else (plan.tracker * 1e3).tolist(),
               "home_display": (plan.home * robot.display_scale).tolist(),
               "max_swing_deg": float(np.degrees(plan.max_swing)), "cycles": cycles,
               "order": "start at P1, then P5, P4, P3, P2, P1 in every cycle",
               "conditions": [{"load_pct": c.load_pct, "speed_pct": c.speed_pct, "payload_kg": c.payload_kg}
                              for c in conditions], "rated_load": rated,
               "poses": [{"pose_id": name, "target_mm": (plan.positions[k] * 1e3).tolist(),
                          "q_display": (plan.q[k] * robot.display_scale).tolist(),
                          **({} if plan.tracker_distance is None else
                             {"tracker_distance_mm": float(plan.tracker_distance[k] * 1e3)})}
                         for k, name in enumerate(plan.pose_ids)],
               "joint_units": robot.display_units, "rows": len(series), "out": str(args.out)}
    if args.json:
        emit_json(payload, args.json)
    if args.json != "-":
        print(_plan_text(robot, plan, args, cycles, conditions, rated))
    status(args, f"plan written to {args.out}")
    return EXIT_OK


def _pose_test_only(args) -> None:
    """InputError for the path test's options given to the pose test's plan."""
    from ..exceptions import InputError

    if args.path_speed_mm_s is not None:
        raise InputError("--path-speed-mm-s is the rated path speed of the path tests: give it with --path")


def pin_rpy(rotation):
    """(3,) roll, pitch, yaw [rad] of a rotation (Pinocchio's, the inverse of ``rpyToMatrix``)."""
    import pinocchio as pin

    return pin.rpy.matrixToRpy(rotation)


def _tracker(args):
    import numpy as np

    return None if args.tracker_mm is None else np.asarray(args.tracker_mm, dtype=float) * 1e-3


def _plan_csv(robot, plan, series, conditions, rated) -> str:
    import io

    joints = [f"{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]
    labels = series.annotations
    payload = series.payload_kg is not None
    out = io.StringIO()
    out.write(f"# ISO 9283 pose test of {robot.name} (TCP {robot.tool_frame}), written by tcr-accuracy iso9283 plan\n")
    out.write(f"# cube centre {', '.join(f'{v * 1e3:.3f}' for v in plan.centre)} mm, edge {plan.size * 1e3:.3f} mm; "
              "run the rows in order, add the measured x_mm,y_mm,z_mm (and qw,qx,qy,qz) columns\n")
    if plan.tracker is not None:
        out.write(f"# tracker at {', '.join(f'{v * 1e3:.1f}' for v in plan.tracker)} mm (base frame): P1..P5 at "
                  + ", ".join(f"{d * 1e3:.0f}" for d in plan.tracker_distance) + " mm from it\n")
    out.write(f"# {len(conditions)} test condition(s), {rated}; before each block, set the load and speed and "
              "move to P1\n")
    out.write(",".join(joints + (["payload_kg"] if payload else []) + ["pose_id", "cycle", "load_pct", "speed_pct",
                                                                       "target_x_mm", "target_y_mm", "target_z_mm"])
              + "\n")
    per_block = len(series) // len(conditions)
    for i in range(len(series)):
        if i % per_block == 0:
            cond = conditions[i // per_block]
            out.write(f"# condition {i // per_block + 1}: {cond.words()}; start at P1\n")
        row = [format(v, ".10g") for v in series.q[i] * robot.display_scale]
        row += [format(series.payload_kg[i], ".10g")] if payload else []
        row += [labels["pose_id"][i], labels["cycle"][i], format(labels["load_pct"][i], "g"),
                format(labels["speed_pct"][i], "g")]
        row += [format(labels[f"target_{a}_mm"][i], ".10g") for a in "xyz"]
        out.write(",".join(row) + "\n")
    return out.getvalue()


def _plan_text(robot, plan, args, cycles, conditions, rated) -> str:
    import numpy as np

    how = (f"the largest found over {plan.n_centres} candidate centres" if plan.searched else "as given")
    lines = [f"{robot.name}: ISO 9283 test cube ({how})",
             f"  centre [mm]      {', '.join(f'{v * 1e3:.1f}' for v in plan.centre)}",
             f"  edge             {plan.size * 1e3:.1f} mm",
             "  orientation      " + ("one TCP orientation at every pose" if plan.orientation == "exact" else
                                     "positions exact, orientation as close as the robot can (rank < 6)")
             + " (roll, pitch, yaw " + ", ".join(f"{v + 0.0:.1f}" for v in np.degrees(pin_rpy(plan.rotation[0])))
             + " deg" + (", as given)" if args.tool_rpy is not None else ")"),
             f"  self-collision   {plan.collision}",
             f"  workspace        {plan.workspace}",
             f"  line of sight    {plan.sight}",
             f"  home [{', '.join(robot.display_units)}]  " + " ".join(f"{v:.2f}" for v in plan.home * robot.display_scale)
             + f"; no joint turns more than {np.degrees(plan.max_swing):.1f} deg from it",
             f"  {'pose':<5}" + "".join(f"{a + ' [mm]':>12}" for a in "xyz") + "  joints [" +
             ", ".join(robot.display_units) + "]"]
    for k in range(5):
        lines.append(f"  P{k + 1:<4}" + "".join(f"{v * 1e3:12.1f}" for v in plan.positions[k]) + "  " +
                     " ".join(f"{v:.2f}" for v in plan.q[k] * robot.display_scale)
                     + ("" if plan.tracker_distance is None else
                        f"  ({plan.tracker_distance[k] * 1e3:.0f} mm from the tracker)"))
    lines.append(f"  conditions       {rated}:")
    lines += [f"    {k + 1}. {c.words()}" for k, c in enumerate(conditions)]
    lines.append(f"  each: start at P1, {cycles} cycles of P5, P4, P3, P2, P1 ({5 * cycles * len(conditions)} rows) "
                 f"-> {args.out}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------
def _run_evaluate(args) -> int:
    import warnings

    from ..exceptions import InputError
    from ..io.campaign import CampaignFacts
    from ..io.measurements import MeasurementWarning, read_measurements
    from ..iso9283.evaluate import compensated_readings, evaluate_conditions, register_from
    from .common import robot_from_args
    from .output import RunOutput

    if args.frame_from and args.frame is not None:
        raise InputError(f"--frame {args.frame} and --frame-from {args.frame_from}: give one (--frame-from fits "
                         "the instrument frame on other poses; --frame base takes the readings as base-frame "
                         "positions)")
    if args.planes is not None and not args.path:
        raise InputError(f"--planes {args.planes}: the normal planes of a path test; give it with --path "
                         "COMMANDED.csv")
    if args.path:
        from .iso9283_path import run_path_evaluate

        if read_campaign_arguments(args) != CampaignFacts():
            raise InputError("--campaign and its flags fill the pose test's calibration report; a path test's "
                             "report (--path) has no such page")
        return run_path_evaluate(args)
    read_campaign_arguments(args)
    robot = robot_from_args(args)
    check_csv_memory(args, args.measurements, "MEAS.csv", sample_bytes(robot))
    model = read_model(robot, args.model) if args.model else None
    with warnings.catch_warnings():  # a pose test repeats its poses on purpose, labelled or not
        warnings.filterwarnings("ignore", message=".*repeated pose", category=MeasurementWarning)
        mset = read_measurements(args.measurements, robot)
    given, given_after = {}, {}
    if args.frame_from:
        calibration = read_measurements(args.frame_from, robot, min_rows=3)
        given = {"registration": register_from(robot, calibration), "registration_source": args.frame_from}
        if model is not None:  # the compensated robot seen from the same poses, compensated alike
            given_after = {**given, "registration": register_from(robot, compensated_readings(
                robot, calibration, given["registration"], *model))}
    band = None if args.band_mm is None else args.band_mm * 1e-3
    blocks = evaluate_conditions(robot, mset, frame=args.frame or "auto", band=band, **given)
    afters = [None] * len(blocks)
    if model is not None:
        compensated = compensated_readings(robot, mset, blocks[0][1].registration, *model)
        # the frame the measured figures were found in (base, or fitted on the test), not found again
        frame = args.frame or (blocks[0][1].frame if blocks[0][1].frame in ("base", "fit") else "auto")
        afters = [r for _, r in evaluate_conditions(robot, compensated, frame=frame, band=band, **given_after)]
    from ..iso9283.result_file import IsoCondition, IsoTestResult

    out = RunOutput(args, f"ISO 9283 pose test: {robot.name}")
    text = "\n".join(format_evaluation(robot, args, result, after, block if len(blocks) > 1 else None)
                     for (block, result), after in zip(blocks, afters))
    result = IsoTestResult(robot.name, robot.robot_source, robot.tool_frame, str(args.measurements), tuple(
        IsoCondition(block.load_pct, block.speed_pct, evaluated, after, "" if after is None else str(args.model))
        for (block, evaluated), after in zip(blocks, afters)))
    payload = result.to_dict()
    if out.report is not None:
        _calibration_page(out.report, args, robot, payload)
    out.add_preformatted(text, "ISO 9283 figures")
    if out.report is not None:
        from ..view.plots_results import plot_iso_poses

        out.add_plots(lambda folder: [plot_iso_poses(payload, folder / "iso_poses.png", args.campaign_facts.limits_mm)],
                      {"iso_poses.png": "ISO 9283 pose accuracy AP_P and repeatability RP_l per pose and test "
                                        "condition" + (", as measured and predicted after compensation"
                                                       if model is not None else "")})
    return out.finish(payload, lambda: print(text))


def _calibration_page(report, args, robot, payload: dict) -> None:
    """The report opens with the calibration report's first page (with the diagnosis of --model, if given),
    then the per-pose tables."""
    from ..results.kinds import kind_or_none
    from ..view.calibration_report import Campaign, RobotFacts
    from ..view.result_tables import add_iso_tables
    from .report import add_calibration_page
    from ..results.files import PAGE_KEYS, read_result_document, validate_result

    documents = [(str(args.measurements), payload)]
    files = [("ISO 9283 JSON", args.json)] if args.json not in (None, "-") else []
    if args.model:  # read and checked already (read_model); one of ours written before the report: shown
        model = read_result_document(args.model, "diagnosis")[1]
        if kind_or_none(model) == "diagnosis":  # on the page: with what the page reads
            documents.insert(0, (str(args.model), validate_result(model, "diagnosis", args.model, PAGE_KEYS)))
        files.append(("diagnosis JSON (--model)", args.model))
    add_calibration_page(report, args, Campaign(RobotFacts.of_robot(robot, payload.get("robot_source", "")), documents),
                         files)
    add_iso_tables(report, str(args.measurements), payload)


def _mm(value):
    return None if value is None else value * 1e3


def format_evaluation(robot, args, result, after=None, block=None) -> str:
    """The printed figures: the per-pose table, the summary, and what could not be computed (of one
    test condition when ``block`` is given); every AP figure relative to a frame fitted on the test's
    poses says so on its line."""
    from ..iso9283.evaluate import RELATIVE_WORDS
    visits = "" if result.n_visits == result.n_readings else f" in {result.n_visits} visits"
    condition = "" if block is None else f", {block.words()}"
    lines = [f"{robot.name}: ISO 9283 pose test {args.measurements}{condition} ({result.n_readings} "
             f"readings{visits}, {len(result.pose_q)} poses)", f"  measurement frame {result.how}"]
    if not result.absolute:
        lines.append(f"  {RELATIVE_WORDS.upper()}: not the standard's absolute AP, which needs the robot's base "
                     "frame (--frame-from CAL.csv: other poses of the session; --frame base: readings in it)")
    lines += _figures_lines(result)
    if after is not None:
        lines += [f"after compensation with {args.model} (predicted: the model's displacement removed from "
                  "each reading, first order, positions only):"] + _figures_lines(after, table_only=True)
    return "\n".join(lines)


#: Distance pairs printed at most (all are in --json); the standard's P2-P4 pairs first.
PRINTED_DISTANCES = 10


def _figures_lines(result, table_only: bool = False) -> list:
    import numpy as np

    from ..iso9283.evaluate import RELATIVE_WORDS
    from ..iso9283.formulas import MIN_REPEATS, STANDARD_CYCLES, pose_name

    fig = result.figures
    angles = any(f.ap_abc is not None for f in fig.poses)
    labelled = any(f.approach is not None for f in fig.poses)
    width = max([5] + [len(pose_name(f.pose_id)) + 1 for f in fig.poses])
    appr = max([5] + [len(str(f.approach)) + 1 for f in fig.poses if f.approach is not None])
    head = f"  {'pose':<{width}}" + (f"{'appr':>{appr}}" if labelled else "") + f"{'n':>4}" + \
        "".join(f"{h:>10}" for h in ("AP_P", "AP_x", "AP_y", "AP_z", "RP_l")) + "  [mm]"
    if angles:
        head += "".join(f"{h:>9}" for h in ("AP_a", "AP_b", "AP_c", "RP_a", "RP_b", "RP_c")) + "  [deg]"
    lines = [head + ("" if result.absolute else f"  ({RELATIVE_WORDS})")]
    relative = "" if result.absolute else "relative"
    for f in fig.poses:
        row = f"  {pose_name(f.pose_id):<{width}}" + (f"{f.approach:>{appr}}" if labelled else "") + f"{f.n:>4}" + \
            "".join(f"{v * 1e3:10.4f}" for v in (f.ap, *f.ap_xyz)) + \
            (f"{f.rp * 1e3:10.4f}" if f.rp is not None else f"{'-':>10}")
        if f.ap_abc is not None:
            row += "       " + "".join(f"{np.degrees(v):9.4f}" for v in f.ap_abc)
            row += "".join(f"{np.degrees(v):9.4f}" for v in f.rp_abc) if f.rp_abc is not None else f"{'-':>27}"
        remarks = [relative] + ([] if f.n >= STANDARD_CYCLES else
                                [f"{f.n} of the standard's {STANDARD_CYCLES} cycles" +
                                 ("" if f.n >= MIN_REPEATS else ": AP only" if f.n == 1 else ": no RP")])
        lines.append(row + "".join(f"  {r}" for r in remarks if r))
    rps = [f.rp for f in fig.poses if f.rp is not None]
    lines.append(f"  largest AP_P {max(f.ap for f in fig.poses) * 1e3:.4f} mm"
                 + ("" if result.absolute else f" ({RELATIVE_WORDS})") + ", largest RP_l "
                 + (f"{max(rps) * 1e3:.4f} mm" if rps else f"- (no pose with {MIN_REPEATS} readings)")
                 + (f" (of {len(rps)} poses read {MIN_REPEATS} times or more)" if rps and len(rps) < len(fig.poses)
                    else ""))
    for d in fig.directional:
        lines.append(f"  vAP {pose_name(d.pose_id)} over approaches {', '.join(map(str, d.approaches))}: "
                     f"{d.vap * 1e3:.4f} mm")
    if fig.distances and not table_only:
        lines += _distance_lines(fig.distances)
    if fig.stabilisation and not table_only:
        lines.append(f"  stabilisation {'pose':<{width}}{'visits':>7}{'band':>9}{'t_mean':>9}{'t_max':>9}"
                     f"{'OV_mean':>9}{'OV_max':>9}  [mm, s]")
        for s in fig.stabilisation:
            cells = [s.band * 1e3, s.time_mean, s.time_max, _mm(s.overshoot_mean), _mm(s.overshoot_max)]
            lines.append(f"                {pose_name(s.pose_id):<{width}}{s.n:>7}" +
                         "".join(f"{'-':>9}" if v is None else f"{v:9.4f}" for v in cells) +
                         (f"  ({s.never_entered} never within the band)" if s.never_entered else ""))
    lines += [f"  note: {n}" for n in fig.notes]
    return lines


def _distance_lines(distances) -> list:
    """The AD/RD table: the standard's pairs (P2-P4 of a cube) first, at most PRINTED_DISTANCES rows."""
    from ..iso9283.formulas import pose_name

    def standard(d):
        a, b = pose_name(d.pose_a), pose_name(d.pose_b)
        return a.endswith("P2") and b.endswith("P4") and a[:-2] == b[:-2]

    shown = sorted(distances, key=lambda d: not standard(d))[:PRINTED_DISTANCES]
    width = max(len(f"{pose_name(d.pose_a)}-{pose_name(d.pose_b)}") for d in shown) + 2
    lines = [f"  distance {'poses':<{width}}{'n':>4}{'D_c':>11}{'AD_P':>10}{'RD':>10}  [mm]"]
    for d in shown:
        pair = f"{pose_name(d.pose_a)}-{pose_name(d.pose_b)}"
        lines.append(f"           {pair:<{width}}{d.n:>4}{d.commanded * 1e3:11.3f}{d.ad * 1e3:10.4f}"
                     f"{d.rd * 1e3:10.4f}")
    if len(distances) > len(shown):
        lines.append(f"           ... {len(distances) - len(shown)} more pairs in --json")
    return lines
