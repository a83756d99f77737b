"""The fold Gram blocks of a measured frame with orientation rows, whitened positions and an angle table's
columns among dense ones (``diagnosis/gram.py``), and the layout's bounds of a column of zero scale,
against the dense products written out here with numpy: the whitened Jacobian W J (only the three
position rows whitened), its J^T J over all rows and each fold's held-out rows, J^T W r and r^T W r of a
residual. Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from tcr_accuracy.diagnosis.error_map import JointColumnsSensitivity
from tcr_accuracy.diagnosis.gram import ColumnLayout, FoldGrams


def _basis(rng, g, k, scales=None, fit=1.0):
    return SimpleNamespace(names=[f"p{i}" for i in range(k)],
                           scales=rng.uniform(0.5, 2.0, k) if scales is None else np.asarray(scales, dtype=float),
                           fit_lower=-fit * np.ones(k), fit_upper=2 * fit * np.ones(k), penalty=np.zeros(k),
                           index=[np.arange(k)], per_part=[SimpleNamespace(g=g)])


def test_an_angle_tables_blocks_on_a_frame_with_orientation_rows_are_the_whitened_dense_products():
    """An angle table's columns (their blocks from its B-spline designs) between two dense effects, on a
    frame of 6 rows per pose whose 3 position rows are whitened: the total and each fold's held-out Gram
    block, J^T W r and r^T W r of a residual are those of the dense whitened Jacobian. Seen failing on
    ``_whitened_joint_jacobian``'s ``jac[:, :3]`` turned to ``jac[:, :4]`` on either side and on
    ``residual_products``' ``r[:, :jac.shape[1]]`` turned to ``jac.shape[2]``."""
    from tcr_accuracy.effects import make_effect
    from tcr_accuracy.effects.angle_table import AngleTableFitPolicy
    from tcr_accuracy.model.robot import load_robot

    rng = np.random.default_rng(4301)
    n, rows = 240, 6
    robot = load_robot("ur10")
    q = rng.uniform(*robot.joint_bounds(), (n, 6))
    table = make_effect("angle_table", robot, **AngleTableFitPolicy().options_for_data(robot, q, None))
    values, joint = table.joint_column_values(q)
    k = table.n_params
    table_g = JointColumnsSensitivity(rng.standard_normal((n, rows, 6)), values, joint, np.arange(k), k)
    bases = {"first": _basis(rng, rng.standard_normal((n, rows, 4)), 4), "angle_table": _basis(rng, table_g, k),
             "last": _basis(rng, rng.standard_normal((n, rows, 3)), 3)}
    whitening = rng.standard_normal((n, 3, 3)) + 3 * np.eye(3)
    part = SimpleNamespace(q=q, rows_per_pose=rows, whitening=whitening)
    order = rng.permutation(n)
    repeats = [[(np.setdiff1d(order, t), t) for t in np.array_split(order, 3)]]
    jacobian = np.concatenate([np.asarray(b.per_part[0].g) * b.scales for b in bases.values()], axis=2)
    jacobian[:, :3] = np.einsum("nij,njk->nik", whitening, jacobian[:, :3])
    store = FoldGrams([part], bases, repeats)
    assert store._structured(0, "angle_table") is table_g  # the table's blocks from its designs

    def dense(r):
        j = jacobian[r].reshape(-1, jacobian.shape[2])
        return j.T @ j

    scale = np.abs(dense(slice(None))).max()
    np.testing.assert_allclose(store.total, dense(slice(None)), rtol=0, atol=1e-11 * scale)
    for block, (_, test) in zip(store.held_blocks()[0], repeats[0]):
        np.testing.assert_allclose(block, dense(test), rtol=0, atol=1e-11 * scale)
    residual = rng.standard_normal((n, rows))
    whitened = residual.copy()
    whitened[:, :3] = np.einsum("nij,nj->ni", whitening, residual[:, :3])
    (total, held), (c_total, c_held) = store.residual_products([residual], store.layout.effects)
    expected = jacobian.reshape(-1, jacobian.shape[2]).T @ whitened.ravel()
    np.testing.assert_allclose(total, expected, rtol=0, atol=1e-11 * np.abs(expected).max())
    assert abs(c_total - np.sum(whitened**2)) < 1e-12 * c_total
    for product, constant, (_, test) in zip(held[0], c_held[0], repeats[0]):
        part_expected = jacobian[test].reshape(-1, jacobian.shape[2]).T @ whitened[test].ravel()
        np.testing.assert_allclose(product, part_expected, rtol=0, atol=1e-11 * np.abs(expected).max())
        assert abs(constant - np.sum(whitened[test] ** 2)) < 1e-12 * c_total


def test_a_column_of_zero_scale_keeps_its_fit_range_as_it_is():
    """The layout's bounds in phi = theta / scale: each fit range divided by its column's scale, and left as
    it is where the scale is zero (no division by zero); the scales, names and offsets of the effects
    side by side. Seen failing on ``np.where(self.scale > 0, ...)`` turned to ``self.scale > -1`` (for the
    lower and for the upper bound)."""
    rng = np.random.default_rng(4302)
    bases = {"a": _basis(rng, None, 3, scales=[2.0, 0.0, 0.5], fit=0.3),
             "b": _basis(rng, None, 2, scales=[4.0, 0.25], fit=1.0)}
    layout = ColumnLayout(bases)
    np.testing.assert_array_equal(layout.scale, [2.0, 0.0, 0.5, 4.0, 0.25])
    np.testing.assert_allclose(layout.lower, [-0.15, -0.3, -0.6, -0.25, -4.0], rtol=1e-15)
    np.testing.assert_allclose(layout.upper, [0.3, 0.6, 1.2, 0.5, 8.0], rtol=1e-15)
    assert layout.names == ["p0", "p1", "p2", "p0", "p1"] and layout.n_columns == 5
    assert (layout.offset, layout.size) == ({"a": 0, "b": 3}, {"a": 3, "b": 2})
    np.testing.assert_array_equal(layout.indices(["b", "a"], {"a": [2, 0], "b": [1]}), [4, 2, 0])
    np.testing.assert_array_equal(layout.columns_of(["b", "a"]), [3, 4, 0, 1, 2])


def test_an_effect_joining_an_anchored_store_adds_its_blocks_and_products_as_a_store_made_with_it():
    """Blocks made for effects a and b, anchored at a residual, then effect c joining (an effect of last
    resort): the total and held-out Gram blocks, J^T W r of the anchor over all rows and each fold, and the
    anchor's phi (zero on c's columns) are those of the dense whitened Jacobian of a, b and c written out
    here; each effect's rows times steps (``moved_rows``, unweighted, 2100 poses: the dense products a chunk
    of 2048 at a time) are the dense J s. Seen failing on ``extend``'s ``total[k_old:]`` turned to
    ``total[k_old + 1:]``, on the folds' ``n[k_old:]`` turned to ``n[k_old - 1:]``, on
    ``np.zeros(self.layout.n_columns - k_old)`` turned to ``+ k_old`` and on ``sensitivity_times``' chunk
    ``start + 4 * CHUNK`` turned to ``start - 4 * CHUNK``."""
    from tcr_accuracy.diagnosis.gram import Anchor, moved_rows

    rng = np.random.default_rng(4303)
    n, rows = 2100, 3
    gs = {"a": rng.standard_normal((n, rows, 3)), "b": rng.standard_normal((n, rows, 2)),
          "c": rng.standard_normal((n, rows, 4))}
    bases = {e: _basis(rng, g, g.shape[2]) for e, g in gs.items()}
    whitening = rng.standard_normal((n, 3, 3)) + 3 * np.eye(3)
    part = SimpleNamespace(q=np.zeros((n, 6)), rows_per_pose=rows, whitening=whitening)
    order = rng.permutation(n)
    repeats = [[(np.setdiff1d(order, t), t) for t in np.array_split(order, 3)]]
    store = FoldGrams([part], {"a": bases["a"], "b": bases["b"]}, repeats)
    residual = 1e-3 * rng.standard_normal((n, rows))
    anchor_phi = rng.standard_normal(5)
    store.set_anchor(Anchor(("a",), anchor_phi, [residual]))
    store.bases = bases
    store.extend(["c"])
    jacobian = np.concatenate([gs[e] * bases[e].scales for e in "abc"], axis=2)
    jacobian = np.einsum("nij,njk->nik", whitening, jacobian)
    whitened = np.einsum("nij,nj->ni", whitening, residual)
    flat = jacobian.reshape(-1, 9)
    scale = np.abs(flat.T @ flat).max()
    np.testing.assert_allclose(store.total, flat.T @ flat, rtol=0, atol=1e-11 * scale)
    np.testing.assert_array_equal(store.anchor.phi, np.r_[anchor_phi, np.zeros(4)])
    total, held = store.gradients
    expected = flat.T @ whitened.ravel()
    np.testing.assert_allclose(total, expected, rtol=0, atol=1e-11 * np.abs(expected).max())
    for block, gradient, (_, test) in zip(store.held_blocks()[0], held[0], repeats[0]):
        j = jacobian[test].reshape(-1, 9)
        np.testing.assert_allclose(block, j.T @ j, rtol=0, atol=1e-11 * scale)
        np.testing.assert_allclose(gradient, j.T @ whitened[test].ravel(), rtol=0, atol=1e-11 * np.abs(expected).max())
    steps = rng.standard_normal((9, 2))
    steps[3:5] = 0.0  # b not moved
    unweighted = np.concatenate([gs[e] * bases[e].scales for e in "abc"], axis=2)
    np.testing.assert_allclose(moved_rows(bases, store.layout, 0, steps, n, rows),
                               np.einsum("nrk,km->nrm", unweighted, steps), rtol=1e-12, atol=1e-12)


def test_a_parts_columns_out_of_the_unions_order_land_in_their_union_places_to_the_last_chunk():
    """A part holding an effect's union columns 2, 0 (its own order, and not column 1) over 513 poses (a last
    chunk of one pose): its Gram block and J^T r are those of the dense Jacobian with each column in its union
    place and zero in column 1. Seen failing on ``_block``'s ``out[:, :values.shape[1], at + index]`` turned
    to ``values.shape[0]`` (and the same in its in-order branch's ``np.multiply(..., out=out[:,
    :values.shape[1], ...])``) and on ``at + index`` turned to ``at - index``."""
    rng = np.random.default_rng(4304)
    n = 513
    g = rng.standard_normal((n, 3, 2))
    basis = _basis(rng, g, 3)
    basis.index = [np.array([2, 0])]
    other = _basis(rng, rng.standard_normal((n, 3, 2)), 2)
    part = SimpleNamespace(q=np.zeros((n, 6)), rows_per_pose=3, whitening=None)
    order = rng.permutation(n)
    repeats = [[(np.setdiff1d(order, t), t) for t in np.array_split(order, 2)]]
    store = FoldGrams([part], {"other": other, "a": basis}, repeats)
    dense = np.zeros((n, 3, 5))
    dense[:, :, :2] = other.per_part[0].g * other.scales
    dense[:, :, 2 + 2] = g[:, :, 0] * basis.scales[2]
    dense[:, :, 2 + 0] = g[:, :, 1] * basis.scales[0]
    flat = dense.reshape(-1, 5)
    np.testing.assert_allclose(store.total, flat.T @ flat, rtol=0, atol=1e-11 * np.abs(flat.T @ flat).max())
    residual = rng.standard_normal((n, 3))
    (total, _), _ = store.residual_products([residual], store.layout.effects)
    np.testing.assert_allclose(total, flat.T @ residual.ravel(), rtol=0, atol=1e-10)
