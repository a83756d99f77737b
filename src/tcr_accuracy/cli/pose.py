"""``tcr-accuracy pose``: the TCP pose at given joint values."""

from __future__ import annotations

from .common import (EXIT_OK, add_quiet_argument, add_robot_arguments, emit_json, format_joint_values, joint_value,
                     joint_values_si, output_file)


# ---------------------------------------------------------------------------------------
def add_parsers(sub) -> None:
    p = sub.add_parser(
        "pose", help="TCP pose at given joint values",
        description="Forward kinematics of the TCP frame. Joint values: revolute joints in "
                    "degrees, prismatic joints in millimetres, in URDF joint order. Without --q, "
                    "the robot's working pose (the seed paper's for the tool-changer).",
    )
    add_robot_arguments(p)
    p.add_argument("--q", nargs="+", type=joint_value, metavar="VALUE",
                   help="joint values: revolute [deg], prismatic [mm]")
    p.add_argument("--json", nargs="?", const="-", default=None, type=output_file, metavar="FILE",
                   help="write JSON (SI units, unit-suffixed keys) to FILE, or to stdout without FILE")
    add_quiet_argument(p)
    p.set_defaults(run=_run_pose)


def _run_pose(args) -> int:
    import numpy as np
    import pinocchio as pin

    from ..model.kinematics import euler_zyx, tcp_poses
    from .common import robot_from_args

    robot = robot_from_args(args)
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
