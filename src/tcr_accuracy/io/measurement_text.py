"""The measurement CSV as text (:func:`format_measurements`): joints in deg and mm or rad and m,
the measured positions, the context and the pose-test labels a :class:`MeasurementSet` holds.

The text is returned, never written: the command line writes it through its one output writer.
"""

from __future__ import annotations

import io

import numpy as np

from ..exceptions import InputError
from ..model.robot import RobotModel
from ..units import JOINT_DISPLAY, REVOLUTE
from .measurement_set import ANNOTATION_COLUMNS, QUATERNION_COLUMNS, TEXT_ANNOTATIONS, MeasurementSet


def measurement_columns(robot: RobotModel, mset: MeasurementSet, unit: str = "mm") -> list[str]:
    """Header of the CSV :func:`format_measurements` writes."""
    if unit not in ("mm", "m"):
        raise InputError(f"unit {unit!r}: use 'mm' (deg, mm columns) or 'm' (rad, m columns)")
    joint_unit = {REVOLUTE: "deg" if unit == "mm" else "rad", "prismatic": unit}
    cols = [f"{n}_{joint_unit[k]}" for n, k in zip(robot.joint_names, robot.joint_kinds)]
    if mset.outside_q is not None:
        cols += [f"{n}_{joint_unit[k]}" for n, k in zip(robot.outside_joint_names, robot.outside_joint_kinds)]
    cols += [f"{a}_{unit}" for a in "xyz"]
    if mset.quaternion is not None:
        cols += list(QUATERNION_COLUMNS)
    if mset.payload_kg is not None:
        cols.append("payload_kg")
    if mset.temperature_c is not None:
        cols.append("temperature_c")
    if mset.direction is not None:
        cols += [f"{n}_dir" for j, n in enumerate(robot.joint_names) if np.any(mset.direction[:, j] != 0)]
    return cols + _annotation_columns(mset)


def _annotation_columns(mset: MeasurementSet) -> list[str]:
    return [c for c in ANNOTATION_COLUMNS if mset.annotations and c in mset.annotations]


def format_measurements(robot: RobotModel, mset: MeasurementSet, unit: str = "mm",
                        comment: str | None = None) -> str:
    """CSV text of a measurement set, joints in deg/mm (unit "mm") or rad/m (unit "m")."""
    cols = measurement_columns(robot, mset, unit)
    if list(mset.joint_names) != list(robot.joint_names):
        raise InputError(f"measurement set joints {mset.joint_names} are not the robot's {robot.joint_names}")
    factor = 1e3 if unit == "mm" else 1.0
    joint_scale = robot.display_scale if unit == "mm" else np.ones(robot.n_joints)
    blocks = [mset.q * joint_scale]
    if mset.outside_q is not None:
        outside_scale = (np.array([JOINT_DISPLAY[k][1] for k in robot.outside_joint_kinds]) if unit == "mm"
                         else np.ones(len(robot.outside_joint_names)))
        blocks.append(mset.outside_q * outside_scale)
    blocks.append(mset.position * factor)
    if mset.quaternion is not None:
        blocks.append(mset.quaternion)
    if mset.payload_kg is not None:
        blocks.append(mset.payload_kg[:, None])
    if mset.temperature_c is not None:
        blocks.append(mset.temperature_c[:, None])
    if mset.direction is not None:
        used = [j for j in range(robot.n_joints) if np.any(mset.direction[:, j] != 0)]
        blocks.append(mset.direction[:, used])
    labels = _annotation_columns(mset)
    numbers = [c for c in labels if c not in TEXT_ANNOTATIONS]
    table = np.concatenate(blocks + [np.stack([np.asarray(mset.annotations[c], dtype=float) for c in numbers], axis=1)]
                           if numbers else blocks, axis=1)
    if not np.all(np.isfinite(table)):
        raise InputError("measurement set has non-finite values; nothing written")
    names = [[_label_cell(mset.annotations[c][k]) if c in TEXT_ANNOTATIONS else None for c in labels]
             for k in range(len(table))]
    out = io.StringIO()
    if comment:
        for line in comment.splitlines():
            out.write(f"# {line}\n")
    out.write(",".join(cols) + "\n")
    n_values = len(cols) - len(labels) - sum(c.endswith("_dir") for c in cols)
    n_dirs = len(cols) - len(labels)
    for row, text in zip(table, names):
        cells = [format(v, ".12g") for v in row[:n_values]]
        cells += [f"{int(v):+d}" for v in row[n_values:n_dirs]]
        given = iter(format(v, ".12g") for v in row[n_dirs:])
        cells += [next(given) if name is None else name for name in text]
        out.write(",".join(cells) + "\n")
    return out.getvalue()


def _label_cell(value) -> str:
    """A text annotation as a CSV cell (quoted when it holds a comma or a quote)."""
    text = str(value)
    return f'"{text.replace(chr(34), chr(34) * 2)}"' if ("," in text or '"' in text) else text


__all__ = ["format_measurements", "measurement_columns"]
