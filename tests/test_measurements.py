"""Measurement CSV: round trips, and every bad file stopped with file, row and column named."""

import math
import warnings

import numpy as np
import pytest

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.io.measurements import (
    MeasurementContext,
    MeasurementSet,
    MeasurementWarning,
    allowed_columns,
    read_measurements,
)
from tcr_accuracy.cli.writers import write_measurements

from conftest import random_joint_values


def _mset(robot, n=12, seed=0, **extra):
    rng = np.random.default_rng(seed)
    q = random_joint_values(robot, n, rng)
    position = tcp_poses(robot, q).position + [1.2, -0.4, 0.3]  # a tracker frame off the base
    return MeasurementSet(robot.joint_names, q, position, **extra)


def _write_rows(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(map(str, r)) + "\n" for r in rows))
    return path


def _good_rows(robot, n=6, seed=1):
    """Header and rows (deg, mm) of a valid file for the tool-changer."""
    rng = np.random.default_rng(seed)
    q = random_joint_values(robot, n, rng)
    p = tcp_poses(robot, q).position * 1e3
    header = [f"{j}_{u}" for j, u in zip(robot.joint_names, robot.display_units)] + ["x_mm", "y_mm", "z_mm"]
    rows = [list(q[i] * robot.display_scale) + list(p[i]) for i in range(n)]
    return header, rows


@pytest.mark.parametrize("unit", ["mm", "m"])
def test_round_trip_keeps_every_column(tool_changer, tmp_path, unit):
    rng = np.random.default_rng(3)
    n = 12
    quat = rng.normal(size=(n, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    direction = rng.choice([-1.0, 1.0], size=(n, 6))
    direction[:, 0] = 0.0  # no j1_dir column
    original = _mset(tool_changer, n, quaternion=quat, payload_kg=rng.choice([0.0, 150.0], n),
                     temperature_c=rng.uniform(10, 30, n), direction=direction)
    path = tmp_path / "m.csv"
    write_measurements(path, tool_changer, original, unit=unit)
    header = path.read_text().splitlines()[0].split(",")
    assert "j1_dir" not in header and "j2_dir" in header
    assert ("x_mm" in header) == (unit == "mm") and ("j4_mm" in header) == (unit == "mm")
    back = read_measurements(path, tool_changer)
    np.testing.assert_allclose(back.q, original.q, atol=1e-10)
    np.testing.assert_allclose(back.position, original.position, atol=1e-9)
    np.testing.assert_allclose(back.quaternion, original.quaternion, atol=1e-11)
    np.testing.assert_allclose(back.payload_kg, original.payload_kg)
    np.testing.assert_allclose(back.temperature_c, original.temperature_c, atol=1e-9)
    np.testing.assert_array_equal(back.direction, direction)
    np.testing.assert_array_equal(back.rows, np.arange(2, 2 + n))  # header is row 1


def test_context_defaults_when_columns_are_absent(tool_changer, tmp_path):
    path = tmp_path / "m.csv"
    write_measurements(path, tool_changer, _mset(tool_changer, 5))
    ctx = read_measurements(path, tool_changer).context
    np.testing.assert_array_equal(ctx.payload_kg, np.zeros(5))
    np.testing.assert_array_equal(ctx.temperature_c, np.full(5, 20.0))
    np.testing.assert_array_equal(ctx.direction, np.zeros((5, 6)))
    sub = ctx.subset([0, 3])
    assert isinstance(sub, MeasurementContext) and len(sub) == 2


def test_comments_are_skipped_and_rows_count_file_lines(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer)
    path = tmp_path / "m.csv"
    path.write_text("# tracker session 3\n" + ",".join(header) + "\n"
                    + "".join(",".join(map(str, r)) + "\n" for r in rows))
    mset = read_measurements(path, tool_changer)
    assert list(mset.rows) == list(range(3, 3 + len(rows)))


def _error(path, robot, **kw):
    with pytest.raises(InputError) as info:
        read_measurements(path, robot, **kw)
    return str(info.value)


def test_non_numeric_and_non_finite_cells_name_file_row_column(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer)
    for bad, expected in (("abc", "'abc' is not a number"), ("nan", "non-finite"), ("inf", "non-finite"),
                          ("", "empty cell")):
        rows_bad = [list(r) for r in rows]
        rows_bad[3][2] = bad
        path = _write_rows(tmp_path / "bad.csv", header, rows_bad)
        msg = _error(path, tool_changer)
        assert str(path) in msg and "row 5" in msg and "column j3_deg" in msg and expected in msg


def test_missing_and_unknown_columns(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer)
    path = _write_rows(tmp_path / "a.csv", header[:2] + header[3:], [r[:2] + r[3:] for r in rows])
    msg = _error(path, tool_changer)
    assert str(path) in msg and "row 1" in msg and "j3_deg or j3_rad" in msg
    path = _write_rows(tmp_path / "b.csv", header + ["humidity"], [r + [40] for r in rows])
    msg = _error(path, tool_changer)
    assert "unknown column 'humidity'" in msg and "payload_kg" in msg and "j6_dir" in msg
    path = _write_rows(tmp_path / "c.csv", header[:-1], [r[:-1] for r in rows])
    assert "missing position column z_mm" in _error(path, tool_changer)
    # a prismatic joint cannot be in degrees
    path = _write_rows(tmp_path / "d.csv", [h.replace("j4_mm", "j4_deg") for h in header], rows)
    assert "unknown column 'j4_deg'" in _error(path, tool_changer)
    path = _write_rows(tmp_path / "e.csv", header + ["qw", "qx"], [r + [1, 0] for r in rows])
    assert "missing qy, qz" in _error(path, tool_changer)


def test_direction_must_be_plus_or_minus_one(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer)
    rows = [r + [1] for r in rows]
    rows[2][-1] = 0.5
    path = _write_rows(tmp_path / "d.csv", header + ["j2_dir"], rows)
    msg = _error(path, tool_changer)
    assert "row 4" in msg and "column j2_dir" in msg and "+1 or -1" in msg


def test_exact_copies_are_errors_and_repeated_poses_warn(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer)
    copy = rows + [list(rows[1])]
    msg = _error(_write_rows(tmp_path / "dup.csv", header, copy), tool_changer)
    assert "row 8 repeats row 3" in msg
    repeat = rows + [list(rows[1][:6]) + [rows[1][6] + 0.01, rows[1][7], rows[1][8]]]
    with pytest.warns(MeasurementWarning, match="row 8 has the same joint values and context as row 3"):
        read_measurements(_write_rows(tmp_path / "rep.csv", header, repeat), tool_changer)


def test_a_time_column_that_never_changes_warns_and_a_varying_one_does_not(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer)
    constant = _write_rows(tmp_path / "constant.csv", header + ["time_s"], [r + [100.0] for r in rows])
    with pytest.warns(MeasurementWarning, match=r"column time_s: all 6 rows \(from row 2\) carry the same time 100 s"):
        mset = read_measurements(constant, tool_changer)
    assert np.all(mset.time_s == 100.0)
    varying = _write_rows(tmp_path / "varying.csv", header + ["time_s"], [r + [30.0 * k] for k, r in enumerate(rows)])
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeasurementWarning)
        assert np.ptp(read_measurements(varying, tool_changer).time_s) == 150.0


def test_too_few_rows(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer, n=6)
    msg = _error(_write_rows(tmp_path / "few.csv", header, rows), tool_changer, min_rows=40)
    assert "6 measurement rows, at least 40" in msg


def test_quaternion_must_be_unit(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer)
    rows = [r + [1, 0, 0, 0] for r in rows]
    rows[4][-4] = 1.2
    msg = _error(_write_rows(tmp_path / "q.csv", header + ["qw", "qx", "qy", "qz"], rows), tool_changer)
    assert "row 6" in msg and "quaternion norm is 1.2" in msg


def test_tracker_in_metres_labelled_mm_is_caught(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer, n=20)
    rows = [r[:6] + [v / 1000 for v in r[6:]] for r in rows]
    msg = _error(_write_rows(tmp_path / "u.csv", header, rows), tool_changer)
    assert "x_mm, y_mm, z_mm" in msg and "name the columns x_m, y_m, z_m" in msg


def test_degrees_labelled_rad_are_caught(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer, n=20)
    header = [h.replace("_deg", "_rad") for h in header]
    msg = _error(_write_rows(tmp_path / "r.csv", header, rows), tool_changer)
    assert "rad is more than a full turn" in msg and "_deg" in msg and "row " in msg


def test_values_outside_limits_warn_once_per_joint(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer, n=20)
    rows[5][1] = 80.0  # j2 limit is 75 deg
    rows[9][1] = 85.0
    rows = [r[:6] + list(tcp_poses(tool_changer, np.array(r[:6]) / tool_changer.display_scale).position[0] * 1e3)
            for r in rows]
    with pytest.warns(MeasurementWarning, match=r"row 7, column j2_deg: 2 value\(s\) outside") as record:
        read_measurements(_write_rows(tmp_path / "l.csv", header, rows), tool_changer)
    assert sum("outside" in str(w.message) for w in record) == 1  # once for the joint, not per row


def test_allowed_columns_for_example_robot(ur5):
    cols = allowed_columns(ur5)
    assert "shoulder_pan_joint_rad" in cols and "shoulder_pan_joint_deg" in cols
    assert "shoulder_pan_joint_mm" not in cols and "shoulder_pan_joint_dir" in cols
    # joints in two units, positions in two, quaternion, context (payload, temperature, time), session,
    # directions, the pose-test labels (pose, cycle, approach, condition, target) and the commanded path's
    assert math.isclose(len(cols), 6 * 2 + 6 + 4 + 3 + 1 + 6 + 8 + 3)
    assert {"pose_id", "cycle", "approach", "load_pct", "speed_pct", "target_x_mm", "target_y_mm", "target_z_mm",
            "path", "speed_mm_s", "s_mm"} <= set(cols)


def test_semicolon_files_get_a_hint(tool_changer, tmp_path):
    header, rows = _good_rows(tool_changer)
    path = tmp_path / "excel.csv"
    path.write_text(";".join(header) + "\n" + ";".join(map(str, rows[0])) + "\n")
    assert "separated by ';'" in _error(path, tool_changer)


def _sessions_file(robot, path, scale=1.0, n_sessions=7, rows=20):
    """One CSV of ``n_sessions`` tracker set-ups metres apart (a ``session`` column); ``scale``
    multiplies the positions (1e-3: metres written under ``x_mm``)."""
    from tcr_accuracy.analysis.simulate import simulate_measurements
    from tcr_accuracy.io.measurements import format_measurements, join_sessions

    sets = []
    for k in range(n_sessions):
        spec = {"effects": {"frames": {"base_mm": {"dx": 8000.0 * np.cos(k), "dy": 8000.0 * np.sin(k), "dz": 100.0 * k},
                                       "base_mrad": {"rz": 500.0 * k}}}, "noise_mm": 0.02}
        mset, _ = simulate_measurements(robot, spec, rows, np.random.default_rng(k))
        sets.append(MeasurementSet(**{**mset.__dict__, "position": mset.position * scale}))
    header, *lines = format_measurements(robot, join_sessions(sets, [f"s{k}" for k in range(n_sessions)])).splitlines()
    path.write_text("\n".join([header + ",session"] + [f"{line},s{i // rows}" for i, line in enumerate(lines)]) + "\n")
    return path


def test_29_09_sessions_in_one_file_are_unit_checked_each_about_its_own_centre(tool_changer, tmp_path):
    """Seven set-ups 8 m apart: pooled, the points spread four times the model's; each about its own
    centre they spread as the model does. Metres under x_mm are still caught."""
    mset = read_measurements(_sessions_file(tool_changer, tmp_path / "sessions.csv"), tool_changer)
    assert mset.session_labels == [f"s{k}" for k in range(7)]
    pooled = np.sqrt(np.mean(np.sum((mset.position - mset.position.mean(axis=0)) ** 2, axis=1)))
    nominal = tcp_poses(tool_changer, mset.q).position
    assert pooled / np.sqrt(np.mean(np.sum((nominal - nominal.mean(axis=0)) ** 2, axis=1))) > 2  # the old check's refusal
    with pytest.raises(InputError, match="the values look like m"):
        read_measurements(_sessions_file(tool_changer, tmp_path / "metres.csv", scale=1e-3), tool_changer)
