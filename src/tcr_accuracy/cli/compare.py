"""``tcr-accuracy compare``: what changed between two calibration campaigns of one robot.

Edge layer: reads two ``diagnose --json`` results (or diagnoses two measurement CSVs with
the same options), runs :func:`tcr_accuracy.diagnosis.compare.compare_models`, prints the
changes in mm and deg, and writes JSON and the HTML report.
"""

from __future__ import annotations

from .common import (MAX_COUNT, MAX_MM, add_robot_arguments, check_csv_memory, check_memory, effect_names, integer,
                     number, sample_bytes, seed_value, status)
from .output import RunOutput, add_output_arguments
from .report import add_campaign_arguments, read_campaign_arguments


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "compare", help="what changed between two campaigns of one robot, beyond both fits' uncertainty",
        description="Compare two diagnoses of the same robot (diagnose --json results, or the two measurement "
                    "CSVs, then diagnosed first with the same options): per parameter of the robot the change "
                    "and its standard error sqrt(std_old^2 + std_new^2), flagged beyond --z of it; the effects "
                    "that appeared or vanished; what the changes do to the TCP over the workspace (both fitted "
                    "robots on the same poses, a rigid frame change removed). The tracker frame is each "
                    "campaign's setup and is not compared; the TCP offset is listed apart.",
    )
    p.add_argument("old", metavar="OLD", help="the earlier campaign: diagnose --json result, or measurement CSV")
    p.add_argument("new", metavar="NEW", help="the later campaign: diagnose --json result, or measurement CSV")
    add_robot_arguments(p)
    p.add_argument("--z", type=number(low=0, low_open=True, high=1e3), default=3.0,
                   help="a change is significant beyond z standard errors of it (default 3)")
    p.add_argument("--poses", metavar="CSV", default=None,
                   help="joint values to evaluate the TCP effect on (joint columns as in a measurement CSV); "
                        "default --n-poses random poses within the joint limits")
    p.add_argument("--n-poses", type=integer(low=3, high=MAX_COUNT), default=1000,
                   help="number of random poses for the TCP effect (default 1000)")
    p.add_argument("--seed", type=seed_value, default=0,
                   help="seed of the random poses (and of the diagnoses of CSV input) (default 0)")
    csv = p.add_argument_group("with measurement CSVs: the options of diagnose, the same for both")
    csv.add_argument("--effects", default=None, metavar="LIST", help="comma-separated effects to consider")
    csv.add_argument("--folds", type=integer(low=2, high=1000), default=5, help="k-fold (default 5)")
    csv.add_argument("--noise-mm", type=number(low=0, low_open=True, high=MAX_MM, unit="mm"), default=None,
                     help="the instrument's noise, std per axis [mm] (default: estimated)")
    add_output_arguments(p, plots=False)
    add_campaign_arguments(p)
    p.set_defaults(run=_run_compare)


def _run_compare(args) -> int:
    import numpy as np

    from ..analysis.simulate import sample_poses
    from ..diagnosis.compare import FittedModel, compare_models
    from ..exceptions import InputError
    from ..model.robot import load_robot

    read_campaign_arguments(args)
    docs = [_read_json(path) for path in (args.old, args.new)]  # each validated (results.files)
    given = [d for d in docs if d is not None]
    tool = args.tool
    if args.robot is None:  # a diagnosis names its robot (and where it was loaded from); a CSV's is the default one
        sources = {d.get("robot_source", d["robot"]) for d in given}
        source = sources.pop() if len(sources) == 1 and len(given) == 2 else None
        source = None if source == "tool_changer" else source
    else:
        source = args.robot
    frames = {d["tool_frame"] for d in given if "tool_frame" in d}
    if len(frames) > 1:
        raise InputError(f"{args.old} is a diagnosis of the TCP frame {docs[0]['tool_frame']}, {args.new} of "
                         f"{docs[1]['tool_frame']}: compare two diagnoses of one TCP frame")
    if len(given) == 2 and len(frames) == 1 and not all("tool_frame" in d for d in given):
        raise InputError(f"{args.old if 'tool_frame' not in docs[0] else args.new}: does not say its TCP frame "
                         f"(the other is of {next(iter(frames))}): compare two diagnoses of one TCP frame, "
                         "written by tcr-accuracy diagnose --json")
    if tool is None and frames:
        tool = frames.pop()  # the frame the diagnoses are of
    robot = _load_named(load_robot, source, tool)
    if args.kinematics is not None:
        from ..asbuilt.factory_kinematics import with_factory_kinematics

        robot = with_factory_kinematics(robot, args.kinematics)
    elif given and isinstance(given[0].get("kinematics"), dict):  # the start the diagnoses recorded
        from ..asbuilt.factory_kinematics import robot_with_start

        robot = robot_with_start(robot, given[0]["kinematics"], args.old if docs[0] is not None else args.new)
    _check_comparable(docs, (args.old, args.new), robot)
    docs = [doc if doc is not None else _diagnose_csv(args, path, robot)
            for doc, path in zip(docs, (args.old, args.new))]
    old, new = (FittedModel.from_dict(d, path) for d, path in zip(docs, (args.old, args.new)))
    # the TCP effect: both fitted robots and the significant changes alone at every pose (about 1.6 kB a pose
    # measured for 6 joints; sample_bytes is a generous 6 kB)
    if args.poses is not None:
        check_csv_memory(args, args.poses, "--poses", sample_bytes(robot))
    else:
        check_memory(args, f"--n-poses {args.n_poses}", args.n_poses * sample_bytes(robot), "use fewer poses")
    if args.poses is not None:
        from .prediction import read_joint_csv

        q, _, context = read_joint_csv(args.poses, robot, need_positions=False)
        poses = f"the {q.shape[0]} poses of {args.poses}"
    else:
        q, context = sample_poses(robot, args.n_poses, np.random.default_rng(args.seed)), None
        poses = f"{args.n_poses} random poses within the joint limits (seed {args.seed})"
    result = compare_models(robot, old, new, q, z=args.z, context=context)
    result.poses = poses
    out = RunOutput(args, f"Comparison of two campaigns: {robot.name}")
    payload = result.to_dict()
    if out.report is not None:
        _calibration_page(out.report, args, robot, payload, docs[1])
    _report(out, result, poses)
    if out.report is not None:
        from ..view.plots_results import plot_changes

        out.add_plots(lambda folder: [plot_changes(payload, folder / "changes.png")],
                      {"changes.png": "Change of each robot parameter between the campaigns in standard errors"})
    return out.finish(payload, lambda: print(format_summary(result, poses)))


def _calibration_page(report, args, robot, payload: dict, new: dict) -> None:
    """The report opens with the calibration report's first page: the later campaign's diagnosis and
    what changed since the earlier one."""
    from ..view.calibration_report import Campaign, RobotFacts
    from .report import add_calibration_page

    files = [(f"{label} campaign: {path}", path) for label, path in (("earlier", args.old), ("later", args.new))]
    if args.json not in (None, "-"):
        files.append(("comparison JSON", args.json))
    campaign = Campaign(RobotFacts.of_robot(robot, payload.get("robot_source", "")),
                        [(str(args.new), new), ("comparison", payload)])
    add_calibration_page(report, args, campaign, files)


def _read_json(path: str):
    """The JSON document of ``path``, or None when it is a measurement CSV (not JSON)."""
    from ..exceptions import InputError
    from ..input_files import SIZE_LIMITS, parse_json, read_input_text

    text = read_input_text(path, "diagnosis or measurement file", limit=SIZE_LIMITS["table"])
    if not text.lstrip().startswith(("{", "[")):
        if path.lower().endswith(".json"):
            raise InputError(f"{path}: not JSON; give a diagnose --json result or a measurement CSV")
        return None
    if len(text.encode("utf-8")) > SIZE_LIMITS["json"]:
        raise InputError(f"{path}: a JSON result larger than the {SIZE_LIMITS['json'] >> 20} MB a result may have")
    from ..results.files import FIT_KEYS, renamed_keys, validate_result

    doc = parse_json(text, path, "give a diagnose --json result or a measurement CSV")
    renamed_keys(doc, path)
    return validate_result(doc, "diagnosis", path, FIT_KEYS)  # the one reader's checks, the robot's below


def _check_comparable(docs, paths, robot) -> None:
    """Two diagnoses of one robot and one TCP frame, their parameters within each effect's physical
    range (a forged standard error or value never decides what changed). InputError otherwise."""
    from ..exceptions import InputError
    from ..results.consistency import check_robot
    from ..results.files import check_physics

    for doc, path in zip(docs, paths):
        if doc is None:  # a CSV, diagnosed here with this robot
            continue
        if doc["robot"] != robot.name:
            raise InputError(f"{path}: a diagnosis of {doc['robot']}, not of {robot.name}: compare two diagnoses of "
                             "the same robot")
        check_robot(doc, robot, path)
        if doc.get("tool_frame", robot.tool_frame) != robot.tool_frame:
            raise InputError(f"{path}: a diagnosis of the TCP frame {doc['tool_frame']}, not of --tool "
                             f"{robot.tool_frame}: compare two diagnoses of one TCP frame")
        start = (doc.get("kinematics") or {}).get("sha256") if isinstance(doc.get("kinematics"), dict) else None
        ours = (robot.kinematics or {}).get("sha256")
        if start != ours:  # parameters relative to another start differ by the starts, not by the robot
            said = {None: "the URDF's kinematics"}
            raise InputError(f"{path}: diagnosed from {said.get(start, 'the kinematics file sha256 ' + str(start)[:12])}"
                             f", the comparison from {said.get(ours, 'the kinematics file sha256 ' + str(ours)[:12])}: "
                             "give --kinematics as the diagnoses had it")
        check_physics(doc, robot, path)


def _load_named(load_robot, source, tool):
    from ..exceptions import InputError

    try:
        return load_robot(source, tool)
    except InputError as exc:
        raise InputError(f"{exc} (give --robot and --tool as in the diagnosis)", parameter=exc.parameter,
                         value=exc.value) from None


def _diagnose_csv(args, path: str, robot) -> dict:
    """The diagnosis of one measurement CSV with compare's diagnose options, as ``diagnose --json`` writes it."""
    from ..diagnosis.diagnose import diagnose
    from ..exceptions import InputError
    from ..io.measurements import measured_frames, read_measurements
    from .diagnose import DIAGNOSE_ROW_BYTES

    check_csv_memory(args, path, "diagnosing", DIAGNOSE_ROW_BYTES)
    if measured_frames(path):
        raise InputError(f"{path} measures several frames: diagnose it with tcr-accuracy diagnose --json and "
                         "compare the two JSON files")
    data = read_measurements(path, robot, min_rows=max(3 * args.folds, 12))
    status(args, f"diagnosing {path} ...")
    result = diagnose(robot, data, effects=effect_names(args.effects), folds=args.folds, random_state=args.seed,
                      tracker_noise=None if args.noise_mm is None else args.noise_mm * 1e-3)
    return {**result.to_dict(), "measurements": str(path)}


# ---------------------------------------------------------------------------------------
# Printed summary and report (display units: mm, deg, labelled)
# ---------------------------------------------------------------------------------------
def _shown(value: float, unit: str) -> tuple[float, str]:
    from ..units import display_value

    return display_value(value, unit)


def _change_row(c) -> tuple:
    old, unit = _shown(c.old, c.unit)
    new, _ = _shown(c.new, c.unit)
    change, _ = _shown(c.change, c.unit)
    se = _shown(c.std_error, c.unit)[0] if c.std_error < float("inf") else float("nan")
    return c.name, unit, old, new, change, se, c.z, "YES" if c.significant else "no"


CHANGE_COLUMNS = ["parameter", "unit", "old", "new", "change", "std error", "z", "beyond"]


def format_summary(r, poses: str) -> str:
    out = [f"Comparison of {r.sources[0]} (old) and {r.sources[1]} (new): {r.robot}, "
           f"significant beyond z = {r.z_threshold:g} standard errors of the change, sqrt(std_old^2 + std_new^2)"]
    out.append(f"\n1. Robot parameters in both fits ({len(r.changes)}; the tracker frame is each campaign's "
               "setup, not compared)")
    out.extend(_table(sorted(r.changes, key=lambda c: -c.z)))
    sig = r.significant
    out.append("   beyond uncertainty: " + (", ".join(
        f"{c.name} {_shown(c.change, c.unit)[0]:+.4g} {_shown(c.change, c.unit)[1]} (z = {c.z:.1f})" for c in sig)
        if sig else "nothing"))
    if r.setup:
        out.append("\n2. Setup: the TCP offset (where the tool or reflector sits)")
        out.extend(_table(r.setup))
    out.append("\n3. In one fit only")
    if not r.one_sided:
        out.append("   nothing: both fits have the same parameters")
    for o in r.one_sided:
        names = ", ".join(f"{n} = {_shown(v, u)[0]:+.4g} {_shown(v, u)[1]}" for n, (v, s, u) in
                          list(o.parameters.items())[:4])
        more = f" (+{len(o.parameters) - 4} more)" if len(o.parameters) > 4 else ""
        out.append(f"   {o.effect}: {o.what}, only in the {o.present_in} fit: {names}{more}")
    mm = 1e3
    out.append(f"\n4. What it does to the TCP over {poses}, rigid frame change removed [mm]")
    out.append(f"   all changes of the robot: mean {r.tcp_all.mean * mm:.4f} mm, RMS {r.tcp_all.rms * mm:.4f} mm, "
               f"max {r.tcp_all.max * mm:.4f} mm")
    out.append(f"   the significant changes alone: mean {r.tcp_significant.mean * mm:.4f} mm, "
               f"RMS {r.tcp_significant.rms * mm:.4f} mm, max {r.tcp_significant.max * mm:.4f} mm")
    out.extend(f"   note: {n}" for n in r.notes)
    return "\n".join(out)


def _table(changes) -> list[str]:
    lines = [f"   {'parameter':26s} {'old':>11s} {'new':>11s} {'change':>11s} {'std error':>10s} {'z':>7s}  unit"]
    for name, unit, old, new, change, se, z, beyond in map(_change_row, changes):
        flag = "  <- beyond" if beyond == "YES" else ""
        lines.append(f"   {name:26s} {old:+11.5f} {new:+11.5f} {change:+11.5f} {se:10.5f} {z:7.1f}  {unit}{flag}")
    return lines


def _report(out, r, poses: str) -> None:
    out.add_text(f"{r.sources[0]} (old) against {r.sources[1]} (new), {r.robot}: a change is beyond both fits' "
                 f"uncertainty when |change| > {r.z_threshold:g} x sqrt(std_old^2 + std_new^2). The tracker frame "
                 "belongs to each campaign's setup and is not compared.", heading="What is compared")
    out.add_table("Robot parameters in both fits", CHANGE_COLUMNS, [_change_row(c) for c in r.changes],
                  note="values in the unit of the second column; z = |change| / std error")
    if r.setup:
        out.add_table("Setup: the TCP offset", CHANGE_COLUMNS, [_change_row(c) for c in r.setup])
    if r.one_sided:
        out.add_table("In one fit only", ["effect", "what", "fit", "parameters"],
                      [(o.effect, o.what, o.present_in, ", ".join(o.parameters)) for o in r.one_sided])
    mm = 1e3
    out.add_table(f"What it does to the TCP over {poses} (rigid frame change removed)",
                  ["changes", "mean", "RMS", "max"],
                  [("all changes of the robot", r.tcp_all.mean * mm, r.tcp_all.rms * mm, r.tcp_all.max * mm),
                   ("the significant changes alone", r.tcp_significant.mean * mm, r.tcp_significant.rms * mm,
                    r.tcp_significant.max * mm)], units=["", "mm", "mm", "mm"])
    out.add_preformatted(format_summary(r, poses), heading="Full printed summary")
