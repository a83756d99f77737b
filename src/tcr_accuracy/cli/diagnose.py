"""``tcr-accuracy diagnose``: the sim-to-real gap of a robot from tracker measurements.

Edge layer: reads the CSV, runs :func:`tcr_accuracy.diagnosis.diagnose.diagnose`, prints the
summary (mm, labelled), writes JSON, the Markdown/HTML report with plots, and the calibration
URDF with the whole model beside it (the export's builder and model format, :mod:`tcr_accuracy.asbuilt`).

One concept, the ``diagnose`` command (its flags, the run and what it writes), and so one module at
the 500-line bound.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

from .common import (add_robot_arguments, as_built_file, check_csv_memory, effect_names, effects_side_file, integer,
                     noise_mm_value, number, seed_value, status)
from .output import RunOutput, add_output_arguments
from .report import add_campaign_arguments, read_campaign_arguments
from ..view.diagnosis_summary import answer_lines, format_summary, primary_effect_text as _primary_text, \
    strongest_links as _strongest, structure_verdict_text as _verdict_text


#: The diagnosis' progress line; tqdm puts ", " before the postfix, so this reads
#: "diagnose, step 2: trying geometry [00:04]".
PROGRESS_FORMAT = "{desc}{postfix} [{elapsed}]"

def add_parsers(sub) -> None:
    p = sub.add_parser(
        "diagnose", help="where the sim-to-real gap lies, which effect causes it, how far it shrinks",
        description="Fit the tracker frame, break the remaining TCP error down over the workspace, "
                    "rank the effects of the vocabulary by k-fold held-out error (forward selection "
                    "with a paired significance test, then backward elimination), check "
                    "identifiability, and say whether structure remains. Units: mm and deg in what "
                    "is printed, SI in the YAML.",
    )
    p.add_argument("measurements", metavar="MEASUREMENTS.csv", nargs="+",
                   help="measurement CSV (see docs/measurements.md); several files are several sessions of one robot (each "
                        "its own tracker frame, the robot's parameters shared), as is a session column")
    add_robot_arguments(p)
    p.add_argument("--effects", default=None, metavar="LIST",
                   help="comma-separated effects to consider (default: the whole vocabulary; frames is "
                        "always in)")
    p.add_argument("--folds", type=integer(low=2, high=1000), default=5,
                   help="k of the k-fold cross-validation (default 5)")
    p.add_argument("--seed", type=seed_value, default=0, help="seed of the fold split and permutation tests")
    p.add_argument("--noise-mm", type=noise_mm_value, default=None,
                   help="the instrument's noise, std per axis [mm]; noise floor = sqrt(3) x this (default: "
                        "estimated from repeated poses, else from the final residual, and said which)")
    p.add_argument("--instrument", default=None, metavar="NAME",
                   help="the measuring instrument, by name (leica-at9xx, leica-at500, api-radian, leica-ts60): every "
                        "point weighed by its own noise from the maker's MPE along and across the beam at its "
                        "distance, and the noise floor from it where the data's redundancy gives none")
    p.add_argument("--instrument-mpe", nargs=2, type=number(low=0, high=1e4, unit="um, um/m"), default=None,
                   metavar=("A_UM", "B_UM_PER_M"),
                   help="the instrument's MPE across the beam, A [um] + B [um/m] x distance (and along it unless "
                        "--instrument-radial-mpe); positions in the instrument's own frame, it at the origin")
    p.add_argument("--instrument-radial-mpe", nargs=2, type=number(low=0, high=1e4, unit="um, um/m"), default=None,
                   metavar=("A_UM", "B_UM_PER_M"), help="the instrument's MPE along the beam, where it differs")
    p.add_argument("--tcp-mm", nargs=3, type=number(low=-1e4, high=1e4, unit="mm"), default=None,
                   metavar=("X", "Y", "Z"),
                   help="the measured point's offset from the tool frame (--tool's, in its axes) as you know it "
                        "[mm]: set beside the fitted one and flagged where they differ by more than the robot's "
                        "class allows")
    p.add_argument("--as-built-urdf", default=None, type=as_built_file, metavar="FILE",
                   help="write the calibration URDF (geometry refitted to the full model, tool0 unchanged) to "
                        "FILE and the whole model (for tcr_accuracy.load_as_built) to FILE with suffix .effects.yaml")
    add_output_arguments(p, view=True)
    add_campaign_arguments(p)
    p.set_defaults(run=_run_diagnose)


def _check_distinct_poses(path, measurements) -> None:
    """At least three different joint configurations: at one pose (repeated) the TCP error of
    every effect is one constant offset, and a 'diagnosis' would only fit the tracker frame to it."""
    import numpy as np

    from ..exceptions import InputError

    distinct = len(np.unique(measurements.q, axis=0))
    if distinct < 3:
        raise InputError(f"{path}: {len(measurements)} rows at {distinct} distinct pose(s); measure the TCP at "
                         "different joint values (at least 3, better dozens) for anything to be diagnosed")


def _frame_robot(args, frame: str):
    """The robot with its TCP at a frame the measurement file's columns name (``<frame>.x_mm``):
    a frame the robot lacks is the file's fault, named by its column, unless --tool named it."""
    from ..exceptions import InputError
    from .common import robot_from_args

    try:
        return robot_from_args(args, frame)
    except InputError as exc:
        if args.tool == frame or "no such frame" not in str(exc):
            raise
        raise InputError(f"{args.measurements[0]}: column {frame}.x_mm: {str(exc).partition(': ')[2]}") from None


#: Memory [bytes] the diagnosis plans per measurement, and beyond the measurements (the libraries'
#: 0.2 GB and the arrays whose size does not grow with the poses), see check_csv_memory in
#: _run_diagnose: scripts/bench_scale.py measured 0.70 GB peak for 10,000 poses of the UR10 with
#: cyclic errors over the whole vocabulary and 2.27 GB for 100,000 (2026-11-27), planned as 0.70 and
#: 2.50 GB (with the 12 bytes per byte of CSV text). Before the streamed Jacobians the plan was 32 kB
#: a pose and no fixed part: 3.4 GB planned at 100,000 poses for 4.82 GB measured.
DIAGNOSE_ROW_BYTES = 18_000
DIAGNOSE_FIXED_BYTES = 0.5e9


def _run_diagnose(args) -> int:
    from ..diagnosis.diagnose import diagnose
    from ..exceptions import FixedFrameError, InputError
    from ..io.measurements import join_sessions, measured_frames, read_measurements
    from ..view.plots_diagnose import write_plots
    from .common import robot_from_args

    effects = effect_names(args.effects)
    read_campaign_arguments(args)
    min_rows = max(3 * args.folds, 12)
    files = list(args.measurements)
    seen = {}
    for path in files:  # one file however spelt (./m.csv, a link): its poses would be their own repeats
        try:
            key = (os.stat(path).st_dev, os.stat(path).st_ino)
        except OSError:
            key = str(path)
        if key in seen:
            raise InputError(f"MEASUREMENTS.csv: {path} is given twice (as {seen[key]} too)")
        seen[key] = path
    # the diagnosis holds each measurement's Jacobians over the whole effect vocabulary and
    # the error maps of the pose-dependent effects
    for path in files:
        check_csv_memory(args, path, "diagnosing", DIAGNOSE_ROW_BYTES, lambda rows: DIAGNOSE_FIXED_BYTES)
    frames = measured_frames(files[0])
    for path in files[1:]:
        if measured_frames(path) != frames:
            raise InputError(f"{path}: measures {', '.join(measured_frames(path)) or 'the TCP'}, {files[0]} "
                             f"{', '.join(frames) or 'the TCP'}: sessions must measure the same frames")
    labels = _session_labels(files)
    per_file = 3 if len(files) > 1 else min_rows  # a session needs 3 rows for its frame; the whole set more
    if frames:  # several measured frames per row: one chain each, their shared parameters fitted once
        if args.tool is not None and args.tool not in frames:
            raise InputError(f"--tool {args.tool}: {files[0]} measures {', '.join(frames)}")
        order = [args.tool] + [f for f in frames if f != args.tool] if args.tool else frames
        robots, fixed = [], {}
        for f in order:  # a frame no joint moves is a base reference: it watches the tracker, not the robot
            try:
                robots.append(_frame_robot(args, f))
            except FixedFrameError as exc:
                if f == args.tool:
                    raise
                fixed[f] = exc.position
        if not robots:
            raise InputError(f"{files[0]}: every measured frame ({', '.join(order)}) is fixed to the base; "
                             "measure at least one frame a joint moves")
        moving = [f for f in order if f not in fixed]
        parts = [(r, join_sessions([read_measurements(path, r, min_rows=per_file, frame=f) for path in files],
                                   labels)) for r, f in zip(robots, moving)]
        references = [(f, position, join_sessions([read_measurements(path, robots[0], min_rows=per_file, frame=f,
                                                                     check_units=False) for path in files],
                                                  labels))
                      for f, position in fixed.items()]
        robot, measurements, data = robots[0], parts[0][1], parts
    else:
        robot = robot_from_args(args)
        measurements = data = join_sessions([read_measurements(path, robot, min_rows=per_file) for path in files],
                                            labels)
        references = []
    if len(measurements) < min_rows:
        raise InputError(f"{', '.join(map(str, files))}: {len(measurements)} measurement rows, at least {min_rows} "
                         f"are needed for {args.folds}-fold cross-validation")
    _check_distinct_poses(", ".join(map(str, files)), measurements)
    out = RunOutput(args, f"Sim-to-real gap diagnosis: {robot.name}")
    from tqdm import tqdm

    bar = tqdm(desc="diagnose", file=sys.stderr, bar_format=PROGRESS_FORMAT,
               disable=args.quiet or not sys.stderr.isatty())
    try:
        result = diagnose(robot, data, effects=effects, folds=args.folds, random_state=args.seed,
                          tracker_noise=None if args.noise_mm is None else args.noise_mm * 1e-3,
                          instrument=_instrument(args),
                          tcp_offset=None if args.tcp_mm is None else [v * 1e-3 for v in args.tcp_mm],
                          references=[(f, p, m.position, m.time_s) for f, p, m in references],
                          progress=bar.set_postfix_str)
    except InputError as error:
        if error.parameter != "measurements" or not isinstance(error.value, tuple):
            raise
        raise InputError(f"{_rows_named(measurements, error.value, files, labels)}: {error}") from None
    finally:
        bar.close()
    payload = {**result.to_dict(), "measurements": ", ".join(map(str, files)),
               "measurement_files": list(map(str, files))}
    source = ", ".join(map(str, files))
    _report_tables(out, robot, result, source)
    out.add_plots(lambda folder: list(write_plots(result, robot, folder).values()), PLOT_CAPTIONS)
    if out.scene_wanted:
        out.set_scene(_scene(robot, result, measurements),
                      "Measured TCP points (base frame) and the gap to the nominal model, magnified; "
                      "nominal robot and the calibrated as-built robot (geometric errors magnified)")
    written = []
    if args.as_built_urdf:
        urdf, side, summary = write_as_built(robot, result, Path(args.as_built_urdf), measurements,
                                             ", ".join(Path(f).name for f in files))
        status(args, f"as-built URDF written to {urdf} (the whole model, every effect and the tracker frame: {side})")
        payload.update(as_built_urdf=str(urdf), as_built_effects=str(side), as_built=summary)
        written += [("calibration URDF", urdf), ("the whole model (tcr_accuracy.load_as_built)", side)]
    if out.report is not None:
        _calibration_page(out.report, args, robot, payload, written)
    steps = _next_steps(args, robot, payload, files)
    return out.finish(payload, lambda: print(format_summary(robot, result, source) + "\n\n" + steps))


def _next_steps(args, robot, payload: dict, files) -> str:
    """What to do next, one sentence a step, with the commands as this run's options need them."""
    import shlex

    from ..view.next_steps import export_step, next_steps, next_steps_lines

    options = ""
    if args.robot is not None:
        options += f" --robot {shlex.quote(str(args.robot))} --tool {shlex.quote(robot.tool_frame)}"
    if getattr(args, "kinematics", None):
        options += f" --kinematics {shlex.quote(str(args.kinematics))}"
    json_file = args.json if args.json not in (None, "-") else None
    steps = next_steps(payload, measurements=[str(f) for f in files], robot_options=options)
    return "\n".join(next_steps_lines(steps + [export_step(None if json_file is None else str(json_file))]))


def _calibration_page(report, args, robot, payload: dict, written: list) -> None:
    """The report's first page (the calibration report) and links to the files of the run."""
    from ..view.calibration_report import Campaign, RobotFacts
    from .report import add_calibration_page

    if args.json not in (None, "-"):
        written = [("diagnosis JSON (every figure of the report)", args.json), *written]
    source = args.json if args.json not in (None, "-") else "diagnosis"
    campaign = Campaign(RobotFacts.of_robot(robot, payload["robot_source"]), [(str(source), payload)])
    add_calibration_page(report, args, campaign, written)


def _session_labels(files) -> list[str]:
    """One session label per file: its name without the suffix, made unique."""
    labels = []
    for path in files:
        stem = Path(path).stem or "session"
        label, k = stem, 2
        while label in labels:
            label, k = f"{stem}_{k}", k + 1
        labels.append(label)
    return labels


def robot_source(source) -> str:
    """How to load the robot again: its example-robot-data name, ``tool_changer``, or the URDF's
    absolute path."""
    from ..model.robot import EXAMPLE_ROBOTS

    if source is None or source == "tool_changer" or str(source) in EXAMPLE_ROBOTS:
        return "tool_changer" if source is None else str(source)
    return str(Path(source).resolve())


# ---------------------------------------------------------------------------------------
# As-built model
# ---------------------------------------------------------------------------------------
def write_as_built(robot, d, path: Path, measurements, label: str) -> tuple[Path, Path, dict]:
    """The calibration URDF at ``path`` and the whole model beside it (``X.effects.yaml``, the one
    model format of :mod:`tcr_accuracy.asbuilt.model_file`), through the export's own builder;
    returns (urdf, model file, the export's summary for the JSON)."""
    from dataclasses import replace

    import numpy as np

    from ..asbuilt.export import build_export
    from ..asbuilt.model import AsBuiltModel
    from .staging import write_text
    from ..view.as_built_summary import urdf_comment

    model = AsBuiltModel.from_diagnosis(robot, d)
    final = d.steps[-1].heldout
    kfold = {"mean": final.mean, "rms": final.rms, "max": final.max, "folds": d.folds, "n": d.n_measurements}
    side = effects_side_file(path)
    export = build_export(model, replace(measurements, source=label), kfold=kfold, urdf_file=path.name,
                          model_file=side.name)
    write_text(path, export.urdf_text(urdf_comment(export, "this diagnosis")))
    informational = {
        **({"measured_frames": list(d.frames_measured),
            "chain_in_urdf": f"the URDF is the chain to {d.frames_measured[0]}; the other frames' TCP offsets "
                             "are among the parameters"} if len(d.frames_measured) > 1 else {}),
        "selected_effects": list(d.selected_effects),
        "uncertainty": {e: {"units": dict(d.parameter_units.get(e, {})), **_uncertainty(d, e)} for e in d.parameters},
        "uncertainty_note": "std: standard error from the fit's Jacobian and residual (noise only, not model "
                            "error); interval_95: value +- 1.96 std cut to the physical range; physical_range: "
                            "where the effect's parameters can lie on a real robot",
        **({"joint_functions": {e: {j: {"angle_deg": np.round(np.degrees(b["angle_rad"][::4]), 3).tolist(),
                                          "error_rad": b["value_rad"][::4].tolist(),
                                          "std_rad": b["std_rad"][::4].tolist()}
                                      for j, b in joints.items()}
                                  for e, joints in d.joint_function_bands.items()},
            "joint_functions_note": "each joint's fitted error against its own angle over the measured range (add "
                                    "error_rad to the joint's angle; interpolate between rows)"}
           if d.joint_function_bands else {}),
    }
    write_text(side, export.model_text(**informational))
    return path, side, export.to_dict()


def _uncertainty(d, effect: str) -> dict:
    """An effect's standard errors, 95 % intervals, physical range and what the bounds hold (YAML-ready)."""
    table = d.parameter_table.get(effect)
    if not table:
        return {}
    finite = lambda v: float(v) if math.isfinite(v) else None  # noqa: E731
    out = {"std": {k: finite(v) for k, v in table["std"].items()},
           "interval_95": {k: [finite(a), finite(b)] for k, (a, b) in table["interval"].items()},
           "physical_range": {k: [finite(a), finite(b)] for k, (a, b) in table["range"].items()},
           "physics": d.physics.get(effect, "")}
    if table["pinned"]:
        out["held_on_physical_bound"] = [dict(p) for p in table["pinned"]]
    return out


# ---------------------------------------------------------------------------------------
# Report tables and 3D view (the report itself is written by cli_output.RunOutput)
# ---------------------------------------------------------------------------------------
PLOT_CAPTIONS = {
    "steps.png": "How far the gap shrinks: held-out RMS after each step, in the order the effects explain the data",
    "axes.png": "Residual after fitting the tracker frame, per axis",
    "joints.png": "Residual after the tracker frame against each joint value",
    "gravity.png": "Residual after the tracker frame against the gravity torque of each joint",
    "regions.png": "Residual after the tracker frame over the workspace (octants, radius, height) and against "
                   "payload, temperature and approach direction",
    "semivariograms.png": "Per-joint semivariograms of the residual (along which joints it varies)",
    "cyclic_joints.png": "Cyclic joint errors: each joint's fitted error against its own angle, with its 95 % band",
    "angle_table_joints.png": "Joint-angle tables: each joint's fitted error against its absolute angle over the measured "
                              "travel, with its 95 % band",
}


def _rows_named(measurements, indices, files, labels) -> str:
    """Rows of the joined measurement set named as the user knows them: file and line."""
    path_of = dict(zip(labels, map(str, files)))
    session = measurements.session

    def file_of(i):
        return str(files[0]) if session is None else path_of.get(str(session[i]).split(":")[0], str(session[i]))

    return " and ".join(f"{file_of(i)} row {int(measurements.rows[i])}" for i in indices)


def _instrument(args):
    """The instrument --instrument or --instrument-mpe names (SI), or None."""
    from ..exceptions import InputError
    from ..frames.instrument import MPE_MAX, MPE_MIN_M, instrument_from

    if args.instrument is not None and args.instrument_mpe is not None:
        raise InputError("--instrument and --instrument-mpe: give one of them")
    if args.instrument_radial_mpe is not None and args.instrument_mpe is None:
        raise InputError("--instrument-radial-mpe: give --instrument-mpe too (the MPE across the beam)")

    def si(pair):
        return None if pair is None else (pair[0] * 1e-6, pair[1] * 1e-6)

    try:
        return instrument_from(args.instrument, si(args.instrument_mpe), si(args.instrument_radial_mpe))
    except InputError as error:  # worded in the flag's units (um, um/m), not the library's SI
        given = {"instrument_mpe": args.instrument_mpe, "instrument_radial_mpe": args.instrument_radial_mpe}
        if error.parameter not in given:
            raise
        a, b = given[error.parameter]
        raise InputError(f"--{error.parameter.replace('_', '-')} {a:g} {b:g}: want A <= {MPE_MAX[0] * 1e6:g} um and "
                         f"B <= {MPE_MAX[1] * 1e6:g} um/m, A + B >= {MPE_MIN_M * 1e6:g} um (no measuring instrument "
                         "lies outside)") from None


def _report_tables(out, robot, d, source: str) -> None:
    from ..units import display_value

    mm = 1e3
    out.add_text(f"{d.n_measurements} measurements of {robot.name} from {source}, {d.folds}-fold "
                 "cross-validation. Every held-out figure comes from measurements not used for that fit.",
                 heading="Data")
    out.add_text("\n\n".join(line.strip() for line in answer_lines(d)), heading="Answer")
    if d.families:
        out.add_table("Families of effects", ["family", "chosen effects", "share", "share 95 % interval"],
                      [(f["family"], ", ".join(f["effects"]), f["share_mm"],
                        f"{f['interval_mm'][0]:+.4f} to {f['interval_mm'][1]:+.4f}") for f in d.families],
                      units=["", "", "mm", "mm"],
                      note="share: how much the held-out RMS rises without every member of the family, the other "
                           "effects held to their parameters; the primary family is named where the held-out rows "
                           "rank it above the others, the member where they rank it above the other members")
    rows = [(m["effect"], m["family"], m["mechanism"], "yes" if m["physical"] else "no", m["check"])
            for m in d.mechanisms if m["effect"] != "frames"]
    if rows:
        out.add_table("What mechanism each chosen effect stands for",
                      ["effect", "family", "mechanism its fitted sign and size fit", "physical", "check"], rows,
                      note="the model keeps whatever signature the held-out data want (within each effect's fit "
                           "range, the union of the mechanisms it can stand for); the words name the mechanism "
                           "whose range holds the fitted values")
    out.add_table("1. Gap after fitting only the tracker frame and TCP offset", ["statistic", "value"],
                  [("mean", d.gap.mean * mm), ("RMS", d.gap.rms * mm), ("max", d.gap.max * mm)],
                  units=["", "mm"])
    axes = d.where_mm["per_axis"]
    out.add_table("2. Where it lies: residual per axis", ["axis", "RMS"],
                  [(a, axes[a]["rms_mm"]) for a in "xyz"], units=["", "mm"],
                  note="strongest links: " + "; ".join(_strongest(d.where_mm)))
    rows = []
    for name, c in d.candidates.items():
        if c.get("tried"):
            rows.append((name, c["heldout_rms_mm_with_frames"], c["gain_mm"], c["z"], c["n_parameters"]))
        else:
            rows.append((name, "not tried", c["why"], "", ""))
    out.add_table("3. Which effect: each effect added to frames alone",
                  ["effect", "held-out RMS", "gain", "paired z", "identifiable parameters"], rows,
                  units=["", "mm", "mm", "", ""])
    noise_said = (f"noise floor at most {d.noise_floor * mm:.4f} mm (from the residual: an upper bound)"
                  if d.noise is not None and not d.noise.independent else
                  f"final held-out RMS = {d.steps[-1].heldout.rms / d.noise_floor:.2f} x the noise floor "
                  f"{d.noise_floor * mm:.4f} mm")
    out.add_table("4. How far it shrinks (k-fold held-out, in the order the effects explain the data)",
                  ["step", "parameters", "train RMS", "held-out mean", "held-out RMS", "held-out max", "gain",
                   "gain 95 % interval"],
                  [(s.effect if i == 0 else "+" + s.effect, s.n_parameters, s.train_rms * mm, s.heldout.mean * mm,
                    s.heldout.rms * mm, s.heldout.max * mm, "" if s.gain is None else s.gain[0] * mm,
                    "" if s.gain is None else f"{s.gain[1] * mm:+.4f} to {s.gain[2] * mm:+.4f}")
                   for i, s in enumerate(d.steps)],
                  units=["", "", "mm", "mm", "mm", "mm", "mm", "mm"],
                  note=f"primary effect: {_primary_text(d)}; {noise_said}; structure remains: {_verdict_text(d)} "
                       f"({d.structure.get('reason', '')}); stability (share of {d.selection.get('n_replays', 0)} "
                       "bootstrap replays of the selection that chose each effect): " + ", ".join(
                           f"{e} {f:.0%}" for e, f in d.selection.get("frequency", {}).items() if f > 0))
    rows = []
    for e, table in d.parameter_table.items():
        units = d.parameter_units.get(e, {})
        for name, value in table["values"].items():
            unit = units.get(name, "")
            shown = display_value(0.0, unit)[1]

            def v(x, fmt):
                return fmt.format(display_value(x, unit)[0])

            low, high = table["interval"][name]
            lo, hi = table["range"][name]
            pinned = any(p["parameter"] == name for p in table["pinned"])
            fit_lo, fit_hi = table["fit_range"][name]
            def span(a, b):
                return "unbounded" if math.isinf(a) and math.isinf(b) else f"{v(a, '{:.3g}')} to {v(b, '{:.3g}')}"

            rows.append((name, v(value, "{:+.4g}"), v(table["std"][name], "{:.2g}"),
                         f"{v(low, '{:+.4g}')} to {v(high, '{:+.4g}')}", shown, span(lo, hi),
                         span(fit_lo, fit_hi) + (" (held on its bound)" if pinned else "")))
    if rows:
        out.add_table("Fitted parameters", ["parameter", "value", "standard error", "95 % interval", "unit",
                                            "physical range", "fit range"], rows,
                      note="display units (SI in the JSON and the effects YAML); "
                           "standard errors from the fit's Jacobian and residual (the noise, not model error); "
                           "physical range: what each effect's own physics allows; fit range: what the fit was held "
                           "to (every mechanism the effect can stand for): " + "; ".join(
                               f"{e}: {why}" for e, why in d.physics.items() if why))
    if d.ambiguous:
        out.add_table("What the data cannot tell apart",
                      ["group", "member", "held-out RMS", "held-out mean", "parameters", "z (worse than chosen)"],
                      [("{" + ", ".join(g["effects"]) + "}", m["effect"], m["heldout_rms_mm"], m["heldout_mean_mm"],
                        m["n_parameters"], m["z_worse_than_chosen"]) for g in d.ambiguous for m in g["members"]],
                      units=["", "", "mm", "mm", "", ""],
                      note="each chosen effect swapped for each unchosen one (with a companion effect where it "
                           "needs one) and refitted: a member is no significantly worse than the chosen one (paired "
                           "z < the selection threshold) yet explains significantly more than neither. "
                           "tcr-accuracy plan-poses suggests poses that separate them.")
    if d.leave_one_out:
        out.add_table("Leave one out of the chosen set",
                      ["dropped", "held-out RMS (others refitted)", "increase", "held-out RMS (own share)",
                       "increase (own share)"],
                      [(r["dropped"], r["heldout_rms_mm"], r["increase_mm"], r["own_share_heldout_rms_mm"],
                        r["own_share_increase_mm"]) for r in d.leave_one_out],
                      units=["", "mm", "mm", "mm", "mm"],
                      note="others refitted: the remaining effects may take the dropped one's place (backward "
                           "elimination uses this); own share: they keep the parameters they have in the final "
                           "model, so an effect is not credited with what a later one of the vocabulary duplicates. "
                           "The primary effect has the largest own share.")
    out.add_preformatted(format_summary(robot, d, source), heading="Full printed summary")


def _scene(robot, d, measurements):
    """Everything in the robot's base frame: the nominal robot, the calibrated as-built robot as a
    ghost, the measured points (the fitted tracker frame applied), the nominal TCPs at the
    measured joints, the gap to the model, and the tracker's own frame as a triad."""
    import numpy as np

    from ..model.errors import ErrorModel
    from ..model.kinematics import tcp_poses
    from ..view.viewer import (COLORS, Scene, data_extent, frame_axis_length, ghost_magnification, point_size,
                               rotate_vectors, segment_magnification, transform_points)

    base_M_tracker = np.linalg.inv(d.trackerMbase)
    context = measurements.context
    model_final = d.model_positions(robot, d.q, context)  # the fitted model's TCP, base frame
    measured = model_final - rotate_vectors(base_M_tracker, d.final_residual)
    nominal_model = measured + rotate_vectors(base_M_tracker, d.gap_residual)  # tracker frame and TCP offset only
    gap = np.linalg.norm(d.gap_residual, axis=1)
    extent = data_extent(measured)
    magnify = segment_magnification(float(gap.max()), extent)
    scene = Scene(f"{robot.name}: sim-to-real gap", frame="data")
    # the robot reaching into the middle of its measurements stands among them, not beside them
    shown = int(np.argmin(np.linalg.norm(measured - np.median(measured, axis=0), axis=1)))
    q_show = d.q[shown]
    row = int(measurements.rows[shown]) if len(getattr(measurements, "rows", ())) == len(d.q) else shown + 2
    scene.add_robot(robot, q_show, name=f"nominal robot at measurement row {row}, the one nearest "
                                        "the middle of the data")
    em = ErrorModel(robot)
    x = np.asarray(d.as_built_x, dtype=float)
    tool = np.zeros_like(x)
    tool[em.tool_slice] = x[em.tool_slice]  # the measured frame's offset: drawn at its true size
    ghost = ghost_magnification(robot, q_show, em, x - tool, magnify)
    as_built = em.perturbed_robot(ghost * (x - tool) + tool)
    scene.add_robot(as_built, q_show, name=f"as-built robot, geometric errors x {ghost:g}, TCP offset x 1",
                    color=(0.85, 0.2, 0.2), opacity=0.35, include_base=False, framed=False)
    scene.add_point_cloud(measured, gap * 1e3, name="measured", size_m=point_size(extent),
                          label="measured points (tracker frame fitted, base frame), coloured by the gap after the "
                                "tracker frame |dP| [mm]")
    scene.add_marker(measured[shown], "marked pose", f"the measured point of row {row}, the pose the robots are "
                                                     "drawn at", radius_m=2.5 * point_size(extent))
    drawn = scene.add_error_segments(measured, nominal_model, magnify=magnify, name="gap", start_color=None,
                                     size_m=0.6 * point_size(extent), start_label="measured point",
                                     end_label="model with the tracker frame and TCP offset only")
    scene.add_points(tcp_poses(robot, d.q[drawn]).position, "nominal TCP", COLORS["nominal_tcp"],
                     size_m=0.5 * point_size(extent), label="nominal TCP (URDF) at the measured joints"
                     + (f" (of the {len(drawn)} with a line)" if len(drawn) < len(d.q) else ""))
    scene.add_frame(base_M_tracker, "tracker frame", length_m=frame_axis_length(measured),
                    label="tracker frame (fitted)")
    scene.add_note(f"{d.n_measurements} measurements" + (f" of {d.frames_measured[0]}" if len(d.frames_measured) > 1
                                                        else "")
                   + f"; base frame of the robot; segments magnified x {magnify:g}, the as-built ghost's "
                     f"geometric errors x {ghost:g}")
    return scene

