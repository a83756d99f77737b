"""What every command of the command line shares: argument helpers, units at the edge, JSON.

Degrees and millimetres live in the CLI and only there: revolute joint values are read in
degrees, prismatic ones in millimetres (:func:`joint_values_si`), and converted to SI
before anything else sees them.
"""

from __future__ import annotations

import argparse
import json
import sys

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
    """The error sampler of --preset (default: ``model.errors.default_preset``) or --config FILE."""
    if config is not None:
        from ..io.budget_file import load_budget_file

        return load_budget_file(config, robot)
    from ..model.errors import default_preset, seed_budget

    preset = preset or default_preset(robot)
    if preset == "clearance":
        from ..model.clearance import ClearanceModel

        return ClearanceModel.from_robot(robot)
    return seed_budget(robot, preset)


def error_sampler(robot, args) -> tuple[object, str]:
    """The error sampler of ``--preset`` or ``--config`` (an ErrorBudget or a ClearanceModel)
    and a label for reports (the preset's name, or ``config FILE``)."""
    sampler = sampler_from_args(robot, args.preset, args.config)
    from ..model.errors import default_preset

    return sampler, args.preset or (default_preset(robot) if args.config is None else f"config {args.config}")


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

        from ..atomic import write_text_atomically

        write_text_atomically(Path(target), text)
