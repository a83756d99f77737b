"""The reproductions of issue 12 (an attack on the command line), one test or more each.

Every bad input must end in ONE line on stderr naming the file, row, column or option at
fault, exit code 2, no traceback and no file left behind. The numbers in the test names
(``test_12_09_...``) are the rows of the issue's table.
"""

import json

import pytest

from tcr_accuracy.cli import main


def run(argv, capsys):
    """(exit code, stdout, stderr) of the command line run in-process."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line(err: str, *fragments: str) -> None:
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], err


@pytest.fixture(scope="module")
def measurements(tmp_path_factory):
    """A small simulated measurement CSV of the tool-changer (24 poses)."""
    path = tmp_path_factory.mktemp("hostile") / "m.csv"
    assert main(["simulate", "--n", "24", "--random", "--seed", "2", "--out", str(path), "--quiet"]) == 0
    return path


# ---------------------------------------------------------------------------------------
# 9, 19, 20: option values
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, fragment", [
    (["diagnose", "M", "--seed", "-1"], "--seed -1: want a seed"),
    (["predict", "--train", "M", "--query", "M", "--seed", "-1"], "--seed -1: want a seed"),
    (["compensate", "--train", "M", "--targets", "M", "--seed", "-1"], "--seed -1: want a seed"),
])
def test_12_09_negative_seed_is_one_line(argv, fragment, measurements, capsys):
    argv = [str(measurements) if a == "M" else a for a in argv]
    code, out, err = run(argv, capsys)
    assert code == 2 and out == ""
    assert_one_line(err, fragment)


@pytest.mark.parametrize("option, value", [
    ("--threshold-mm", "nan"), ("--threshold-mm", "inf"), ("--threshold-mm", "-1"), ("--threshold-mm", "1e999"),
    ("--threshold-mm", "1_5"), ("--threshold-mm", "\uff11\uff15"), ("--max-iter", "1_5"), ("--max-iter", "0"),
])
def test_12_20_compensate_options_must_be_finite_and_in_range(option, value, measurements, capsys):
    code, out, err = run(["compensate", "--train", measurements, "--targets", measurements, option, value], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"{option} ")


@pytest.mark.parametrize("argv", [
    ["montecarlo", "--samples", "1_000"],
    ["montecarlo", "--samples", "\uff11\uff10\uff10"],
    ["montecarlo", "--tol", "nan"],
    ["montecarlo", "--angle-tol", "inf"],
    ["montecarlo", "--q", "0", "0", "0", "0", "0", "nan"],
    ["pose", "--q", "0", "0", "0", "0", "0", "1_0"],
    ["tolerance", "--target-prob", "nan"],
    ["tolerance", "--target-tol=-inf"],
    ["view", "--magnify", "nan"],
    ["simulate", "--noise-mm", "nan", "--out", "x.csv"],
    ["simulate", "--box", "nan", "1", "0", "1", "0", "1", "--out", "x.csv"],
    ["diagnose", "m.csv", "--noise-mm", "1e300"],
    ["diagnose", "m.csv", "--folds", "0x10"],
])
def test_12_20_every_numeric_option_is_finite_and_in_range(argv, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(argv, capsys)
    option = next(a for a in argv if a.startswith("--")).partition("=")[0]
    assert code == 2 and out == ""
    assert_one_line(err, f"{option} ")
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------
# 10: nothing identifiable
# ---------------------------------------------------------------------------------------
def test_12_10_diagnose_with_every_parameter_unidentifiable(measurements, tmp_path, capsys):
    # at 1 m tracker noise nothing is identifiable: the diagnosis must say so, not crash
    target = tmp_path / "d.json"
    code, out, err = run(["diagnose", measurements, "--noise-mm", "1000", "--effects", "joint_offsets",
                          "--quiet", "--json", target], capsys)
    assert code == 0, err
    steps = json.loads(target.read_text())["steps"]
    assert steps[0]["n_parameters"] == 0
    # no parameter fitted: the held-out residual is the training residual
    assert steps[0]["heldout_rms_mm"] == pytest.approx(steps[0]["train_rms_mm"])


# ---------------------------------------------------------------------------------------
# 18, 19: measurement CSV cells and row numbers
# ---------------------------------------------------------------------------------------
def _with_comments(measurements, tmp_path, edit):
    """The fixture's CSV behind three comment lines, its data rows changed by ``edit(rows)``;
    returns (path, line of data row k = k + 4)."""
    header, *rows = measurements.read_text().splitlines()
    rows = [r.split(",") for r in rows]
    edit(header.split(","), rows)
    path = tmp_path / "c.csv"
    path.write_text("# tracker: a comment\n#\n# another one\n" + header + "\n"
                    + "\n".join(",".join(r) for r in rows) + "\n")
    return path


@pytest.mark.parametrize("cell", ["1_5", "\uff11\uff15", "0x1f", "1e999"])
def test_12_19_strict_numbers_in_a_measurement_csv(cell, measurements, tmp_path, capsys):
    def edit(header, rows):
        rows[2][header.index("x_mm")] = cell

    path = _with_comments(measurements, tmp_path, edit)
    code, out, err = run(["diagnose", path, "--effects", "joint_offsets"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: row 7, column x_mm")


def test_12_19_strict_numbers_in_a_trajectory_csv(tmp_path, capsys):
    path = tmp_path / "t.csv"
    path.write_text("t_s,j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg\n0,0,0,0,0,0,0\n1,1_5,0,0,0,0,0\n")
    code, out, err = run(["trajectory", "--file", path, "--samples", "10"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: row 3, column 'j1_deg'")


def test_12_18_duplicate_training_poses_are_named_by_file_line(measurements, tmp_path, capsys):
    def edit(header, rows):  # data row 12 takes data row 5's joint values, with another position
        joints = [i for i, h in enumerate(header) if h.startswith("j") and h.endswith(("_deg", "_mm"))]
        for i in joints:
            rows[11][i] = rows[4][i]
        rows[11][header.index("x_mm")] = str(float(rows[4][header.index("x_mm")]) + 0.5)

    path = _with_comments(measurements, tmp_path, edit)
    code, out, err = run(["predict", "--train", path, "--query", path, "--method", "kriging"], capsys)
    assert code == 2
    last = err.splitlines()[-1]
    assert "rows 9 and 16 have the same joint values" in last, err
