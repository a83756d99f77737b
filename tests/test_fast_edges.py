"""The fast paths around the fit core (issue 39) against the slow ways they replace, computed here:
a measurement table read whole against the cell-by-cell strict reader, and the k-d tree's
neighbours against a brute-force distance sort."""

import itertools

import numpy as np
import pytest

from tcr_accuracy.analysis.semivariogram import nearest_neighbours
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
