"""Whether the fitted geometry is one the robot and the setup can have: how far the calibration
moves the tool frame and tilts each joint's axis, and how far the fitted TCP offset lies from the
one the user gives, each against a stated tolerance for the robot's class.

A geometry fit keeps whatever explains the held-out data; where two parameter sets explain them
equally (a tilted wrist axis and a shorter tool, say) it takes the one the identifiability order
prefers, which may not be the robot's. Nothing here changes the fit: it says the sizes, beside what
is plausible, so that a calibration engineer checks the robot, the drawing or the mounting where
they differ. The tolerances are in one table, :data:`TOLERANCES`, with the reasoning behind each.

Lengths in m and angles in rad inside; ``to_dict`` gives mm and deg.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from ..model.errors import ErrorModel
from ..model.kinematics import tcp_poses


@dataclass(frozen=True)
class GeometryTolerance:
    """What a geometry fit may do before it is flagged, for one class of robot (SI units).

    Attributes
    ----------
    robot_class : str
    axis_tilt : float
        Largest plausible tilt of a joint axis from its nominal direction [rad].
    tool_position, tool_rotation : float
        Largest plausible displacement [m] and rotation [rad] of the tool frame (the URDF's, with
        the fitted geometry and no TCP offset) from the nominal robot's, at a measured pose.
    tcp_offset : float
        Largest plausible distance [m] between a fitted TCP offset and the one the user gives.
    reason : str
        Where the figures come from.
    """

    robot_class: str
    axis_tilt: float
    tool_position: float
    tool_rotation: float
    tcp_offset: float
    reason: str

    def to_dict(self) -> dict:
        return {"robot_class": self.robot_class, "axis_tilt_deg": math.degrees(self.axis_tilt),
                "tool_position_mm": self.tool_position * 1e3, "tool_rotation_deg": math.degrees(self.tool_rotation),
                "tcp_offset_mm": self.tcp_offset * 1e3, "reason": self.reason}


#: The tolerances, per class of robot (see :func:`robot_class`).
TOLERANCES = {
    "industrial arm": GeometryTolerance(
        "industrial arm", axis_tilt=math.radians(0.3), tool_position=3e-3, tool_rotation=math.radians(0.3),
        tcp_offset=1e-3,
        reason="a serial arm of up to 7 joints on a fixed base (industrial or collaborative, ~0.5-3 m reach): its "
               "axes are set by machined bearing seats (perpendicularity of a few hundredths of a mm over a "
               "100-200 mm seat: a few tenths of a mrad) and by assembly, and its rigid links bend under gravity by "
               "tenths of a mrad, so an axis tilted by more than a few tenths of a degree is not the arm's; "
               "uncalibrated, such arms miss absolute targets by about 1-3 mm, so a calibration that moves the tool "
               "frame further (or turns it by more than a few tenths of a degree) takes up something else (the "
               "tool, the mounting, a joint's elasticity); a tool or reflector mounted from a drawing sits within "
               "about a tenth of a mm to 1 mm of its drawn place"),
    "arm on a torso": GeometryTolerance(
        "arm on a torso", axis_tilt=math.radians(1.0), tool_position=25e-3, tool_rotation=math.radians(1.5),
        tcp_offset=3e-3,
        reason="an arm on a torso or a humanoid's (more than 7 joints from the base to the tool: light links, "
               "elastic or cable-driven joints): its published calibrations identify axis errors of up to about a "
               "degree and position errors of some 20 mm before calibration (DLR's Agile Justin: 21 mm mean with "
               "only the camera frame fitted), and its markers sit where a guess puts them within a few mm"),
}


def robot_class(robot) -> str:
    """The robot's class in :data:`TOLERANCES`: an arm on a torso when more than 7 joints move the
    tool frame, else an industrial arm."""
    return "arm on a torso" if robot.n_joints > 7 else "industrial arm"


@dataclass(frozen=True)
class GeometryCheck:
    """One fitted figure against its tolerance (SI units).

    Attributes
    ----------
    what : str
        ``axis_tilt``, ``tool_position``, ``tool_rotation`` or ``tcp_offset``.
    subject : str
        The joint, or the tool frame.
    value : float
        Its size [m or rad] (the largest over the measured poses for the tool frame).
    std : float or None
        Its standard error [m or rad], where the fit's covariance gives it.
    tolerance : float
        What :data:`TOLERANCES` allows [m or rad].
    flagged : bool
        The size exceeds the tolerance.
    text : str
        The check in words (mm and deg).
    detail : dict
        The figures behind it (JSON form, mm and deg).
    """

    what: str
    subject: str
    value: float
    std: float | None
    tolerance: float
    flagged: bool
    text: str
    detail: dict

    def to_dict(self) -> dict:
        unit, scale = ("deg", 180.0 / math.pi) if self.what in ("axis_tilt", "tool_rotation") else ("mm", 1e3)
        return {"what": self.what, "subject": self.subject, f"value_{unit}": self.value * scale,
                f"std_{unit}": None if self.std is None else self.std * scale,
                f"tolerance_{unit}": self.tolerance * scale, "flagged": self.flagged, "text": self.text,
                **self.detail}


def geometry_checks(robot, q: np.ndarray, as_built_x: np.ndarray, table: dict, tcp_name: str | None = None,
                    tcp_given: np.ndarray | None = None, tolerance: GeometryTolerance | None = None) -> list:
    """The fitted geometry against what its class of robot allows (every check, flagged or not).

    Parameters
    ----------
    robot : RobotModel
        The nominal robot of the first measured frame.
    q : ndarray of shape (N, n_joints)
        The measured poses [rad, m].
    as_built_x : ndarray of shape (p_em,)
        The geometric effects' error vector (the base twist taken out, the fitted TCP offset in the
        tool slice), :attr:`~.stages.parameters.FittedParameters.as_built_x`.
    table : dict
        The parameter table (effect -> values, std, ...), for the standard errors.
    tcp_name : str, default=None
        The name of the first measured frame's TCP offset parameters (``frames.tool`` or
        ``frames.<frame>``).
    tcp_given : ndarray of shape (3,), default=None
        The measured point's offset from the tool frame as the user knows it [m]; None: not checked.
    tolerance : GeometryTolerance, default=None
        None: the robot's class' (:func:`robot_class`).

    Returns
    -------
    list of GeometryCheck
        The largest axis tilt (and every tilt beyond the tolerance), the tool frame's displacement
        and rotation, and the TCP offset against the given one.
    """
    tolerance = tolerance or TOLERANCES[robot_class(robot)]
    em = ErrorModel(robot)
    parts = em.split(as_built_x)
    checks = []
    tilts = []
    std_of = {name: s for rows in table.values() for name, s in rows["std"].items()}
    for j, joint in enumerate(robot.joint_names):
        axis = robot.joint_axis(j)
        w = parts.placement[j, 3:]
        tilt = w - (w @ axis) * axis
        size = float(np.linalg.norm(tilt))
        # its standard error, to first order: the fitted rotations' errors weighed by the tilt's direction
        sigma = [_std(std_of, joint, c) for c in ("rx", "ry", "rz")]
        std = None if size == 0 else float(math.sqrt(sum((t / size) ** 2 * s**2 for t, s in zip(tilt, sigma))))
        tilts.append((size, joint, std))
    tilts.sort(key=lambda t: -t[0])
    for k, (size, joint, std) in enumerate(tilts):
        if k > 0 and size <= tolerance.axis_tilt or size == 0.0:
            continue
        flagged = size > tolerance.axis_tilt
        checks.append(GeometryCheck(
            "axis_tilt", joint, size, std, tolerance.axis_tilt, flagged,
            f"the fit tilts {joint}'s axis by {math.degrees(size):.3g} deg"
            + ("" if std is None else f" (+- {math.degrees(std):.2g})")
            + f": {'beyond' if flagged else 'within'} the {math.degrees(tolerance.axis_tilt):.2g} deg plausible for "
              f"{_article(tolerance.robot_class)}", {}))
    if len(q):
        checks += _tool_frame_checks(robot, q, as_built_x, em, tolerance)
    if tcp_given is not None:
        checks.append(_tcp_check(as_built_x, em, std_of, tcp_name, np.asarray(tcp_given, dtype=float), tolerance,
                                 robot.tool_frame))
    return checks


def _std(std_of: dict, joint: str, component: str) -> float:
    """The standard error [rad] of a fitted rotation of a joint's placement (geometry's), 0 where not fitted."""
    s = std_of.get(f"geometry.{joint}.{component}")
    return float(s) if s is not None and np.isfinite(s) else 0.0


def _article(robot_class_name: str) -> str:
    return ("an " if robot_class_name[0] in "aeiou" else "a ") + robot_class_name


def _tool_frame_checks(robot, q, as_built_x, em, tolerance) -> list:
    """How far the fitted geometry moves and turns the tool frame (the URDF's, no TCP offset) at the
    measured poses."""
    x = np.array(as_built_x, dtype=float)
    x[em.tool_slice] = 0.0  # the tool frame itself, not the measured point
    nominal, built = tcp_poses(robot, q), tcp_poses(robot, q, x, em)
    moved = np.linalg.norm(built.position - nominal.position, axis=1)
    relative = np.einsum("nji,njk->nik", nominal.rotation, built.rotation)
    turned = np.array([np.linalg.norm(pin.log3(r)) for r in relative])
    frame, who = robot.tool_frame, _article(tolerance.robot_class)
    out = []
    for what, values, limit, unit, scale in (("tool_position", moved, tolerance.tool_position, "mm", 1e3),
                                             ("tool_rotation", turned, tolerance.tool_rotation, "deg", 180 / math.pi)):
        largest, rms = float(values.max()), float(math.sqrt(np.mean(values**2)))
        flagged = largest > limit
        out.append(GeometryCheck(
            what, frame, largest, None, limit, flagged,
            f"the fitted geometry {'moves' if what == 'tool_position' else 'turns'} the tool frame {frame} by "
            f"{values.min() * scale:.3g} to {largest * scale:.3g} {unit} (RMS {rms * scale:.3g}) from the nominal "
            f"robot's over the measured poses: {'beyond' if flagged else 'within'} the {limit * scale:.2g} {unit} "
            f"plausible for {who}",
            {f"min_{unit}": float(values.min() * scale), f"rms_{unit}": rms * scale}))
    return out


def _tcp_check(as_built_x, em, std_of: dict, tcp_name: str | None, given: np.ndarray, tolerance, frame: str):
    """The fitted TCP offset (the measured point in the tool frame) against the given one."""
    fitted = pin.exp6(np.asarray(as_built_x[em.tool_slice], dtype=float)).translation
    difference = fitted - given
    size = float(np.linalg.norm(difference))
    sigma = np.array([std_of.get(f"{tcp_name}.{c}") or 0.0 for c in ("dx", "dy", "dz")] if tcp_name else [0.0] * 3)
    sigma = np.where(np.isfinite(sigma), sigma, 0.0)
    std = float(math.sqrt(np.sum((difference / size) ** 2 * sigma**2))) if size > 0 else None
    flagged = size > tolerance.tcp_offset

    def mm(v) -> str:
        return "(" + ", ".join(f"{c * 1e3:.4g}" for c in v) + f") mm ({np.linalg.norm(v) * 1e3:.4g} mm away)"

    text = (f"the measured point is fitted at {mm(fitted)} from the tool frame {frame}, the given offset is "
            f"{mm(given)}: {size * 1e3:.3g} mm apart" + ("" if std is None else f" (+- {std * 1e3:.2g})")
            + f", {'beyond' if flagged else 'within'} the {tolerance.tcp_offset * 1e3:.2g} mm plausible for a tool "
              "mounted from a drawing")
    if flagged:
        text += ("; the fit or the given offset is off (a tool or reflector not where it is said to be, or the "
                 "geometry fit taking up the tool's length)")
    return GeometryCheck("tcp_offset", frame, size, std, tolerance.tcp_offset, flagged, text,
                         {"fitted_mm": (fitted * 1e3).tolist(), "given_mm": (given * 1e3).tolist(),
                          "difference_mm": (difference * 1e3).tolist()})
