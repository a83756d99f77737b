"""Error maps' products in the layouts few data sets give (``diagnosis/error_map.py``), against the dense
products written out here with numpy (issue 36). Each test names a planted change it was seen to catch."""

from __future__ import annotations

import numpy as np

from tcr_accuracy.diagnosis.error_map import JointColumnsSensitivity, column_rms


class _Rows:
    """(N, k) values whose rows are made when indexed (as an angle table's are): not an ndarray."""

    def __init__(self, values: np.ndarray):
        self._values, self.shape = values, values.shape

    def __getitem__(self, rows):
        return self._values[rows].copy()


def test_interleaved_joints_columns_made_when_read_multiply_as_the_dense_product():
    """g @ theta for g[n, :, c] = jac_q[n, :, joint[c]] values[n, c], values made when read, with two joints'
    columns interleaved (every other column: neither joint's columns a run) and a third joint's one column:
    the dense product written out with numpy. Seen failing on ``_run``'s ``np.diff(index) == 1`` turned to
    ``== 2`` (every other column read as the run between them)."""
    rng = np.random.default_rng(3502)
    n, k = 12, 6
    jac_q = rng.standard_normal((n, 3, 3))
    joint = np.array([0, 1, 0, 1, 0, 2])
    values = rng.standard_normal((n, k))
    dense = jac_q[:, :, joint] * values[:, None, :]
    g = JointColumnsSensitivity(jac_q, _Rows(values), joint, np.arange(k), k)
    theta = rng.standard_normal((k, 2))
    np.testing.assert_allclose(g.times(theta), np.einsum("nrk,km->nrm", dense, theta), rtol=1e-12, atol=1e-12)


def test_the_rms_motion_of_one_pose_is_each_columns_norm():
    """column_rms over a single pose: each column's norm over the components asked for (N = 1: the mean
    over one pose), and zeros for no pose. Seen failing on ``max(g.shape[0], 1)`` turned to
    ``max(g.shape[0], 2)``."""
    g = np.array([[[3.0, 0.0], [4.0, 1.0], [12.0, 2.0]]])  # (1, 3, 2)
    np.testing.assert_allclose(column_rms(g), [13.0, np.sqrt(5.0)], rtol=1e-15)
    np.testing.assert_allclose(column_rms(g, slice(0, 2)), [5.0, 1.0], rtol=1e-15)
    np.testing.assert_array_equal(column_rms(np.zeros((0, 3, 2))), [0.0, 0.0])


def test_a_dense_sensitivity_times_parameters_over_more_poses_than_a_chunk_is_the_einsum():
    """sensitivity_times of a dense (N, r, k) array over 2100 poses (one chunk of 2048 and a part) and
    over 5 is numpy's einsum. Seen failing on the chunks' step ``range(0, n, 4 * CHUNK)`` turned to
    ``5 * CHUNK`` (poses 2048..2559 left unwritten) and on their slice ``start + 4 * CHUNK`` turned to
    ``3 * CHUNK``."""
    from tcr_accuracy.diagnosis.gram import sensitivity_times

    rng = np.random.default_rng(3503)
    for n in (2100, 5):
        g = rng.standard_normal((n, 3, 4))
        theta = rng.standard_normal((4, 2))
        np.testing.assert_allclose(sensitivity_times(g, theta), np.einsum("nrk,km->nrm", g, theta),
                                   rtol=1e-12, atol=1e-12)


def test_a_map_from_pose_entries_with_a_part_the_same_for_every_pose_is_the_dense_product():
    """ErrorMap.of_entries with a part the same for every pose (x (p_em, k)) and pose entries: one pair whose
    value varies with the pose, one the same at every pose, one sharing its entry and column with x: its
    errors at theta are the dense Jacobian's (x plus the entries placed per pose) times theta, written out
    with numpy. Seen failing on ``np.zeros((size, k)) + x`` turned to ``% x``."""
    from tcr_accuracy.diagnosis.error_map import ErrorMap
    from tcr_accuracy.effects.pose_entries import PoseEntries

    rng = np.random.default_rng(3504)
    n, size, k = 6, 9, 3
    x = np.zeros((size, k))
    x[[0, 2, 8], [0, 1, 2]] = [0.5, -1.5, 2.0]
    values = np.column_stack([rng.standard_normal(n), np.full(n, 0.25), rng.standard_normal(n)])
    entries = PoseEntries(values=values, entry=np.array([1, 4, 2]), column=np.array([0, 2, 1]))
    dense = np.broadcast_to(x, (n, size, k)).copy()
    for i in range(3):
        dense[:, entries.entry[i], entries.column[i]] += values[:, i]
    built = ErrorMap.of_entries(n, size, slice(3, 7), x, None, entries, k)
    theta = np.array([0.3, -2.0, 0.7])
    np.testing.assert_allclose(built.errors(theta), dense @ theta, rtol=1e-13, atol=1e-15)
