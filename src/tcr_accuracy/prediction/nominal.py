"""The nominal robot's error: the one figure every command calls "nominal".

**Definition.** The nominal robot (its URDF, no effect fitted) with the measurement (tracker)
frame and the TCP offset of the measured point fitted to the measured poses
(:func:`~tcr_accuracy.frames.registration.register_tracker`: Kabsch, then the ``frames`` effect
by least squares); its error at a pose is ``|trackerMbase^-1 p_measured - FK_nominal+offset(q)|``
[m], on the poses it is stated for: the poses the frame was fitted on (in-sample) or others
measured in the same tracker frame (held out).

``export`` (the ``nominal`` line of every form's table), ``predict`` and ``compensate`` (the
measured query or target poses) and ``report`` (from the export's result) print this figure, so
one robot on one set of poses has one nominal figure. Until this module they differed: ``export``
took the TCP offset the full model had fitted (with every effect beside it) and a Kabsch frame for
it, ``compensate`` the frames-only fit here, so the UR5's 20 random poses read 0.4950 and 0.4879
mm. SI units (m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..frames.registration import Registration, register_tracker
from ..model.robot import RobotModel

#: What the nominal figure is, in words (printed beside it).
NOMINAL_DEFINITION = ("the nominal robot with the tracker frame and the TCP offset of the measured point fitted to the "
                      "measured poses")


@dataclass(frozen=True)
class NominalError:
    """The nominal robot's TCP position error on stated poses.

    Attributes
    ----------
    error : ndarray of shape (N,)
        ``|measured point in the base frame - nominal FK with the fitted TCP offset|`` per pose [m].
    on : str
        ``"measured"`` (the poses the frame was fitted on) or ``"held-out"``.
    registration : Registration
        The fitted tracker frame and TCP offset.
    """

    error: np.ndarray
    on: str
    registration: Registration

    @property
    def n(self) -> int:
        return int(self.error.size)

    @property
    def mean(self) -> float:
        """Mean error [m]."""
        return float(self.error.mean())

    @property
    def rms(self) -> float:
        """RMS error [m]."""
        return float(np.sqrt(np.mean(self.error ** 2)))

    @property
    def max(self) -> float:
        """Largest error [m]."""
        return float(self.error.max())


def nominal_registration(robot: RobotModel, q, measured, *, fit_frame: bool = True) -> Registration:
    """The tracker frame and TCP offset of the nominal robot fitted to measured poses.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    q : array-like of shape (N, n_joints)
        Joint values [rad, m].
    measured : array-like of shape (N, 3)
        Measured positions in the tracker frame [m].
    fit_frame : bool, default=True
        False: the positions are in the base frame already (only the TCP offset is fitted).
    """
    return register_tracker(robot, q, measured, fit_base=fit_frame)


def nominal_error(registration: Registration, robot: RobotModel, q, measured, on: str = "held-out") -> NominalError:
    """The nominal robot's error at poses ``q`` measured at ``measured`` (tracker frame [m]).

    Parameters
    ----------
    registration : Registration
        From :func:`nominal_registration` on the measured (training) poses.
    robot : RobotModel
        The nominal robot the registration was fitted for.
    q : array-like of shape (N, n_joints)
    measured : array-like of shape (N, 3)
        In the tracker frame the registration was fitted in [m].
    on : str
        ``"measured"`` when these are the poses the registration was fitted on, else ``"held-out"``.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    points = registration.to_base(measured)
    return NominalError(np.linalg.norm(points - registration.tcp_positions(robot, q), axis=1), on, registration)


def nominal_errors(robot: RobotModel, q, measured, *, session=None, held_out=None) -> list[NominalError]:
    """The nominal figure on the measured poses and, given, on held-out ones.

    Parameters
    ----------
    robot : RobotModel
    q, measured : arrays of shape (N, n_joints) and (N, 3) [m]
        The measured poses (the frame and TCP offset are fitted on them).
    session : ndarray of shape (N,), optional
        Each row's session: each session gets its own tracker frame and TCP offset fit.
    held_out : (q (M, n_joints), measured (M, 3)), optional
        Poses measured in the tracker frame of the first session.

    Returns
    -------
    list of NominalError
        The measured poses' (the rows in their order), then the held-out poses'.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    measured = np.atleast_2d(np.asarray(measured, dtype=float))
    session = np.zeros(len(q), dtype=int) if session is None else np.asarray(session)
    error = np.empty(len(q))
    first = None
    for s in np.unique(session):
        rows = np.flatnonzero(session == s)
        registration = nominal_registration(robot, q[rows], measured[rows])
        first = first or registration
        error[rows] = nominal_error(registration, robot, q[rows], measured[rows]).error
    out = [NominalError(error, "measured", first)]
    if held_out is not None:
        out.append(nominal_error(first, robot, held_out[0], held_out[1]))
    return out


__all__ = ["NOMINAL_DEFINITION", "NominalError", "nominal_error", "nominal_errors", "nominal_registration"]
