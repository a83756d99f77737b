"""Plausibility checks of a measurement file, each failing with the file, row and column at fault.

Used by :mod:`tcr_accuracy.io.measurements` once a file is parsed: joint values outside the
URDF limits and repeated poses warn; exact duplicate rows and positions in the wrong unit stop.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..exceptions import InputError

class MeasurementWarning(UserWarning):
    """Something in a measurement file is suspicious but may be intended."""


def warn_outside_limits(robot, q, rows, joint_columns, source):
    lo, hi = robot.lower_limits, robot.upper_limits
    with np.errstate(invalid="ignore"):
        outside = (q < lo - 1e-12) | (q > hi + 1e-12)
    for j in np.flatnonzero(outside.any(axis=0)):
        r = int(np.argmax(outside[:, j]))
        scale, unit = robot.display_scale[j], robot.display_units[j]
        warnings.warn(
            f"{source}: row {rows[r]}, column {joint_columns[j][1] or joint_columns[j][0] + ' (mimic)'}: "
            f"{int(outside[:, j].sum())} value(s) "
            f"outside the limits [{lo[j] * scale:.6g}, {hi[j] * scale:.6g}] {unit} of joint "
            f"{robot.joint_names[j]} (first: {q[r, j] * scale:.6g} {unit})",
            MeasurementWarning, stacklevel=3,
        )


def warn_constant_time(time_s, rows, source):
    """A ``time_s`` column that never changes carries no time: the diagnosis then orders drift and its
    time checks by the measurement order, and says so here (a clock not logged is a common export fault)."""
    if time_s is not None and len(time_s) > 1 and np.ptp(time_s) == 0:
        warnings.warn(
            f"{source}: column time_s: all {len(time_s)} rows (from row {rows[0]}) carry the same time "
            f"{time_s[0]:g} s; drift and the time checks use the measurement order instead",
            MeasurementWarning, stacklevel=3,
        )


def check_duplicates(mset, values, header, source, context_columns):
    """Exact copies of a row are an error; repeated poses under the same context warn (not in a
    pose test, whose ``pose_id`` column says it repeats its poses on purpose)."""
    rows = mset.rows
    full = {}
    for k in range(len(rows)):
        key = values[k].tobytes()
        if key in full:
            raise InputError(f"{source}: row {rows[k]} repeats row {rows[full[key]]} exactly "
                             "(a copy-paste?); remove one")
        full[key] = k
    ctx_cols = [c for c, name in enumerate(header) if name in context_columns or name.endswith("_dir")]
    blocks = [mset.q, values[:, ctx_cols]] + ([mset.outside_q] if mset.outside_q is not None else [])
    pose = np.concatenate(blocks, axis=1)
    seen = {}
    repeats = []
    for k in range(len(rows)):
        key = pose[k].tobytes()
        if key in seen:
            repeats.append((seen[key], k))
        else:
            seen[key] = k
    if repeats and "pose_id" not in header:
        a, b = repeats[0]
        warnings.warn(
            f"{source}: row {rows[b]} has the same joint values and context as row {rows[a]} "
            f"({len(repeats)} repeated pose(s) in all); repeated poses weigh more in a fit",
            MeasurementWarning, stacklevel=3,
        )


#: Below this RMS spread of the nominal points [m] the unit check cannot tell a unit (and is not made).
MIN_UNIT_SPREAD = 1e-3


def rms_spread(points, groups=None) -> float:
    """RMS distance [m] of points (N, 3) [m] from their centre, or from the centre of their own
    group where ``groups`` (N,) int is given (each session its own tracker frame)."""
    points = np.asarray(points, dtype=float)
    if groups is None:
        return float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))
    groups = np.asarray(groups, dtype=int)
    centres = np.zeros((groups.max() + 1, 3))
    np.add.at(centres, groups, points)
    centres /= np.maximum(np.bincount(groups, minlength=len(centres)), 1)[:, None]
    return float(np.sqrt(np.mean(np.sum((points - centres[groups]) ** 2, axis=1))))


def check_position_units(mset, robot, columns, source):
    """Compare the spread of the measured TCP with the nominal model's spread.

    The tracker frame is unknown, so absolute values say nothing; distances between
    measured points do, and a rigid frame change keeps them. Each session (``session``
    column) has its own tracker frame: the spreads are taken about each session's own centre,
    so that sessions set up metres apart are not read as a unit error.
    """
    from ..model.kinematics import tcp_poses

    if len(mset) < 3:
        return
    joint_units = ", ".join(col or f"{name} (its <mimic> rule)" for name, col, _ in columns["joints"])
    sessions = mset.session_index()  # None: one session
    check_spread_units(mset.position, tcp_poses(robot, mset.q).position, columns["position"], source,
                       f"check the position units and the joint columns' units ({joint_units})", groups=sessions)


def check_spread_units(measured, nominal, position_columns, source, other_hint, groups=None):
    """InputError when measured points (N, 3) [m, as read] spread over more than twice or less than
    half what the nominal points (M, 3) [m] they stand for spread (RMS about their centre): a file in
    metres labelled mm or the reverse (the hint names the other unit), else ``other_hint``.

    Parameters
    ----------
    measured : array-like of shape (N, 3)
    nominal : array-like of shape (M, 3)
    position_columns : tuple of (list of str, str)
        The position columns and their unit, as the file names them.
    source : str
    other_hint : str
        What to check when the ratio is not a unit's factor.
    groups : array-like of shape (N,), optional
        The session of each point (measured and nominal then row for row): spreads about each
        session's own centre, so sessions set up metres apart are not read as a unit error.
    """
    model_spread, measured_spread = rms_spread(nominal, groups), rms_spread(measured, groups)
    if model_spread < MIN_UNIT_SPREAD:  # all poses (nearly) the same: nothing to compare
        return
    ratio = measured_spread / model_spread
    if 0.5 <= ratio <= 2.0:
        return
    cols, unit = position_columns
    other = "m" if unit == "mm" else "mm"
    if 0.3e-3 <= ratio <= 3e-3 or 0.3e3 <= ratio <= 3e3:
        hint = (f"the values look like {other}: name the columns "
                f"{', '.join(f'{a}_{other}' for a in 'xyz')}")
    else:
        hint = other_hint
    raise InputError(
        f"{source}: columns {', '.join(cols)}: the measured points spread over "
        f"{measured_spread * 1e3:.4g} mm (RMS about their centre) while the model's TCP at the same "
        f"joint values spreads over {model_spread * 1e3:.4g} mm ({ratio:.3g} times); {hint}"
    )
