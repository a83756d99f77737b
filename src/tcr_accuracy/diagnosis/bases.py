"""Each effect linearised on the measured poses: the measured frames (:class:`Part`), one effect on
one part (:class:`EffectBasis`), one effect over all parts with its parameters by name
(:class:`UnionBasis`), and the error Jacobians they are chained with.

For every effect and part, the effect's parameters map linearly onto error vectors per pose
(joint-side offsets go into the drive slice of :class:`~tcr_accuracy.model.errors.ErrorModel`);
chained with Pinocchio's error Jacobian (:func:`~tcr_accuracy.model.jacobians.error_jacobians`)
this gives each parameter's column of the identification Jacobian.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..effects import vocabulary
from ..effects.base import LinearEffect
from ..model.context import MeasurementContext
from ..model.errors import ErrorModel
from ..model.jacobians import error_jacobians
from ..model.robot import JointLimitWarning, RobotModel
from .error_map import ErrorMap, SensitivityWhenRead

#: an effect's dense TCP sensitivity (N, r, P) is held up to this many bytes (the largest, lateral compliance's,
#: is 14 MB at 10^4 poses), held as factors or made when read beyond
DENSE_BYTES = 16e6


def ordered(effects) -> list:
    """The effects in vocabulary order."""
    return [e for e in vocabulary() if e in effects]


@dataclass
class Part:
    """One measured frame: its chain, joint values and targets (in the robot's base frame).

    q : (N, n_joints) commanded joints of this chain [rad, m]
    target : (N, 3) measured position in the base frame [m]
    target_rotation : (N, 3, 3) measured orientation in the base frame, or None
    context : the rows' context for this chain (directions of its joints, the other joints)
    orientation_weight : [m/rad] weight of the orientation rows
    label : the frame's name
    whitening : (N, 3, 3) or None, the instrument's per-point weights of the position rows
    """

    robot: RobotModel
    q: np.ndarray
    target: np.ndarray
    context: MeasurementContext
    label: str
    target_rotation: np.ndarray | None = None
    orientation_weight: float = 0.0
    #: (N, 3, 3) each measured point's whitening in the base frame: Sigma^-1/2 of the instrument's
    #: noise times a reference noise (so weighted rows stay metres), or None (every point alike)
    whitening: np.ndarray | None = None

    @property
    def rows_per_pose(self) -> int:
        return 6 if self.target_rotation is not None else 3


class EffectBasis:
    """One effect on one part, linearised: x_total(theta) = basis @ theta per pose.

    ``basis`` (:class:`~tcr_accuracy.diagnosis.error_map.ErrorMap`) gives the error vectors
    (N, p_em) of the parameters, with joint-side offsets dq placed in the drive slice
    (``q + dq`` is a drive offset).
    ``g`` (N, r, P) is the TCP sensitivity (error Jacobian chained with it): position
    rows, then weighted orientation rows when the part measures orientation.
    """

    def __init__(self, effect, part: Part, em: ErrorModel, jac_x: np.ndarray, names: list[str] | None = None,
                 jac_q: np.ndarray | None = None):
        self.effect = effect
        self.name = effect.name
        self.names = list(names if names is not None else effect.parameter_names())
        self.scales = np.asarray(effect.parameter_scales(), dtype=float)
        self.units = list(effect.parameter_units())
        self.lower, self.upper = (np.asarray(b, dtype=float) for b in effect.physical_range())
        self.fit_lower, self.fit_upper = (np.asarray(b, dtype=float) for b in effect.fit_range())
        weights = effect.fit_policy.penalty_weights(effect)
        self.penalty = np.zeros(len(self.names)) if weights is None else np.asarray(weights, dtype=float)
        n, k = part.q.shape[0], len(self.names)
        #: whether g is held as its factors (every column moves one joint: a cyclic series)
        self.factored = hasattr(effect, "joint_columns")
        if self.factored:  # never the dense (N, n_joints, k) Jacobian
            values, joint = effect.joint_column_values(part.q)
            self.basis = ErrorMap.of_joint_columns(n, em.size, em.drive_slice, values, joint)
        elif hasattr(effect, "sparse_parameter_jacobian"):  # never the dense (N, p_em, k) Jacobian
            maps, entries = effect.sparse_parameter_jacobian(np.zeros(k), part.q, part.context)
            self.basis = ErrorMap.of_entries(n, em.size, em.drive_slice, maps.x, maps.dq, entries, k)
        else:
            maps = effect.parameter_jacobian(np.zeros(k), part.q, part.context)
            self.basis = ErrorMap.of(n, em.size, em.drive_slice, maps.x, maps.dq, k)
        self.relinearise(jac_x, jac_q)
        self.nonlinearity = 0.0
        if type(effect).perturb is LinearEffect.perturb:
            return  # perturb is this very map: nothing to check
        # check perturb against the map at one point
        probe = self.scales * np.linspace(-1.0, 1.0, k) if k > 1 else self.scales
        out = effect.perturb(probe, part.q, part.context)
        total = np.zeros((n, em.size))
        if out.x is not None:
            total += out.x
        if out.dq is not None:
            total[:, em.drive_slice] += out.dq
        size = max(float(np.abs(total).max()), 1e-300)
        self.nonlinearity = float(np.abs(total - self.basis.errors(probe)).max() / size)

    def relinearise(self, jac_x: np.ndarray, jac_q: np.ndarray | None = None) -> None:
        """TCP sensitivity (N, r, P) for error Jacobians jac_x (N, r, p_em): the dense array while it is
        at most :data:`DENSE_BYTES` (read faster so), beyond that its factors (a
        :class:`~tcr_accuracy.diagnosis.error_map.JointColumnsSensitivity`) where every column moves
        one joint's drive only (joint offsets, compliance, backlash, gear errors: at 10^5 poses their
        dense arrays were 150 MB, their factors a sixth of it with the drive columns of jac_x shared,
        ``jac_q`` (N, r, n_joints) or None), else made when read
        (:class:`~tcr_accuracy.diagnosis.error_map.SensitivityWhenRead`, holding jac_x, which the caller
        shares among the effects). A per-joint series (``factored``) is held as factors at any size."""
        n, r, _ = jac_x.shape
        large = n * r * self.basis.n_columns * 8 > DENSE_BYTES  # small ones are read faster dense
        if self.basis.factors_only() and (self.factored or large):
            self.g = self.basis.joint_sensitivity(jac_x, jac_q)
        elif large:
            self.g = SensitivityWhenRead(self.basis, jac_x)
        else:
            self.g = self.basis.sensitivity(jac_x)


class UnionBasis:
    """One effect over all parts: its parameters by name, and the stacked sensitivity.

    ``names`` and ``scales`` are the union over the parts (first part's order, then new
    names of later parts); ``index[p]`` maps part p's columns into the union; ``g`` is
    (sum of the parts' N, r, P_union), zero where a part lacks a parameter, for the
    identifiability test.
    """

    def __init__(self, per_part: list[EffectBasis]):
        self.per_part = per_part
        self.name = per_part[0].name
        names: list[str] = []
        scales: list[float] = []
        units: list[str] = []
        bounds: list[tuple[float, float, float, float]] = []
        penalty: list[float] = []
        for b in per_part:
            for name, scale, unit, lo, hi, fit_lo, fit_hi, w in zip(b.names, b.scales, b.units, b.lower, b.upper,
                                                                    b.fit_lower, b.fit_upper, b.penalty):
                if name not in names:
                    names.append(name)
                    scales.append(float(scale))
                    units.append(unit)
                    bounds.append((float(lo), float(hi), float(fit_lo), float(fit_hi)))
                    penalty.append(float(w))
        self.names, self.scales, self.units = names, np.array(scales), units
        #: (P,) physical range of each parameter [SI] (the effect's ``physical_range``)
        self.lower = np.array([bound[0] for bound in bounds])
        self.upper = np.array([bound[1] for bound in bounds])
        #: (P,) the range a fit stays in [SI] (the effect's ``fit_range``)
        self.fit_lower = np.array([bound[2] for bound in bounds])
        self.fit_upper = np.array([bound[3] for bound in bounds])
        #: (P,) smoothness-penalty weight of each parameter in scaled units (0: not penalised)
        self.penalty = np.array(penalty)
        self.index = [np.array([names.index(n) for n in b.names], dtype=int) for b in per_part]
        self.nonlinearity = max(b.nonlinearity for b in per_part)
        self.restack()

    def restack(self) -> None:
        rows = max(b.g.shape[1] for b in self.per_part)
        if len(self.per_part) == 1 and np.array_equal(self.index[0], np.arange(len(self.names))):
            self.g = self.per_part[0].g  # one measured frame: the union is the part itself, no copy
            return
        blocks = []
        for b, idx in zip(self.per_part, self.index):
            block = np.zeros((b.g.shape[0], rows, len(self.names)))
            block[:, :b.g.shape[1], idx] = b.g
            blocks.append(block)
        self.g = np.concatenate(blocks, axis=0)


#: poses whose error Jacobians are taken at once (their temporaries, a few placement-chain arrays of
#: (N, n_joints, 6, 6), were 1 GB at 10^5 poses taken whole)
JACOBIAN_CHUNK = 8192


def position_jacobians(robot: RobotModel, q: np.ndarray, x: np.ndarray | None = None,
                       orientation_weight: float | None = None) -> np.ndarray:
    """Error Jacobians (N, r, p_em) at error vector x (p_em,) or per pose (N, p_em): position rows,
    plus weighted rotation rows; a chunk of poses at a time."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if x is not None and np.ndim(x) == 2:
        xs = np.asarray(x, dtype=float)
        if not np.any(xs != xs[0]):  # one error vector for every pose: the one error_jacobians would take
            x = xs.mean(axis=0)
    out = None
    for start in range(0, q.shape[0], JACOBIAN_CHUNK):
        rows = slice(start, start + JACOBIAN_CHUNK)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", JointLimitWarning)
            _, jx = error_jacobians(robot, q[rows], x if x is None or np.ndim(x) == 1 else x[rows])
        r = 3 if orientation_weight is None else 6
        if out is None:
            out = np.empty((q.shape[0], r, jx.shape[2]))
        out[rows] = jx[:, :r]
        if orientation_weight is not None:
            out[rows, 3:] *= orientation_weight
    return out
