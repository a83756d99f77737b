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
