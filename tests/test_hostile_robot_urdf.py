"""Robot loading under attack (issues 12 and 22): URDF files with missing names, numbers that
are no finite number or out of range, loops, unsupported joints, chains too long, and
``<mimic>`` rules held to the same bounds.

The rules every test here holds the command to, and the helpers, are in ``hostile.py``.
"""

import json

import pytest
from hypothesis import given, settings, strategies as st

from hostile import INERTIAL, assert_one_line, mimic_urdf, run, two_joint_urdf
from tcr_accuracy.cli import main


# ---------------------------------------------------------------------------------------
# Bad URDF elements and numbers (12: 6, 8, 15, 16, 17)
# ---------------------------------------------------------------------------------------
def test_the_two_joint_urdf_itself_is_fine(tmp_path, capsys):
    path = tmp_path / "ok.urdf"
    path.write_text(two_joint_urdf())
    code, out, err = run(["pose", "--robot", path, "--json"], capsys)
    assert code == 0, err
    assert json.loads(out)["position_m"] == pytest.approx([0.0, 0.5, 0.5])


@pytest.mark.parametrize("case, urdf, fragment", [
    ("6 link without a name", two_joint_urdf(extra="<link/>"), "link #2 (<link> element 2) has no name"),
    ("8 huge origin", two_joint_urdf(j1_origin="0 1e308 0"), "joint j1 <origin>: xyz='0 1e308 0': 1e308 is beyond"),
    ("8 inf origin", two_joint_urdf(j1_origin="0 inf 0"), "joint j1 <origin>: xyz='0 inf 0': 'inf' is not a finite"),
    ("15 nan origin", two_joint_urdf(j1_origin="0 nan 0"), "'nan' is not a finite number"),
    ("15 text in an origin", two_joint_urdf(j1_origin="0 abc 0"), "'abc' is not a finite number"),
    ("15 two numbers", two_joint_urdf(j1_origin="0 1"), "needs three numbers"),
    ("15 text in a limit", two_joint_urdf(j1_limit='lower="-1" upper="x"'), "joint j1: <limit>: upper='x'"),
    ("15 nan in an axis", two_joint_urdf(j1_axis="0 nan 1"), "joint j1: <axis>"),
    ("15 duplicate links", two_joint_urdf(extra='<link name="l2"/>'), "link l2 is defined twice"),
    ("15 a loop", two_joint_urdf(extra='<joint name="back" type="fixed"><parent link="l2"/><child link="base"/>'
                                       '</joint>'), "a loop through link"),
    ("15 unknown joint type", two_joint_urdf(j2_type="spinning"), "joint j2: type 'spinning' is not a URDF joint"),
    ("16 planar joint", two_joint_urdf(j2_type="planar"), "joint j2: joint type JointModelPlanar is not supported"),
    ("16 floating joint", two_joint_urdf(j2_type="floating"), "joint j2: joint type JointModelFreeFlyer"),
    ("17 zero-length axis", two_joint_urdf(j1_axis="0 0 0"), "joint j1: <axis xyz=...> has zero length"),
    ("17 lower above upper", two_joint_urdf(j1_limit='lower="1" upper="-1"'), "joint j1: <limit> lower 1 is above"),
])
def test_12_06_08_15_16_17_bad_urdf_is_one_line(case, urdf, fragment, tmp_path, capfd):
    path = tmp_path / "bad.urdf"
    path.write_text(urdf)
    try:
        code = main(["pose", "--robot", str(path)])
    except SystemExit as exc:
        code = exc.code
    out, err = capfd.readouterr()  # file descriptors: urdfdom writes to fd 2 itself
    assert code == 2 and out == ""
    assert_one_line(err, str(path), fragment)


def test_12_15_urdfdom_complaints_stay_one_line(tmp_path, capfd):
    # passes our checks, but urdfdom refuses it (a revolute joint without <limit>) on fd 2
    text = two_joint_urdf().replace('<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>\n</robot>',
                                    "</joint>\n</robot>")
    path = tmp_path / "nolimit.urdf"
    path.write_text(text)
    code = main(["pose", "--robot", str(path)])
    out, err = capfd.readouterr()
    assert code == 2
    assert_one_line(err, "Pinocchio cannot build a model", "does not specify limits")


def test_12_15_a_huge_list_of_leaf_links_stays_short(tmp_path, capsys):
    leaves = "".join(f'<link name="leaf{i}"/><joint name="f{i}" type="fixed"><parent link="base"/>'
                     f'<child link="leaf{i}"/></joint>' for i in range(900))
    path = tmp_path / "many.urdf"
    path.write_text(two_joint_urdf(extra=leaves))
    code, out, err = run(["pose", "--robot", path], capsys)
    assert code == 2
    assert_one_line(err, "leaf links", "in all)")
    assert len(err) < 600


def _chain_urdf(n):
    links = "".join(f'<link name="l{i}">{INERTIAL}</link>' for i in range(n + 1))
    joints = "".join(f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
                     f'<origin xyz="0 0 0.01"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" '
                     f'velocity="1"/></joint>' for i in range(n))
    return f'<robot name="chain">{links}{joints}</robot>'


@pytest.mark.parametrize("n, fragment", [(3000, "3000 joints, more than the 1000"),
                                         (300, "300 joints move this frame")])
def test_12_07_a_chain_too_long_is_refused(n, fragment, tmp_path, capsys):
    path = tmp_path / "chain.urdf"
    path.write_text(_chain_urdf(n))
    code, out, err = run(["pose", "--robot", path], capsys)
    assert code == 2
    assert_one_line(err, str(path), fragment)


# ---------------------------------------------------------------------------------------
# Mimic joints (22: 10, 21)
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("attribute, fragment", [
    ('multiplier="1e308"', "multiplier=1e308 is outside [-1000, 1000]"),
    ('multiplier="nan"', "multiplier='nan' is not a finite number"),
    ('multiplier="1" offset="1e5"', "offset=1e5 is outside [-10000, 10000]"),
    ('multiplier="1_0"', "multiplier='1_0' is not a finite number"),
])
def test_22_10_a_mimic_rule_is_bounded_like_other_urdf_numbers(attribute, fragment, tmp_path, capsys):
    path = tmp_path / "mim.urdf"
    path.write_text(mimic_urdf("1").replace('multiplier="1"/>', attribute + "/>"))
    code, out, err = run(["pose", "--robot", path, "--tool", "tool"], capsys)
    assert code == 2
    assert_one_line(err, f"{path}: joint finger: <mimic>: {fragment}")


def test_22_10_a_bounded_mimic_rule_is_read(tmp_path, capsys):
    from tcr_accuracy.model.robot import load_robot

    path = tmp_path / "mim.urdf"
    path.write_text(mimic_urdf("2.5"))
    robot = load_robot(str(path), "tool")
    assert (robot.mimic["finger"].multiplier, robot.mimic["j3"].multiplier, robot.mimic["j3"].offset) == (2.5, -1, 0.1)


def test_22_21_simulate_and_plan_poses_apply_the_mimic_rule(tmp_path, capsys):
    import csv
    import math

    urdf = tmp_path / "mim2.urdf"
    urdf.write_text(mimic_urdf())
    measured = tmp_path / "mm.csv"
    assert run(["simulate", "--robot", urdf, "--tool", "tool", "--random", "--n", "40", "--seed", "4",
                "--out", measured, "--quiet"], capsys)[0] == 0
    planned = tmp_path / "plan.csv"
    code, out, err = run(["plan-poses", measured, "--robot", urdf, "--tool", "tool", "-k", "4",
                          "--effects", "joint_offsets", "--n-candidates", "300", "--out", planned], capsys)
    assert code == 0, err
    offset_deg = math.degrees(0.1)
    for path, n in ((measured, 40), (planned, 4)):
        rows = list(csv.DictReader(line for line in path.read_text().splitlines() if not line.startswith("#")))
        assert len(rows) == n
        for row in rows:  # j3 = -1 x j2 + 0.1 rad, and within its limits
            assert float(row["j3_deg"]) == pytest.approx(-float(row["j2_deg"]) + offset_deg, abs=1e-6)
            assert abs(float(row["j3_deg"])) <= math.degrees(2.2) + 1e-9


# ---------------------------------------------------------------------------------------
# Fuzz: URDF origins (hypothesis, derandomized)
# ---------------------------------------------------------------------------------------
@settings(max_examples=80, deadline=None, derandomize=True)
@given(st.lists(st.text(alphabet="0123456789.eE+-_nainf x\uff11", max_size=6), min_size=1, max_size=4))
def test_fuzz_an_origin_is_three_finite_numbers_or_one_input_error(parts):
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.model.robot import robot_from_urdf_text

    try:
        robot = robot_from_urdf_text(two_joint_urdf(j1_origin=" ".join(parts)), None, source="f.urdf")
    except InputError as exc:
        assert str(exc).startswith("f.urdf: ") and "\n" not in str(exc)
        return
    assert all(abs(v) <= 1e4 for v in robot.model.jointPlacements[1].translation)
