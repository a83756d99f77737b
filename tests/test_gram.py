"""The fit engine's Gram-matrix shortcuts against plain numpy/scipy: a factor of the Gram matrix
read as the columns it came from, pivoting through the Gram matrix against LAPACK's pivoted QR,
and an angle table's knots placed by the data's density (counted here on the angles themselves)."""

import numpy as np
from scipy import linalg

from tcr_accuracy.diagnosis.identifiability import GRAM_PIVOTING, _pivoted, gram_factor
from tcr_accuracy.effects import make_effect
from tcr_accuracy.effects.angle_table import MAX_INTERVALS, UNIFORM_SHARE, AngleTableFitPolicy, density_knots
from tcr_accuracy.model.robot import load_robot


def _columns(rng, rows: int, k: int, dependent: int) -> np.ndarray:
    """(rows, k) columns of norms a hundredfold apart (scaled to their typical sizes, as the diagnosis
    reads them), the last ``dependent`` sums of the first ones."""
    a = rng.standard_normal((rows, k - dependent)) * np.logspace(-1, 1, k - dependent)
    mix = rng.standard_normal((k - dependent, dependent))
    return np.hstack([a, a @ mix])


def test_a_factor_of_the_gram_matrix_has_the_columns_gram_matrix():
    rng = np.random.default_rng(0)
    a = _columns(rng, 400, 30, 4)
    gram = a.T @ a
    blocks = gram_factor(gram, {"first": ([f"p{i}" for i in range(10)], np.arange(10)),
                                "rest": ([f"p{i}" for i in range(10, 30)], np.arange(10, 30))}, n_poses=400)
    factor = np.hstack([blocks["first"].g[:, 0, :], blocks["rest"].g[:, 0, :]])
    assert factor.shape[0] == 26  # four columns are sums of others: the factor's rank is the columns'
    rebuilt = factor.T @ factor
    norms = np.sqrt(np.diag(gram))
    # each entry to ~1e-8 of its columns' norms (the factor keeps every column's own relative precision)
    assert np.max(np.abs(rebuilt - gram) / np.outer(norms, norms)) < 1e-8


def test_pivoting_through_the_gram_matrix_follows_pivoted_qr():
    rng = np.random.default_rng(1)
    k = GRAM_PIVOTING + 40
    a = _columns(rng, 2 * k, k, 10)
    tie_break = 1.0 + 1e-9 * np.arange(k, 0, -1) / k
    piv, diag, basis = _pivoted(a, tie_break)
    _, r, piv_qr = linalg.qr(a * tie_break, mode="economic", pivoting=True)
    diag_qr = np.abs(np.diag(r)) / tie_break[piv_qr]
    rank = int(np.sum(diag_qr > 1e-9 * diag_qr[0]))
    assert rank == k - 10
    # the same columns in the same order while they are well apart from round-off, R's diagonal alike
    assert np.array_equal(piv[:rank - 20], piv_qr[:rank - 20])
    np.testing.assert_allclose(diag[:rank - 20], diag_qr[:rank - 20], rtol=1e-6)
    # the same rank read off either diagonal (the dependent columns' own are at round-off)
    assert int(np.sum(diag > 1e-7 * diag[0])) == rank
    q = basis(rank)
    np.testing.assert_allclose(q.T @ q, np.eye(rank), atol=1e-6)
    # the basis spans the pivoted columns: they are reproduced from it
    chosen = a[:, piv[:rank]]
    np.testing.assert_allclose(q @ (q.T @ chosen), chosen, atol=1e-7 * np.max(np.abs(chosen)))


def test_knots_follow_the_poses_and_no_interval_collapses():
    rng = np.random.default_rng(2)
    # 80% of the poses in the first fifth of the travel
    angles = np.concatenate([rng.uniform(-3.0, -1.8, 8000), rng.uniform(-1.8, 3.0, 2000)])
    intervals = 100
    inner = density_knots(angles, -3.0, 3.0, intervals)
    edges = np.concatenate([[-3.0], inner, [3.0]])
    widths = np.diff(edges)
    equal = 6.0 / intervals
    assert np.all(widths >= UNIFORM_SHARE * equal * (1 - 1e-12))
    # most knots where most poses are; each interval's poses counted here
    assert np.sum(inner < -1.8) > 2 * 0.2 * inner.size  # equal intervals: a fifth of them
    counts = np.histogram(angles, edges)[0]
    assert counts.max() < 3 * angles.size / intervals
    # uniform poses: the knots are within a few poses' spacing of the equal ones
    uniform = density_knots(np.linspace(-3.0, 3.0, 100001), -3.0, 3.0, intervals)
    np.testing.assert_allclose(uniform, np.linspace(-3.0, 3.0, intervals + 1)[1:-1], atol=1e-4)


def test_the_diagnosis_gives_a_fine_table_hundreds_of_modes_at_ten_thousand_poses():
    robot = load_robot("ur10")
    rng = np.random.default_rng(3)
    lower, upper = robot.joint_bounds()
    q = rng.uniform(lower, upper, (10_000, 6))
    options = AngleTableFitPolicy().options_for_data(robot, q, None)
    assert 150 <= options["intervals"] <= MAX_INTERVALS
    effect = make_effect("angle_table", robot, **options)
    assert effect.n_params == 6 * (options["intervals"] - 3)
    # the table's rows made when read are those of the whole array
    values, _ = effect.joint_column_values(q)
    whole, _ = effect.joint_columns(q)
    rows = np.array([5, 17, 9999])
    np.testing.assert_array_equal(values[rows], whole[rows])
    np.testing.assert_array_equal(np.asarray(values), whole)


def _table_grams_case(rng, n=1300):
    """Fold Gram blocks of a dense effect, an angle table and another dense effect (the table's columns in
    the middle), on one whitened part, and the same whitened Jacobian written out whole here."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.error_map import JointColumnsSensitivity

    robot = load_robot("ur10")
    lower, upper = robot.joint_bounds()
    q = rng.uniform(lower, upper, (n, 6))
    table = make_effect("angle_table", robot, **AngleTableFitPolicy().options_for_data(robot, q, None))
    values, joint = table.joint_column_values(q)
    k = table.n_params
    table_g = JointColumnsSensitivity(rng.standard_normal((n, 3, 6)), values, joint, np.arange(k), k)

    def basis(g, k):
        return SimpleNamespace(names=[f"p{i}" for i in range(k)], scales=rng.uniform(0.5, 2.0, k),
                               fit_lower=-np.ones(k), fit_upper=np.ones(k), penalty=np.zeros(k),
                               index=[np.arange(k)], per_part=[SimpleNamespace(g=g)])

    bases = {"first": basis(rng.standard_normal((n, 3, 7)), 7), "angle_table": basis(table_g, k),
             "last": basis(rng.standard_normal((n, 3, 5)), 5)}
    whitening = rng.standard_normal((n, 3, 3)) + 3 * np.eye(3)
    part = SimpleNamespace(q=q, rows_per_pose=3, whitening=whitening)
    order = rng.permutation(n)
    repeats = [[(np.setdiff1d(order, t), t) for t in np.array_split(order, 4)],
               [(np.setdiff1d(order[::-1], t), t) for t in np.array_split(order[::-1], 3)]]
    # the whitened Jacobian, whole: each effect's dense columns times their scales, side by side
    columns = [np.asarray(b.per_part[0].g) * b.scales for b in bases.values()]
    jacobian = np.einsum("nij,njk->nik", whitening, np.concatenate(columns, axis=2))
    return part, bases, repeats, jacobian


def test_an_angle_tables_gram_blocks_from_its_splines_are_the_dense_products():
    from tcr_accuracy.diagnosis.gram import FoldGrams

    rng = np.random.default_rng(4)
    part, bases, repeats, jacobian = _table_grams_case(rng)

    def dense(rows):
        j = jacobian[rows].reshape(-1, jacobian.shape[2])
        return j.T @ j

    def check(store):
        scale = np.max(np.abs(dense(slice(None))))
        np.testing.assert_allclose(store.total, dense(slice(None)), rtol=0, atol=1e-11 * scale)
        for blocks, folds in zip(store.held_blocks(), repeats):
            for block, (_, test) in zip(blocks, folds):
                np.testing.assert_allclose(block, dense(test), rtol=0, atol=1e-11 * scale)

    # every effect at once: the table's columns between two dense effects'
    check(FoldGrams([part], bases, repeats))
    # the table joining later (an effect of last resort), then the last effect; the folds' blocks made again
    store = FoldGrams([part], {"first": bases["first"]}, repeats)
    store.bases = bases
    store.extend(["angle_table"])
    store.extend(["last"])
    check(store)
    store.release()
    check(store)
    # J^T W r and r^T W r of a residual, whitened as the rows are
    residual = rng.standard_normal((part.q.shape[0], 3))
    whitened = np.einsum("nij,nj->ni", part.whitening, residual)
    (total, held), (c_total, c_held) = store.residual_products([residual], store.layout.effects)

    def gradient(rows):
        return jacobian[rows].reshape(-1, jacobian.shape[2]).T @ whitened[rows].ravel()

    scale = np.max(np.abs(gradient(slice(None))))
    np.testing.assert_allclose(total, gradient(slice(None)), rtol=0, atol=1e-11 * scale)
    assert abs(c_total - np.sum(whitened**2)) < 1e-10 * c_total
    for products, constants, folds in zip(held, c_held, repeats):
        for product, constant, (_, test) in zip(products, constants, folds):
            np.testing.assert_allclose(product, gradient(test), rtol=0, atol=1e-11 * scale)
            assert abs(constant - np.sum(whitened[test] ** 2)) < 1e-10 * c_total


def test_an_angle_tables_rows_times_steps_are_the_dense_products():
    from tcr_accuracy.diagnosis.gram import sensitivity_times

    rng = np.random.default_rng(5)
    _, bases, _, _ = _table_grams_case(rng, n=300)
    g = bases["angle_table"].per_part[0].g
    theta = rng.standard_normal((g.shape[2], 2))
    theta[: g.shape[2] // 6] = 0.0  # a joint whose parameters do not move
    expected = np.einsum("nrk,km->nrm", np.asarray(g), theta)
    np.testing.assert_allclose(sensitivity_times(g, theta), expected, rtol=0, atol=1e-12 * np.abs(expected).max())


def test_a_penalised_fit_from_blocks_is_the_ridge_solved_here():
    from tcr_accuracy.diagnosis.block_fit import PENALTY_GRID, fit_blocks
    from tcr_accuracy.diagnosis.gram import Quadratic

    rng = np.random.default_rng(6)
    n, k = 400, 30
    x = rng.standard_normal((n, k)) * np.logspace(0, -1, k)
    truth = np.where(np.arange(k) < 5, 1.0, 0.05 * rng.standard_normal(k))
    y = x @ truth + 0.3 * rng.standard_normal(n)  # residual at the anchor: r = -y, the step d fits it
    weights = np.where(np.arange(k) < 5, 0.0, np.linspace(0.1, 10.0, k))  # the first five not penalised
    center = np.zeros(k)
    folds = np.array_split(rng.permutation(n), 5)

    def quadratic(rows):
        return Quadratic(x[rows].T @ x[rows], -x[rows].T @ y[rows], float(y[rows] @ y[rows]))

    total = quadratic(np.arange(n))
    held = [[(lambda rows=rows: quadratic(rows)) for rows in folds]]
    fit = fit_blocks(total, held, -np.full(k, 1e3), np.full(k, 1e3), weights, center)
    # each lambda's k-fold held-out error, solved here on the rows
    grid = np.median(np.diag(total.gram)[weights > 0]) * PENALTY_GRID

    def fold_step(rows, lam):
        train = np.setdiff1d(np.arange(n), rows)
        return np.linalg.solve(x[train].T @ x[train] + lam * np.diag(weights), x[train].T @ y[train])

    scores = [sum(np.sum((y[rows] - x[rows] @ fold_step(rows, lam)) ** 2) for rows in folds) for lam in grid]
    best = int(np.argmin(scores))
    assert fit.grid_index == best and fit.penalty == grid[best]
    for d, rows in zip(fit.fold_steps[0], folds):
        expected = fold_step(rows, grid[best])
        np.testing.assert_allclose(d, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
    for value, rows, d in zip(fit.heldout_ssq[0], folds, fit.fold_steps[0]):
        assert abs(value - np.sum((y[rows] - x[rows] @ d) ** 2)) < 1e-9 * value
    whole = np.linalg.solve(total.gram + grid[best] * np.diag(weights), x.T @ y)
    np.testing.assert_allclose(fit.step, whole, rtol=0, atol=1e-9 * np.abs(whole).max())


def test_identifiability_resuming_a_stored_leading_run_keeps_the_same_columns():
    from tcr_accuracy.diagnosis.identifiability import identifiability

    rng = np.random.default_rng(7)
    a = _columns(rng, 300, 40, 0)
    # effects that share directions: c repeats two of a's columns, d mixes b's and c's
    a = np.hstack([a, a[:, [3, 12]] + 1e-12 * rng.standard_normal((300, 2)), a[:, 20:26] @ rng.standard_normal((6, 4))])
    names = {"a": range(0, 15), "b": range(15, 30), "c": range(30, 42), "d": range(42, 46)}
    gram = a.T @ a
    bases = gram_factor(gram, {e: ([f"{e}{i}" for i in cols], np.asarray(cols)) for e, cols in names.items()},
                        n_poses=300)
    prefixes: dict = {}
    for order in (["a", "b", "c"], ["a", "b", "d"], ["a", "b", "c", "d"], ["a", "c"], ["a", "b", "c", "d"], ["b", "d"]):
        for motion in (0.0, {"a": 0.0, "b": 0.0, "c": 0.5, "d": 0.0}):
            fresh, report = identifiability(bases, order, 1e-6, motion, report=True)
            resumed, _ = identifiability(bases, order, 1e-6, motion, report=False, prefixes=prefixes)
            assert fresh.keys() == resumed.keys()
            for e in order:
                np.testing.assert_array_equal(fresh[e], resumed[e])
    assert len(prefixes) > 2  # leading runs were stored (and some resumed: ["a", "b"] three times)


def test_maps_side_by_side_give_the_dense_jacobians_errors():
    from tcr_accuracy.diagnosis.error_map import ErrorMap, JoinedMaps

    rng = np.random.default_rng(8)
    n, size, drive = 50, 12, slice(4, 10)
    dense, maps = [], []
    for k, kind in ((3, "fixed"), (4, "per pose"), (5, "drive")):
        x = np.zeros((n, size, k))
        dq = None
        if kind == "fixed":
            x[:] = rng.standard_normal((size, k))
        elif kind == "per pose":
            x[:, [0, 2, 11]] = rng.standard_normal((n, 3, k))
        else:
            dq = rng.standard_normal((n, 6, k))
            x[:, drive] = dq
        maps.append(ErrorMap.of(n, size, drive, x[0] if kind == "fixed" else (x if kind == "per pose" else None),
                                dq, k))
        dense.append(x)
    theta = rng.standard_normal(12)
    expected = np.einsum("nek,k->ne", np.concatenate(dense, axis=2), theta)
    rows = np.array([3, 7, 41])
    np.testing.assert_allclose(JoinedMaps(maps).errors(theta), expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(JoinedMaps(maps).errors(theta, rows), expected[rows], rtol=0, atol=1e-12)


def test_a_models_quadratic_with_other_columns_stepped_is_the_sum_of_squares_of_its_rows():
    """FoldGrams.quadratic on a model's columns (scattered over three effects, an angle table's among
    them), the other columns stepped by ``fixed``: its value at a step d is |W r + J_model d + J_other
    fixed|^2 summed here on all rows and on each fold's held-out rows, its Gram and gradient the dense
    products. Seen failing on the stepped columns' term added with the wrong sign (``b + gram[np.ix_(index,
    moved)] @ step`` turned to ``b - ...``) and on the model's block taken in layout order
    (``gram[np.ix_(index, index)]`` turned to ``gram[np.ix_(np.sort(index), np.sort(index))]``)."""
    from tcr_accuracy.diagnosis.gram import FoldGrams

    rng = np.random.default_rng(7)
    part, bases, repeats, jacobian = _table_grams_case(rng, n=300)
    store = FoldGrams([part], bases, repeats)
    residual = rng.standard_normal((part.q.shape[0], 3))
    whitened = np.einsum("nij,nj->ni", part.whitening, residual)
    products = store.residual_products([residual], store.layout.effects)
    n_columns = jacobian.shape[2]
    index = np.sort(rng.choice(n_columns, n_columns // 2, replace=False))[::-1].copy()  # not in layout order
    fixed = np.zeros(n_columns)
    others = np.setdiff1d(np.arange(n_columns), index)
    fixed[others[::2]] = rng.standard_normal(others[::2].size)
    d = rng.standard_normal(index.size)
    for repeat, fold, rows in [(None, None, np.arange(part.q.shape[0]))] + \
            [(r, f, test) for r, folds in enumerate(repeats) for f, (_, test) in enumerate(folds)]:
        quad = store.quadratic(index, fixed, repeat, fold, products=products)
        j = jacobian[rows].reshape(-1, n_columns)
        moved = whitened[rows].ravel() + j @ fixed
        expected = np.sum((moved + j[:, index] @ d) ** 2)
        assert abs(quad.value(d) - expected) < 1e-10 * expected
        scale = np.abs(j[:, index].T @ j[:, index]).max()
        np.testing.assert_allclose(quad.gram, j[:, index].T @ j[:, index], rtol=0, atol=1e-11 * scale)
        np.testing.assert_allclose(quad.gradient, j[:, index].T @ moved, rtol=0,
                                   atol=1e-11 * np.abs(j[:, index].T @ moved).max())
