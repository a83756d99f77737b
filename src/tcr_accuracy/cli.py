"""Command line: ``tcr-accuracy <command> ...``.

Exit codes: 0 ok, 1 the analysis failed (or an unexpected error), 2 bad input,
130 interrupted. Every failure is one line on stderr naming the command and what
went wrong; ``--debug`` (before or after the command) prints the full traceback
as well. Degrees and millimetres live here and only here: revolute joint values
are read in degrees, prismatic ones in millimetres, and converted to SI before
anything else sees them.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

from . import __version__

EXIT_OK, EXIT_ANALYSIS, EXIT_INPUT = 0, 1, 2


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.stderr.write(f"{self.prog}: error: {message} (see {self.prog} --help)\n")
        sys.exit(EXIT_INPUT)


def add_robot_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robot", default=None, metavar="URDF|NAME",
                        help="URDF file or example-robot-data name (ur3, ur5, ur10, panda, z1, xarm7); "
                             "default: the built-in shield-machine tool-changer")
    parser.add_argument("--tool", default=None, metavar="FRAME",
                        help="TCP frame name (default: 'tool' for the tool-changer, the usual "
                             "flange frame for named robots, the single leaf link of a URDF)")


def seed_value(text: str) -> int:
    """argparse type of ``--seed``: an integer >= 0 (what numpy's SeedSequence accepts)."""
    try:
        seed = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if seed < 0:
        raise argparse.ArgumentTypeError(f"{seed}: seeds are integers >= 0")
    return seed


#: Error distributions ``--preset`` names: the seed's Table 1, Table 2 and Table 4 (joint clearance).
PRESETS = ("table1", "table2", "clearance")


def add_sampler_arguments(parser: argparse.ArgumentParser, *, pose: bool = False) -> None:
    """What an analysis of an error sampler starts from: ``--robot``, ``--tool``, (with pose)
    ``--q``, ``--preset`` or ``--config``, and ``--seed`` (read with :func:`error_sampler`)."""
    add_robot_arguments(parser)
    if pose:
        parser.add_argument("--q", nargs="+", type=float, metavar="VALUE",
                            help="joint values: revolute [deg], prismatic [mm] (default: the working pose)")
    source = parser.add_mutually_exclusive_group()
    source.add_argument("--preset", choices=PRESETS, default=None,
                        help="error distributions: the seed's Table 1, Table 2 or Table 4 (joint clearance); "
                             "default table2")
    source.add_argument("--config", default=None, metavar="FILE",
                        help="TOML or YAML file of error distributions (as for 'montecarlo --config')")
    parser.add_argument("--seed", type=seed_value, default=0, help="random seed (default 0)")


def sampler_from_args(robot, preset: str | None, config: str | None):
    """The error sampler of --preset (default table2) or --config FILE."""
    if config is not None:
        from .budget_file import load_budget_file

        return load_budget_file(config, robot)
    preset = preset or "table2"
    if preset == "clearance":
        from .clearance import ClearanceModel

        return ClearanceModel.from_robot(robot)
    from .errors import seed_budget

    return seed_budget(robot, preset)


def error_sampler(robot, args) -> tuple[object, str]:
    """The error sampler of ``--preset`` or ``--config`` (an ErrorBudget or a ClearanceModel)
    and a label for reports (the preset's name, or ``config FILE``)."""
    sampler = sampler_from_args(robot, args.preset, args.config)
    return sampler, args.preset or ("table2" if args.config is None else f"config {args.config}")


def add_quiet_argument(parser: argparse.ArgumentParser) -> None:
    """``--quiet``: no progress bars and no status lines on stderr (results are still printed)."""
    parser.add_argument("--quiet", action="store_true",
                        help="no progress bars and no status lines on stderr (results still print)")


def status(args, message: str) -> None:
    """A status line (which file was written, ...) on stderr, unless ``--quiet``.

    Results go to stdout; what a run did besides goes here, so that ``--json -`` output
    stays pure JSON and ``--quiet`` leaves only the results.
    """
    if not getattr(args, "quiet", False):
        sys.stderr.write(message.rstrip("\n") + "\n")


def joint_values_si(robot, values, source="--q"):
    """CLI joint values (deg for revolute, mm for prismatic) to SI, validated; None: working pose."""
    import numpy as np

    if values is None:
        return robot.working_pose.copy()
    values = np.asarray(values, dtype=float)
    if values.shape != (robot.n_joints,):
        units = ", ".join(f"{n} [{u}]" for n, u in zip(robot.joint_names, robot.display_units))
        from .exceptions import InputError

        raise InputError(f"{source}: expected {robot.n_joints} joint values ({units}), got {values.size}")
    return robot.check_joint_values(values / robot.display_scale, source=source)


def format_joint_values(robot, q) -> str:
    return ", ".join(f"{n} = {v * s:.6g} {u}" for n, v, s, u in
                     zip(robot.joint_names, q, robot.display_scale, robot.display_units))


# ---------------------------------------------------------------------------------------
# pose
# ---------------------------------------------------------------------------------------
def _pose_parser(sub) -> None:
    p = sub.add_parser(
        "pose", help="TCP pose at given joint values",
        description="Forward kinematics of the TCP frame. Joint values: revolute joints in "
                    "degrees, prismatic joints in millimetres, in URDF joint order. Without --q, "
                    "the robot's working pose (the seed paper's for the tool-changer).",
    )
    add_robot_arguments(p)
    p.add_argument("--q", nargs="+", type=float, metavar="VALUE",
                   help="joint values: revolute [deg], prismatic [mm]")
    p.add_argument("--json", nargs="?", const="-", default=None, metavar="FILE",
                   help="write JSON (SI units, unit-suffixed keys) to FILE, or to stdout without FILE")
    add_quiet_argument(p)
    p.set_defaults(run=_run_pose)


def _run_pose(args) -> int:
    import numpy as np
    import pinocchio as pin

    from .kinematics import euler_zyx, tcp_poses
    from .robot import load_robot

    robot = load_robot(args.robot, args.tool)
    q = joint_values_si(robot, args.q)
    pose = tcp_poses(robot, q)
    position, rotation = pose.position[0], pose.rotation[0]
    rpy = pin.rpy.matrixToRpy(rotation)
    payload = {
        "robot": robot.name,
        "tool_frame": robot.tool_frame,
        "joint_names": robot.joint_names,
        "joint_values_si": q.tolist(),
        "joint_units_si": ["rad" if u == "deg" else "m" for u in robot.display_units],
        "position_m": position.tolist(),
        "rotation_matrix": rotation.tolist(),
        "rpy_rad": rpy.tolist(),
        "euler_zyx_rad": euler_zyx(rotation[None])[0].tolist(),
    }
    if args.json is not None:
        emit_json(payload, args.json)
        if args.json == "-":
            return EXIT_OK
    print(f"{robot.name}: TCP frame '{robot.tool_frame}' at {format_joint_values(robot, q)}")
    print("  position [mm]: x = {:.4f}, y = {:.4f}, z = {:.4f}".format(*(position * 1000)))
    print("  roll, pitch, yaw [deg]: {:.4f}, {:.4f}, {:.4f}".format(*np.degrees(rpy)))
    print("  rotation matrix:")
    for row in rotation:
        print("    [{:+.6f} {:+.6f} {:+.6f}]".format(*row))
    return EXIT_OK


def emit_json(payload: dict, target: str) -> None:
    text = json.dumps(payload, indent=2, allow_nan=False) + "\n"
    if target == "-":
        sys.stdout.write(text)
    else:
        from pathlib import Path

        from .atomic import write_text_atomically

        write_text_atomically(Path(target), text)


# ---------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="tcr-accuracy",
        description="Motion accuracy of serial robots on Pinocchio: kinematics with error "
                    "screws, Monte Carlo accuracy, sim-to-real gap diagnosis, compensation.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("--debug", action="store_true", help=DEBUG_HELP)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    sub.required = True
    for add in COMMANDS + _topic_commands():
        add(sub)
    for command_parser in set(sub.choices.values()):
        # also accepted after the command; SUPPRESS keeps a --debug given before it
        command_parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                    help=DEBUG_HELP)
    return parser


DEBUG_HELP = "on an error, print the full Python traceback as well as the one-line message"


def _topic_commands():
    """Subcommands that live in their own ``cli_<topic>`` modules (each has ``add_parsers``)."""
    import importlib

    return [importlib.import_module(f".{name}", __package__).add_parsers for name in TOPIC_MODULES]


#: Modules holding further subcommands, one per topic; each defines add_parsers(sub).
TOPIC_MODULES: list[str] = [
    "cli_demo",
    "cli_montecarlo",
    "cli_sensitivity",
    "cli_tolerance",
    "cli_trajectory",
    "cli_simulate",
    "cli_view",
    "cli_diagnose",
    "cli_prediction",
]

COMMANDS = [_pose_parser]


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    sys.stderr.write(f"tcr-accuracy: warning: {message}\n")


#: How many main() calls are running (``demo`` runs ``montecarlo`` and ``diagnose`` through
#: main); an unexpected error in an inner one goes up to the outermost, which reports it.
_depth = 0


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code.

    Bad input (:class:`InputError`) is one line and exit code 2, a failed analysis
    (:class:`AnalysisError`) one line and 1, anything else (a bug, an unhandled case, no
    memory left) one line naming the command, the exception's type and message, and 1.
    With ``--debug`` the traceback is printed before that line.
    """
    global _depth

    argv = list(sys.argv[1:] if argv is None else argv)
    # read before parsing too, so that a failure while building the parser is traced as well
    debug = "--debug" in argv
    command = next((a for a in argv if not a.startswith("-")), None)
    _depth += 1
    try:
        return _main(argv, debug, command)
    finally:
        _depth -= 1


def _main(argv: list[str], debug: bool, command: str | None) -> int:
    from .exceptions import AnalysisError, InputError

    name = f"tcr-accuracy {command}" if command else "tcr-accuracy"
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        args.argv = argv  # the command as typed, for reports
        name = f"tcr-accuracy {args.command}"
        debug = debug or getattr(args, "debug", False)  # also an abbreviated --deb
        with warnings.catch_warnings():
            warnings.simplefilter("default", UserWarning)
            warnings.showwarning = _show_warning
            return args.run(args)
    except InputError as exc:
        _report(f"{name}: error: {exc}", debug)
        return EXIT_INPUT
    except AnalysisError as exc:
        _report(f"{name}: analysis failed: {exc}", debug)
        return EXIT_ANALYSIS
    except KeyboardInterrupt:
        _report("tcr-accuracy: interrupted", debug)
        return 130
    except BrokenPipeError:  # output piped into `head` and closed: not an error of ours
        import os

        try:  # so that Python's own flush of stdout at exit does not fail again
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):  # stdout is no file (captured, replaced)
            pass
        return EXIT_OK
    except MemoryError as exc:
        _report(f"{name}: out of memory ({_describe(exc)}); try fewer samples, poses or measurements"
                f"{'' if debug else ', or rerun with --debug for the traceback'}", debug)
        return EXIT_ANALYSIS
    except Exception as exc:
        if _depth > 1:  # an inner main (demo's steps): the outermost one reports it
            raise
        _report(f"{name}: unexpected error: {_describe(exc)}"
                f"{'' if debug else ' (rerun with --debug for the traceback)'}", debug)
        return EXIT_ANALYSIS


def _describe(exc: BaseException) -> str:
    """``Type: message`` on one line (a message over several lines is joined with spaces)."""
    message = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {message}" if message else type(exc).__name__


def _report(line: str, debug: bool) -> None:
    """One line on stderr; with --debug, the traceback of the exception being handled first."""
    if debug:
        import traceback

        traceback.print_exc(file=sys.stderr)
    sys.stderr.write(line + "\n")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
