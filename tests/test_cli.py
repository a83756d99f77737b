"""The command line as a user sees it: numbers, exit codes, one-line errors."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from tcr_accuracy.cli import main

from conftest import REPO


def run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse usage errors
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_pose_json_prints_the_working_pose_tcp(capsys):
    code, out, err = run(["pose", "--q", "15", "30", "-10", "0", "-20", "0", "--json"], capsys)
    assert code == 0
    payload = json.loads(out)
    # by hand: the arm stays in a vertical plane turned 15 deg about z
    l1, l2, l3, l4, l5, l6 = 0.315, 0.210, 0.796, 0.560, 0.240, 0.165
    planar_y = l3 * math.cos(math.radians(30)) + (l4 + l5) * math.cos(math.radians(20)) + l6
    planar_z = l1 + l2 + l3 * math.sin(math.radians(30)) + (l4 + l5) * math.sin(math.radians(20))
    expected = [-planar_y * math.sin(math.radians(15)), planar_y * math.cos(math.radians(15)), planar_z]
    np.testing.assert_allclose(payload["position_m"], expected, atol=1e-12)
    np.testing.assert_allclose(payload["rpy_rad"], [0, 0, math.radians(15)], atol=1e-12)
    assert np.array(payload["rotation_matrix"]).shape == (3, 3)
    assert payload["joint_units_si"] == ["rad", "rad", "rad", "m", "rad", "rad"]


def test_pose_prismatic_value_is_read_in_mm(capsys):
    _, out0, _ = run(["pose", "--q", "0", "0", "0", "0", "0", "0", "--json"], capsys)
    _, out1, _ = run(["pose", "--q", "0", "0", "0", "250", "0", "0", "--json"], capsys)
    dy = json.loads(out1)["position_m"][1] - json.loads(out0)["position_m"][1]
    assert dy == pytest.approx(0.250, abs=1e-12)


def test_pose_json_to_file(tmp_path, capsys):
    target = tmp_path / "pose.json"
    code, out, _ = run(["pose", "--json", str(target)], capsys)
    assert code == 0 and "position [mm]" in out
    assert json.loads(target.read_text())["robot"] == "tool_changer"


@pytest.mark.parametrize("argv, message", [
    (["pose", "--q", "1", "2"], "expected 6 joint values"),
    (["pose", "--q", "1", "2", "3", "4", "5", "nan"], "non-finite"),
    (["pose", "--robot", "nowhere.urdf"], "no such file"),
    (["pose", "--tool", "flange"], "no such frame"),
    (["pose", "--q", "1", "x"], "invalid float"),
    (["demo", "--samples", "1"], "at least 2"),
])
def test_bad_input_is_one_line_and_exit_code_2(argv, message, capsys):
    code, out, err = run(argv, capsys)
    assert code == 2
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], err


def test_limit_warning_is_one_line_and_the_pose_still_prints(capsys):
    code, out, err = run(["pose", "--q", "0", "0", "0", "900", "0", "0"], capsys)
    assert code == 0 and "position [mm]" in out
    assert err.count("\n") == 1 and "outside its limits" in err


def test_broken_urdf_file_exit_code_2(tmp_path, capsys):
    path = tmp_path / "broken.urdf"
    path.write_text("<robot name='x'><link name='a'></robot>")
    code, _, err = run(["pose", "--robot", str(path)], capsys)
    assert code == 2 and str(path) in err and err.count("\n") == 1


def test_console_entry_point_runs_as_a_module():
    done = subprocess.run([sys.executable, "-m", "tcr_accuracy", "pose", "--robot", "ur5",
                           "--q", "0", "-90", "0", "-90", "0", "0", "--json"],
                          capture_output=True, text=True, cwd=REPO, timeout=120)
    assert done.returncode == 0, done.stderr
    assert len(json.loads(done.stdout)["position_m"]) == 3


def test_demo_runs_both_analyses_and_writes_one_report(tmp_path, capsys):
    """The main job: Monte Carlo next to first order, a diagnosis that finds the hidden
    compliance of the bundled set (its truth is never given to diagnose), one report."""
    out_dir = tmp_path / "demo"
    code, out, _ = run(["demo", "--samples", "4000", "--out", str(out_dir), "--quiet"], capsys)
    assert code == 0
    accuracy = json.loads((out_dir / "accuracy.json").read_text())
    # Monte Carlo std of dx against the first-order std (within sampling error at n = 4000)
    assert accuracy["stats_mm"]["dx"]["std"] == pytest.approx(8.177, rel=0.06)
    diagnosis = json.loads((out_dir / "diagnosis.json").read_text())
    assert diagnosis["primary_effect"] == "compliance"  # the bundled set's dominant hidden effect
    assert diagnosis["steps"][-1]["heldout_rms_mm"] < 1.5 * diagnosis["noise_floor_mm"]
    index = (out_dir / "index.html").read_text()
    assert "accuracy/index.html" in index and "diagnosis/index.html" in index
    assert (out_dir / "accuracy" / "index.html").is_file() and (out_dir / "diagnosis" / "index.html").is_file()
    assert (out_dir / "tool_changer_as_built.urdf").is_file()
    assert "primary effect found" in out and "compliance" in out
