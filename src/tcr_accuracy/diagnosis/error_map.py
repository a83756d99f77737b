"""Effect parameters -> error vectors per pose, stored by what depends on the pose.

An effect's parameters map linearly onto the error vector of every pose
(:class:`~tcr_accuracy.model.errors.ErrorModel`): x = map @ theta. Stored densely the map is
(N, p_em, k), about 40 MB per effect at 10^4 poses and 10x that at 10^5, although most of it
is the same for every pose (link geometry, frames) or lives in the n_joints drive entries
(joint offsets, encoder scale, transmission, compliance, backlash). :class:`ErrorMap` keeps
the three parts apart:

* ``fixed`` (p_em, k): the part that is the same for every pose;
* ``per_pose`` (N, p_em, k_pose) for the columns ``pose_columns`` whose error-vector entries
  change with the pose (lateral compliance, thermal growth);
* ``drive`` (N, n_joints, k_drive) for the columns ``drive_columns``: joint-side offsets,
  placed in the error model's drive slice.
"""

from __future__ import annotations

import numpy as np


class ErrorMap:
    """x(theta) = fixed @ theta + per_pose @ theta[pose_columns] + drive @ theta[drive_columns]
    (the last into the drive slice), per pose."""

    def __init__(self, n_poses: int, size: int, drive_slice: slice, fixed: np.ndarray,
                 per_pose: np.ndarray | None = None, pose_columns=(), drive: np.ndarray | None = None,
                 drive_columns=()):
        self.n_poses, self.size, self.drive_slice = n_poses, size, drive_slice
        self.fixed = fixed
        self.per_pose, self.pose_columns = per_pose, np.asarray(pose_columns, dtype=int)
        self.drive, self.drive_columns = drive, np.asarray(drive_columns, dtype=int)

    @classmethod
    def of(cls, n_poses: int, size: int, drive_slice: slice, x: np.ndarray | None,
           dq: np.ndarray | None, k: int) -> "ErrorMap":
        """From an effect's parameter Jacobian: x (p_em, k) or (N, p_em, k) or None, dq (N,
        n_joints, k) or None. Columns that are zero in a part are not stored in it."""
        fixed = np.zeros((size, k))
        per_pose, pose_columns = None, []
        if x is not None and x.ndim == 2:
            fixed += x
        elif x is not None:
            moving = np.any(x != x[:1], axis=(0, 1))  # columns that differ between poses
            fixed += x[0] * ~moving
            pose_columns = np.flatnonzero(moving)
            per_pose = np.ascontiguousarray(x[:, :, pose_columns]) if pose_columns.size else None
        drive, drive_columns = None, []
        if dq is not None:
            drive_columns = np.flatnonzero(np.any(dq != 0, axis=(0, 1)))
            drive = np.ascontiguousarray(dq[:, :, drive_columns]) if drive_columns.size else None
        return cls(n_poses, size, drive_slice, fixed, per_pose, pose_columns, drive, drive_columns)

    @property
    def n_columns(self) -> int:
        return self.fixed.shape[1]

    def errors(self, theta: np.ndarray, rows=None) -> np.ndarray:
        """Error vectors (len(rows) or N, p_em) at parameters theta (k,)."""
        n = self.n_poses if rows is None else len(rows)
        out = np.empty((n, self.size))
        out[:] = self.fixed @ theta
        if self.per_pose is not None:
            out += _rows(self.per_pose @ theta[self.pose_columns], rows)
        if self.drive is not None:
            out[:, self.drive_slice] += _rows(self.drive @ theta[self.drive_columns], rows)
        return out

    def sensitivity(self, jac_x: np.ndarray) -> np.ndarray:
        """The TCP sensitivity (N, r, k) for error Jacobians jac_x (N, r, p_em)."""
        g = jac_x @ self.fixed
        if self.per_pose is not None:
            g[:, :, self.pose_columns] += jac_x @ self.per_pose  # batched over poses
        if self.drive is not None:
            g[:, :, self.drive_columns] += jac_x[:, :, self.drive_slice] @ self.drive
        return g

    def take(self, columns) -> "ErrorMap":
        """The map of some of its columns, in the given order."""
        columns = np.asarray(columns, dtype=int)
        pose_pos, pose_new = _positions(self.pose_columns, columns)
        drive_pos, drive_new = _positions(self.drive_columns, columns)
        return ErrorMap(self.n_poses, self.size, self.drive_slice, self.fixed[:, columns],
                        self.per_pose[:, :, pose_pos] if pose_pos.size else None, pose_new,
                        self.drive[:, :, drive_pos] if drive_pos.size else None, drive_new)

    @classmethod
    def concatenate(cls, maps: list["ErrorMap"]) -> "ErrorMap":
        """The maps side by side (their columns one after the other)."""
        first = maps[0]
        offsets = np.cumsum([0] + [m.n_columns for m in maps])
        fixed = np.concatenate([m.fixed for m in maps], axis=1)
        pose = [(m.per_pose, m.pose_columns + o) for m, o in zip(maps, offsets) if m.per_pose is not None]
        drive = [(m.drive, m.drive_columns + o) for m, o in zip(maps, offsets) if m.drive is not None]
        return cls(first.n_poses, first.size, first.drive_slice, fixed,
                   np.concatenate([p for p, _ in pose], axis=2) if pose else None,
                   np.concatenate([c for _, c in pose]) if pose else (),
                   np.concatenate([d for d, _ in drive], axis=2) if drive else None,
                   np.concatenate([c for _, c in drive]) if drive else ())


def _rows(values: np.ndarray, rows) -> np.ndarray:
    return values if rows is None else values[rows]


def _positions(stored: np.ndarray, wanted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For the wanted columns that are stored: their positions in the store, and their new
    column numbers (positions in ``wanted``)."""
    where = {int(c): i for i, c in enumerate(stored)}
    pairs = [(where[int(c)], new) for new, c in enumerate(wanted) if int(c) in where]
    return (np.array([p for p, _ in pairs], dtype=int), np.array([n for _, n in pairs], dtype=int))
