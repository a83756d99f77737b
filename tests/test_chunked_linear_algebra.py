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
    expected = np.zeros((N, 3, 5))
    expected[:, :, idx] = gathered * scale[idx]
    for idx in (idx, np.arange(5)):  # scattered columns, and a run of them (written in place)
        expected = np.zeros((N, 3, 5))
        expected[:, :, idx] = gathered * scale[idx]
        jac = fit_columns.ChainedJacobian(s, idx, scale)
        np.testing.assert_array_equal(np.concatenate([jac.block(c) for c in jac.chunks(None)]), expected)


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



def test_chained_jacobian_products_equal_the_dense_jacobian(monkeypatch):
    """J^T J, J^T r and J s taken a chunk of poses at a time from the effects' columns equal the
    products of the dense J = W G S written out here (whitened position rows, a part whose columns
    land in a larger model, a fold's rows)."""
    monkeypatch.setattr(fit_columns.Sensitivity, "CHUNK", 7)
    rng = np.random.default_rng(6)
    g1, g2 = rng.standard_normal((N, 6, 5)), rng.standard_normal((N, 6, 4))
    cols1, cols2 = np.array([4, 0, 2]), np.array([1, 3])
    idx = np.array([5, 0, 2, 1, 4])  # the part's 5 columns among the model's 6 (column 3: another part's)
    scale = rng.random(6) + 0.5
    whitening = rng.standard_normal((N, 3, 3)) + 3.0 * np.eye(3)
    gathered = np.concatenate([g1[:, :, cols1], g2[:, :, cols2]], axis=2)
    dense = np.zeros((N, 6, 6))
    dense[:, :, idx] = gathered * scale[idx]
    dense[:, :3] = np.einsum("nij,njk->nik", whitening, dense[:, :3])
    jac = fit_columns.ChainedJacobian(fit_columns.Sensitivity([(g1, cols1), (g2, cols2)]), idx, scale, whitening)
    rows = np.sort(rng.choice(N, 23, replace=False))
    for r in (None, rows):
        d = dense if r is None else dense[r]
        flat = d.reshape(-1, 6)
        gram = fit_columns.gram_matrix([jac], r)
        np.testing.assert_allclose(gram, flat.T @ flat, rtol=1e-12, atol=1e-12 * np.abs(flat.T @ flat).max())
        residual = rng.standard_normal((d.shape[0], 6))
        gradient = fit_columns.gradient_vector([jac], [residual], r, N)
        expected = flat.T @ residual.ravel()
        np.testing.assert_allclose(gradient, expected, rtol=1e-12, atol=1e-12 * np.abs(expected).max())
    step = rng.standard_normal(6)
    np.testing.assert_allclose(jac.times(step, rows), dense[rows] @ step, rtol=1e-12, atol=1e-13)


def test_compact_cyclic_jacobian_is_the_derivative_of_the_series_written_out():
    """The cyclic effect's compact Jacobian (values, joint) expanded to (N, n_joints, k) equals the
    central differences of the Fourier series dq_j = sum_n a_n sin(n q_j) + b_n cos(n q_j) written
    out here, its perturb equals that series, and the error map built from the compact form is the
    one built from the dense Jacobian."""
    from tcr_accuracy.effects import make_effect
    from tcr_accuracy.model.robot import load_robot

    robot = load_robot("ur10")
    effect = make_effect("cyclic", robot, max_order=7)
    rng = np.random.default_rng(7)
    q = rng.uniform(-3.0, 3.0, (40, robot.n_joints))
    theta = rng.standard_normal(effect.n_params) * 1e-4

    def series(theta):  # (N, n_joints) [rad], from the parameter names alone
        dq = np.zeros(q.shape)
        for value, name in zip(theta, effect.parameter_names()):
            _, joint, term = name.split(".")
            j, n = robot.joint_names.index(joint), int(term[1:])
            dq[:, j] += value * (np.sin(n * q[:, j]) if term[0] == "a" else np.cos(n * q[:, j]))
        return dq

    values, joint = effect.joint_columns(q)
    expanded = np.zeros((len(q), robot.n_joints, effect.n_params))
    expanded[:, joint, np.arange(effect.n_params)] = values
    h = 1e-6
    numeric = np.stack([(series(theta + h * e) - series(theta - h * e)) / (2 * h)
                        for e in np.eye(effect.n_params)], axis=2)
    np.testing.assert_allclose(expanded, numeric, rtol=0, atol=1e-8)
    np.testing.assert_allclose(effect.parameter_jacobian(theta, q, None).dq, numeric, rtol=0, atol=1e-8)
    np.testing.assert_allclose(effect.perturb(theta, q, None).dq, series(theta), rtol=1e-13, atol=1e-18)
    compact = ErrorMap.of_joint_columns(len(q), 20, slice(2, 2 + robot.n_joints), values, joint)
    dense = ErrorMap.of(len(q), 20, slice(2, 2 + robot.n_joints), None, expanded, effect.n_params)
    np.testing.assert_array_equal(compact.drive, dense.drive)
    np.testing.assert_array_equal(compact.drive_joint, dense.drive_joint)
    np.testing.assert_array_equal(compact.drive_columns, dense.drive_columns)
    np.testing.assert_array_equal(compact.errors(theta), dense.errors(theta))


def test_least_squares_residual_by_chunks_equals_numpys_lstsq(monkeypatch):
    """The leftover of motion patterns off a model's columns, by a tall-skinny QR a chunk of poses at
    a time, equals numpy's least squares on the whole (3N x k) matrix written out here."""
    from tcr_accuracy.diagnosis import ambiguity

    monkeypatch.setattr(ambiguity, "QR_CHUNK", 6)  # 50 poses in 9 steps
    rng = np.random.default_rng(8)
    g = rng.standard_normal((N, 6, 7))  # orientation rows too: only the position rows are fitted
    cols, scale = np.array([6, 1, 3, 0]), rng.random(4) + 0.5
    model = fit_columns.ChainedJacobian(fit_columns.Sensitivity([(g, cols)]), np.arange(4), scale)
    vectors = rng.standard_normal((N, 3, 2))
    dense = (g[:, :3, cols] * scale).reshape(-1, 4)
    for i in range(2):
        v = vectors[:, :, i].reshape(-1)
        expected = v - dense @ np.linalg.lstsq(dense, v, rcond=None)[0]
        got = ambiguity._least_squares_residual(model, vectors)[:, :, i].reshape(-1)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.abs(v).max())


def test_factored_sensitivity_equals_the_dense_product(monkeypatch):
    """A per-joint map's sensitivity held as its factors gives the dense (N, r, k) product's rows, its
    own J^T r, and the column RMS, against the products written out here."""
    from tcr_accuracy.diagnosis.error_map import JointColumnsSensitivity, column_rms

    monkeypatch.setattr(ErrorMap, "CHUNK", 16)
    rng = np.random.default_rng(9)
    k, joints = 9, DRIVE.stop - DRIVE.start
    values, joint = rng.standard_normal((N, k)), rng.integers(0, joints, k)
    values[:, 4] = 0.0  # a column no pose moves: not stored, zero in g
    jac_x = rng.standard_normal((N, 3, P_EM))
    dense = np.zeros((N, 3, k))
    for c in range(k):
        dense[:, :, c] = jac_x[:, :, DRIVE.start + joint[c]] * values[:, c, None]
    g = ErrorMap.of_joint_columns(N, P_EM, DRIVE, values, joint).joint_sensitivity(jac_x)
    assert isinstance(g, JointColumnsSensitivity)
    rows = np.array([40, 2, 17, 33])
    np.testing.assert_allclose(np.asarray(g), dense, rtol=1e-15, atol=0)
    np.testing.assert_allclose(g[rows], dense[rows], rtol=1e-15, atol=0)
    np.testing.assert_allclose(g[5:30, :2], dense[5:30, :2], rtol=1e-15, atol=0)
    residual = rng.standard_normal((N, 3))
    expected = np.einsum("nrk,nr->k", dense, residual)
    np.testing.assert_allclose(g.transposed_times(residual, None), expected, rtol=1e-12, atol=1e-12)
    expected = np.einsum("nrk,nr->k", dense[rows], residual[rows])
    np.testing.assert_allclose(g.transposed_times(residual[rows], rows), expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(column_rms(g, slice(0, 2)), np.sqrt(np.mean(np.sum(dense[:, :2] ** 2, axis=1), axis=0)),
                               rtol=1e-12)
    every = ErrorMap.of_joint_columns(N, P_EM, DRIVE, values[:, [0, 1, 2, 3, 5]], joint[[0, 1, 2, 3, 5]])
    np.testing.assert_allclose(every.joint_sensitivity(jac_x)[rows], dense[rows][:, :, [0, 1, 2, 3, 5]], rtol=1e-15)


def test_error_jacobians_by_chunks_of_poses_equal_the_whole(monkeypatch):
    """position_jacobians a chunk of poses at a time gives the very floats of error_jacobians over all
    poses at once: no error vector, one for every pose (given per pose), one per pose."""
    import warnings

    from tcr_accuracy.diagnosis import bases
    from tcr_accuracy.model.jacobians import error_jacobians
    from tcr_accuracy.model.robot import load_robot

    monkeypatch.setattr(bases, "JACOBIAN_CHUNK", 16)
    robot = load_robot("ur10")
    rng = np.random.default_rng(10)
    q = rng.uniform(-3.0, 3.0, (N, robot.n_joints))
    p = error_jacobians(robot, q[:1])[1].shape[2]
    per_pose = rng.standard_normal((N, p)) * 1e-4
    for x in (None, np.tile(per_pose[0], (N, 1)), per_pose):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            whole = error_jacobians(robot, q, x)[1]
        np.testing.assert_array_equal(bases.position_jacobians(robot, q, x), whole[:, :3])
        weighted = whole.copy()
        weighted[:, 3:] *= 0.3
        np.testing.assert_array_equal(bases.position_jacobians(robot, q, x, 0.3), weighted)


def test_maps_side_by_side_keep_their_drive_columns_apart(monkeypatch):
    """Per-joint maps concatenated hold their drive values as blocks (never joined whole) and give the
    error vectors and sensitivity of the dense maps written out here; a part of their columns too."""
    from tcr_accuracy.diagnosis.error_map import ColumnBlocks

    monkeypatch.setattr(ErrorMap, "CHUNK", 16)
    rng = np.random.default_rng(11)
    effects = [_effect(rng, 6), _effect(rng, 4)]
    maps = [ErrorMap.of(N, P_EM, DRIVE, None, dq, dq.shape[2]) for _, dq in effects]
    joined = ErrorMap.concatenate(maps)
    assert isinstance(joined.drive, ColumnBlocks)
    dense = np.zeros((N, P_EM, 10))
    dense[:, DRIVE] = np.concatenate([dq for _, dq in effects], axis=2)
    theta = rng.standard_normal(dense.shape[2])
    rows = np.array([49, 3, 17])
    np.testing.assert_allclose(joined.errors(theta), np.einsum("npk,k->np", dense, theta), atol=1e-12)
    np.testing.assert_allclose(joined.errors(theta, rows), np.einsum("npk,k->np", dense[rows], theta), atol=1e-12)
    jac_x = rng.standard_normal((N, 3, P_EM))
    np.testing.assert_allclose(joined.sensitivity(jac_x), np.einsum("nrp,npk->nrk", jac_x, dense), atol=1e-12)
    cols = [7, 0, 2, 5]
    np.testing.assert_allclose(joined.take(cols).errors(theta[:4]),
                               np.einsum("npk,k->np", dense[:, :, cols], theta[:4]), atol=1e-12)
