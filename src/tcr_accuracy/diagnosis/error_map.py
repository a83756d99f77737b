"""Effect parameters -> error vectors per pose, stored by what depends on the pose.

An effect's parameters map linearly onto the error vector of every pose
(:class:`~tcr_accuracy.model.errors.ErrorModel`): x = map @ theta. Stored densely the map is
(N, p_em, k), about 40 MB per effect at 10^4 poses and 10x that at 10^5, although most of it
is the same for every pose (link geometry, frames) or lives in the n_joints drive entries
(joint offsets, encoder scale, transmission, compliance, backlash). :class:`ErrorMap` keeps
the three parts apart:

* ``fixed`` (p_em, k): the part that is the same for every pose;
* ``per_pose`` (N, e, k_pose) for the columns ``pose_columns`` whose error-vector entries
  change with the pose (lateral compliance, thermal growth), over the e entries ``pose_entries``
  of the error vector they move (a few of its p_em: stored whole it was 95 MB at 10^4 poses for
  the vocabulary's three such effects, 12 MB over their entries);
* ``drive`` (N, n_joints, k_drive) for the columns ``drive_columns``: joint-side offsets,
  placed in the error model's drive slice; where each of them moves one joint only (every
  per-joint effect: offsets, compliance, gear errors, a cyclic series of 300 terms), stored as
  (N, k_drive) values and the joint each moves (``drive_joint``), n_joints times smaller.
"""

from __future__ import annotations

import numpy as np


class ErrorMap:
    """x(theta) = fixed @ theta + per_pose @ theta[pose_columns] (into pose_entries) + drive @ theta[drive_columns]
    (the last into the drive slice), per pose."""

    #: poses at a time where a product over all poses would be a large temporary
    CHUNK = 2048

    def __init__(self, n_poses: int, size: int, drive_slice: slice, fixed: np.ndarray,
                 per_pose: np.ndarray | None = None, pose_columns=(), drive: np.ndarray | None = None,
                 drive_columns=(), drive_joint=None, pose_entries=None):
        self.n_poses, self.size, self.drive_slice = n_poses, size, drive_slice
        self.fixed = fixed
        self.per_pose, self.pose_columns = per_pose, np.asarray(pose_columns, dtype=int)
        #: (e,) the error-vector entries ``per_pose`` moves (its second axis); None: all p_em of them
        self.pose_entries = np.arange(size) if pose_entries is None else np.asarray(pose_entries, dtype=int)
        self.drive, self.drive_columns = drive, np.asarray(drive_columns, dtype=int)
        #: (k_drive,) the joint each drive column moves, when ``drive`` is (N, k_drive); else None
        self.drive_joint = None if drive_joint is None else np.asarray(drive_joint, dtype=int)

    @property
    def n_drive(self) -> int:
        return self.drive_slice.stop - self.drive_slice.start

    def dense_drive(self) -> np.ndarray | None:
        """``drive`` as (N, n_joints, k_drive), whichever way it is stored."""
        if self.drive is None or self.drive_joint is None:
            return self.drive
        dense = np.zeros((self.drive.shape[0], self.n_drive, self.drive.shape[1]))
        dense[:, self.drive_joint, np.arange(self.drive.shape[1])] = np.asarray(self.drive)
        return dense

    @classmethod
    def of(cls, n_poses: int, size: int, drive_slice: slice, x: np.ndarray | None,
           dq: np.ndarray | None, k: int) -> "ErrorMap":
        """From an effect's parameter Jacobian: x (p_em, k) or (N, p_em, k) or None, dq (N,
        n_joints, k) or None. Columns that are zero in a part are not stored in it."""
        fixed = np.zeros((size, k))
        per_pose, pose_columns, pose_entries = None, [], None
        if x is not None and x.ndim == 2:
            fixed += x
        elif x is not None:
            moving = np.any(x != x[:1], axis=(0, 1))  # columns that differ between poses
            fixed += x[0] * ~moving
            pose_columns = np.flatnonzero(moving)
            if pose_columns.size:
                pose_entries = np.flatnonzero(np.any(x[:, :, pose_columns] != 0, axis=(0, 2)))
                per_pose = np.ascontiguousarray(x[:, pose_entries][:, :, pose_columns])
        return cls(n_poses, size, drive_slice, fixed, per_pose, pose_columns, *_drive_part(dq), pose_entries)

    @classmethod
    def of_entries(cls, n_poses: int, size: int, drive_slice: slice, x: np.ndarray | None, dq: np.ndarray | None,
                   entries, k: int) -> "ErrorMap":
        """The map :meth:`of` builds, from a parameter Jacobian whose per-pose error-vector part is given as
        its nonzero entries (:class:`~tcr_accuracy.effects.pose_entries.PoseEntries`, an effect's
        ``sparse_parameter_jacobian``), without the dense (N, p_em, k) array: x (p_em, k) or None, the part
        the same for every pose; dq as for :meth:`of`."""
        values, entry, column = entries.values, entries.entry, entries.column
        fixed = np.zeros((size, k)) if x is None else np.zeros((size, k)) + x
        varies = np.any(values != values[:1], axis=0)  # (m,) pairs that differ between poses
        moving = np.zeros(k, dtype=bool)
        moving[column[varies]] = True
        still = ~moving[column]
        fixed[entry[still], column[still]] += values[0, still]
        pose_columns = np.flatnonzero(moving)
        per_pose, pose_entries = None, None
        if pose_columns.size:
            kept = moving[column] & np.any(values != 0, axis=0)
            pose_entries = np.unique(entry[kept])
            per_pose = np.zeros((values.shape[0], pose_entries.size, pose_columns.size))
            per_pose[:, np.searchsorted(pose_entries, entry[kept]), np.searchsorted(pose_columns, column[kept])] = \
                values[:, kept]
        return cls(n_poses, size, drive_slice, fixed, per_pose, pose_columns, *_drive_part(dq), pose_entries)

    @classmethod
    def of_joint_columns(cls, n_poses: int, size: int, drive_slice: slice, values: np.ndarray,
                         joint: np.ndarray) -> "ErrorMap":
        """From a parameter Jacobian whose every column moves one joint (an effect's compact
        ``joint_columns``): values (N, k) of d(dq_joint)/d(theta), joint (k,). The map
        :meth:`of` builds from the same Jacobian made dense (N, n_joints, k), without that array."""
        k = values.shape[1]
        if not isinstance(values, np.ndarray):  # rows made when read (a table's): every column is a mode
            return cls(n_poses, size, drive_slice, np.zeros((size, k)), None, [], values, np.arange(k),
                       np.asarray(joint, dtype=int))
        drive_columns = np.flatnonzero(np.any(values != 0, axis=0))
        drive = None
        if drive_columns.size:
            drive = values if drive_columns.size == k else np.ascontiguousarray(values[:, drive_columns])
        return cls(n_poses, size, drive_slice, np.zeros((size, k)), None, [], drive, drive_columns,
                   np.asarray(joint, dtype=int)[drive_columns] if drive_columns.size else None)

    @property
    def n_columns(self) -> int:
        return self.fixed.shape[1]

    def errors(self, theta: np.ndarray, rows=None) -> np.ndarray:
        """Error vectors (len(rows) or N, p_em) at parameters theta (k,)."""
        rows = None if rows is None else np.asarray(rows)
        n = self.n_poses if rows is None else len(rows)
        out = np.empty((n, self.size))
        out[:] = self.fixed @ theta
        if self.per_pose is not None:
            out[:, self.pose_entries] += _rows(self.per_pose @ theta[self.pose_columns], rows)
        if self.drive is not None and self.drive_joint is not None:
            joint = np.zeros((len(self.drive_joint), self.n_drive))
            joint[np.arange(len(self.drive_joint)), self.drive_joint] = 1.0
            weights = theta[self.drive_columns]
            for start in range(0, n, self.CHUNK):  # the (N, k_drive) products a chunk of poses at a time
                part = slice(start, start + self.CHUNK)
                values = (self.drive[part] if rows is None else self.drive[rows[part]]) * weights
                out[part, self.drive_slice] += values @ joint
        elif self.drive is not None:
            out[:, self.drive_slice] += _rows(self.drive @ theta[self.drive_columns], rows)
        return out

    def sensitivity(self, jac_x: np.ndarray, rows=None) -> np.ndarray:
        """The TCP sensitivity (N, r, k) for error Jacobians jac_x (N, r, p_em); with ``rows`` (a slice
        or an index array of the N poses) that of those poses, for jac_x of those rows."""
        g = jac_x @ self.fixed
        if self.per_pose is not None:
            per_pose = self.per_pose if rows is None else self.per_pose[rows]
            g[:, :, self.pose_columns] += jac_x[:, :, self.pose_entries] @ per_pose  # batched over poses
        if self.drive is not None and self.drive_joint is not None:
            # a chunk of poses at a time: whole, the gathered Jacobian columns and their product were two
            # more (N, r, k) arrays, 80 MB each for a cyclic series of 336 terms at 10^4 poses
            drive = self.drive if rows is None else self.drive[rows]
            for start in range(0, g.shape[0], self.CHUNK):
                at = slice(start, start + self.CHUNK)
                g[at, :, self.drive_columns] += (jac_x[at][:, :, self.drive_slice][:, :, self.drive_joint]
                                                 * np.asarray(drive[at])[:, None, :])
        elif self.drive is not None:
            g[:, :, self.drive_columns] += jac_x[:, :, self.drive_slice] @ (self.drive if rows is None
                                                                             else self.drive[rows])
        return g

    def factors_only(self) -> bool:
        """Whether every column moves one joint's drive and nothing else (:meth:`joint_sensitivity`
        then gives the sensitivity as its factors)."""
        return not (self.drive is None or self.drive_joint is None or self.per_pose is not None
                    or np.any(self.fixed))

    def joint_sensitivity(self, jac_x: np.ndarray, jac_q: np.ndarray | None = None):
        """The TCP sensitivity as :meth:`sensitivity`, left as its two factors
        (:class:`JointColumnsSensitivity`) when every column moves one joint and nothing else (a
        cyclic series: its (N, r, k) product was 806 MB at 10^5 poses, the factors n_joints x
        r + k floats a pose); else the dense array. ``jac_q``: the drive columns of jac_x (N, r,
        n_joints), contiguous, when the caller shares one copy of them among several effects."""
        if not self.factors_only():
            return self.sensitivity(jac_x)
        if jac_q is None:
            jac_q = np.ascontiguousarray(jac_x[:, :, self.drive_slice])
        return JointColumnsSensitivity(jac_q, self.drive, self.drive_joint, self.drive_columns, self.n_columns)

    def take(self, columns) -> "ErrorMap":
        """The map of some of its columns, in the given order."""
        columns = np.asarray(columns, dtype=int)
        pose_pos, pose_new = _positions(self.pose_columns, columns)
        drive_pos, drive_new = _positions(self.drive_columns, columns)
        compact = self.drive_joint is not None
        drive = None if not drive_pos.size else (ColumnSubset.of(self.drive, drive_pos) if compact else
                                                 self.drive[:, :, drive_pos])
        return ErrorMap(self.n_poses, self.size, self.drive_slice, self.fixed[:, columns],
                        _columns(self.per_pose, pose_pos) if pose_pos.size else None, pose_new,
                        drive, drive_new, self.drive_joint[drive_pos] if compact and drive_pos.size else None,
                        self.pose_entries)

    @classmethod
    def concatenate(cls, maps: list["ErrorMap"]) -> "ErrorMap":
        """The maps side by side (their columns one after the other)."""
        first = maps[0]
        offsets = np.cumsum([0] + [m.n_columns for m in maps])
        fixed = np.concatenate([m.fixed for m in maps], axis=1)
        pose = [(m.per_pose, m.pose_columns + o, m.pose_entries) for m, o in zip(maps, offsets)
                if m.per_pose is not None]
        entries = np.unique(np.concatenate([e for _, _, e in pose])) if pose else None
        if len(pose) > 1:  # the entries any of them moves, each map's zero in the others'
            pose = [(_embedded(p, e, entries), c, entries) for p, c, e in pose]
        driven = [m for m in maps if m.drive is not None]
        compact = bool(driven) and all(m.drive_joint is not None for m in driven)
        drive = [(m.drive if compact else m.dense_drive(), m.drive_columns + o)
                 for m, o in zip(maps, offsets) if m.drive is not None]
        return cls(first.n_poses, first.size, first.drive_slice, fixed,
                   _joined([p for p, _, _ in pose], axis=2) if pose else None,
                   np.concatenate([c for _, c, _ in pose]) if pose else (),
                   (ColumnBlocks([d for d, _ in drive]) if compact else _joined([d for d, _ in drive], axis=2))
                   if drive else None,
                   np.concatenate([c for _, c in drive]) if drive else (),
                   np.concatenate([m.drive_joint for m in driven]) if compact else None, entries)


class JoinedMaps:
    """Maps side by side, as :meth:`ErrorMap.concatenate` joins them, for their errors alone: x(theta)
    is the sum of each map's errors at its own part of theta, the maps' arrays never joined (a model
    of the whole vocabulary joined its effects' per-pose arrays, each spread over the union of
    their entries: 1 GB at 10^5 poses, the diagnosis' memory peak)."""

    def __init__(self, maps: list):
        self.maps = list(maps)
        # one robot's error model at one set of poses: the errors are summed entry by entry
        shapes = sorted({(m.n_poses, m.size) for m in self.maps})
        if len(shapes) != 1:
            raise ValueError(f"maps joined side by side must share their poses and error vector: (poses, size) {shapes}")
        ends = np.cumsum([m.n_columns for m in self.maps])
        self.bounds = list(zip(np.concatenate([[0], ends[:-1]]).astype(int), ends.astype(int)))
        self.n_poses, self.size = self.maps[0].n_poses, self.maps[0].size

    def errors(self, theta: np.ndarray, rows=None) -> np.ndarray:
        """Error vectors (len(rows) or N, p_em) at parameters theta (k,): the maps' errors summed."""
        out = None
        for m, (start, stop) in zip(self.maps, self.bounds):
            x = m.errors(theta[start:stop], rows)
            if out is None:
                out = x
            else:
                out += x
        return out


class _SensitivityRows:
    """A TCP sensitivity (N, r, k) that makes its rows when indexed: ``g[rows]``, ``g[rows, ...]``, ``g[i]``
    (subclasses give :meth:`rows` for a slice or an index array)."""

    dtype = np.dtype(float)

    def __getitem__(self, key):
        if not isinstance(key, tuple):
            key = (key,)
        if isinstance(key[0], (int, np.integer)):
            return self.rows([key[0]])[0][key[1:]]
        return self.rows(key[0])[(slice(None),) + key[1:]]


class SensitivityWhenRead(_SensitivityRows):
    """A TCP sensitivity (N, r, k) made when its rows are read, from the effect's error map (compact:
    what is the same for every pose, its per-pose entries, its drive values) and the error Jacobians
    (N, r, p_em), which every effect held so shares: ``g[rows]`` is :meth:`ErrorMap.sensitivity` of
    those rows (the same floats as the whole array's rows). At 10^5 poses geometry, lateral compliance,
    thermal growth and drift held 350 MB of dense sensitivities, the shared Jacobians are 130 MB.
    ``np.asarray`` of it is the whole dense array."""

    def __init__(self, basis: ErrorMap, jac_x: np.ndarray):
        self.basis, self.jac_x = basis, jac_x
        self.shape = (jac_x.shape[0], jac_x.shape[1], basis.n_columns)

    def rows(self, rows) -> np.ndarray:
        """g[rows] (len(rows), r, k) for a slice or an index array."""
        return self.basis.sensitivity(self.jac_x[rows], rows)

    def __array__(self, dtype=None, copy=None):
        out = np.empty(self.shape)
        for start in range(0, self.shape[0], ErrorMap.CHUNK):
            at = slice(start, start + ErrorMap.CHUNK)
            out[at] = self.rows(at)
        return out if dtype is None else out.astype(dtype)


class JointColumnsSensitivity(_SensitivityRows):
    """A TCP sensitivity (N, r, k) whose every column moves one joint, held as its two factors:
    g[n, :, c] = jac_q[n, :, joint[c]] * values[n, c] (the joints' columns of the error Jacobian times
    each parameter's joint offset per unit). Rows are made on demand (``g[rows]``, ``g[rows, ...]``:
    the same floats as the dense product), and the products the fit takes are formed from the
    factors (:meth:`transposed_times`). ``np.asarray`` of it is the whole dense array."""

    def __init__(self, jac_q: np.ndarray, values: np.ndarray, joint: np.ndarray, columns: np.ndarray, k: int):
        """jac_q (N, r, n_joints), values (N, k_drive), joint (k_drive,), columns (k_drive,) of the k."""
        self.jac_q, self.values, self.joint, self.columns = jac_q, values, joint, columns
        self.shape = (jac_q.shape[0], jac_q.shape[1], k)

    def rows(self, rows) -> np.ndarray:
        """g[rows] (len(rows), r, k) for a slice or an index array."""
        jac_q, values = self.jac_q[rows], self.values[rows]
        product = jac_q[:, :, self.joint]
        product *= values[:, None, :]
        if self.columns.size == self.shape[2]:  # every column moves its joint (columns are increasing)
            return product
        out = np.zeros((jac_q.shape[0], self.shape[1], self.shape[2]))
        out[:, :, self.columns] = product
        return out

    def __array__(self, dtype=None, copy=None):
        out = self.rows(slice(None))
        return out if dtype is None else out.astype(dtype)

    def transposed_times(self, residual: np.ndarray, rows) -> np.ndarray:
        """g[rows]^T residual (k,) for residual (len(rows) or N, r): sum_n values[n, c] u[n, joint[c]]
        with u = jac_q^T residual per pose, a chunk of poses at a time."""
        total = np.zeros(self.shape[2])
        for start in range(0, residual.shape[0], ErrorMap.CHUNK):
            at = slice(start, start + ErrorMap.CHUNK)
            where = at if rows is None else rows[at]
            u = np.einsum("nij,ni->nj", self.jac_q[where], residual[at])
            total[self.columns] += np.einsum("nc,nc->c", self.values[where], u[:, self.joint])
        return total

    def times(self, theta: np.ndarray) -> np.ndarray:
        """g @ theta (N, r, m) for parameter vectors theta (k, m): per joint, its columns' values times
        their parameters (N, m), times the joint's column of the error Jacobian; a chunk of poses at
        a time. The values are read in place (:func:`_pieces`): a model's kept terms of a cyclic series
        were gathered (copied) at every product, most of its time."""
        n, r, _ = self.shape
        theta = np.asarray(theta)[self.columns]
        pieces = _pieces(self.values)
        if pieces is None:  # values whose rows are made when read
            return self._gathered_times(theta)
        # per stored array and joint, the run of the array's columns the joint's columns occupy and their
        # parameters spread over it (zero on the columns not kept)
        runs = []
        for array, stored, own in pieces:
            for j in np.unique(self.joint[own]):
                mine = self.joint[own] == j
                if not np.any(theta[own[mine]]):
                    continue
                lo, hi = int(stored[mine].min()), int(stored[mine].max()) + 1
                weights = np.zeros((hi - lo, theta.shape[1]))
                np.add.at(weights, stored[mine] - lo, theta[own[mine]])
                runs.append((array, slice(lo, hi), weights, j))
        out = np.zeros((n, r, theta.shape[1]))
        for start in range(0, n, ErrorMap.CHUNK):
            at = slice(start, start + ErrorMap.CHUNK)
            for array, columns, weights, j in runs:
                out[at] += self.jac_q[at, :, j, None] * (array[at, columns] @ weights)[:, None, :]
        return out

    def _gathered_times(self, theta: np.ndarray) -> np.ndarray:
        """:meth:`times` for theta (k_drive, m) already of the stored columns, the values' rows read a
        chunk at a time."""
        n, r, _ = self.shape
        out = np.zeros((n, r, theta.shape[1]))
        joints = [(j, np.flatnonzero(self.joint == j)) for j in np.unique(self.joint)]
        joints = [(j, _run(c)) for j, c in joints if np.any(theta[c])]
        for start in range(0, n, ErrorMap.CHUNK):
            at = slice(start, start + ErrorMap.CHUNK)
            values = np.asarray(self.values[at])
            for j, columns in joints:
                out[at] += self.jac_q[at, :, j, None] * (values[:, columns] @ theta[columns])[:, None, :]
        return out


def _pieces(values) -> list | None:
    """Where the columns of compact drive values (N, k) are stored: [(array (N, k_a), its columns (c,),
    the values' columns they are (c,))], through :class:`ColumnSubset` and :class:`ColumnBlocks`; None
    when some are rows made when read."""
    if isinstance(values, np.ndarray):
        every = np.arange(values.shape[1])
        return [(values, every, every)]
    if isinstance(values, ColumnSubset):
        inner = _pieces(values.values)
        if inner is None or np.unique(values.positions).size < values.positions.size:
            return None
        place = np.full(values.values.shape[1], -1)
        place[values.positions] = np.arange(values.positions.size)
        out = []
        for array, stored, own in inner:
            kept = place[own] >= 0
            if np.any(kept):
                out.append((array, stored[kept], place[own[kept]]))
        return out
    if isinstance(values, ColumnBlocks):
        out, offset = [], 0
        for block in values.blocks:
            inner = _pieces(block)
            if inner is None:
                return None
            out += [(array, stored, own + offset) for array, stored, own in inner]
            offset += block.shape[1]
        return out
    return None


class ColumnBlocks:
    """Arrays (N, k_i) side by side, read as one (N, sum k_i) a chunk of rows at a time and never
    joined whole: the compact drive columns of a model's effects (joined, a model with the cyclic effect
    copied its 336 columns: 300 MB at 10^5 poses per model evaluated). ``blocks[rows]`` is the joined
    rows (the same floats as the joined array's)."""

    def __init__(self, blocks: list):
        self.blocks = [b for block in blocks for b in (block.blocks if isinstance(block, ColumnBlocks) else [block])]
        self.shape = (self.blocks[0].shape[0], sum(b.shape[1] for b in self.blocks))

    def __getitem__(self, rows) -> np.ndarray:
        return _joined([b[rows] for b in self.blocks], axis=1)

    def __array__(self, dtype=None, copy=None):
        out = _joined([np.asarray(b) for b in self.blocks], axis=1)
        return out if dtype is None else out.astype(dtype)


def _drive_part(dq: np.ndarray | None) -> tuple:
    """(drive, drive_columns, drive_joint) of :class:`ErrorMap` from d(dq)/d(theta) (N, n_joints, k) or None."""
    drive, drive_columns, drive_joint = None, [], None
    if dq is not None:
        moved = np.any(dq != 0, axis=0)  # (n_joints, k): which joints each column moves
        drive_columns = np.flatnonzero(moved.any(axis=0))
        if drive_columns.size and np.all(moved[:, drive_columns].sum(axis=0) == 1):
            drive_joint = np.argmax(moved[:, drive_columns], axis=0)
            drive = np.ascontiguousarray(dq[:, drive_joint, drive_columns])
        elif drive_columns.size:
            drive = np.ascontiguousarray(dq[:, :, drive_columns])
    return drive, drive_columns, drive_joint


class ColumnSubset:
    """Some columns of an (N, k) array (or :class:`ColumnBlocks`), read a chunk of rows at a time and
    never copied whole: a model's kept columns of an effect's compact drive values (copied, the kept
    terms of a cyclic series were 250 MB at 10^5 poses per model evaluated). ``subset[rows]`` is those
    rows of the chosen columns (the same floats as the copy's)."""

    def __init__(self, values, positions: np.ndarray):
        self.values, self.positions = values, np.asarray(positions, dtype=int)
        self.shape = (values.shape[0], self.positions.size)

    @staticmethod
    def of(values, positions: np.ndarray):
        """values[:, positions]: values itself when that is all of it in order, else a subset."""
        positions = np.asarray(positions, dtype=int)
        if positions.size == values.shape[1] and np.array_equal(positions, np.arange(positions.size)):
            return values
        return ColumnSubset(values, positions)

    def __getitem__(self, rows) -> np.ndarray:
        return np.asarray(self.values[rows])[:, self.positions]

    def __array__(self, dtype=None, copy=None):
        out = np.asarray(self.values)[:, self.positions]
        return out if dtype is None else out.astype(dtype)


def column_rms(g, components: slice = slice(None)) -> np.ndarray:
    """(k,) RMS over the poses of each column's norm over the given components of g (N, r, k): the TCP motion
    of each parameter per unit; a chunk of poses at a time (g may be a :class:`JointColumnsSensitivity`)."""
    total = np.zeros(g.shape[2])
    for start in range(0, g.shape[0], ErrorMap.CHUNK):
        total += np.sum(g[start:start + ErrorMap.CHUNK][:, components, :] ** 2, axis=(0, 1))
    return np.sqrt(total / max(g.shape[0], 1))


def _columns(values: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """values[..., positions]; the array itself (no copy) when that is all of it in order."""
    if positions.size == values.shape[-1] and np.array_equal(positions, np.arange(positions.size)):
        return values
    return values[..., positions]


def _joined(arrays: list, axis: int) -> np.ndarray:
    """np.concatenate, without the copy of a single array."""
    return arrays[0] if len(arrays) == 1 else np.concatenate(arrays, axis=axis)


def _embedded(values: np.ndarray, entries: np.ndarray, into: np.ndarray) -> np.ndarray:
    """(N, e, k) values over error entries ``entries`` spread over the entries ``into`` (a superset), zero elsewhere."""
    out = np.zeros((values.shape[0], into.size, values.shape[2]))
    out[:, np.searchsorted(into, entries)] = values
    return out


def _rows(values: np.ndarray, rows) -> np.ndarray:
    return values if rows is None else values[rows]


def _positions(stored: np.ndarray, wanted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For the wanted columns that are stored: their positions in the store, and their new
    column numbers (positions in ``wanted``)."""
    where = {int(c): i for i, c in enumerate(stored)}
    pairs = [(where[int(c)], new) for new, c in enumerate(wanted) if int(c) in where]
    return (np.array([p for p, _ in pairs], dtype=int), np.array([n for _, n in pairs], dtype=int))


def _run(index: np.ndarray):
    """A slice for consecutive indices (a view when taken), else the index array itself."""
    if index.size and np.all(np.diff(index) == 1):
        return slice(int(index[0]), int(index[-1]) + 1)
    return index
