"""The robot a set of effects describes, and its Jacobian in their parameters.

::

    TCP = tcp_poses(robot, q + sum(dq), sum(x), error_model)

Every effect adds joint offsets ``dq`` and/or placement errors ``x`` (never output
positions); :func:`prediction_jacobian` chains Pinocchio's frame Jacobian (joint side)
and frame kinematic regressor (placement side) with the effects' parameter maps.
"""

from __future__ import annotations

import warnings
from typing import Sequence

import numpy as np

from ..model.context import MeasurementContext
from ..model.errors import ErrorModel
from ..exceptions import InputError
from ..model.jacobians import error_jacobians
from ..model.kinematics import TcpPoses, tcp_poses
from ..model.robot import JointLimitWarning, RobotModel
from .base import Effect


def _as_context(context, n_rows: int, n_joints: int) -> MeasurementContext:
    return context if context is not None else MeasurementContext.defaults(n_rows, n_joints)


def total_perturbation(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                       context: MeasurementContext | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sum of the effects' outputs: dq (N, n_joints) and x (N, n_error_params)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if len(effects) != len(params_list):
        raise InputError(f"{len(effects)} effects but {len(params_list)} parameter vectors")
    context = _as_context(context, q.shape[0], robot.n_joints)
    em = ErrorModel(robot)
    dq = np.zeros_like(q)
    x = np.zeros((q.shape[0], em.size))
    for effect, params in zip(effects, params_list):
        out = effect.perturb(params, q, context)
        if out.dq is not None:
            dq = dq + out.dq
        if out.x is not None:
            x = x + out.x
    return dq, x


def predict_poses(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                  context: MeasurementContext | None = None) -> TcpPoses:
    """TCP poses of the robot the effects describe: ``tcp_poses(robot, q + dq, x)``.

    q : (N, n_joints) commanded joints [SI]; params_list : one (k_e,) array per effect.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    dq, x = total_perturbation(robot, effects, params_list, q, context)
    em = ErrorModel(robot)
    return tcp_poses(robot, q + dq, x if x.any() else None, em if x.any() else None)


def fixed_point_motion(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                       context: MeasurementContext | None = None) -> np.ndarray:
    """(N, 3) [m] how far the TCP moves when the effects' joint offsets are evaluated at the
    deflected joints q + dq instead of the commanded q (one fixed-point step).

    The effects are first order in their own deflection: compliance takes the gravity
    torque at the commanded pose, not at the pose it sags to. This is the size of what that
    leaves out (zero for offsets that do not depend on q, tiny for scale errors).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    context = _as_context(context, q.shape[0], robot.n_joints)
    dq, x = total_perturbation(robot, effects, params_list, q, context)
    dq_at_deflected, _ = total_perturbation(robot, effects, params_list, q + dq, context)
    em = ErrorModel(robot)
    first = tcp_poses(robot, q + dq, x if x.any() else None, em if x.any() else None).position
    second = tcp_poses(robot, q + dq_at_deflected, x if x.any() else None, em if x.any() else None).position
    return second - first


def predict_positions(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                      context: MeasurementContext | None = None) -> np.ndarray:
    """(N, 3) TCP positions [m] of the robot the effects describe (see :func:`predict_poses`)."""
    return predict_poses(robot, effects, params_list, q, context).position


def prediction_jacobian(robot: RobotModel, effects: Sequence[Effect], params_list, q,
                        context: MeasurementContext | None = None, *, orientation: bool = False
                        ) -> np.ndarray:
    """d(TCP)/d(parameters of all effects), shape (N, 3, K) (or (N, 6, K) with orientation).

    Columns follow the effects' order, each effect's parameters in its own order
    (K = sum of n_params). Stochastic effects (clearance) get zero columns: they add
    scatter, not a predictable displacement. Rows: TCP displacement in base-frame axes
    [m], then rotation vector [rad] with orientation.
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    context = _as_context(context, q.shape[0], robot.n_joints)
    deterministic = [(e, p) for e, p in zip(effects, params_list) if not e.stochastic]
    dq, x = total_perturbation(robot, [e for e, _ in deterministic], [p for _, p in deterministic], q, context)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", JointLimitWarning)
        jq, jx = error_jacobians(robot, q + dq, x)
    rows = 6 if orientation else 3
    jq, jx = jq[:, :rows], jx[:, :rows]
    blocks = []
    for effect, params in zip(effects, params_list):
        block = np.zeros((q.shape[0], rows, effect.n_params))
        if not effect.stochastic:
            maps = effect.parameter_jacobian(params, q, context)
            if maps.dq is not None:
                block += jq @ maps.dq  # (N, r, n) @ (N, n, k)
            if maps.x is not None:
                block += jx @ maps.x  # (N, r, p) @ (p, k) or (N, p, k)
        blocks.append(block)
    return np.concatenate(blocks, axis=2) if blocks else np.zeros((q.shape[0], rows, 0))


def split_parameters(effects: Sequence[Effect], flat) -> list[np.ndarray]:
    """One flat vector (K,) of all effects' parameters -> one (k_e,) array per effect."""
    flat = np.asarray(flat, dtype=float)
    sizes = [e.n_params for e in effects]
    if flat.shape != (sum(sizes),):
        raise InputError(f"{flat.size} parameter values for effects with {sum(sizes)} parameters")
    return np.split(flat, np.cumsum(sizes)[:-1]) if effects else []


def parameter_names(effects: Sequence[Effect]) -> list[str]:
    """Names of all effects' parameters, in the order of prediction_jacobian's columns."""
    return [name for effect in effects for name in effect.parameter_names()]
