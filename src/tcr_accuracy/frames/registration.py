"""Registering the measurement (tracker) frame to the robot's base frame.

A laser tracker or a camera system reports the TCP in its own frame. Everything that
compares measurements with the model first needs the rigid transform between that
frame and the robot's base,

    p_tracker = R p_base + t,

and, because the measured point is rarely exactly the model's TCP, the TCP offset.
This module is the one home for that fit:

1. **Closed form** (:func:`~tcr_accuracy.frames.rigid.rigid_fit`): the rotation and translation that best map the
   nominal TCP positions onto the measured ones in the least-squares sense (Kabsch;
   scipy's ``Rotation.align_vectors`` on the centred point sets).
2. **Refinement** (:func:`register_tracker`): the ``frames`` effect of
   :mod:`tcr_accuracy.effects` (a base twist applied on the left of the chain and a TCP
   offset in the TCP frame) fitted by nonlinear least squares (scipy's
   ``least_squares``) on top of the closed form, with
   :func:`~tcr_accuracy.effects.predict_positions` as the model and
   :func:`~tcr_accuracy.effects.prediction_jacobian` as its Jacobian. Columns that the
   data cannot tell apart from earlier ones (a TCP offset when the TCP orientation
   hardly changes is a base translation) are held at zero.

The fitted base twist is folded into ``R, t``, so :class:`Registration` maps points
with one rotation and one translation, and its TCP offset belongs to the robot's model
(:meth:`Registration.tcp_positions`). Lengths are metres, angles radians; nothing here
prints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.linalg import qr
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from ..effects import make_effect, predict_positions, prediction_jacobian
from ..exceptions import InputError
from ..model.kinematics import tcp_poses
from ..model.context import MeasurementContext
from ..model.robot import RobotModel
from .rigid import rigid_fit

#: A column whose part not explained by the columns before it is below this fraction of
#: its own size (parameters at their typical scales) is not identifiable and stays 0.
IDENTIFIABILITY_TOL = 1e-6


@dataclass(frozen=True)
class Registration:
    """The measurement (tracker) frame and TCP offset fitted to measured TCP positions.

    Points map as ``p_tracker = rotation @ p_base + translation``.

    Attributes
    ----------
    rotation : ndarray of shape (3, 3)
        Rotation of the base frame in the tracker frame (``trackerRbase``).
    translation : ndarray of shape (3,)
        Position of the base frame's origin in the tracker frame [m].
    frames_parameters : ndarray of shape (k,)
        The fitted ``frames`` effect parameters [m, rad] in the order of
        ``parameter_names``: the base twist (before it was folded into rotation and
        translation) and the TCP offset in the TCP frame.
    parameter_names : tuple of str
        ``frames.base.dx`` ... ``frames.tool.dz``.
    fitted : tuple of str
        The parameters that were fitted; the others are held at 0 (not asked for, or not
        identifiable from these poses).
    closed_form_rotation, closed_form_translation : ndarray of shape (3, 3) and (3,)
        The closed-form (Kabsch) start, before the refinement.
    residual_rms : float
        RMS of |measured - registered model| over the points [m].
    n_points : int
        Number of measured positions used.
    """

    rotation: np.ndarray
    translation: np.ndarray
    frames_parameters: np.ndarray
    parameter_names: tuple
    fitted: tuple
    closed_form_rotation: np.ndarray
    closed_form_translation: np.ndarray
    residual_rms: float
    n_points: int

    # -- mapping points ----------------------------------------------------------------
    def to_base(self, points) -> np.ndarray:
        """Tracker-frame points (N, 3) [m] -> base-frame points (N, 3) [m]."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        return (points - self.translation) @ self.rotation  # R^T (p - t), row by row

    def to_tracker(self, points) -> np.ndarray:
        """Base-frame points (N, 3) [m] -> tracker-frame points (N, 3) [m]."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        return points @ self.rotation.T + self.translation

    def vectors_to_base(self, vectors) -> np.ndarray:
        """Tracker-frame displacements (N, 3) -> base-frame displacements (rotation only)."""
        return np.atleast_2d(np.asarray(vectors, dtype=float)) @ self.rotation

    @property
    def trackerMbase(self) -> np.ndarray:
        """(4, 4) homogeneous transform from the base to the tracker frame
        (``p_tracker = trackerMbase @ p_base``), the name every result gives it."""
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = self.rotation, self.translation
        return out

    @property
    def matrix(self) -> np.ndarray:
        """(4, 4) :attr:`trackerMbase` (its former name, kept for the callers that use it)."""
        return self.trackerMbase

    @property
    def tool_offset(self) -> np.ndarray:
        """(3,) fitted TCP offset in the TCP frame [m] (``frames.tool.dx, dy, dz``)."""
        names = list(self.parameter_names)
        return np.array([self.frames_parameters[names.index(f"frames.tool.{c}")] for c in ("dx", "dy", "dz")])

    # -- the model with the fitted TCP offset ---------------------------------------------
    def tool_parameters(self) -> np.ndarray:
        """(k,) frames parameters with the base twist zeroed (it is in rotation/translation)."""
        params = np.array(self.frames_parameters, dtype=float)
        params[[i for i, n in enumerate(self.parameter_names) if n.startswith("frames.base.")]] = 0.0
        return params

    def tcp_positions(self, robot: RobotModel, q, context: MeasurementContext | None = None) -> np.ndarray:
        """Base-frame TCP positions (N, 3) [m] of the nominal robot with the fitted TCP offset.

        Parameters
        ----------
        robot : RobotModel
            The robot the registration was fitted for.
        q : array-like of shape (N, n_joints)
            Joint values [rad, m].
        context : MeasurementContext, optional
            Unused by the frames effect; passed on for symmetry.
        """
        frames = make_effect("frames", robot)
        return predict_positions(robot, [frames], [self.tool_parameters()], q, context)

    def measured_frame_robot(self, robot: RobotModel) -> RobotModel:
        """The robot whose TCP is the measured point: its TCP frame moved by the fitted TCP
        offset (``frames.tool.*``, in the TCP frame), the chain otherwise nominal. Its TCP
        positions are :meth:`tcp_positions`; what it misses is what the robot itself adds."""
        from ..model.errors import ErrorModel

        em = ErrorModel(robot)
        x = em.zeros()
        x[em.tool_slice.start:em.tool_slice.start + 3] = self.tool_offset
        return em.perturbed_robot(x, name=robot.name)

    def to_dict(self) -> dict:
        """JSON-ready summary (mm, deg; unit-suffixed keys)."""
        rotvec = Rotation.from_matrix(self.rotation).as_rotvec()
        return {
            "rotation_matrix": self.rotation.tolist(),
            "translation_mm": (self.translation * 1e3).tolist(),
            "rotation_vector_deg": np.degrees(rotvec).tolist(),
            "rotation_angle_deg": float(np.degrees(np.linalg.norm(rotvec))),
            "tool_offset_mm": (self.tool_offset * 1e3).tolist(),
            "fitted": list(self.fitted),
            "residual_rms_mm": self.residual_rms * 1e3,
            "n_points": self.n_points,
        }


#: poses the refinement of :func:`register_tracker` uses at most (a random subset above):
#: nine parameters are fixed to noise / sqrt(N), and each iteration's exact Jacobian costs
#: seconds at 10^5 poses
REGISTRATION_MAX_POSES = 20_000


def register_tracker(robot: RobotModel, q, measured, *, context: MeasurementContext | None = None,
                     fit_base: bool = True, fit_tool: bool = True, max_nfev: int = 50) -> Registration:
    """Fit the tracker frame (and the TCP offset) to measured TCP positions.

    Parameters
    ----------
    robot : RobotModel
        The nominal robot.
    q : array-like of shape (N, n_joints)
        Commanded joint values [rad, m].
    measured : array-like of shape (N, 3)
        Measured TCP positions in the tracker frame [m].
    context : MeasurementContext, optional
        Passed to the effect functions (the frames effect does not use it).
    fit_base : bool, default=True
        Fit the tracker frame (closed form, then the base twist). False: the positions
        are already in the base frame (rotation identity, translation zero).
    fit_tool : bool, default=True
        Fit the TCP offset (``frames.tool.dx, dy, dz``).
    max_nfev : int, default=50
        Most function evaluations of the refinement.

    Returns
    -------
    Registration

    Examples
    --------
    >>> import numpy as np
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot("ur5")
    >>> q = np.random.default_rng(0).uniform(-1, 1, (30, 6))
    >>> measured = tcr.tcp_poses(robot, q).position + [1.0, 2.0, 0.5]  # a tracker 2.3 m away, not turned
    >>> frame = tcr.register_tracker(robot, q, measured)
    >>> np.round(frame.trackerMbase[:3, 3], 6)
    array([1. , 2. , 0.5])
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    measured = np.atleast_2d(np.asarray(measured, dtype=float))
    if q.shape[0] != measured.shape[0] or measured.shape[1] != 3 or q.shape[1] != robot.n_joints:
        raise InputError(f"registration: needs joint values (N, {robot.n_joints}) and positions (N, 3), got "
                         f"{q.shape} and {measured.shape}")
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(measured))):
        raise InputError("registration: joint values and positions must be finite")
    nominal = tcp_poses(robot, q).position
    if fit_base:
        r0, t0 = rigid_fit(nominal, measured)
    else:
        r0, t0 = np.eye(3), np.zeros(3)
    all_q, all_measured, all_context = q, measured, context
    if q.shape[0] > REGISTRATION_MAX_POSES:
        rows = np.sort(np.random.default_rng(0).choice(q.shape[0], REGISTRATION_MAX_POSES, replace=False))
        q, measured = q[rows], measured[rows]
        context = None if context is None else context.subset(rows)
    target = (measured - t0) @ r0  # measured points in the closed-form base frame
    frames = make_effect("frames", robot)
    names = tuple(frames.parameter_names())
    wanted = [i for i, n in enumerate(names)
              if (fit_base and n.startswith("frames.base.")) or (fit_tool and n.startswith("frames.tool."))]
    params = frames.zeros()
    fitted: list = []
    if wanted:
        scales = frames.parameter_scales()
        jac0 = prediction_jacobian(robot, [frames], [params], q, context).reshape(-1, len(names))
        active = _identifiable(jac0[:, wanted] * scales[wanted])
        cols = [wanted[k] for k in active]
        fitted = [names[i] for i in cols]

        def full(theta):
            p = np.zeros(len(names))
            p[cols] = theta
            return p

        def residual(theta):
            return (predict_positions(robot, [frames], [full(theta)], q, context) - target).ravel()

        def jacobian(theta):
            jac = prediction_jacobian(robot, [frames], [full(theta)], q, context)
            return jac.reshape(-1, len(names))[:, cols]

        if cols:
            # Levenberg-Marquardt needs no fewer residuals than unknowns: the identifiable columns are
            # independent columns of 3N rows, so never more than 3N
            sol = least_squares(residual, np.zeros(len(cols)), jac=jacobian, x_scale=scales[cols],
                                max_nfev=max_nfev, method="lm")
            params = full(sol.x)
    # fold the base twist into the rigid transform: p_cf = exp6(xi) p_model, p_tracker = R0 p_cf + t0
    base = np.array([params[names.index(f"frames.base.{c}")] for c in ("dx", "dy", "dz", "rx", "ry", "rz")])
    twist = pin.exp6(pin.Motion(base[:3], base[3:]))
    rotation = r0 @ twist.rotation
    translation = r0 @ twist.translation + t0
    tool_only = params.copy()
    tool_only[[i for i, n in enumerate(names) if n.startswith("frames.base.")]] = 0.0
    model = predict_positions(robot, [frames], [tool_only], all_q, all_context)
    rms = float(np.sqrt(np.mean(np.sum((model @ rotation.T + translation - all_measured) ** 2, axis=1))))
    return Registration(rotation=rotation, translation=translation, frames_parameters=params,
                        parameter_names=names, fitted=tuple(fitted), closed_form_rotation=r0,
                        closed_form_translation=t0, residual_rms=rms, n_points=int(all_q.shape[0]))


def _identifiable(columns: np.ndarray) -> list[int]:
    """Indices of columns (in their order of priority) not spanned by the earlier ones.

    A QR decomposition without pivoting: ``|R_kk|`` is the part of column k orthogonal
    to columns 0..k-1; it is compared with the column's own norm.
    """
    if columns.shape[1] == 0:
        return []
    norms = np.linalg.norm(columns, axis=0)
    _, r = qr(columns, mode="economic")
    own = np.abs(np.diag(r))
    return [k for k in range(columns.shape[1]) if norms[k] > 0 and own[k] > IDENTIFIABILITY_TOL * norms[k]]


__all__ = ["Registration", "register_tracker", "rigid_fit"]
