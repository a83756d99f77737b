"""What every command of the command line shares: argument helpers, units at the edge, JSON.

Degrees and millimetres live in the CLI and only there: revolute joint values are read in
degrees, prismatic ones in millimetres (:func:`joint_values_si`), and converted to SI
before anything else sees them.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys

from .output_paths import (as_built_file, effects_side_file, output_file, output_file_only, output_folder,  # noqa: F401
                           shown as _shown)

EXIT_OK, EXIT_ANALYSIS, EXIT_INPUT = 0, 1, 2


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2, and a value that starts with a minus
    sign is a value, not an option, in every form a number takes here (``-1e-3``, ``-10/50``: argparse
    reads only ``-1`` and ``-1.5`` so)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_VALUE


    def error(self, message: str) -> None:  # type: ignore[override]
        # "argument --tol: 0: want ..." (an option's type refusing a value) -> "--tol 0: want ..."
        match = _TYPE_REFUSAL.fullmatch(message)
        if match:
            message = f"{match['option']} {match['rest']}"
        message = " ".join(message.split())[:500]
        sys.stderr.write(f"{self.prog}: error: {message} (see {self.prog} --help)\n")
        sys.exit(EXIT_INPUT)


#: A value starting with a minus sign: a number (with an exponent) or a range of them (``-10/50``).
_NEGATIVE_VALUE = re.compile(r"^-(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?:/[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)?$")

#: What the argparse types of this module say after the value ("--x VALUE: <one of these>...").
_REFUSALS = ("want", "not a number", "non-finite", "the folder", "is a folder", "exists and is not a folder",
             "not writable", "not a regular file", "its side file", "an empty folder name")
_TYPE_REFUSAL = re.compile(r"argument (?P<option>--[\w-]+)(?:/[\w-]+)*: "
                           rf"(?P<rest>.+?: (?:{'|'.join(map(re.escape, _REFUSALS))}).*)", re.DOTALL)


def effect_names(text: str | None) -> list[str] | None:
    """The effects named by ``--effects a,b,...`` (None when not given), each checked against the
    vocabulary: one line naming the unknown ones. ``--effects ''`` names none, as ``,`` does: refused."""
    if text is None:
        return None
    from ..effects import vocabulary
    from ..exceptions import InputError

    effects = [e.strip() for e in text.split(",") if e.strip()]
    if not effects:  # ',' read as no effect at all: frames only, and 'structure remains: no' of nothing
        raise InputError(f"--effects {text!r}: names no effect (vocabulary: {', '.join(vocabulary())})")
    unknown = [e for e in effects if e not in vocabulary()]
    if unknown:
        raise InputError(f"--effects: unknown {', '.join(unknown)} (vocabulary: {', '.join(vocabulary())})")
    return effects


def add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robot", default=None, metavar="URDF|NAME",
                        help="URDF file or example-robot-data name (ur3, ur5, ur10, panda, z1, xarm7, kinova); "
                             "default: the built-in shield-machine tool-changer")
    parser.add_argument("--tool", default=None, metavar="FRAME",
                        help="TCP frame name (default: 'tool' for the tool-changer, the usual "
                             "flange frame for named robots, the single leaf link of a URDF)")
    parser.add_argument("--package-dir", action="append", default=None, type=package_folder, metavar="DIR",
                        help="where the URDF's package://NAME/... meshes are: a ROS package folder (with "
                             "package.xml), or a folder holding DIR/NAME or packages further below; "
                             "repeatable; searched before the folders of ROS_PACKAGE_PATH")
    parser.add_argument("--kinematics", default=None, metavar="FILE",
                        help="the robot's own (factory) kinematics as the nominal robot: a UR ROS 2 driver "
                             "calibration YAML (ur_calibration's, or the ur_calibration.yaml export writes) or a "
                             "DH/MDH table CSV as export writes dh.csv/mdh.csv (its *_base_tool.csv beside it); "
                             "what follows is relative to it (docs/programs.md)")


def robot_from_args(args, tool: str | None = None):
    """The nominal robot of ``--robot``, ``--tool`` (or ``tool``) and ``--package-dir``, with the
    kinematics of ``--kinematics`` where given."""
    from ..model.robot import load_robot

    robot = load_robot(args.robot, args.tool if tool is None else tool)
    if getattr(args, "kinematics", None) is not None:
        from ..asbuilt.factory_kinematics import with_factory_kinematics

        robot = with_factory_kinematics(robot, args.kinematics)
    return robot


def package_folder(text: str) -> str:
    """argparse type of ``--package-dir``: an existing folder (refused now, before any work)."""
    import os

    if not os.path.exists(text):
        raise argparse.ArgumentTypeError(f"{_shown(text)}: the folder does not exist")
    if not os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{_shown(text)}: exists and is not a folder")
    return text


def number(*, low: float | None = None, high: float | None = None, low_open: bool = False,
           high_open: bool = False, unit: str = ""):
    """argparse type of a real-valued option: a finite decimal number within [low, high].

    ``low_open``/``high_open`` exclude the bound itself (``low=0, low_open=True``: > 0). The
    text is read by :func:`tcr_accuracy.units.parse_number` (no ``nan``, ``inf``, ``1_5`` or
    full-width digits), so a bad value is argparse's one line naming the option.
    """
    unit = f" {unit}" if unit else ""
    parts = ([f"{'>' if low_open else '>='} {low:g}{unit}"] if low is not None else []) + \
            ([f"{'<' if high_open else '<='} {high:g}{unit}"] if high is not None else [])
    wanted = "a number" + (" " + " and ".join(parts) if parts else "")

    def convert(text: str) -> float:
        from ..units import parse_number

        try:
            value = parse_number(text, finite=False)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{_shown(text)}: not a number (want {wanted})") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{_shown(text)}: non-finite (want {wanted})")
        if (low is not None and (value < low or (low_open and value == low))) or \
                (high is not None and (value > high or (high_open and value == high))):
            raise argparse.ArgumentTypeError(f"{_shown(text)}: want {wanted}")
        return value

    convert.__name__ = "number"
    return convert


def integer(*, low: int | None = None, high: int | None = None, what: str = ""):
    """argparse type of an integer option within [low, high] (ASCII digits only; see :func:`number`)."""
    parts = ([f">= {low}"] if low is not None else []) + ([f"<= {high}"] if high is not None else [])
    wanted = (what or "an integer") + (" " + " and ".join(parts) if parts else "")

    def convert(text: str) -> int:
        from ..units import parse_integer

        try:
            value = parse_integer(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{_shown(text)}: not a number (want {wanted})") from None
        if (low is not None and value < low) or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"{_shown(text)}: want {wanted}")
        return value

    convert.__name__ = "integer"
    convert.bounds = (low, high)  # read by the tests that try every count option at its largest
    return convert


#: argparse type of ``--seed``: an integer that numpy's SeedSequence accepts.
seed_value = integer(low=0, high=2**32 - 1, what="a seed, an integer")

#: Most samples, poses or iterations any count option takes before the memory budget is even
#: asked (a bound on the number itself, so that no estimate overflows).
MAX_COUNT = 10**12

#: The largest length [mm] an option takes (1 km): beyond it a value is a typo, not a robot.
MAX_MM = 1e6

#: argparse type of an instrument's noise (``--noise-mm`` of diagnose and plan-poses), std per axis:
#: 1 nm to 1 m. Below, no tracker resolves it and its square underflows the statistics' divisions;
#: above, every parameter drowns in it and the fit's condition number is no number.
noise_mm_value = number(low=1e-6, high=1e3, unit="mm")

#: argparse type of joint values on the command line: finite numbers (deg or mm; the robot's
#: limits are checked later, by :func:`joint_values_si`).
joint_value = number(low=-1e9, high=1e9)


# ---------------------------------------------------------------------------------------
# Memory: an estimate before large work, refused above a budget
# ---------------------------------------------------------------------------------------
#: The memory [GB] a run may plan for unless ``--max-memory-gb`` says otherwise.
DEFAULT_MEMORY_GB = 4.0


def add_memory_argument(parser: argparse.ArgumentParser) -> None:
    """``--max-memory-gb``: the budget :func:`check_memory` holds an estimate to."""
    parser.add_argument("--max-memory-gb", type=number(low=0, low_open=True, high=1e6, unit="GB"), default=None,
                        metavar="GB", help=f"refuse work estimated to need more memory than this "
                                           f"(default {DEFAULT_MEMORY_GB:g} GB)")


def check_memory(args, what: str, n_bytes: float, hint: str = "make it smaller") -> None:
    """Refuse, in one line, work whose memory estimate ``n_bytes`` exceeds the budget
    (``--max-memory-gb``, default :data:`DEFAULT_MEMORY_GB`), before it starts; ``hint``
    says what to do instead."""
    budget = getattr(args, "max_memory_gb", None) or DEFAULT_MEMORY_GB
    if n_bytes > budget * 1e9:
        from ..exceptions import InputError

        raise InputError(f"{what} needs about {n_bytes / 1e9:.3g} GB of memory, more than the {budget:g} GB "
                         f"allowed; {hint}, or allow more with --max-memory-gb")


def sample_bytes(robot) -> float:
    """Working memory [bytes] one error sample or pose takes while a batch is evaluated
    (error vector, joint placements and Jacobian columns, a few copies): a rough, generous
    figure for :func:`check_memory`."""
    n = robot.n_joints
    return 8.0 * 4 * (7 * (n + 2) + 12 * n + 64)


def check_csv_memory(args, path, what: str, row_bytes: float, fixed_bytes=lambda rows: 0.0,
                     hint: str = "use fewer rows") -> int:
    """Count the rows and cells of a CSV (without reading it into memory) and refuse it with
    :func:`check_memory` when reading it (about 12 bytes per byte of text, :data:`CELL_BYTES`
    per cell, ``row_bytes`` per row) and ``fixed_bytes(rows)`` would exceed the budget; returns
    the row count (0 when the file is missing or cannot be opened: its reader says why). A pipe,
    a device or a folder is refused here, in one line, before anything opens it."""
    import os

    from ..input_files import SIZE_LIMITS, open_input

    if not os.path.lexists(path):
        return 0
    fd, st = open_input(path, "measurement file", limit=SIZE_LIMITS["table"])
    size, rows, cells = st.st_size, 0, 0
    try:
        with os.fdopen(fd, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                rows += block.count(b"\n")
                cells += block.count(b",") + block.count(b";") + block.count(b"\t")  # any reader's delimiter
    except OSError:
        return 0
    shape = f"{rows} rows" if cells <= 100 * max(rows, 1) else f"{rows} rows, {cells + rows} cells"  # cells when many
    check_memory(args, f"{what} {path} ({shape})",
                 12.0 * size + (cells + rows) * CELL_BYTES + rows * row_bytes + fixed_bytes(rows), hint)
    return rows


#: Memory [bytes] a cell of a CSV takes beyond its text once split: its slot in the row's list,
#: over-allocated as the list grows (one-character cells are shared strings, so their text costs
#: nothing more: a 320 MB file of one such row, 160 million cells, took 3.6 GB before it failed).
CELL_BYTES = 16.0


#: Error distributions ``--preset`` names: the seed's Table 1, Table 2 and Table 4 (joint clearance).
PRESETS = ("table1", "table2", "clearance")


def add_sampler_arguments(parser: argparse.ArgumentParser, *, pose: bool = False) -> None:
    """What an analysis of an error sampler starts from: ``--robot``, ``--tool``, (with pose)
    ``--q``, ``--preset`` or ``--config``, and ``--seed`` (read with :func:`error_sampler`)."""
    add_robot_arguments(parser)
    if pose:
        parser.add_argument("--q", nargs="+", type=joint_value, metavar="VALUE",
                            help="joint values: revolute [deg], prismatic [mm] (default: the working pose)")
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--preset", choices=PRESETS, default=None,
                        help="error distributions: the seed's Table 1, Table 2 or Table 4 (joint clearance); "
                             "default table2")
    source.add_argument("--config", default=None, metavar="FILE",
                        help="TOML or YAML file of error distributions (as for 'montecarlo --config')")
    parser.add_argument("--seed", type=seed_value, default=0, help="random seed (default 0)")


def sampler_from_args(robot, preset: str | None, config: str | None):
    """The error sampler of --preset (default: ``model.errors.default_preset``) or --config FILE."""
    if config is not None:
        from ..io.budget_file import load_budget_file

        return load_budget_file(config, robot)
    from ..model.errors import default_preset, seed_budget

    preset = preset or default_preset(robot)
    if preset == "clearance":
        from ..model.clearance import ClearanceModel

        return ClearanceModel.from_robot(robot)
    from ..exceptions import InputError

    try:
        return seed_budget(robot, preset)
    except InputError as exc:  # a preset that does not fit the robot: the budget file is the other way
        if exc.parameter != "preset" or exc.value not in PRESETS:
            raise
        raise InputError(f"{exc} or a --config file", parameter=exc.parameter, value=exc.value) from None


def error_sampler(robot, args) -> tuple[object, str]:
    """The error sampler of ``--preset`` or ``--config`` (an ErrorBudget or a ClearanceModel)
    and a label for reports (the preset's name, or ``config FILE``)."""
    sampler = sampler_from_args(robot, args.preset, args.config)
    from ..model.errors import default_preset

    return sampler, args.preset or (default_preset(robot) if args.config is None else f"config {args.config}")


def add_reach_arguments(parser: argparse.ArgumentParser, poses: str) -> None:
    """``--box`` and ``--tracker-mm``: the task box the TCP of ``poses`` must lie in and the tracker
    that must see it [mm, base frame] (:mod:`tcr_accuracy.analysis.reachable`); read by :func:`reach_values`."""
    parser.add_argument("--box", nargs=6, type=number(low=-MAX_MM, high=MAX_MM, unit="mm"), default=None,
                        metavar=("XMIN", "XMAX", "YMIN", "YMAX", "ZMIN", "ZMAX"),
                        help=f"task box [mm], in the robot's base frame: keep only {poses} whose TCP lies inside")
    parser.add_argument("--tracker-mm", nargs=3, type=number(low=-MAX_MM, high=MAX_MM, unit="mm"), default=None,
                        metavar=("X", "Y", "Z"),
                        help=f"the tracker's position [mm] in the base frame: keep only {poses} whose TCP it sees "
                             "(no collision body on the line; needs the URDF's collision geometry)")


def reach_values(args) -> tuple:
    """(box (3, 2) [m] or None, tracker (3,) [m] or None) from ``--box`` and ``--tracker-mm``.

    Raises
    ------
    InputError
        A box whose minimum is not below its maximum on some axis.
    """
    import numpy as np

    from ..exceptions import InputError

    box = None if args.box is None else np.asarray(args.box, dtype=float).reshape(3, 2) * 1e-3
    if box is not None and not (box[:, 0] < box[:, 1]).all():
        raise InputError(f"--box {' '.join(f'{v:g}' for v in args.box)}: give XMIN XMAX YMIN YMAX ZMIN ZMAX "
                         "[mm] with each min below its max")
    tracker = None if args.tracker_mm is None else np.asarray(args.tracker_mm, dtype=float) * 1e-3
    return box, tracker


def add_quiet_argument(parser: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress bars and no status lines on stderr (results are still printed)."""
    parser.add_argument("--quiet", action="store_true",
                        help="no progress bars and no status lines on stderr (results still print)")


def status(args, message: str) -> None:
    """A status line (which file was written, ...) on stderr, unless ``--quiet``.

    Results go to stdout; what a run did besides goes here, so that ``--json -`` output
    stays pure JSON and ``--quiet`` leaves only the results. Shown once the run's files are
    written, not at all if they are not.
    """
    if not getattr(args, "quiet", False):
        from .staging import hold_message

        hold_message(sys.stderr, message.rstrip("\n") + "\n", "status")  # after the files are written


def joint_values_si(robot, values, source="--q"):
    """CLI joint values (deg for revolute, mm for prismatic) to SI, validated; None: working pose."""
    import numpy as np

    if values is None:
        return robot.working_pose.copy()
    values = np.asarray(values, dtype=float)
    if values.shape != (robot.n_joints,):
        units = ", ".join(f"{n} [{u}]" for n, u in zip(robot.joint_names, robot.display_units))
        from ..exceptions import InputError

        raise InputError(f"{source}: expected {robot.n_joints} joint values ({units}), got {values.size}")
    return robot.check_joint_values(values / robot.display_scale, source=source)


def format_joint_values(robot, q) -> str:
    return ", ".join(f"{n} = {v * s:.6g} {u}" for n, v, s, u in
                     zip(robot.joint_names, q, robot.display_scale, robot.display_units))


# ---------------------------------------------------------------------------------------
# pose
def emit_json(payload: dict, target: str) -> None:
    text = json.dumps(payload, indent=2, allow_nan=False) + "\n"
    if target == "-":
        sys.stdout.write(text)
    else:
        from pathlib import Path

        from .staging import write_text

        write_text(Path(target), text)
