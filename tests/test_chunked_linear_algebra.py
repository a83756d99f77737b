"""The diagnosis' memory-saving storage and chunked products against the dense formulas written out
here: error maps over the entries they move, the model's Jacobian filled a chunk of poses at a time,
and identifiability's R factor by a tall-skinny QR (R^T R = A^T A)."""

import numpy as np

from tcr_accuracy.diagnosis import fit_columns, identifiability
from tcr_accuracy.diagnosis.error_map import ErrorMap
from tcr_accuracy.diagnosis.identifiability import SensitivityColumns, compressed

N, P_EM, DRIVE = 50, 10, slice(4, 8)  # poses, error-vector size, the drive entries


def _dense(x_fixed, x_pose, dq):
    """The map written out densely: (N, p_em, k)."""
    m = np.broadcast_to(x_fixed, (N,) + x_fixed.shape).copy() if x_fixed is not None else 0.0
    if x_pose is not None:
        m = m + x_pose
    if dq is not None:
        m = m + 0.0
        m[:, DRIVE] += dq
    return m


def _effect(rng, k, pose_entries=(), per_joint=True):
    """A parameter Jacobian: per-pose x on a few error entries, and joint-side dq."""
    x = np.zeros((N, P_EM, k))
    x[:, :, :] = rng.standard_normal((P_EM, k)) * (rng.random((P_EM, k)) < 0.3)  # the same for every pose
    moving = np.zeros((N, P_EM, k))
    for e in pose_entries:
        moving[:, e, : k // 2] = rng.standard_normal((N, k // 2))
    x[:, :, : k // 2] = 0.0  # a moving column moves only its own entries
    x = x + moving
    dq = np.zeros((N, DRIVE.stop - DRIVE.start, k))
    if per_joint:
        for c in range(k // 2, k):
            dq[:, c % dq.shape[1], c] = rng.standard_normal(N)
    return x, dq


def test_error_map_over_its_moving_entries_equals_the_dense_map(monkeypatch):
    monkeypatch.setattr(ErrorMap, "CHUNK", 16)  # several chunks of poses
    rng = np.random.default_rng(3)
    x_a, dq_a = _effect(rng, 6, pose_entries=(1, 7))
    x_b, dq_b = _effect(rng, 4, pose_entries=(2,))
    maps = [ErrorMap.of(N, P_EM, DRIVE, x, dq, x.shape[2]) for x, dq in ((x_a, dq_a), (x_b, dq_b))]
    assert maps[0].per_pose.shape == (N, 2, 3)  # only the two entries that move are stored
    dense = [_dense(None, x, dq) for x, dq in ((x_a, dq_a), (x_b, dq_b))]
    jac_x = rng.standard_normal((N, 3, P_EM))
    for m, d in zip(maps, dense):
        theta = rng.standard_normal(d.shape[2])
        np.testing.assert_allclose(m.errors(theta), np.einsum("npk,k->np", d, theta), rtol=0, atol=1e-12)
        rows = np.array([3, 17, 40])
        np.testing.assert_allclose(m.errors(theta, rows), np.einsum("npk,k->np", d[rows], theta), atol=1e-12)
        np.testing.assert_allclose(m.sensitivity(jac_x), np.einsum("nrp,npk->nrk", jac_x, d), atol=1e-12)
    # two maps with different moving entries side by side, and a part of their columns
    joined = ErrorMap.concatenate(maps)
    both = np.concatenate(dense, axis=2)
    theta = rng.standard_normal(both.shape[2])
    np.testing.assert_allclose(joined.errors(theta), np.einsum("npk,k->np", both, theta), atol=1e-12)
    np.testing.assert_allclose(joined.sensitivity(jac_x), np.einsum("nrp,npk->nrk", jac_x, both), atol=1e-12)
    cols = [8, 0, 2, 5]
    np.testing.assert_allclose(joined.take(cols).errors(theta[:4]),
                               np.einsum("npk,k->np", both[:, :, cols], theta[:4]), atol=1e-12)


def test_jacobian_filled_by_chunks_equals_gathered_columns_times_scales(monkeypatch):
    monkeypatch.setattr(fit_columns.Sensitivity, "CHUNK", 7)
    rng = np.random.default_rng(4)
    g1, g2 = rng.standard_normal((N, 3, 5)), rng.standard_normal((N, 3, 4))
    cols1, cols2 = np.array([4, 0, 2]), np.array([1, 3])
    s = fit_columns.Sensitivity([(g1, cols1), (g2, cols2)])
    gathered = np.concatenate([g1[:, :, cols1], g2[:, :, cols2]], axis=2)
    np.testing.assert_array_equal(s[:, :3, :], gathered)
    scale = rng.random(5) + 0.5
    idx = np.array([2, 0, 4, 1, 3])  # where each gathered column lands
    block = np.zeros((N, 3, 5))
    s.scaled_into(block, idx, scale[idx])
    expected = np.zeros((N, 3, 5))
    expected[:, :, idx] = gathered * scale[idx]
    np.testing.assert_array_equal(block, expected)


def test_tall_skinny_r_has_the_gram_matrix_of_the_scaled_columns(monkeypatch):
    monkeypatch.setattr(identifiability, "QR_CHUNK", 7)  # 50 poses in 8 steps
    rng = np.random.default_rng(5)
    bases = {"a": SensitivityColumns(["a1", "a2", "a3"], rng.standard_normal((N, 3, 3)), rng.random(3) + 0.1),
             "b": SensitivityColumns(["b1", "b2"], rng.standard_normal((N, 3, 2)), rng.random(2) + 0.1)}
    out = compressed(bases)
    r = np.concatenate([out[e].g[:, 0, :] for e in ("a", "b")], axis=1)
    a = np.concatenate([(bases[e].g * bases[e].scales).reshape(-1, bases[e].g.shape[2]) for e in ("a", "b")], axis=1)
    assert r.shape == (5, 5)
    np.testing.assert_allclose(r.T @ r, a.T @ a, rtol=1e-12, atol=1e-12 * np.abs(a.T @ a).max())
    assert np.allclose(np.tril(r, -1), 0.0)
    assert all(out[e].n_poses == N for e in out)

