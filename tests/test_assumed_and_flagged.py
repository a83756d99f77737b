"""Say what was assumed (issue 36, part 5): a drift fitted on the measurement order for want of a
time column is said in the answer, the JSON and the report; a geometry fit that tilts an axis or
moves the tool frame beyond what the robot's class allows, and a fitted TCP offset far from the one
the user gives (``--tcp-mm``), are flagged with their size.

The simulated robots are written here on Pinocchio (tests/hidden_robot.py): a UR5 whose encoder
zero drifts row by row, and a UR5 whose wrist_1 axis is tilted 0.7 deg with its reflector 28.3 mm
from tool0 where the user says 31 mm. The real UR5 (``$TCR_REAL_DATA``) has no time column and its
calibration tilts wrist_1 by about 0.69 deg with the reflector fitted about 28.3 mm from tool0, where
the data's README says 31.0 mm.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.plausibility import TOLERANCES, geometry_checks, robot_class
from tcr_accuracy.io.measurement_set import MeasurementSet
from tcr_accuracy.model.robot import load_robot
from tcr_accuracy.view.calibration_report import Campaign, RobotFacts, first_page
from tcr_accuracy.view.diagnosis_summary import answer_lines

from conftest import REPO, run_command
from hidden_robot import DEG, MM, HiddenRobot, frame_id, in_tracker, random_poses, tracker_frame
from test_interval_coverage import assert_intervals_hold

REAL = Path(os.environ.get("TCR_REAL_DATA", REPO.parent / "shared" / "real"))
ORDER = "fitted on the measurement order"


def _page(doc: dict) -> str:
    """The calibration report's first page (Markdown) of a diagnosis' JSON."""
    return first_page(Campaign(RobotFacts.from_documents([("d.json", doc)]), [("d.json", doc)]),
                      "2026-01-01 00:00:00 UTC")[1]


def _drifting_ur5(with_time: bool):
    """A UR5 measured at 150 random poses whose shoulder encoder zero moves 0.05 deg and elbow's
    -0.03 deg from the first row to the last, linearly; 15 um noise; a ``time_s`` column (10 s a
    row) or none."""
    robot = load_robot("ur5")
    rng = np.random.default_rng(5)
    n = 150
    q = random_poses(robot, n, rng)
    progress = np.linspace(0.0, 1.0, n)[:, None]
    drift = np.zeros(6)
    drift[1:3] = np.array([0.05, -0.03]) * DEG
    real = HiddenRobot(robot).positions(q + progress * drift, [robot.tool_frame])[robot.tool_frame]
    seen = in_tracker(tracker_frame(rng, 3.0), real) + 15e-6 * rng.standard_normal((n, 3))
    measured = MeasurementSet(joint_names=list(robot.joint_names), q=q, position=seen,
                              time_s=10.0 * np.arange(n) if with_time else None)
    return GapDiagnosis(robot=robot, effects=["joint_offsets", "drift"], random_state=0).fit(measured).result_


@pytest.mark.slow
def test_a_drift_fitted_on_the_row_order_says_so_in_the_answer_the_json_and_the_report():
    """No time column: the drift is fitted on the row order and the mechanism line, the JSON's
    ``mechanisms`` (``assumed``) and notes, and the report's first page say the order was taken for
    time; with a time column, nothing is said (the time was measured)."""
    d = _drifting_ur5(with_time=False)
    assert "drift" in d.selected_effects and d.effect_options["drift"].get("time_axis", "order") == "order"
    doc = json.loads(json.dumps(d.to_dict()))
    drift = next(m for m in doc["mechanisms"] if m["effect"] == "drift")
    assert drift["assumed"] and ORDER in drift["assumed"][0] and "no time_s column" in drift["assumed"][0]
    assert any(note.startswith("drift: " + ORDER) for note in doc["notes"])
    lines = answer_lines(d)
    said = lines.index(next(line for line in lines if line.startswith("  drift (time):")))
    assert lines[said + 1].strip().startswith("assumed: " + ORDER)
    assert "Assumed: " + ORDER in _page(doc)

    timed = _drifting_ur5(with_time=True)
    assert "drift" in timed.selected_effects and timed.effect_options["drift"].get("time_axis") == "time_s"
    assert not any(m["assumed"] for m in timed.mechanisms)
    assert ORDER not in "\n".join(answer_lines(timed)) and ORDER not in _page(timed.to_dict())


#: the simulated UR5's reflector in tool0's axes [m], and where the user says it is
REFLECTOR = np.array([0.0, 0.07, 28.3]) * MM
GIVEN = np.array([0.0, 0.07, 31.0]) * MM
TILT = 0.7 * DEG


@pytest.fixture(scope="module")
def tilted_ur5():
    """A UR5 whose wrist_1 axis is tilted 0.7 deg (its placement turned about its own x axis) and
    whose reflector sits at REFLECTOR from tool0, measured at 200 random poses (15 um noise),
    diagnosed with geometry and joint offsets and the user's TCP offset GIVEN."""
    robot = load_robot("ur5")
    rng = np.random.default_rng(9)
    q = random_poses(robot, 200, rng)
    hidden = HiddenRobot(robot, {"wrist_1_joint": np.array([0.0, 0.0, 0.0, TILT, 0.0, 0.0])},
                         {robot.tool_frame: REFLECTOR})
    real = hidden.positions(q, [robot.tool_frame])[robot.tool_frame]
    seen = in_tracker(tracker_frame(rng, 3.0), real) + 15e-6 * rng.standard_normal((200, 3))
    measured = MeasurementSet(joint_names=list(robot.joint_names), q=q, position=seen)
    d = GapDiagnosis(robot=robot, effects=["joint_offsets", "geometry"], tcp_offset=GIVEN,
                     random_state=0).fit(measured).result_
    return robot, hidden, q, d


@pytest.mark.slow
def test_an_axis_tilt_and_a_tcp_offset_beyond_the_plausible_are_flagged_with_their_size(tilted_ur5):
    """The flags give the hidden truth's sizes: wrist_1's tilt within 0.03 deg of 0.7 deg, beyond the
    0.3 deg an industrial arm allows; the fitted reflector within 0.05 mm of where it is, 2.7 mm from
    the given offset, beyond 1 mm; tool0 turned by the tilt (within 0.05 deg of the angle between the
    hidden and the nominal tool0, by Pinocchio), beyond 0.3 deg. Each in the answer, the JSON and the
    report's first page; given the true offset instead, the TCP offset is within its tolerance."""
    robot, hidden, q, d = tilted_ur5
    assert robot_class(robot) == "industrial arm"
    checks = {(c["what"], c["subject"]): c for c in d.geometry_checks}
    tilt = checks[("axis_tilt", "wrist_1_joint")]
    assert tilt["flagged"] and tilt["value_deg"] == pytest.approx(0.7, abs=0.03)
    assert tilt["tolerance_deg"] == pytest.approx(math.degrees(TOLERANCES["industrial arm"].axis_tilt))
    tcp = checks[("tcp_offset", "tool0")]
    assert np.allclose(tcp["fitted_mm"], REFLECTOR / MM, atol=0.05)
    assert tcp["given_mm"] == pytest.approx(list(GIVEN / MM))
    assert tcp["flagged"] and tcp["value_mm"] == pytest.approx(2.7, abs=0.05)
    # how far the hidden tool0 turns from the nominal one, by Pinocchio (the tilt turns all after it)
    model = hidden.model()
    data, nominal = model.createData(), robot.full_model.createData()
    fid = frame_id(robot.full_model, "tool0")
    angles = []
    for config in robot.full_configurations(q[:20]):
        pin.framesForwardKinematics(model, data, config)
        pin.framesForwardKinematics(robot.full_model, nominal, config)
        angles.append(np.linalg.norm(pin.log3(nominal.oMf[fid].rotation.T @ data.oMf[fid].rotation)))
    turned = checks[("tool_rotation", "tool0")]
    assert turned["flagged"] and turned["value_deg"] == pytest.approx(math.degrees(max(angles)), abs=0.05)

    lines = answer_lines(d)
    said = f"the fit tilts wrist_1_joint's axis by {tilt['value_deg']:.3g} deg"
    assert "  flag: " + said in lines[lines.index(next(line for line in lines if said in line))]
    assert any(line.startswith("  flag: the measured point is fitted at") and "2.7 mm apart" in line for line in lines)
    doc = json.loads(json.dumps(d.to_dict()))
    assert doc["plausibility"]["tolerance"]["robot_class"] == "industrial arm"
    assert {c["what"] for c in doc["plausibility"]["checks"] if c["flagged"]} == {"axis_tilt", "tool_rotation",
                                                                                 "tcp_offset"}
    page = _page(doc)
    assert "Flag: T" + said[1:] in page and "2.7 mm apart" in page

    parameters = d.stages.parameters
    close = geometry_checks(robot, q, parameters.as_built_x, parameters.table, "frames.tool", REFLECTOR)
    assert not next(c for c in close if c.what == "tcp_offset").flagged


def test_a_given_tcp_offset_that_is_not_three_numbers_is_refused_before_the_fit():
    """``tcp_offset`` with two numbers or a NaN: one clear error naming it, before anything is fitted."""
    from tcr_accuracy.exceptions import InputError

    robot = load_robot("ur5")
    q = random_poses(robot, 30, np.random.default_rng(0))
    measured = MeasurementSet(joint_names=list(robot.joint_names), q=q, position=np.zeros((30, 3)))
    for bad in ([0.0, 0.03], [0.0, float("nan"), 0.03]):
        with pytest.raises(InputError, match="tcp_offset"):
            GapDiagnosis(robot=robot, tcp_offset=bad).fit(measured)


def test_tcp_mm_on_the_command_line_wants_three_numbers(capsys, tmp_path):
    """``--tcp-mm`` with two numbers, or a word: argparse's one line naming the flag, exit 2."""
    data = tmp_path / "m.csv"
    data.write_text("j1_deg,x_mm,y_mm,z_mm\n")
    for argv in (["--tcp-mm", "1", "2"], ["--tcp-mm", "1", "2", "far"]):
        code, _, err = run_command(["diagnose", str(data), *argv], capsys)
        assert code == 2 and "--tcp-mm" in err


@pytest.mark.slow
@pytest.mark.skipif(not (REAL / "ur5_tracker").is_dir(), reason=f"real data not here: {REAL} (set TCR_REAL_DATA)")
def test_the_real_ur5_says_its_drift_is_on_the_row_order_and_flags_its_geometry(tmp_path, capsys):
    """The real UR5 (no time column) with the README's reflector offset, 0 0.07 31.0 mm: the answer and
    the report say the drift was fitted on the row order; the wrist_1 tilt (about 0.69 deg), tool0's
    rotation and the reflector fitted about 28.3 mm from tool0 (2.7 mm from the given 31.0) are
    flagged with their sizes; and every interval of its JSON holds its estimate."""
    out, report = tmp_path / "d.json", tmp_path / "report"
    code, printed, err = run_command(["diagnose", str(REAL / "ur5_tracker" / "ur5_grid_1000.csv"), "--robot", "ur5",
                                      "--tcp-mm", "0", "0.07", "31.0", "--json", str(out), "--out", str(report)],
                                     capsys)
    assert code == 0, err
    doc = json.loads(out.read_text())
    answer = printed[printed.index("Answer:"):printed.index("\n1. Gap")]
    assert "assumed: fitted on the measurement order: the rows carry no time_s column" in answer
    assert "flag: the fit tilts wrist_1_joint's axis by 0.6" in answer
    assert "flag: the measured point is fitted at" in answer and "given offset is (0, 0.07, 31) mm" in answer
    checks = {(c["what"], c["subject"]): c for c in doc["plausibility"]["checks"]}
    assert checks[("axis_tilt", "wrist_1_joint")]["value_deg"] == pytest.approx(0.69, abs=0.05)
    assert np.linalg.norm(checks[("tcp_offset", "tool0")]["fitted_mm"]) == pytest.approx(28.3, abs=0.3)
    assert checks[("tcp_offset", "tool0")]["flagged"] and checks[("tool_rotation", "tool0")]["flagged"]
    markdown = (report / "report.md").read_text()
    assert "fitted on the measurement order" in markdown and "Flag: The fit tilts wrist_1_joint's axis" in markdown
    assert_intervals_hold(doc)
