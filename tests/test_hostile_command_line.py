"""The command line's options and error lines under attack (issues 12 and 22): option values
that are no finite number in range, options that would be ignored, and the one line an error
becomes whatever the exception says.

The rules every test here holds the command to, and the helpers, are in ``hostile.py``.
"""

import pytest
from hypothesis import given, settings, strategies as st

from hostile import assert_one_line, run


# ---------------------------------------------------------------------------------------
# Option values (12: 9, 19, 20, 21; 22: 9, 30)
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


def test_12_21_an_empty_or_inverted_box_is_refused(tmp_path, capsys):
    code, out, err = run(["simulate", "--random", "--box", "500", "-500", "0", "100", "0", "100",
                          "--out", tmp_path / "o.csv"], capsys)
    assert code == 2
    assert_one_line(err, "--box")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", [["diagnose", "M"], ["plan-poses", "M", "-k", "3"]])
@pytest.mark.parametrize("value", ["1e-300", "1e-7", "1e6"])
def test_22_09_30_an_instrument_noise_out_of_range_is_refused(command, value, m60, capsys):
    code, out, err = run([str(m60) if a == "M" else a for a in command] + ["--noise-mm", value], capsys)
    assert code == 2 and out == ""
    assert_one_line(err, f"--noise-mm {value}", "want a number >= 1e-06 mm and <= 1000 mm")


# ---------------------------------------------------------------------------------------
# Messages: the actual argument and cause, one bounded line (12: 15; 22: 24)
# ---------------------------------------------------------------------------------------
def test_22_24_messages_name_the_actual_argument_and_cause(m60, tmp_path, capsys, monkeypatch):
    import os

    monkeypatch.chdir(tmp_path)
    (tmp_path / "f").write_text("a file")
    os.mkfifo(tmp_path / "fifo")
    mixed = tmp_path / "mix.csv"
    lines = m60.read_text().splitlines()
    mixed.write_text("\n".join([lines[0].replace("z_mm", "z_m"), *lines[1:]]) + "\n")
    for argv, fragment in [
        (["view", "--error-preset", "table2", "--robot", "ur5", "--view", "v.html"],
         "--error-preset table2: the seed's Table 2 lists the tool-changer's joints"),
        (["pose", "--json", "f/x.json"], "--json f/x.json: the folder f is a file"),
        (["pose", "--robot", "."], "--robot .: a folder; give a URDF file"),
        (["pose", "--robot", "/dev/zero"], "--robot /dev/zero: not a regular file"),
        (["pose", "--robot", "fifo"], "--robot fifo: not a regular file"),
        (["diagnose", mixed], f"{mixed}: row 1: position columns mix units (x_mm, y_mm, z_m)"),
    ]:
        code, out, err = run(argv, capsys)
        assert code == 2, err
        assert_one_line(err, fragment)
        assert "--preset " not in err and "no such file" not in err and "does not exist" not in err


def test_12_15_an_error_line_is_one_bounded_line(tmp_path, capsys, monkeypatch):
    # whatever an exception says (here many lines and megabytes), the user gets one short line
    from tcr_accuracy.cli import pose

    def huge(args):
        raise ValueError("line one\n" + "x" * 5_000_000 + "\nline three")

    monkeypatch.setattr(pose, "_run_pose", huge)
    code, out, err = run(["pose"], capsys)
    assert code == 1
    assert_one_line(err, "tcr-accuracy pose: unexpected error: ValueError: line one x")
    assert len(err) <= 1001


# ---------------------------------------------------------------------------------------
# Options that would be ignored or answer with no number (22: 30, 31)
# ---------------------------------------------------------------------------------------
def test_22_30_refused_rather_than_nan_or_an_unearned_certainty(m60, tmp_path, capsys):
    zero = tmp_path / "zero.yaml"
    zero.write_text("groups:\n  drive:\n    std_rad: 0.0\n    std_m: 0.0\n")
    for argv, fragment in [
        (["sensitivity", "--config", zero, "--sobol-samples", "64"], "no error source moves the TCP"),
        (["diagnose", m60, "--effects", ","], "--effects ',': names no effect"),
        (["diagnose", m60, "--effects", " , ,"], "names no effect"),
        (["tolerance", "--target-prob", "0.9999999", "--samples", "2000"],
         "--target-prob 0.9999999: 2000 samples cannot tell it from 1"),
    ]:
        code, out, err = run(argv, capsys)
        assert code == 2 and out == "", err
        assert_one_line(err, fragment)
        assert "nan" not in err


def test_22_31_ignored_options_and_one_pose_are_refused(m60, tmp_path, capsys):
    from conftest import REPO

    lines = m60.read_text().splitlines()
    header, row = lines[0].split(","), lines[1].split(",")
    one_pose = tmp_path / "one_pose.csv"  # 20 measurements of one pose, the tracker's noise apart
    x = header.index("x_mm")
    one_pose.write_text("\n".join([lines[0]] + [",".join(row[:x] + [f"{float(row[x]) + 0.01 * i:.4f}"] + row[x + 1:])
                                                 for i in range(20)]) + "\n")
    poses = REPO / "examples" / "poses.csv"
    for argv, fragment in [
        (["simulate", "--poses", poses, "--n", "5", "--out", tmp_path / "s.csv"], "--n with --poses"),
        (["simulate", "--poses", poses, "--box", "0", "1", "0", "1", "0", "1", "--out", tmp_path / "s.csv"],
         "--box with --poses"),
        (["view", "--magnify", "5", "--view", tmp_path / "v.html"], "--magnify 5: only with --error-preset"),
        (["diagnose", one_pose], f"{one_pose}: 20 rows at 1 distinct pose(s)"),
    ]:
        code, out, err = run(argv, capsys)
        assert code == 2 and out == "", err
        assert_one_line(err, fragment)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one_pose.csv"]
    code, out, err = run(["simulate", "--poses", poses, "--out", tmp_path / "s.csv", "--quiet"], capsys)
    assert code == 0, err


# ---------------------------------------------------------------------------------------
# Fuzz: a numeric option (hypothesis, derandomized)
# ---------------------------------------------------------------------------------------
FUZZ = settings(max_examples=200, deadline=None, derandomize=True)


@FUZZ
@given(st.text(max_size=30))
def test_fuzz_a_numeric_option_is_a_finite_number_in_range_or_one_refusal(text):
    import argparse
    import math
    import re

    from tcr_accuracy.cli.common import number

    convert = number(low=0, low_open=True, high=1e6, unit="mm")
    try:
        value = convert(text)
    except argparse.ArgumentTypeError as exc:
        assert "\n" not in str(exc) or "\n" in text
        return
    assert math.isfinite(value) and 0 < value <= 1e6
    # only plain ASCII decimals get through: no 1_5, no full-width digits, no hex, no inf/nan
    assert re.fullmatch(r"\s*[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\s*", text, re.ASCII)
