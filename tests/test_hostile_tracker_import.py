"""``import`` under attack (issue 22): tracker exports and joint logs with time units, clock
times, repeated samples, line separators inside cells, UTF-16, decimal commas and metadata
lines; its options checked before the work.

The rules every test here holds the command to, and the helpers, are in ``hostile.py``.
"""

import pytest
from hypothesis import given, settings, strategies as st

from hostile import JOINTS, assert_one_line, m60_rows, run


# ---------------------------------------------------------------------------------------
# Options checked before the work (22: 18, 19)
# ---------------------------------------------------------------------------------------
def test_22_18_19_import_options_are_checked_before_the_work(tmp_path, capsys):
    (tmp_path / "t.csv").write_text("X,Y,Z\n1,2,3\n")
    for argv, fragment in [(["--tolerance-ms", "\u0665\u0660"], "--tolerance-ms \u0665\u0660: not a number"),
                           (["--tolerance-ms", "1_000"], "--tolerance-ms 1_000: not a number"),
                           (["--out", tmp_path / "nowhere" / "m.csv"], "does not exist"),
                           (["--out", tmp_path], "is a folder")]:
        argv = ["import", tmp_path / "t.csv", *argv]
        if "--out" not in argv:
            argv += ["--out", tmp_path / "m.csv"]
        code, out, err = run(argv, capsys)
        assert code == 2
        assert_one_line(err, fragment)
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]


# ---------------------------------------------------------------------------------------
# Tracker exports and joint logs (22: 11, 13-17, 20)
# ---------------------------------------------------------------------------------------
def _exports(tmp_path, tracker_times, log_rows, tracker_header="Time", m60=None):
    """A tracker file (one point per time: m60's positions when given) and a joint log
    (``(time, joints)`` rows)."""
    points = m60_rows(m60, len(tracker_times)) if m60 is not None else [
        (f"{1000 + i}.5", "200", "300", "") for i in range(len(tracker_times))]
    tracker = tmp_path / "tracker.csv"
    tracker.write_text(f"Point;{tracker_header};X [mm];Y [mm];Z [mm]\n" + "".join(
        f"P{i};{t};{x.replace('.', ',')};{y.replace('.', ',')};{z.replace('.', ',')}\n"
        for i, (t, (x, y, z, _)) in enumerate(zip(tracker_times, points))))
    log = tmp_path / "log.csv"
    log.write_text(f"time,{JOINTS}\n" + "".join(f"{t},{joints}\n" for t, joints in log_rows))
    return tracker, log


def _import(tracker, log, capsys, *extra):
    out = tracker.parent / "m.csv"
    code, stdout, err = run(["import", tracker, "--joints", log, "--out", out, "--quiet", *extra], capsys)
    return code, err, out


def _first_column(path):
    return [float(r.split(",")[0]) for r in path.read_text().splitlines()[2:]]


def test_22_11_the_time_unit_in_the_header_is_honoured(m60, tmp_path, capsys):
    joints = [j for *_, j in m60_rows(m60, 3)]
    tracker, log = _exports(tmp_path, [1000, 1020, 1040], list(zip([1000, 1020, 1040], joints)),
                            tracker_header="Time [ms]", m60=m60)
    log.write_text(log.read_text().replace("time,", "time [ms],", 1))
    code, err, out = _import(tracker, log, capsys)
    assert code == 0, err
    assert _first_column(out) == pytest.approx([float(j.split(",")[0]) for j in joints])
    # a log in seconds against a tracker in milliseconds: joined as the units say
    log.write_text(f"time_s,{JOINTS}\n" + "".join(f"{t},{j}\n" for t, j in zip([1.0, 1.02, 1.04], joints)))
    code, err, out = _import(tracker, log, capsys)
    assert code == 0, err
    assert _first_column(out) == pytest.approx([float(j.split(",")[0]) for j in joints])
    tracker.write_text(tracker.read_text().replace("Time [ms]", "Time [mm]"))
    code, err, out = _import(tracker, log, capsys)
    assert code == 2
    assert_one_line(err, "column 'Time [mm]': unit 'mm' is not a unit of time")


def test_22_13_two_log_samples_at_one_time_with_different_joints_are_refused(tmp_path, capsys):
    tracker, log = _exports(tmp_path, [10.0], [(10.0, "1,2,3,4,5,6"), (10.0, "9,2,3,4,5,6")])
    code, err, out = _import(tracker, log, capsys)
    assert code == 2
    assert_one_line(err, f"{log}: rows 2 and 3 have the same time '10.0' but different joint values")
    assert not out.exists()
    log.write_text(f"time,{JOINTS}\n10.0,1,2,3,4,5,6\n10.0,1,2,3,4,5,6\n")  # a repeated line: harmless
    assert _import(tracker, log, capsys)[0] == 0


def test_22_14_times_of_day_wrap_at_midnight(tmp_path, capsys):
    tracker, log = _exports(tmp_path, ["23:59:59,990"], [("00:00:00.010", "1,2,3,4,5,6"),
                                                         ("12:00:00.000", "9,2,3,4,5,6")])
    code, err, out = _import(tracker, log, capsys)
    assert code == 0, err
    assert out.read_text().splitlines()[2].startswith("1,")


def test_22_15_one_source_column_mapped_twice_is_refused(tmp_path, capsys):
    tracker, log = _exports(tmp_path, [10.0], [(10.0, "1,2,3,4,5,6")])
    code, err, out = _import(tracker, log, capsys, "--map", "x_mm=X [mm]", "y_mm=X [mm]")
    assert code == 2
    assert_one_line(err, "--map 'y_mm=X [mm]': column 'X [mm]' is already mapped to x_mm")


@settings(max_examples=80, deadline=None, derandomize=True)
@given(st.integers(0, 120), st.integers(0, 120), st.integers(0, 120), st.integers(0, 999))
def test_fuzz_22_16_a_clock_time_is_a_time_of_day_or_refused(h, m, s, ms):
    from pathlib import Path

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.tracker_import import Table, parse_time

    text = f"{h:02d}:{m:02d}:{s:02d},{ms:03d}"
    table = Table(Path("t.csv"), ["Time"], [[text]], [5], ";", True)
    try:
        seconds, kind = parse_time(table, 0, 0)
    except InputError as exc:
        assert h > 23 or m > 59 or s > 59
        assert str(exc).startswith(f"t.csv: row 5, column 'Time': '{text}' is not a time")
        return
    assert h <= 23 and m <= 59 and s <= 59 and kind == "clock"
    assert seconds == pytest.approx(h * 3600 + m * 60 + s + ms / 1000)


@pytest.mark.parametrize("separator", ["\u2028", "\u0085", "\x0c"])
def test_22_17_a_line_separator_inside_a_cell_does_not_shift_the_row_numbers(separator, tmp_path, capsys):
    tracker = tmp_path / "tracker.csv"
    tracker.write_text(f"X;Y;Z;Note\n1;2;3;a{separator}b\n1;2;x;c\n", encoding="utf-8")
    code, out, err = run(["import", tracker, "--out", tmp_path / "m.csv"], capsys)
    assert code == 2
    assert_one_line(err, f"{tracker}: row 3, column 'Z': 'x' is not a number")


def _tracker_with_joints(m60, n, decimal=","):
    header = f"X [mm];Y [mm];Z [mm];{JOINTS.replace(',', ';')}\n"
    return header + "".join(f"{x.replace('.', decimal)};{y};{z};{j.replace(',', ';')}\n"
                            for x, y, z, j in m60_rows(m60, n))


def test_22_20_utf16_exports_joint_columns_and_directions(m60, tmp_path, capsys):
    tracker = tmp_path / "t16.csv"
    tracker.write_bytes(_tracker_with_joints(m60, 5).encode("utf-16"))  # with a byte-order mark, as Windows writes
    code, out, err = run(["import", tracker, "--out", tmp_path / "m.csv", "--quiet"], capsys)
    assert code == 0, err
    header, first = (tmp_path / "m.csv").read_text().splitlines()[1:3]
    x, y, z, joints = m60_rows(m60, 1)[0]
    assert header.split(",")[3:] == JOINTS.split(",")  # the tracker file's own joint columns are kept
    assert [float(v) for v in first.split(",")] == pytest.approx([float(v) for v in (x, y, z, *joints.split(","))])
    # a direction with a unit is no direction
    tracker, log = _exports(tmp_path, [10.0], [(10.0, "1,2,3,4,5,6")])
    log.write_text(f"time,{JOINTS},j1_dir\n10.0,1,2,3,4,5,6,1 mm\n")
    code, err, out = _import(tracker, log, capsys)
    assert code == 2
    assert_one_line(err, "column 'j1_dir': a direction is +1 or -1, got '1 mm'")


def test_22_20_a_decimal_comma_after_row_50_is_recognised(m60, tmp_path, capsys):
    tracker = tmp_path / "late.csv"
    rows = _tracker_with_joints(m60, 56, decimal=".").splitlines(keepends=True)
    last = rows[-1].split(";")
    last[0] = last[0].replace(".", ",")
    tracker.write_text("".join(rows[:-1]) + ";".join(last))
    code, out, err = run(["import", tracker, "--out", tmp_path / "m.csv", "--quiet"], capsys)
    assert code == 0, err
    assert float((tmp_path / "m.csv").read_text().splitlines()[-1].split(",")[0]) == pytest.approx(
        float(m60_rows(m60, 56)[-1][0]))


def test_22_20_a_metadata_line_naming_the_columns_and_a_second_x_column(m60, tmp_path, capsys):
    tracker = tmp_path / "meta.csv"
    tracker.write_text("Leica export\nColumns: X;Y;Z\n\n" + _tracker_with_joints(m60, 5))
    code, out, err = run(["import", tracker, "--out", tmp_path / "m.csv", "--quiet"], capsys)
    assert code == 0, err  # the real header, below the metadata line, is found
    assert len((tmp_path / "m.csv").read_text().splitlines()) == 2 + 5
    dev = tmp_path / "dev.csv"
    dev.write_text("X [mm];Dev X;Y [mm];Z [mm]\n1000;0,1;200;300\n")
    code, out, err = run(["import", dev, "--out", tmp_path / "d.csv"], capsys)
    assert code == 2
    assert_one_line(err, f"{dev}: columns 'X [mm]', 'Dev X' could each be the x position")


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.text(alphabet="0123456789.,-+eE _mi\u0665\uff11 ", max_size=10), st.booleans())
def test_fuzz_22_18_20_an_import_cell_is_a_plain_number_or_one_refusal(cell, decimal_comma):
    import math
    import re
    from pathlib import Path

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.tracker_import import Table, parse_time, parse_value

    def table(header):
        return Table(Path("t.csv"), [header], [[cell]], [4], ";" if decimal_comma else ",", decimal_comma)

    for header, parse in (("X [mm]", lambda: parse_value(table("X [mm]"), 0, 0, "mm")),
                          ("Time", lambda: parse_time(table("Time"), 0, 0)[0])):
        try:
            value = parse()
        except InputError as exc:
            assert str(exc).startswith(f"t.csv: row 4, column '{header}': ") and "\n" not in str(exc)
            continue
        assert math.isfinite(value)
        assert re.fullmatch(r"[0-9.,+\-eE ]*[a-z]*\s*", cell.strip(), re.ASCII), cell  # no other digits got in
