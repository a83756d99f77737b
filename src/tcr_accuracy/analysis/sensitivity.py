"""Which error matters, locally: one-at-a-time sweeps of single error sources.

The seed's control-variable method (its Fig. 7-9 and 13-16): one error source at a
time is set to a list of signed values, every other source at zero, and the TCP
position and attitude errors are recorded. Exact (no linearisation). The global view
(Sobol indices over all random inputs at once) is :mod:`tcr_accuracy.analysis.sobol`; how far
the spreads may grow for a reliability target is :mod:`tcr_accuracy.analysis.tolerance`.

This module also owns the names of the TCP error outputs that sweeps and Sobol indices
share, :data:`OUTPUTS` (named as in :mod:`tcr_accuracy.analysis.montecarlo`): ``dx, dy, dz``
(base frame [m]), ``norm`` (|dP| [m]), ``d_alpha_z, d_beta_y, d_gamma_x`` (ZYX Euler
angle errors [rad]) and ``rotation_angle`` (the angle of the attitude error [rad]), and
:func:`error_columns`, which computes them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..model.errors import ErrorModel, link_length_direction
from ..exceptions import InputError
from ..model.kinematics import pose_error, tcp_poses
from ..model.robot import REVOLUTE, RobotModel

#: Output columns of sweeps and Sobol indices (SI units: m then rad).
OUTPUTS = ("dx", "dy", "dz", "norm", "d_alpha_z", "d_beta_y", "d_gamma_x", "rotation_angle")
OUTPUT_UNITS = ("m", "m", "m", "m", "rad", "rad", "rad", "rad")

#: The seed's sweep values: link lengths +-0.02, 0.04, 0.06 mm (Fig. 7) [m] ...
SEED_LINK_SWEEP = np.array([-0.06, -0.04, -0.02, 0.0, 0.02, 0.04, 0.06]) * 1e-3
#: ... and joint angles +-0.02 .. 0.1 deg (Fig. 8, 9) [rad].
SEED_ANGLE_SWEEP = np.radians(np.array([-0.1, -0.08, -0.06, -0.04, -0.02, 0.0,
                                        0.02, 0.04, 0.06, 0.08, 0.1]))


def error_columns(robot: RobotModel, q: np.ndarray, x: np.ndarray, error_model: ErrorModel,
                  nominal=None) -> np.ndarray:
    """The TCP error of as-built robots at one pose, as the columns :data:`OUTPUTS`.

    Parameters
    ----------
    robot : RobotModel
    q : ndarray of shape (n_joints,)
        Joint values [rad, m].
    x : ndarray of shape (N, n_params)
        Error vectors in the layout of ``error_model``.
    error_model : ErrorModel
    nominal : TcpPoses, optional
        ``tcp_poses(robot, q)``, when the caller already has it.

    Returns
    -------
    ndarray of shape (N, 8)
        dx, dy, dz, |dP| [m], ZYX Euler angle errors and the attitude error angle [rad].
    """
    nominal = nominal if nominal is not None else tcp_poses(robot, q)
    err = pose_error(nominal, tcp_poses(robot, q, x, error_model))
    return np.column_stack([err.position, err.position_norm, err.euler_zyx, err.rotation_angle])


# ---------------------------------------------------------------------------------------
# One-at-a-time sweeps
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepResult:
    """TCP errors when each source alone takes each value.

    Attributes
    ----------
    source_names : list of str, length n_sources
    values : ndarray of shape (n_values,)
        The signed values every source was set to [unit].
    unit : str
        Unit of ``values`` (``m`` or ``rad``).
    errors : ndarray of shape (n_sources, n_values, 8)
        Columns :data:`OUTPUTS` [m, rad].
    """

    source_names: list[str]
    values: np.ndarray
    unit: str
    errors: np.ndarray

    def output(self, name: str) -> np.ndarray:
        """(n_sources, n_values) one output column."""
        return self.errors[:, :, OUTPUTS.index(name)]


def sweep(robot: RobotModel, q: np.ndarray, sources: Sequence[tuple[str, np.ndarray]],
          values: np.ndarray, unit: str, error_model: ErrorModel | None = None) -> SweepResult:
    """Set each source alone to each value and record the exact TCP error.

    Parameters
    ----------
    robot : RobotModel
    q : ndarray of shape (n_joints,)
        Joint values [rad, m].
    sources : sequence of (name, direction (n_params,)) pairs
        The error vector of source k at value v is ``v * direction_k``.
    values : ndarray of shape (n_values,)
        Signed values [unit].
    unit : str
        ``m`` or ``rad``, for reports.
    """
    error_model = error_model or ErrorModel(robot)
    values = np.asarray(values, dtype=float)
    if not sources:
        raise InputError("sweep: no error sources to sweep")
    directions = np.stack([d for _, d in sources])  # (n_sources, n_params)
    x = (directions[:, None, :] * values[None, :, None]).reshape(-1, error_model.size)
    cols = error_columns(robot, q, x, error_model)
    return SweepResult([n for n, _ in sources], values, unit,
                       cols.reshape(len(sources), values.size, len(OUTPUTS)))


def link_length_sources(robot: RobotModel, error_model: ErrorModel) -> list[tuple[str, np.ndarray]]:
    """(name, direction) of a unit length error of every link with a length.

    Named ``l1`` .. after the joint the link ends at, as in the seed's Table 2 (l_j is
    the offset of joint j's origin from the previous joint).
    """
    out = []
    for j in range(robot.n_joints):
        direction = link_length_direction(robot, j, error_model)
        if direction is not None:
            out.append((f"l{j + 1}", direction))
    return out


def drive_sources(robot: RobotModel, error_model: ErrorModel, kind: str = REVOLUTE
                  ) -> list[tuple[str, np.ndarray]]:
    """(name, direction) of a unit drive error of every joint of one kind."""
    out = []
    for name, k in zip(robot.joint_names, robot.joint_kinds):
        if k == kind:
            d = error_model.zeros()
            d[error_model.index(f"{name}.drive")] = 1.0
            out.append((name, d))
    return out


def seed_sweeps(robot: RobotModel, q: np.ndarray, link_values: np.ndarray = SEED_LINK_SWEEP,
                angle_values: np.ndarray = SEED_ANGLE_SWEEP) -> dict[str, SweepResult]:
    """The seed's Fig. 7 (link lengths) and Fig. 8-9 (joint angles) sweeps at q."""
    em = ErrorModel(robot)
    return {
        "link_length": sweep(robot, q, link_length_sources(robot, em), link_values, "m", em),
        "joint_angle": sweep(robot, q, drive_sources(robot, em), angle_values, "rad", em),
    }


# ---------------------------------------------------------------------------------------
# Clearance sweeps (the seed's Fig. 13-16)
# ---------------------------------------------------------------------------------------
#: Clearance offsets swept: -0.5 .. 0.5 mm, one Table 4 standard deviation of s [m].
CLEARANCE_OFFSET_SWEEP = np.linspace(-0.5e-3, 0.5e-3, 11)
#: Clearance deflections swept: -0.087 .. 0.087 rad, one Table 4 standard deviation of w.
CLEARANCE_DEFLECTION_SWEEP = np.linspace(-0.087, 0.087, 11)

#: Clearance quantities swept one at a time: (key, ClearanceSample field, angle theta or None, unit).
CLEARANCE_QUANTITIES = (
    ("axial", "axial", None, "m"),  # axial movement d along the joint axis
    ("radial_u", "radial", 0.0, "m"),  # clearance rod s at theta = 0 (along u)
    ("radial_v", "radial", 0.5 * math.pi, "m"),  # clearance rod s at theta = 90 deg (along v)
    ("deflection_u", "deflection_u", None, "rad"),  # axis tilt w_x about u
    ("deflection_v", "deflection_v", None, "rad"),  # axis tilt w_y about v
)


def clearance_sweeps(model, q: np.ndarray, offsets: np.ndarray = CLEARANCE_OFFSET_SWEEP,
                     deflections: np.ndarray = CLEARANCE_DEFLECTION_SWEEP) -> dict[str, SweepResult]:
    """One clearance quantity of one joint at a time, through the clearance model's own map.

    Parameters
    ----------
    model : :class:`~tcr_accuracy.model.clearance.ClearanceModel`
        Which joints have play and how a play displaces the joint placement.
    q : ndarray of shape (n_joints,) [rad, m]
    offsets : ndarray of shape (n_offsets,)
        Values of the axial movement d and of the radial rod s [m].
    deflections : ndarray of shape (n_deflections,)
        Values of the deflections w_x, w_y [rad].

    Returns
    -------
    dict with keys ``axial``, ``radial_u``, ``radial_v``, ``deflection_u``,
    ``deflection_v``; each a SweepResult over the joints with play (named after them).
    """
    from ..model.clearance import ClearanceSample

    robot, em = model.robot, model.error_model
    k = len(model.joints)
    nominal = tcp_poses(robot, q)
    out = {}
    for key, field_name, theta, unit in CLEARANCE_QUANTITIES:
        values = np.asarray(offsets if unit == "m" else deflections, dtype=float)
        m = values.size
        errors = np.empty((k, m, len(OUTPUTS)))
        for idx in range(k):
            parts = {f: np.zeros((m, k)) for f in ("axial", "radial", "angle", "deflection_u", "deflection_v")}
            parts[field_name][:, idx] = values
            if theta is not None:
                parts["angle"][:, idx] = theta
            x = model.to_parameters(ClearanceSample(**parts))
            errors[idx] = error_columns(robot, q, x, em, nominal)
        out[key] = SweepResult([robot.joint_names[j] for j in model.joints], values, unit, errors)
    return out
