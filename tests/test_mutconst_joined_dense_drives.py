"""Error maps side by side whose joint-side columns each move several joints (stored dense, not as one
joint per column): the joined map's errors are the parts' joint-side products added, written out
with numpy. Seen failing on ``_joined([...], axis=2)`` turned to ``axis=1`` in
``ErrorMap.concatenate`` (a measuring sample's survivor: no test joined two such maps)."""

import numpy as np

from tcr_accuracy.diagnosis.error_map import ErrorMap


def test_maps_with_dense_drives_side_by_side_add_their_joint_errors():
    rng = np.random.default_rng(3)
    n, joints, size = 7, 6, 9
    drive = slice(3, 9)
    dq_a, dq_b = rng.normal(size=(n, joints, 2)), rng.normal(size=(n, joints, 3))
    x_a = rng.normal(size=(size, 2))
    a = ErrorMap.of(n, size, drive, x_a, dq_a, 2)
    b = ErrorMap.of(n, size, drive, None, dq_b, 3)
    assert a.drive_joint is None and b.drive_joint is None  # every column moves several joints: dense
    joined = ErrorMap.concatenate([a, b])
    theta = rng.normal(size=5)
    expected = np.tile(x_a @ theta[:2], (n, 1))
    expected[:, drive] += np.einsum("njk,k->nj", dq_a, theta[:2]) + np.einsum("njk,k->nj", dq_b, theta[2:])
    np.testing.assert_allclose(joined.errors(theta), expected, rtol=1e-12, atol=1e-14)
    rows = np.array([5, 0, 3])
    np.testing.assert_allclose(joined.errors(theta, rows), expected[rows], rtol=1e-12, atol=1e-14)
