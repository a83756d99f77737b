"""The geometry a URDF can carry, refitted to the whole calibrated model.

A URDF holds geometry only: joint placements (joint zero offsets folded in) and fixed frames.
The diagnosis fitted its geometric parameters together with the non-geometric effects
(transmission, cyclic errors, compliance, drift, ...), and those took their share of what a
URDF could have carried: the diagnosis' geometric part alone is no calibration (the real UR5:
0.2 mm held-out where a geometry-only fit reaches 0.10 mm). So the calibration URDF's geometry
is fitted anew, to the full model's TCP:

* **where**: the calibrated workspace, the measured poses and the midpoints between each of them
  and its five nearest measured neighbours (joint space, each joint scaled by its measured
  span). That is the joint space the poses span where the full model is backed by data; a box
  over the joints' ranges would ask the URDF to follow the model's periodic terms where nothing
  was measured (on the real UR5 it costs 0.005 to 0.01 mm held-out). The sample is fixed by the
  poses: no seed.
* **under what**: each pose as it was measured (its load, the other joints of the tree, its time
  in the campaign; a midpoint as the pose it starts from), or at a load the caller states. So the
  URDF holds the campaign as measured, as a geometry-only fit to the data does.
* **what**: every parameter of :class:`~tcr_accuracy.model.errors.ErrorModel` (joint placement
  twists, drive offsets, base and tool twists) that the residual determines: columns are kept by
  pivoted QR on the Jacobian scaled to 1 mm and 1 mrad, the rest stay at the diagnosis' values.
* **to what**: the full model's TCP position, and its orientation with a small weight (an angle
  counts as the position error it makes at 10 mm, :data:`ORIENTATION_LEVER`). Positions alone
  leave the wrist's frames free to turn while the measured point stays put: on the real UR5 a
  position-only refit turns ``tool0`` by 24 deg to gain 0.0003 mm. The orientation holds every
  frame where the full model has it (0.65 deg from nominal there).

The fit is Gauss-Newton (halved steps) from the diagnosis' geometric part, with Pinocchio's
error Jacobians (:func:`~tcr_accuracy.model.jacobians.error_jacobians`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import qr

from ..analysis.semivariogram import nearest_neighbours
from ..exceptions import InputError
from ..model.context import MeasurementContext
from ..model.errors import ErrorModel
from ..model.jacobians import error_jacobians
from ..model.kinematics import tcp_poses
from .model import AsBuiltModel

#: Most measured poses the refit uses (a random subset beyond; with their samples 6 times as many).
MAX_MEASURED = 2000
#: Measured neighbours a sampled segment may run to.
NEIGHBOURS = 5
#: A column whose pivot is below this share of the largest (1 mm / 1 mrad scaling) is not fitted.
RANK_TOL = 1e-6
#: Every parameter is scaled to this (1 mm for a length, 1 mrad for an angle) in the fit [m, rad].
SCALE = 1e-3
#: An orientation error counts as the position error it makes at this distance [m].
ORIENTATION_LEVER = 0.01


@dataclass(frozen=True)
class CalibrationGeometry:
    """The URDF-expressible geometry closest to a full model over its calibrated workspace.

    x : (n_params,) error vector of :class:`~tcr_accuracy.model.errors.ErrorModel` [m, rad]
    rms : RMS over the poses of |full model - this geometry| (TCP position) [m]
    max : largest such distance [m]
    rotation_rms : RMS of the angle between the two TCP frames [rad]
    n_measured, n_sampled : poses of each kind the fit used
    fitted : names of the parameters fitted (the others kept at the diagnosis' values)
    """

    x: np.ndarray
    rms: float
    max: float
    rotation_rms: float
    n_measured: int
    n_sampled: int
    fitted: tuple


def workspace_sample(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The midpoints between each measured pose and its :data:`NEIGHBOURS` nearest measured
    neighbours (joint space, each joint scaled by its measured span).

    Parameters
    ----------
    q : (N, n_joints) measured joint values [rad, m]

    Returns
    -------
    samples : (N * k, n_joints) [rad, m], k = min(NEIGHBOURS, N - 1)
    origin : (N * k,) index of the measured pose each sample starts from (its context is used)
    """
    q = np.asarray(q, dtype=float)
    span = np.ptp(q, axis=0)
    span[span <= 0] = 1.0
    k = min(NEIGHBOURS, q.shape[0] - 1)
    neighbours = nearest_neighbours(q / span, k)
    origin = np.repeat(np.arange(q.shape[0]), k)
    return 0.5 * (q[origin] + q[neighbours.reshape(-1)]), origin


def refit_geometry(model: AsBuiltModel, q, context: MeasurementContext | None = None, *,
                   payload_kg: float | None = None, random_state=0) -> CalibrationGeometry:
    """The geometry (a URDF's) that best reproduces the full model's TCP over the calibrated workspace.

    Parameters
    ----------
    model : AsBuiltModel
        The full fitted model.
    q : (N, n_joints) the measured joint values [rad, m]
    context : MeasurementContext of those rows, optional
        Their load and the joints outside the chain; samples take their origin row's.
    payload_kg : float, optional
        The load to hold the calibration at [kg] (default: each row's own).
    random_state : int or numpy.random.Generator, default=0
        Seeds the subset of measured poses when there are more than :data:`MAX_MEASURED`.

    Returns
    -------
    CalibrationGeometry

    Examples
    --------
    >>> import tcr_accuracy as tcr
    >>> robot = tcr.load_robot()
    >>> measured = tcr.read_measurements("examples/measured.csv", robot)
    >>> d = tcr.diagnose(robot, measured, effects=["joint_offsets", "compliance"], folds=3)
    >>> geometry = tcr.refit_geometry(tcr.AsBuiltModel.from_diagnosis(robot, d), measured.q)
    >>> geometry.x.shape == (tcr.ErrorModel(robot).size,)
    True
    """
    robot = model.robot
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if q.ndim != 2 or q.shape[1] != robot.n_joints or q.shape[0] < 3 or not np.all(np.isfinite(q)):
        raise InputError(f"calibration refit: needs 3 or more finite joint vectors (N, {robot.n_joints}), "
                         f"got shape {q.shape}")
    context = MeasurementContext.defaults(len(q), robot.n_joints) if context is None else context
    if len(q) > MAX_MEASURED:
        keep = np.sort(np.random.default_rng(random_state).choice(len(q), MAX_MEASURED, replace=False))
        q, context = q[keep], context.subset(keep)
    samples, origin = workspace_sample(q)
    poses = np.vstack([q, samples])
    rows = context.subset(np.concatenate([np.arange(len(q)), origin]))
    if payload_kg is not None:
        rows.payload_kg = np.full(len(poses), float(payload_kg))
    target = model.tcp_poses(poses, rows)
    em = ErrorModel(robot)
    x0 = model.geometric_errors()
    problem = _Problem(robot, em, poses, target.position, target.rotation)
    columns = problem.determined_columns(x0)
    x = _gauss_newton(problem, x0, columns)
    pose = tcp_poses(robot, poses, x, em)
    miss = np.linalg.norm(pose.position - target.position, axis=1)
    turn = np.linalg.norm(_rotation_errors(pose.rotation, target.rotation), axis=1)
    return CalibrationGeometry(x=x, rms=float(np.sqrt(np.mean(miss ** 2))), max=float(miss.max()),
                               rotation_rms=float(np.sqrt(np.mean(turn ** 2))), n_measured=len(q),
                               n_sampled=len(samples), fitted=tuple(em.names[i] for i in columns))


def fit_to_poses(robot, q, position, rotation) -> np.ndarray:
    """The error vector (:class:`~tcr_accuracy.model.errors.ErrorModel` of ``robot``) whose robot puts
    its TCP frame at the given poses: the same Gauss-Newton fit, from zero, of every parameter the
    poses determine (the others stay zero: the nearest such robot to ``robot``).

    Parameters
    ----------
    robot : RobotModel
    q : (N, n_joints) joint values [rad, m]
    position : (N, 3) TCP positions [m]; rotation : (N, 3, 3) TCP orientations, base frame

    Returns
    -------
    ndarray of shape (n_params,)
    """
    em = ErrorModel(robot)
    problem = _Problem(robot, em, np.asarray(q, dtype=float), np.asarray(position, dtype=float),
                       np.asarray(rotation, dtype=float))
    x0 = em.zeros()
    return _gauss_newton(problem, x0, problem.determined_columns(x0), max_iter=60)


def _rotation_errors(rotation: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors of ``rotation @ target^T`` (base frame) [rad]."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(rotation @ np.transpose(target, (0, 2, 1))).as_rotvec()


class _Problem:
    """The residual (positions, and orientations times :data:`ORIENTATION_LEVER`) and its Jacobian in
    the error parameters scaled by :data:`SCALE`."""

    def __init__(self, robot, em, poses, position, rotation):
        self.robot, self.em, self.poses, self.position, self.rotation = robot, em, poses, position, rotation

    def residual(self, x) -> np.ndarray:
        pose = tcp_poses(self.robot, self.poses, x, self.em)
        turn = _rotation_errors(pose.rotation, self.rotation) * ORIENTATION_LEVER
        return np.hstack([pose.position - self.position, turn]).reshape(-1)

    def jacobian(self, x, columns) -> np.ndarray:
        _, jx = error_jacobians(self.robot, self.poses, x, self.em)
        jac = jx[:, :, columns]
        jac[:, 3:] *= ORIENTATION_LEVER
        return jac.reshape(-1, len(columns)) * SCALE

    def determined_columns(self, x0) -> np.ndarray:
        """Indices of the parameters the residual determines (pivoted QR, :data:`RANK_TOL`)."""
        _, r, pivots = qr(self.jacobian(x0, np.arange(self.em.size)), mode="economic", pivoting=True)
        diagonal = np.abs(np.diag(r))
        return np.sort(pivots[: int(np.sum(diagonal > RANK_TOL * diagonal[0]))])


def _gauss_newton(problem: _Problem, x0, columns, max_iter: int = 30) -> np.ndarray:
    """Least squares on the problem's residual over ``columns`` of x: Gauss-Newton steps
    (least-squares solves of the scaled Jacobian) halved until the cost falls, to a relative
    change of 1e-10."""
    x = x0.copy()
    r = problem.residual(x)
    cost = float(r @ r)
    for _ in range(max_iter):
        step = np.linalg.lstsq(problem.jacobian(x, columns), -r, rcond=None)[0] * SCALE
        for shrink in 0.5 ** np.arange(12):
            trial = x.copy()
            trial[columns] += shrink * step
            r_trial = problem.residual(trial)
            if float(r_trial @ r_trial) < cost:
                break
        else:
            break
        cost_trial = float(r_trial @ r_trial)
        x, r, done = trial, r_trial, cost - cost_trial <= 1e-10 * cost
        cost = cost_trial
        if done:
            break
    return x
