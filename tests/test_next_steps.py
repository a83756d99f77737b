"""The steps after a diagnosis (view/next_steps.py): a person can act on each.

Checked against what a person would do with them: the effects are named in words (no vocabulary
identifier outside a command), and the plan-poses command the first step gives runs, as written,
to its end and writes the poses it promises.
"""

from __future__ import annotations

import csv
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from tcr_accuracy.effects import effect_classes
from tcr_accuracy.view.next_steps import NEXT_POSES, export_step, next_steps, next_steps_lines
from tcr_accuracy.view.page_blocks import Code

REPO = Path(__file__).resolve().parents[1]

#: The UR5's groups as its real diagnosis gave them (members with a companion joined by "+").
GROUPS = [{"effects": ["joint_offsets", "compliance+encoder_scale", "backlash+encoder_scale"], "chosen": "joint_offsets"},
          {"effects": ["cyclic", "angle_table"], "chosen": "cyclic"}]


def _prose(step) -> str:
    return "".join(p for p in step.parts if not isinstance(p, Code))


def test_effects_are_named_in_words_not_vocabulary_sets():
    steps = next_steps({"ambiguous": GROUPS, "structure_verdict": "yes"}, measurements=["meas.csv"])
    # the vocabulary's compound identifiers ("backlash", "cyclic" are words of English as well)
    vocabulary = re.compile(r"\b(" + "|".join(n for n in effect_classes(vocabulary_only=False) if "_" in n) + r")\b")
    for step in steps:
        assert not vocabulary.search(_prose(step)), _prose(step)
        assert "{" not in _prose(step) and "+" not in _prose(step)
    # every alternative of a group, companions included, is named once in the check on the robot
    check = _prose(steps[1])
    assert check.startswith("Until then, check on the robot which of these it is: encoder zero offsets, ")
    for words in ("joints giving way under gravity", "a gear-ratio error", "backlash"):
        assert check.count(words) == 1


def test_one_numbered_sentence_a_step():
    steps = next_steps({"ambiguous": GROUPS}, measurements=["a.csv", "b.csv"], robot_options=" --robot ur5 --tool tool0")
    lines = next_steps_lines(steps + [export_step("d.json")])
    assert lines[0] == "Next steps:"
    assert [line.split(".", 1)[0].strip() for line in lines[1:]] == [str(i) for i in range(1, len(lines))]
    assert "`tcr-accuracy diagnose a.csv b.csv next_poses_measured.csv --robot ur5 --tool tool0`" in lines[1]
    assert lines[-1].startswith("  4. Load the calibration into the controller: `tcr-accuracy export d.json")


def test_the_suggested_plan_poses_command_runs_to_its_end(tmp_path):
    shutil.copy(REPO / "examples" / "measured.csv", tmp_path / "measured.csv")
    step = next_steps({"structure_verdict": "no"}, measurements=["measured.csv"])[0]
    commands = [p.text for p in step.parts if isinstance(p, Code)]
    assert commands[0].startswith("tcr-accuracy plan-poses measured.csv")
    argv = shlex.split(commands[0])
    done = subprocess.run([sys.executable, "-m", "tcr_accuracy", *argv[1:], "--quiet"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    with open(tmp_path / "next_poses.csv", newline="") as handle:
        rows = [r for r in csv.reader(line for line in handle if not line.startswith("#"))]
    pose_rows = rows[1:]
    assert len({tuple(r) for r in pose_rows}) >= NEXT_POSES  # the 30 poses (a reference pose may repeat)
