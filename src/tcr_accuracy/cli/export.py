"""``tcr-accuracy export``: the calibrated robot of a ``diagnose --json`` result in the forms
controllers and other tools take.

Writes into ``--to DIR`` (files written together at the end of the run):

* ``as_built.urdf`` and ``as_built.yaml``: the geometry as a URDF, and the whole fitted model
  (non-geometric effects included) that :func:`tcr_accuracy.load_as_built` reads back
  (:mod:`tcr_accuracy.prediction.as_built_model`);
* ``joint_offsets_tcp.csv``: joint zero offsets [deg, mm] and the TCP (offset in the TCP
  frame and its pose on the flange) [mm, deg];
* ``dh.csv``, ``mdh.csv`` and their ``*_base_tool.csv``: the standard and the modified
  (Craig, Hayati's beta for parallel axes) Denavit-Hartenberg tables, nominal, as built and
  the correction (:mod:`tcr_accuracy.model.dh`); where the axes admit no DH table (axes parallel
  by design, tilted as built) a one-line warning says so and the rest is written;
* ``compensation.csv`` (with ``--targets CSV``): for controllers that cannot take a model,
  each target's corrected joint command: the calibrated robot's measured point at the
  corrected command lands where the nominal robot with the fitted TCP offset puts it at
  the target joints.
"""

from __future__ import annotations

from pathlib import Path

from .common import EXIT_OK, MAX_MM, add_quiet_argument, number, output_folder, status


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "export", help="the calibrated robot of a diagnosis as URDF, model file, offsets, compensation table",
        description="Read a 'diagnose --json' result and write the calibrated robot: the as-built URDF, "
                    "the whole model (non-geometric effects included) as YAML for tcr_accuracy.load_as_built, "
                    "joint offsets and the TCP in deg and mm, and with --targets a table of corrected commands.",
    )
    p.add_argument("diagnosis", metavar="DIAGNOSIS.json", help="the JSON that 'diagnose --json FILE' wrote")
    p.add_argument("--to", required=True, type=output_folder, metavar="DIR", help="folder to write the files to")
    p.add_argument("--targets", metavar="CSV", default=None,
                   help="target joint values (CSV, the measurement format without positions): write "
                        "compensation.csv, the corrected commands")
    p.add_argument("--threshold-mm", type=number(low=0, low_open=True, high=MAX_MM, unit="mm"), default=0.0001,
                   help="compensation: stop when the model's miss is below this [mm] (default 0.0001)")
    add_quiet_argument(p)
    p.set_defaults(run=_run_export)


def read_diagnosis_json(path: str) -> dict:
    """The JSON of ``diagnose --json``, validated on read (:mod:`tcr_accuracy.cli.result_files`:
    one line naming the key at fault)."""
    from .result_files import MODEL_KEYS, read_result

    return read_result(path, "diagnosis", hint="give the JSON that 'diagnose --json FILE' wrote",
                       required=MODEL_KEYS)[1]


def _run_export(args) -> int:
    import numpy as np

    from .staging import stage_folder, write_text
    from ..exceptions import InputError
    from ..model.dh import NoDhForm
    from ..model.robot import load_robot
    from ..prediction.as_built_model import AsBuiltModel, write_as_built_model

    from .result_files import check_physics

    data = read_diagnosis_json(args.diagnosis)
    source = data["robot_source"]
    robot = load_robot(None if source == "tool_changer" else source, data["tool_frame"])
    check_physics(data, robot, args.diagnosis)
    try:
        model = AsBuiltModel(robot, {e: dict(p) for e, p in data["effect_parameters"].items()}, source,
                             np.asarray(data["tracker_transform"], dtype=float),
                             {e: dict(o) for e, o in (data.get("effect_options") or {}).items()})
    except (TypeError, ValueError, AttributeError) as exc:
        raise InputError(f"{args.diagnosis}: effect_parameters: {exc}") from None
    folder = Path(args.to)
    files = write_as_built_model(model, folder, "as_built")
    files["joint_offsets_tcp.csv"] = offsets_and_tcp_csv(model)
    summary = [f"{robot.name}: calibrated model of {args.diagnosis} ({', '.join(model.parameters)}) -> {folder}"]
    for convention in ("DH", "MDH"):
        try:
            table, frames = dh_csv(model, convention)
        except NoDhForm as exc:
            import sys

            from .staging import hold_message

            hold_message(sys.stderr, f"tcr-accuracy: warning: {exc}\n", "warning")  # once the files are written
            summary.append(f"  {convention}: not written ({exc})")
            continue
        files[f"{convention.lower()}.csv"], files[f"{convention.lower()}_base_tool.csv"] = table, frames
    if args.targets is not None:
        from .common import check_csv_memory

        # each target: the model's TCP and its Jacobian over the joints, a few copies
        check_csv_memory(args, args.targets, "--targets", 3 * 64 * 8.0 * (robot.n_joints + 1), hint="use fewer targets")
        text, solved, total = compensation_csv(model, args.targets, args.threshold_mm * 1e-3)
        files["compensation.csv"] = text
        summary.append(f"  compensation.csv: {solved} of {total} targets corrected"
                       + ("" if solved == total else " (the others listed with the reason, commands left empty)"))
    stage_folder(folder)
    for name, text in files.items():
        write_text(folder / name, text)
    summary.insert(1, "  " + ", ".join(files))
    print("\n".join(summary))
    status(args, f"export written to {folder}")
    return EXIT_OK


def offsets_and_tcp_csv(model) -> str:
    """``quantity,value,unit`` rows: each joint's zero offset, the fitted TCP offset in the TCP
    frame, and the as-built TCP pose on the last joint's frame (x, y, z, roll, pitch, yaw)."""
    import numpy as np
    import pinocchio as pin

    robot = model.robot
    rows = [("quantity", "value", "unit")]
    for name, value, unit, scale in zip(robot.joint_names, model.joint_offsets(), robot.display_units,
                                        robot.display_scale):
        rows.append((f"joint_offset.{name}", f"{value * scale:.9g}", unit))
    for axis, value in zip("xyz", model.tcp_offset()):
        rows.append((f"tcp_offset_in_tcp_frame.{axis}", f"{value * 1e3:.9g}", "mm"))
    as_built = model.geometric_robot()
    placement = as_built.tool_placement
    for axis, value in zip("xyz", placement.translation):
        rows.append((f"tcp_on_last_joint.{axis}", f"{value * 1e3:.9g}", "mm"))
    for axis, value in zip(("roll", "pitch", "yaw"), pin.rpy.matrixToRpy(placement.rotation)):
        rows.append((f"tcp_on_last_joint.{axis}", f"{np.degrees(value):.9g}", "deg"))
    return "\n".join(",".join(r) for r in rows) + "\n"


def dh_csv(model, convention: str) -> tuple[str, str]:
    """(rows, base and tool) of the DH or MDH table as CSV: nominal, as built and the correction
    (as built - nominal), lengths in mm, angles in deg. Raises NoDhForm (one line) where the
    robot's axes admit no such table."""
    import numpy as np
    import pinocchio as pin

    from ..model.dh import dh_table, mdh_table

    build = dh_table if convention == "DH" else mdh_table
    nominal = build(model.robot, model.robot)
    as_built = build(model.geometric_robot(), model.robot)
    names = ["a_mm", "alpha_deg", "d_mm", "theta_deg"] + (["beta_deg"] if convention == "MDH" else [])
    scale = np.array([1e3, 180.0 / np.pi, 1e3, 180.0 / np.pi, 180.0 / np.pi])[:len(names)]
    header = ["joint", "variable"] + names + [f"{n}_as_built" for n in names] + [f"{n}_correction" for n in names]
    lines = [",".join(header)]
    for i, joint in enumerate(nominal.joints):
        before, after = nominal.params[i, :len(names)], as_built.params[i, :len(names)]
        change = after - before
        change[1::2] = np.angle(np.exp(1j * change[1::2]))  # angles wrapped to (-180, 180] deg
        if convention == "MDH":
            change[4] = after[4] - before[4]
        cells = [joint, nominal.variable[i]] + [f"{v:.9g}" for v in np.concatenate([before, after, change]) *
                                                np.tile(scale, 3)]
        lines.append(",".join(cells))
    frames = ["frame,model,x_mm,y_mm,z_mm,roll_deg,pitch_deg,yaw_deg"]
    for label, table in (("nominal", nominal), ("as_built", as_built)):
        for frame, matrix in (("base_to_frame0", table.base), ("last_frame_to_tcp", table.tool)):
            rpy = np.degrees(pin.rpy.matrixToRpy(matrix[:3, :3]))
            frames.append(",".join([frame, label] + [f"{v:.9g}" for v in (*matrix[:3, 3] * 1e3, *rpy)]))
    return "\n".join(lines) + "\n", "\n".join(frames) + "\n"


def compensation_csv(model, targets: str, threshold: float) -> tuple[str, int, int]:
    """(CSV text, solved, total): target joints and their corrected commands [deg, mm]."""
    import numpy as np

    from ..io.measurements import read_measurements
    from ..model.kinematics import tcp_poses
    from ..prediction.compensation import compensate_joints

    robot = model.robot
    mset = read_measurements(targets, robot, require_position=False, repeats_allowed=True)  # as compensate
    context = mset.context
    point = _measured_point_robot(robot, model.tcp_offset())

    class _Model:  # the calibrated robot's error beyond the measured point, at the targets' context
        @staticmethod
        def predict(q, context=None):
            return model.tcp_poses(q, context).position - tcp_poses(point, q).position

    result = compensate_joints(point, _Model(), mset.q, threshold=threshold, context=context)
    scale = robot.display_scale
    header = ([f"target_{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]
              + [f"command_{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]
              + ["model_miss_mm", "target_row", "status"])
    lines = [",".join(header)]
    for i in range(len(mset.q)):
        command = (result.q[i] * scale) if result.converged[i] else [None] * robot.n_joints
        cells = [f"{v:.9g}" for v in mset.q[i] * scale] + ["" if v is None else f"{v:.9g}" for v in command]
        cells += [f"{result.predicted_miss[i] * 1e3:.6g}", str(int(mset.rows[i])),
                  "ok" if result.converged[i] else f"{result.reason[i]}: {result.detail[i]}".replace(",", ";")]
        lines.append(",".join(cells))
    return "\n".join(lines) + "\n", int(result.converged.sum()), len(mset.q)


def _measured_point_robot(robot, offset):
    """The nominal robot whose TCP is moved by the fitted TCP offset (in the TCP frame)."""
    from ..model.errors import ErrorModel

    em = ErrorModel(robot)
    x = em.zeros()
    x[em.tool_slice.start:em.tool_slice.start + 3] = offset
    return em.perturbed_robot(x, name=robot.name)
