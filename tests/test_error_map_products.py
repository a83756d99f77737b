"""A per-joint sensitivity held as its factors times parameter vectors (``ErrorMap``'s
:class:`JointColumnsSensitivity.times`, issue 39: the values read in place, never gathered), against the
dense (N, r, k) product written out here, for the ways a model's drive values are stored: one array, some
of its columns (a model's kept terms), effects side by side, and a subset of those."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.error_map import ColumnBlocks, ColumnSubset, ErrorMap, JointColumnsSensitivity

N, JOINTS = 40, 4


def _dense(jac_q: np.ndarray, values: np.ndarray, joint: np.ndarray) -> np.ndarray:
    """g[n, :, c] = jac_q[n, :, joint[c]] * values[n, c], column by column."""
    out = np.zeros((jac_q.shape[0], jac_q.shape[1], values.shape[1]))
    for c in range(values.shape[1]):
        out[:, :, c] = jac_q[:, :, joint[c]] * values[:, c, None]
    return out


@pytest.mark.parametrize("storage", ["array", "subset", "blocks", "subset of blocks"])
def test_factored_sensitivity_times_parameters_is_the_dense_product(monkeypatch, storage):
    """g @ theta (N, r, m) for three parameter vectors (one of them zero on a whole joint) against the dense
    product, with chunks of poses that do not divide N. The kept columns are out of order and interleave
    the joints. Seen failing when a subset's columns were mapped by their stored positions instead of their
    place in the subset (``place[own[kept]]`` turned to ``own[kept]``)."""
    monkeypatch.setattr(ErrorMap, "CHUNK", 7)
    rng = np.random.default_rng(4)
    first, second = rng.standard_normal((N, 9)), rng.standard_normal((N, 6))
    joint_first, joint_second = rng.integers(0, JOINTS, 9), rng.integers(0, JOINTS, 6)
    kept = np.array([7, 1, 2, 5, 0, 8])  # some columns of the first, out of order
    if storage == "array":
        values, joint = first, joint_first
    elif storage == "subset":
        values, joint = ColumnSubset(first, kept), joint_first[kept]
    elif storage == "blocks":
        values, joint = ColumnBlocks([first, second]), np.concatenate([joint_first, joint_second])
    else:
        chosen = np.array([10, 3, 11, 0, 8, 5])
        values = ColumnSubset(ColumnBlocks([ColumnSubset(first, kept), second]), chosen)
        joint = np.concatenate([joint_first[kept], joint_second])[chosen]
    plain = np.asarray(values)
    k = plain.shape[1]
    jac_q = rng.standard_normal((N, 3, JOINTS))
    g = JointColumnsSensitivity(jac_q, values, joint, np.arange(k), k)
    theta = rng.standard_normal((k, 3))
    theta[joint == joint[0], 1] = 0.0  # a vector that moves one joint not at all
    expected = np.einsum("nrk,km->nrm", _dense(jac_q, plain, joint), theta)
    np.testing.assert_allclose(g.times(theta), expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
