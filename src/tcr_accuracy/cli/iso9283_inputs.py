"""What ``iso9283 plan`` and ``iso9283 evaluate`` (pose and path tests) read from their arguments:
the test conditions, the robot and where the test may go, a diagnosis' model. Shared by
:mod:`tcr_accuracy.cli.iso9283` and :mod:`tcr_accuracy.cli.iso9283_path`; imports nothing heavy
at the top (the parser uses :func:`condition`).
"""

from __future__ import annotations

import argparse

from .common import number


def condition(text: str) -> tuple:
    """argparse type of a test condition ``LOAD/SPEED`` [% of the rated load, % of the rated speed]."""
    load, _, speed = text.partition("/")
    parts = ((number(low=0, high=100, unit="%"), load), (number(low=0, low_open=True, high=100, unit="%"), speed))
    try:
        return tuple(convert(value) for convert, value in parts)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"{text!r}: want LOAD/SPEED, a load of 0-100 % and a speed of (0, 100] % "
                                         "of the rated ones, e.g. 100/50") from None


def plan_inputs(args):
    """(robot, home, workspace, conditions, condition words) from the plan's arguments."""
    from ..exceptions import InputError
    from ..iso9283.plan import STANDARD_CONDITIONS, plan_conditions
    from ..iso9283.reach import Workspace
    from .common import robot_from_args
    from .common import joint_values_si, reach_values

    if (args.cube_centre_mm is None) != (args.cube_size_mm is None):
        raise InputError("--cube-centre-mm and --cube-size-mm: give both, or neither to search the largest cube")
    robot = robot_from_args(args)
    home = None if args.home is None else joint_values_si(robot, args.home, "--home")
    box, _ = reach_values(args)
    workspace = Workspace(floor=args.floor_mm * 1e-3, box=None if box is None else box.T)
    if box is not None and box[2, 1] <= workspace.floor:
        raise InputError(f"--box and --floor-mm {args.floor_mm:g}: the box lies below the floor")
    conditions, said = plan_conditions(robot, tuple(args.conditions or STANDARD_CONDITIONS), args.rated_load_kg)
    return robot, home, workspace, conditions, said


def read_model(robot, path: str):
    """The effects and parameter vectors of the ``diagnose --json`` result at ``path`` (``--model``),
    validated on read (:mod:`tcr_accuracy.results.files`) and held to each effect's physics."""
    from ..iso9283.evaluate import diagnosis_model
    from ..results.types import read_result

    payload = read_result(path, "diagnosis", robot=robot, hint="give the JSON that 'diagnose --json FILE' wrote"
                          ).to_dict()  # checked whole, its robot and physics too
    return diagnosis_model(robot, payload, path)


def tool_rotation(args):
    """(3, 3) the TCP orientation of ``--tool-rpy`` [deg], or None."""
    import numpy as np
    import pinocchio as pin

    return None if args.tool_rpy is None else pin.rpy.rpyToMatrix(*np.radians(args.tool_rpy))
