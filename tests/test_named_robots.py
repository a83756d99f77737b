"""Named robots out of the box: a default pose inside the limits, one warning per joint
outside them, and a Monte Carlo error budget that fits the robot."""

import json
import math

import numpy as np
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.model.robot import default_working_pose, load_robot


def run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_default_pose_is_zero_where_allowed_else_mid_range():
    nan = math.nan
    lower = np.array([-1.0, -3.07, 0.2, nan, nan, -0.5])
    upper = np.array([1.0, -0.07, 0.6, nan, -0.3, nan])
    # zero inside; mid-range; mid-range; unbounded; only an upper bound below zero; zero inside
    assert default_working_pose(lower, upper) == pytest.approx([0.0, -1.57, 0.4, 0.0, -0.3, 0.0])


def test_panda_default_pose_is_inside_its_limits():
    panda = load_robot("panda")
    q = panda.working_pose
    lo, hi = panda.lower_limits, panda.upper_limits
    assert np.all((q >= lo) & (q <= hi))
    # joint 4 lives in [-176, -4] deg (Franka's datasheet): the middle of it
    j4 = panda.joint_names.index("panda_joint4")
    assert math.degrees(q[j4]) == pytest.approx(-90.0, abs=0.01)


def test_pose_of_a_named_robot_by_default_gives_no_warning(capsys):
    code, out, err = run(["pose", "--robot", "panda"], capsys)
    assert code == 0 and "warning" not in err
    assert "panda_joint4 = -90" in out


def test_a_joint_outside_its_limits_is_warned_once_in_the_users_words(tmp_path, capsys):
    code, _, err = run(["montecarlo", "--robot", "panda", "--preset", "table1", "--samples", "200",
                        "--tail-samples", "0", "--q", "0", "0", "0", "0", "0", "0", "0",
                        "--view", str(tmp_path / "v.html"), "--quiet"], capsys)
    assert code == 0
    warnings = [line for line in err.splitlines() if "warning" in line]
    assert warnings == ["tcr-accuracy: warning: --q: joint panda_joint4 = 0 deg is outside its limits "
                        "[-176.001, -3.99925] deg"]


def test_pose_warns_for_a_joint_outside_its_limits(capsys):
    code, _, err = run(["pose", "--robot", "panda", "--q", "0", "0", "0", "0", "0", "0", "0"], capsys)
    assert code == 0 and err.count("warning") == 1 and "panda_joint4 = 0 deg is outside" in err


@pytest.mark.parametrize("robot, preset", [("ur5", "table1"), ("tool_changer", "table2")])
def test_montecarlo_default_budget_fits_the_robot(robot, preset, tmp_path, capsys):
    out = tmp_path / "mc.json"
    code, printed, err = run(["montecarlo", "--robot", robot, "--samples", "500", "--tail-samples", "0",
                              "--json", str(out), "--quiet"], capsys)
    assert code == 0, err
    data = json.loads(out.read_text())
    assert data["preset"] == preset
    assert f"preset {preset} (the default for" in printed
    assert data["stats_mm"]["norm"]["mean"] > 0
