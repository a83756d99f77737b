"""The fast paths around the fit core (issue 39) against the slow ways they replace, computed here:
a measurement table read whole against the cell-by-cell strict reader, and the k-d tree's
neighbours against a brute-force distance sort."""

import itertools

import numpy as np
import pytest

from tcr_accuracy.analysis.semivariogram import nearest_neighbours
from tcr_accuracy.diagnosis.error_map import SensitivityWhenRead
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.io.measurements import parse_measurements
from tcr_accuracy.units import parse_number, parse_number_table

#: every character a number cell may hold, and a few it may not
ALPHABET = "0123456789+-.eE \t_xn"


def _strict(cell: str):
    """parse_number's reading of a cell (stripped, finite), or None: what the table must agree with."""
    try:
        value = parse_number(cell.strip(), finite=True)
    except ValueError:
        return None
    return value


def test_a_table_of_cells_reads_as_the_strict_cell_reader_reads_each_cell():
    rng = np.random.default_rng(0)
    cells = ["".join(rng.choice(list(ALPHABET), size=rng.integers(0, 6))) for _ in range(20000)]
    cells += ["".join(c) for c in itertools.product("1.e-+", repeat=3)]  # every short form near the grammar
    cells += ["1e999", "-1e999", "1_5", "１５", "nan", "inf", " 2.5\t", "+.5e-3", "5.", ".", "e5", ""]
    agreed = 0
    for cell in cells:
        expected = _strict(cell)
        table = parse_number_table([f"{cell},1"], 2)
        if expected is None:
            assert table is None, cell
        else:
            assert table is not None and table[0, 0] == expected and table[0, 1] == 1.0, cell
            agreed += 1
    assert agreed > 500  # the draw held numbers, not only rejects


def test_a_table_refuses_a_row_of_the_wrong_length_and_reads_a_good_one_whole():
    assert parse_number_table(["1,2,3", "4,5"], 3) is None
    assert parse_number_table(["1,2,3", "4,5,6,7"], 3) is None
    values = parse_number_table(["1,2,3", " 4 ,5e1,-6"], 3)
    np.testing.assert_array_equal(values, [[1, 2, 3], [4, 50, -6]])
    assert parse_number_table([], 3).shape == (0, 3)


def _csv(robot, n, rng):
    header = [f"{j}_deg" for j in robot.joint_names] + ["x_mm", "y_mm", "z_mm"]
    q = rng.uniform(-1.0, 1.0, (n, robot.n_joints))
    xyz = rng.uniform(300.0, 600.0, (n, 3))
    rows = [",".join(f"{v:.10g}" for v in np.concatenate([np.rad2deg(a), b])) for a, b in zip(q, xyz)]
    return header, rows


@pytest.mark.parametrize("bad, where", [("1_5", "'1_5' is not a number"), ("", "an empty cell"),
                                        ("1e999", "non-finite value '1e999'"), ("0x10", "'0x10' is not a number")])
def test_a_bad_cell_among_many_good_ones_is_named_by_file_row_and_column(ur5, bad, where):
    header, rows = _csv(ur5, 300, np.random.default_rng(1))
    cells = rows[200].split(",")
    cells[2] = bad
    rows[200] = ",".join(cells)
    text = "# a comment\n" + ",".join(header) + "\n" + "\n".join(rows) + "\n"
    with pytest.raises(InputError) as caught:
        parse_measurements(text, ur5, source="decoy.csv", check_units=False)
    # the comment is row 1, the header row 2: the 201st data row is the file's row 203
    assert str(caught.value).startswith(f"decoy.csv: row 203, column {header[2]}: ")
    assert str(caught.value).endswith(where)


def test_a_file_read_whole_holds_the_numbers_written(ur5):
    rng = np.random.default_rng(2)
    header, rows = _csv(ur5, 500, rng)
    text = ",".join(header) + "\n" + "\n".join(rows) + "\n"
    got = parse_measurements(text, ur5, source="decoy.csv", check_units=False)
    written = np.array([[float(c) for c in r.split(",")] for r in rows])  # Python's float of each cell
    np.testing.assert_array_equal(got.q, np.deg2rad(written[:, :ur5.n_joints]))
    np.testing.assert_array_equal(got.position, written[:, ur5.n_joints:] * 1e-3)
    np.testing.assert_array_equal(got.rows, np.arange(2, 502))


@pytest.mark.parametrize("d", [1, 2, 6])
def test_nearest_neighbours_are_the_k_closest_other_points_by_a_full_sort(d):
    rng = np.random.default_rng(d)
    points = rng.standard_normal((400, d))
    got = nearest_neighbours(points, 7)
    distance = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    np.fill_diagonal(distance, np.inf)  # a point is not its own neighbour
    expected = np.argsort(distance, axis=1, kind="stable")[:, :7]
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("name", ["geometry", "lateral_compliance", "thermal", "drift", "joint_offsets",
                                  "compliance", "transmission"])
def test_a_sensitivity_made_when_read_or_held_as_factors_is_the_chained_dense_jacobian(ur5, monkeypatch, name):
    """Every effect's TCP sensitivity, however the basis holds it (made when read, forced here; factors;
    dense), against the error Jacobian times the effect's dense parameter Jacobian chained by hand."""
    from tcr_accuracy.diagnosis import bases as bases_module
    from tcr_accuracy.diagnosis.bases import EffectBasis, Part, position_jacobians
    from tcr_accuracy.effects.base import make_effect
    from tcr_accuracy.model.context import MeasurementContext
    from tcr_accuracy.model.errors import ErrorModel

    rng = np.random.default_rng(3)
    n = 150
    q = rng.uniform(-2.5, 2.5, (n, ur5.n_joints))
    context = MeasurementContext(np.full(n, 2.0), 20.0 + rng.uniform(-5, 5, n), np.sign(rng.standard_normal((n, 6))),
                                 time_s=np.sort(rng.uniform(0, 3600, n)))
    part = Part(ur5, q, np.zeros((n, 3)), context, "tool0")
    effect = make_effect(name, ur5, **make_effect(name, ur5).fit_policy.options_for_data(ur5, q, context))
    em = ErrorModel(ur5)
    jac_x = position_jacobians(ur5, q)
    maps = effect.parameter_jacobian(np.zeros(effect.n_params), q, context)
    expected = np.zeros((n, 3, effect.n_params))
    if maps.x is not None:
        expected += np.einsum("nrp,npk->nrk", jac_x, np.broadcast_to(maps.x, (n,) + maps.x.shape[-2:]))
    if maps.dq is not None:
        expected += np.einsum("nrj,njk->nrk", jac_x[:, :, em.drive_slice], maps.dq)
    for limit in (0.0, 1e12):  # made when read / held
        monkeypatch.setattr(bases_module, "DENSE_BYTES", limit)
        g = EffectBasis(effect, part, em, jac_x).g
        if limit == 0.0 and name in ("geometry", "lateral_compliance", "thermal", "drift"):
            assert isinstance(g, SensitivityWhenRead)  # the path under test, not the dense array
        assert g.shape == expected.shape
        np.testing.assert_allclose(np.asarray(g), expected, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(g[20:57], expected[20:57], rtol=1e-12, atol=1e-15)
        picked = np.array([140, 3, 77, 3])
        np.testing.assert_allclose(g[picked], expected[picked], rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(g[5], expected[5], rtol=1e-12, atol=1e-15)
