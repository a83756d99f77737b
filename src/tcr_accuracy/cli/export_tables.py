"""The CSV tables ``tcr-accuracy export`` writes (mm and deg, labelled in every column name).

Table numbers are written to the last digit (the shortest text that reads back as the same
double): a plain DH table of a calibrated UR puts d hundreds of metres away, and the table must
still give the TCP to 1e-9 m.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin



def exact(value: float) -> str:
    """The shortest decimal text that reads back as the same double."""
    return repr(float(value))


def _rows(lines: list[list[str]]) -> str:
    return "\n".join(",".join(cells) for cells in lines) + "\n"


def offsets_and_tcp_csv(export) -> str:
    """``quantity,value,unit`` rows: each joint's fitted zero offset (the diagnosis'), the fitted TCP
    offset in the TCP frame, and the measured point on the TCP frame as the calibration URDF has it
    (x, y, z, roll, pitch, yaw)."""
    model = export.model
    robot = model.robot
    rows = [["quantity", "value", "unit"]]
    for name, value, unit, scale in zip(robot.joint_names, model.joint_offsets(), robot.display_units,
                                        robot.display_scale):
        rows.append([f"joint_offset.{name}", f"{value * scale:.9g}", unit])
    for axis, value in zip("xyz", model.tcp_offset()):
        rows.append([f"tcp_offset_in_tcp_frame.{axis}", f"{value * 1e3:.9g}", "mm"])
    offset = export.measured_offset
    for axis, value in zip("xyz", offset[:3, 3]):
        rows.append([f"measured_point_on_{robot.tool_frame}.{axis}", f"{value * 1e3:.9g}", "mm"])
    for axis, value in zip(("roll", "pitch", "yaw"), pin.rpy.matrixToRpy(offset[:3, :3])):
        rows.append([f"measured_point_on_{robot.tool_frame}.{axis}", f"{np.degrees(value):.9g}", "deg"])
    return _rows(rows)


def table_csv(table) -> tuple[str, str]:
    """(rows, base and tool) of a :class:`~tcr_accuracy.asbuilt.export.TableForm` as CSV: nominal,
    as built and the correction (as built - nominal, angles wrapped to (-180, 180] deg), lengths in
    mm, angles in deg."""
    nominal, as_built = table.nominal, table.as_built
    names = ["a_mm", "alpha_deg", "d_mm", "theta_deg", "beta_deg"]
    scale = np.array([1e3, 180.0 / np.pi, 1e3, 180.0 / np.pi, 180.0 / np.pi])
    header = ["joint", "variable"] + names + [f"{n}_as_built" for n in names] + [f"{n}_correction" for n in names]
    lines = [header]
    for i, joint in enumerate(nominal.joints):
        before, after = nominal.params[i], as_built.params[i]
        change = after - before
        change[[1, 3, 4]] = np.angle(np.exp(1j * change[[1, 3, 4]]))
        cells = [joint, nominal.variable[i]] + [exact(v) for v in
                                                np.concatenate([before, after, change]) * np.tile(scale, 3)]
        lines.append(cells)
    frames = [["frame", "model", "x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"]]
    for label, t in (("nominal", nominal), ("as_built", as_built)):
        for frame, matrix in (("base_to_frame0", t.base), ("last_frame_to_tcp", t.tool)):
            rpy = np.degrees(pin.rpy.matrixToRpy(matrix[:3, :3]))
            frames.append([frame, label] + [exact(v) for v in (*matrix[:3, 3] * 1e3, *rpy)])
    return _rows(lines), _rows(frames)


def compensation_csv(filtered, robot, rows) -> str:
    """One line per target: the target (joints, or the Cartesian target and the controller's joints
    for it), the corrected command (joints, and for Cartesian targets the pose to send), the full
    model's predicted error before and after [mm], the target's row in its file and its status."""
    joints = [f"{n}_{u}" for n, u in zip(robot.joint_names, robot.display_units)]
    scale = robot.display_scale
    header = []
    if filtered.cartesian:
        header += ["target_x_mm", "target_y_mm", "target_z_mm"]
    header += [f"target_{c}" for c in joints] + [f"command_{c}" for c in joints]
    if filtered.cartesian:
        header += ["command_x_mm", "command_y_mm", "command_z_mm", "command_qw", "command_qx", "command_qy",
                   "command_qz"]
    header += ["predicted_error_before_mm", "predicted_error_after_mm", "target_row", "status"]
    lines = [header]
    for i in range(len(filtered.target_q)):
        cells = []
        solved = bool(filtered.solved[i])
        if filtered.cartesian:
            cells += [f"{v * 1e3:.9g}" for v in filtered.target_position[i]]
        cells += [f"{v:.9g}" for v in filtered.target_q[i] * scale]
        cells += [f"{v:.9g}" if solved else "" for v in filtered.command_q[i] * scale]
        if filtered.cartesian:
            cells += [f"{v * 1e3:.9g}" if solved else "" for v in filtered.command_position[i]]
            quat = pin.Quaternion(filtered.command_rotation[i]).coeffs()  # x, y, z, w
            cells += [f"{v:.12g}" if solved else "" for v in (quat[3], quat[0], quat[1], quat[2])]
        cells += [f"{filtered.error_before[i] * 1e3:.6g}", f"{filtered.error_after[i] * 1e3:.6g}" if solved else "",
                  str(int(rows[i])), str(filtered.status[i]).replace(",", ";")]
        lines.append(cells)
    return _rows(lines)
