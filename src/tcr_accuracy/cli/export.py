"""``tcr-accuracy export``: the calibration of a ``diagnose --json`` result in the forms controllers
and ROS take, each with what it reaches.

Reads the diagnosis (its full model) and the measurements it was fitted to (the files its JSON
names, or ``--measurements``), builds every form (:func:`tcr_accuracy.asbuilt.export.build_export`)
and writes into ``--to DIR`` (files written together at the end of the run):

* ``as_built.urdf``: the calibration URDF, geometry and joint offsets refitted to the full model;
  ``tool0`` unchanged, the measured point the frame ``<tool>_measured``; its accuracy in a comment;
* ``as_built.yaml``: the whole fitted model for :func:`tcr_accuracy.load_as_built`
  (``docs/as-built-format.md``);
* ``dh.csv``, ``mdh.csv`` (Hayati's beta for parallel axes) and for a named robot the maker's
  convention (``ur5_dh.csv``, ``panda_mdh.csv``), each with ``*_base_tool.csv``;
* ``ur_calibration.yaml`` for a UR arm (the ROS 2 driver's kinematics calibration file);
* ``joint_offsets_tcp.csv``; ``accuracy.json`` and ``accuracy.png``: what every form reaches;
* with ``--targets CSV``, ``compensation.csv``: the compensation filter's corrected commands;
* with ``--program FILE ...``, each robot program (URScript, KRL, RAPID, a joint trajectory CSV) filtered
  through the full model, under its own name (:mod:`tcr_accuracy.cli.export_programs`).
"""

from __future__ import annotations

from pathlib import Path

from .common import EXIT_OK, MAX_MM, add_quiet_argument, number, output_folder, status
from ..exceptions import InputError

#: Memory [bytes] planned per measured row (the refit holds six poses' Jacobians per row).
EXPORT_ROW_BYTES = 40_000


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "export", help="the calibration in every form: URDF, model file, DH tables, UR file, compensation filter",
        description="Read a 'diagnose --json' result and write the calibration in the forms controllers and ROS "
                    "take, each with what it reaches: the calibration URDF (geometry refitted to the full model, "
                    "tool0 unchanged, the measured point a frame of its own), the whole model as YAML for "
                    "tcr_accuracy.load_as_built, DH/MDH tables (and the maker's convention), the UR ROS 2 driver's "
                    "calibration file, with --targets the compensation filter's corrected commands, and with "
                    "--program the robot programs filtered through the full model. "
                    "Units: mm and deg in what is printed and in the CSV tables, SI in URDF and YAML.",
    )
    p.add_argument("diagnosis", metavar="DIAGNOSIS.json", help="the JSON that 'diagnose --json FILE' wrote")
    p.add_argument("--to", required=True, type=output_folder, metavar="DIR", help="folder to write the files to")
    p.add_argument("--measurements", nargs="+", metavar="CSV", default=None,
                   help="the measurements the diagnosis was fitted to (default: the files its JSON names)")
    p.add_argument("--check", metavar="CSV", default=None,
                   help="measurements the diagnosis was not fitted to, in the tracker frame of the first "
                        "measurement file: every form's held-out error on them")
    p.add_argument("--targets", metavar="CSV", default=None,
                   help="targets to correct: joint values (the measurement format) or Cartesian positions of "
                        "the measured point, base frame (x_mm,y_mm,z_mm [qw..qz] [seed_<joint>_deg ...] "
                        "[payload_kg]); writes compensation.csv")
    p.add_argument("--program", nargs="+", metavar="FILE", default=None,
                   help="robot programs to filter through the full model, each written under --to with its own "
                        "name: URScript (.script), KUKA KRL (.src with its .dat), ABB RAPID (.mod, .prg, .sys), a "
                        "joint trajectory CSV (.csv: time_from_start and a column per joint, rad); only the motion "
                        "targets change, the header says how, what was not filtered is listed (docs/programs.md)")
    p.add_argument("--payload-kg", type=number(low=0, high=1e6, unit="kg"), default=None,
                   help="the load the URDF and tables hold [kg] (default: each measured row's); the load the "
                        "programs run with (default 0)")
    p.add_argument("--threshold-mm", type=number(low=0, low_open=True, high=MAX_MM, unit="mm"), default=None,
                   help="compensation: stop when the model's miss is below this [mm] (default 0.0001; for "
                        "--program a thousandth of the diagnosis' noise floor)")
    add_quiet_argument(p)
    p.set_defaults(run=_run_export)


def _run_export(args) -> int:
    import sys

    from dataclasses import replace

    from ..asbuilt.diagnosis_file import kfold_figures, model_from_diagnosis
    from ..asbuilt.export import MODEL_FILE, RESULT_FILE, UR_FILE, URDF_FILE, build_export
    from ..io.session_rows import shared_rows
    from ..results.consistency import check_fitted_to
    from ..results.files import MODEL_KEYS
    from ..results.types import read_result
    from ..view.as_built_summary import accuracy_lines, ur_file_header, urdf_comment
    from ..view.plots_export import accuracy_plot
    from .export_tables import offsets_and_tcp_csv, table_csv
    from .staging import hold_message, stage_folder, write_bytes, write_text

    # checked whole on read (schema, figures, one copy of each number, the robot its source loads, the
    # physics): one line naming the key at fault
    data = read_result(args.diagnosis, "diagnosis", hint="give the JSON that 'diagnose --json FILE' wrote",
                       required=MODEL_KEYS).to_dict()
    model = model_from_diagnosis(data, args.diagnosis)
    programs = []
    if args.program:  # every program read and parsed before the export's work
        from .export_programs import read_programs

        programs = read_programs(args, model.robot)
    measured = read_calibration_measurements(args, data, model.robot)
    if (data.get("session_setup") or {}).get("session_tools") and measured.session is not None:
        # each session had its own TCP offset (the reflector re-seated): the model carries the first
        # session's, and is measured on that session's rows
        measured = measured.subset(measured.session_index() == 0)
    check_fitted_to(data, _model_rms(model, measured), measured.source, args.diagnosis)
    held_out = None
    if args.check is not None:
        held_out = _read(args.check, model.robot, 3)
        shared = shared_rows(measured, held_out)
        if shared:
            raise InputError(f"--check {args.check}: {shared} of its {len(held_out)} rows are rows of the "
                             f"measurements {args.diagnosis} was fitted to ({measured.source}): their error is "
                             "in-sample, not held-out; give measurements the diagnosis was not fitted to")
        held_out = replace(held_out, source=Path(args.check).name)
    filtered = _targets(args, model) if args.targets is not None else None
    export = build_export(model, measured, held_out, payload_kg=args.payload_kg,
                          kfold=kfold_figures(data, args.diagnosis))
    files = {URDF_FILE: export.urdf_text(urdf_comment(export, args.diagnosis)), MODEL_FILE: export.model_text(),
             "joint_offsets_tcp.csv": offsets_and_tcp_csv(export)}
    for table in export.tables:
        files[table.file], files[table.file.replace(".csv", "_base_tool.csv")] = table_csv(table)
    if export.ur is not None:
        from ..asbuilt.model_file import model_yaml

        files[UR_FILE] = ur_file_header(export) + model_yaml(export.ur)
    if filtered is not None:
        from .export_tables import compensation_csv

        files["compensation.csv"] = compensation_csv(filtered[0], model.robot, filtered[1])
    program_lines = []
    if programs:
        from .export_programs import filtered_programs, threshold_m

        program_files, program_lines = filtered_programs(args, model, data, programs, threshold_m(args, data))
        clash = sorted((set(program_files) & set(files)) | (set(program_files) & {RESULT_FILE, "accuracy.png"}))
        if clash:
            raise InputError(f"--program {clash[0]}: export writes a file of that name under --to; rename the program")
        files.update(program_files)
    # the export's result (kind 'export', read back by report): the diagnosis by its file name only
    result = export.result(Path(args.diagnosis).name, measured, held_out)
    files[RESULT_FILE] = result.to_json()
    folder = Path(args.to)
    stage_folder(folder)
    for name, text in files.items():
        write_text(folder / name, text)
    plot = accuracy_plot(export.accuracy, folder / "accuracy.png")
    write_bytes(plot.path, plot.png)
    for name, why in export.not_tabled.items():  # said on stderr too (--quiet), once the files are in place
        hold_message(sys.stderr, f"tcr-accuracy: warning: {name}: not written ({why})\n", "warning")
    print("\n".join(_summary(args, export, files, filtered) + program_lines + accuracy_lines(export.accuracy)))
    status(args, f"export written to {folder}")
    return EXIT_OK


def _summary(args, export, files, filtered) -> list[str]:
    model = export.model
    lines = [f"{model.robot.name}: calibration of {args.diagnosis} ({', '.join(model.parameters)}) -> {args.to}",
             "  " + ", ".join([*files, "accuracy.png"])]
    start = model.robot.kinematics
    if start:  # the diagnosis' nominal robot: the robot's own kinematics
        lines.append(f"  start: the factory kinematics of {start['file']} ({start['format']}); the files hold the whole "
                     "calibrated kinematics, the tables' corrections are relative to that start")
    geometry = export.geometry
    lines.append(f"  URDF: geometry and joint offsets refitted to the full model over {geometry.n_measured} measured "
                 f"poses and {geometry.n_sampled} between them ({len(geometry.fitted)} parameters, RMS "
                 f"{geometry.rms * 1e3:.4f} mm from the full model); {model.robot.tool_frame} unchanged, the measured "
                 f"point is {export.measured_frame}")
    for name, why in export.not_tabled.items():
        lines.append(f"  {name}: not written ({why})")
    if filtered is not None:
        result = filtered[0]
        solved = int(result.solved.sum())
        lines.append(f"  compensation.csv: {solved} of {len(result.solved)} targets corrected"
                     + ("" if solved == len(result.solved) else " (the others listed with the reason, commands left "
                                                                "empty)"))
    return lines


def read_calibration_measurements(args, data: dict, robot):
    """The measurements the diagnosis was fitted to (``--measurements``, else the files its JSON
    names, relative to the working folder or to the JSON's), one session per file."""
    from dataclasses import replace

    from ..asbuilt.diagnosis_file import measurement_files
    from ..exceptions import InputError
    from ..io.measurements import join_sessions, measured_frames
    from .common import check_csv_memory
    from .diagnose import _session_labels

    if args.measurements:
        files = list(args.measurements)
    else:
        files = []
        for name in measurement_files(data, args.diagnosis):
            candidates = [Path(name), Path(args.diagnosis).parent / name]
            found = next((c for c in candidates if c.is_file()), None)
            if found is None:
                raise InputError(f"{args.diagnosis}: the measurements it was fitted to ({name}) are not found; give "
                                 "them with --measurements CSV ...")
            files.append(str(found))
        if not files:
            raise InputError(f"{args.diagnosis}: names no measurement file; give them with --measurements CSV ...")
    for path in files:
        check_csv_memory(args, path, "exporting", EXPORT_ROW_BYTES)
    sets = [_read(path, robot, 3) for path in files]
    joined = sets[0] if len(sets) == 1 else join_sessions(sets, _session_labels(files))
    fitted = data.get("n_measurements")
    single_point = not any(measured_frames(path) for path in files)  # rows of several points count otherwise
    if single_point and isinstance(fitted, int) and len(joined) != fitted:
        # another campaign's files (or a part of them) would refit the URDF to poses the
        # diagnosis never saw and print their error as "on the measured poses"
        raise InputError(f"{', '.join(files)}: {len(joined)} measurement rows, but {args.diagnosis} was fitted to "
                         f"{fitted} (n_measurements); give the files it was fitted to with --measurements CSV ...")
    return replace(joined, source=", ".join(Path(f).name for f in files))


def _model_rms(model, measured) -> float:
    """RMS [m] of the full model's miss on the measurements, each session's frame fitted to them:
    what it reached on the data it was fitted to, if these are they."""
    from ..asbuilt.accuracy import MeasuredPoses, form_accuracy

    rows = MeasuredPoses.of(measured, measured.source)
    return form_accuracy("full model", "", lambda q, context, later: model.tcp_poses(q, context).position, rows)[0].rms


def _read(path, robot, min_rows: int):
    from ..io.measurements import measured_frames, read_measurements

    frame = robot.tool_frame if measured_frames(path) else None
    return read_measurements(path, robot, min_rows=min_rows, frame=frame)


def _targets(args, model):
    """(FilteredTargets, the targets' rows in their file) of ``--targets``."""
    from ..asbuilt.compensation_filter import filter_joint_targets, filter_pose_targets
    from ..io.measurements import read_measurements
    from ..io.pose_targets import is_cartesian, read_pose_targets

    from .common import check_csv_memory

    # each target: the model's TCP and its Jacobian over the joints, a few copies
    check_csv_memory(args, args.targets, "--targets", 3 * 64 * 8.0 * (model.robot.n_joints + 1),
                     hint="use fewer targets")
    threshold = (1e-4 if args.threshold_mm is None else args.threshold_mm) * 1e-3
    if is_cartesian(args.targets, model.robot):
        targets = read_pose_targets(args.targets, model.robot)
        return filter_pose_targets(model, targets.positions, targets.rotations, q_seed=targets.q_seed,
                                   context=targets.context, threshold=threshold), targets.rows
    mset = read_measurements(args.targets, model.robot, require_position=False, repeats_allowed=True)
    return filter_joint_targets(model, mset.q, mset.context, threshold=threshold), mset.rows
