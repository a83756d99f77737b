"""Cartesian targets for the compensation filter: where the measured point should go.

A CSV with one target per row, in the robot's base frame:

* ``x_mm, y_mm, z_mm`` (or ``_m``): the target position of the measured point;
* optional ``qw, qx, qy, qz``: the TCP frame's orientation there (unit quaternion);
* optional seed joints ``seed_<joint>_deg`` (or ``_rad``, ``_mm``, ``_m``; every joint of the chain
  or none): where the controller's inverse kinematics starts, which picks the arm's branch;
* optional ``payload_kg``: the load carried at that target.

A file whose header names the chain's joints (the measurement format) holds joint targets and is
read by :func:`~tcr_accuracy.io.measurements.read_measurements` instead (:func:`is_cartesian`).
Every message names the file, row and column at fault.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import InputError
from ..input_files import csv_cells
from ..model.context import MeasurementContext
from ..model.robot import RobotModel
from ..units import JOINT_COLUMN_UNITS, POSITION_UNITS, parse_number
from .measurements import QUATERNION_TOLERANCE, read_user_text

#: Largest target position [m] and payload [kg].
MAX_POSITION_M = 1e3
MAX_PAYLOAD_KG = 1e6


@dataclass(frozen=True)
class PoseTargets:
    """positions (N, 3) [m]; rotations (N, 3, 3) or None; q_seed (N, n_joints) or None [rad, m];
    context (payload per row); rows (N,) the file's line numbers."""

    positions: np.ndarray
    rotations: np.ndarray | None
    q_seed: np.ndarray | None
    context: MeasurementContext
    rows: np.ndarray


def _lines(path) -> list[tuple[int, str]]:
    text = read_user_text(Path(path), "targets file")
    return [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip() and not line.startswith("#")]


def is_cartesian(path, robot: RobotModel) -> bool:
    """Whether a targets file holds Cartesian targets: position columns and no joint column of the
    chain (joint targets may carry the positions they were measured at)."""
    lines = _lines(path)
    if not lines:
        raise InputError(f"{path}: empty targets file (no header row)")
    header = {h.strip() for h in csv_cells(lines[0][1], path, lines[0][0])}
    joints = {f"{n}_{u}" for n, k in zip(robot.joint_names, robot.joint_kinds) for u in JOINT_COLUMN_UNITS[k]}
    return any(f"x_{unit}" in header for unit in POSITION_UNITS) and not header & joints


def read_pose_targets(path, robot: RobotModel) -> PoseTargets:
    """The Cartesian targets of a CSV file (see the module docstring)."""
    lines = _lines(path)
    header_line, header_text = lines[0]
    header = [h.strip() for h in csv_cells(header_text, path, header_line)]
    unit = next((u for u in POSITION_UNITS if f"x_{u}" in header), None)
    position_columns = [f"{a}_{unit}" for a in "xyz"]
    for c in position_columns:
        if c not in header:
            raise InputError(f"{path}: row {header_line}: column {c} is missing (targets need x, y, z)")
    joint_columns = {}
    for name, kind in zip(robot.joint_names, robot.joint_kinds):
        found = [f"seed_{name}_{u}" for u in JOINT_COLUMN_UNITS[kind] if f"seed_{name}_{u}" in header]
        if found:
            joint_columns[name] = found[0]
    if joint_columns and len(joint_columns) != robot.n_joints:
        missing = next(n for n in robot.joint_names if n not in joint_columns)
        raise InputError(f"{path}: row {header_line}: column seed_{missing}_... is missing (seed joints need "
                         "every joint of the chain, or none)")
    quaternion = [c for c in ("qw", "qx", "qy", "qz") if c in header]
    if quaternion and len(quaternion) != 4:
        raise InputError(f"{path}: row {header_line}: an orientation needs all of qw, qx, qy, qz")
    known = set(position_columns) | set(joint_columns.values()) | set(quaternion) | {"payload_kg"}
    for c in header:
        if c not in known:
            raise InputError(f"{path}: row {header_line}: column {c!r} is not a target column (x_{unit}, y_{unit}, "
                             f"z_{unit}, qw..qz, seed_<joint>_<unit>, payload_kg)")
    values, rows = [], []
    for line_no, line in lines[1:]:
        cells = [c.strip() for c in csv_cells(line, path, line_no)]
        if len(cells) != len(header):
            raise InputError(f"{path}: row {line_no}: {len(cells)} cells, the header has {len(header)} columns")
        row = []
        for column, cell in zip(header, cells):
            try:
                row.append(parse_number(cell))
            except ValueError:
                raise InputError(f"{path}: row {line_no}, column {column}: "
                                 f"{'an empty cell' if not cell else repr(cell) + ' is not a finite number'}") from None
        values.append(row)
        rows.append(line_no)
    if not rows:
        raise InputError(f"{path}: no target rows")
    table = np.array(values)
    column = {c: table[:, k] for k, c in enumerate(header)}
    positions = np.stack([column[c] for c in position_columns], axis=1) * POSITION_UNITS[unit]
    _bounded(path, rows, positions, position_columns, MAX_POSITION_M, unit, POSITION_UNITS[unit])
    rotations = None
    if quaternion:
        quat = np.stack([column[c] for c in ("qw", "qx", "qy", "qz")], axis=1)
        norms = np.linalg.norm(quat, axis=1)
        bad = np.flatnonzero(np.abs(norms - 1.0) > QUATERNION_TOLERANCE)
        if bad.size:
            raise InputError(f"{path}: row {rows[bad[0]]}, columns qw,qx,qy,qz: quaternion norm is {norms[bad[0]]:.6g}, "
                             f"not 1 (within {QUATERNION_TOLERANCE:g})")
        from scipy.spatial.transform import Rotation

        quat = quat / norms[:, None]
        rotations = Rotation.from_quat(quat[:, [1, 2, 3, 0]]).as_matrix()
    seed = None
    if joint_columns:
        seed = np.stack([column[joint_columns[n]] * JOINT_COLUMN_UNITS[k][joint_columns[n].rpartition("_")[2]]
                         for n, k in zip(robot.joint_names, robot.joint_kinds)], axis=1)
        if np.abs(seed).max() > 1e4:
            raise InputError(f"{path}: a seed joint value beyond 1e4 rad or m")
    context = MeasurementContext.defaults(len(rows), robot.n_joints)
    if "payload_kg" in column:
        payload = column["payload_kg"]
        bad = np.flatnonzero((payload < 0) | (payload > MAX_PAYLOAD_KG))
        if bad.size:
            raise InputError(f"{path}: row {rows[bad[0]]}, column payload_kg: {payload[bad[0]]:g} kg is not a load "
                             f"(0 to {MAX_PAYLOAD_KG:g} kg)")
        context.payload_kg = payload.astype(float)
    return PoseTargets(positions, rotations, seed, context, np.array(rows))


def _bounded(path, rows, values, columns, bound, unit, factor) -> None:
    bad = np.argwhere(np.abs(values) > bound)
    if bad.size:
        r, c = bad[0]
        raise InputError(f"{path}: row {rows[r]}, column {columns[c]}: {values[r, c] / factor:g} {unit} is beyond "
                         f"{bound / factor:g} {unit}")
