"""Effects whose every parameter moves one joint's offset only, given as a compact Jacobian."""

from __future__ import annotations

import abc

import numpy as np

from .base import EffectJacobian, EffectOutput, LinearEffect


#: an effect's compact values (N, k) are held as an array up to this many bytes, made when read beyond
HELD_BYTES = 64e6


class RowsWhenRead:
    """An effect's compact Jacobian values (N, k) at fixed joint values, made when rows are read:
    ``values[rows]`` (or ``values[rows, columns]``) is those rows of
    :meth:`JointColumnsEffect.joint_columns`; ``np.asarray`` of it is the whole array."""

    ndim = 2
    dtype = np.dtype(float)

    def __init__(self, effect: "JointColumnsEffect", q: np.ndarray):
        self.effect, self.q = effect, q
        self.shape = (q.shape[0], effect.n_params)

    def __getitem__(self, key):
        rows, columns = (key if isinstance(key, tuple) else (key, slice(None)))
        if isinstance(rows, (int, np.integer)):
            return self.effect.joint_columns(self.q[[rows]])[0][0, columns]
        return self.effect.joint_columns(self.q[rows])[0][:, columns]

    def __array__(self, dtype=None, copy=None):
        out = self.effect.joint_columns(self.q)[0]
        return out if dtype is None else out.astype(dtype)


class JointColumnsEffect(LinearEffect):
    """A linear effect whose every parameter moves one joint's offset only (a series or a table of
    each joint's own angle): it gives its Jacobian in the compact form :meth:`joint_columns`, which
    the diagnosis keeps as it is (never the dense (N, n_joints, k) array: 161 MB at 10^4 poses of a
    six-joint arm with 336 terms), and :meth:`perturb` takes a chunk of poses at a time."""

    #: poses at a time in :meth:`perturb` (its (N, k) values are 27 MB at 10^4 poses of 336 terms)
    CHUNK = 4096
    #: each parameter's physical bound [rad]: a gear or encoder term above 1 mrad (3.4 arc-min) is a fault
    PHYSICAL_LIMIT = 1e-3
    #: each parameter's bound in the fit [rad], wide enough to show such a fault
    FIT_LIMIT = 1e-2

    def physical_range(self):
        return np.full(self.n_params, -self.PHYSICAL_LIMIT), np.full(self.n_params, self.PHYSICAL_LIMIT)

    def fit_range(self):
        return np.full(self.n_params, -self.FIT_LIMIT), np.full(self.n_params, self.FIT_LIMIT)

    @abc.abstractmethod
    def joint_columns(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The parameter Jacobian in its compact form at commanded joints q (N, n_joints).

        Returns
        -------
        values : (N, k) d(dq_j)/d(theta_k) of the joint j = ``joint[k]`` [rad/rad]
        joint : (k,) int, the joint each parameter moves
        """

    def joint_column_values(self, q: np.ndarray) -> tuple:
        """:meth:`joint_columns` as the diagnosis keeps it for all its poses: the same (values, joint),
        values possibly an array-like (N, k) that makes its rows when indexed (``values[rows]``)
        rather than an array (a table of a thousand modes is 100 MB at 10^4 poses). Here: the array
        while it is at most :data:`HELD_BYTES`, else :class:`RowsWhenRead` (a cyclic series of 336
        terms is 27 MB at 10^4 poses, held; 270 MB at 10^5, made a chunk at a time when read)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if q.shape[0] * self.n_params * 8 <= HELD_BYTES:
            return self.joint_columns(q)
        return RowsWhenRead(self, q), self.joint_columns(q[:1])[1]

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(np.asarray(q, dtype=float))
        values, joint = self.joint_columns(q)
        ddq = np.zeros((q.shape[0], self.robot.n_joints, joint.size))
        ddq[:, joint, np.arange(joint.size)] = values
        return EffectJacobian(dq=ddq)

    def perturb(self, params, q, context) -> EffectOutput:
        """Each joint's offset dq (N, n_joints) [rad] at commanded joints q (N, n): the compact
        Jacobian times the parameters, a chunk of poses at a time (never the dense one)."""
        params = self.check_params(params)
        q = np.atleast_2d(np.asarray(q, dtype=float))
        dq = np.zeros((q.shape[0], self.robot.n_joints))
        for start in range(0, q.shape[0], self.CHUNK):
            values, joint = self.joint_columns(q[start:start + self.CHUNK])
            for j in np.unique(joint):
                dq[start:start + self.CHUNK, j] = values[:, joint == j] @ params[joint == j]
        return EffectOutput(dq=dq)
