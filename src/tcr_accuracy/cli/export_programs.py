"""``export --program FILE ...``: robot programs filtered through the calibrated model, written under
``--to DIR`` with their own names (:mod:`tcr_accuracy.asbuilt.programs`).

A KRL ``.src`` and the ``.dat`` of the same name are one program; every other file is one. Each is read
(and refused, in one line naming the file, line and column, when it does not parse) before any heavy
work; the header comment written into each says what was done, when and with which model.
"""

from __future__ import annotations

from pathlib import Path

#: The compensation's stop, as a share of the diagnosis' noise floor, when --threshold-mm is not given:
#: the filtered command lands on the target far inside what the tracker can tell apart.
NOISE_FLOOR_SHARE = 1e-3
#: The default stop [mm] without a noise floor in the diagnosis (as --targets).
DEFAULT_THRESHOLD_MM = 1e-4
#: The files export writes whatever the robot (its tables end in dh.csv and _base_tool.csv): a program may not
#: take one's name.
EXPORT_FILES = ("as_built.urdf", "as_built.yaml", "ur_calibration.yaml", "joint_offsets_tcp.csv", "accuracy.json",
                "accuracy.png", "compensation.csv")


def read_programs(args, robot) -> list[dict]:
    """The programs of ``--program``: one {file name: text} per program, each parsed once to refuse a file that
    does not parse (or names another robot's joints) before the export's work."""
    from ..asbuilt.programs import check_language_robot, parse_program_files, program_language
    from ..exceptions import InputError
    from ..input_files import SIZE_LIMITS, read_input_text

    names = [Path(p).name for p in args.program]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"--program: two files named {twice[0]}; each is written under --to with its own name")
    groups: dict[tuple, dict] = {}
    for path in args.program:
        language = program_language(path)
        key = (language, Path(path).stem.lower()) if language == "KRL" else (language, path)
        groups.setdefault(key, {})[Path(path).name] = read_input_text(path, "robot program",
                                                                       limit=SIZE_LIMITS["table"])
    programs = list(groups.values())
    for name in names:
        if name.lower() in EXPORT_FILES or name.lower().endswith(("dh.csv", "_base_tool.csv")):
            raise InputError(f"--program {name}: export writes a file of that name under --to; rename the program")
    for files in programs:
        check_language_robot(parse_program_files(files, robot), robot)
    return programs


def threshold_m(args, data: dict) -> float:
    """The compensation's stop [m]: --threshold-mm, else a thousandth of the diagnosis' noise floor."""
    if args.threshold_mm is not None:
        return args.threshold_mm * 1e-3
    floor = data.get("noise_floor_mm")
    return (NOISE_FLOOR_SHARE * floor if isinstance(floor, (int, float)) and floor > 0 else DEFAULT_THRESHOLD_MM) * 1e-3


def filtered_programs(args, model, data: dict, programs: list[dict], threshold: float) -> tuple[dict, list[str]]:
    """({file name: filtered text}, the printed lines) of every program."""
    from datetime import datetime, timezone

    from ..asbuilt.export import MODEL_FILE
    from ..asbuilt.programs import filter_program

    robot = model.robot
    start = robot.kinematics
    nominal = (f"the factory kinematics of {start['file']}" if start else "the URDF's kinematics")
    header = [f"Filtered by tcr-accuracy export on {datetime.now(timezone.utc).date().isoformat()} (UTC) through the "
              f"calibrated model of {Path(args.diagnosis).name} ({robot.name}, nominal: {nominal}; effects "
              f"{', '.join(model.parameters)}; the whole model is {MODEL_FILE} beside this file).",
              "Each motion target is the command that puts the TCP on the programmed target as the full model "
              f"predicts it (to {threshold * 1e3:.3g} mm, load {args.payload_kg or 0.0:g} kg); nothing else changed."]
    out, lines = {}, []
    for files in programs:
        result = filter_program(model, files, threshold=threshold, payload_kg=args.payload_kg or 0.0, header=header)
        out.update(result.texts)
        done = [t for t in result.targets if t.status == "filtered"]
        before = [t.error_before_m for t in done if t.error_before_m is not None]
        after = [t.error_after_m for t in done if t.error_after_m is not None]
        figures = (f" (the full model's miss: mean {1e3 * sum(before) / len(before):.4f} mm as written, "
                   f"{1e3 * max(after):.2g} mm at most filtered)") if done else ""
        lines.append(f"  {', '.join(files)} ({result.language}): {len(done)} of {len(result.targets)} motion targets "
                     f"filtered{figures}")
        for target in result.not_filtered:
            lines.append(f"    not filtered: {target.label}: {target.reason}")
        for note in dict.fromkeys(t.tcp for t in result.targets if t.measured_point):
            lines.append(f"    the measured point as the TCP: {note}")
        for item in result.unknown:
            lines.append(f"    kept as written, not understood: {item}")
    return out, lines
