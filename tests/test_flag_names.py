"""Library errors name Python parameters; the command line words them as its flags.

The library half: an error carries the parameter at fault and its value, and its message names
the parameter, not a flag. The command-line half: :func:`tcr_accuracy.cli.flag_names.in_flags`
rewrites the keyword forms with the table read from the parsers, and the commands print the
flag. The table's aliases are checked against the parsers, so a renamed option cannot leave one
behind.
"""

import argparse
import ast
from pathlib import Path

import numpy as np
import pytest

import tcr_accuracy
from tcr_accuracy.cli import build_parser
from tcr_accuracy.cli.flag_names import ALIASES, in_flags
from tcr_accuracy.exceptions import InputError
from conftest import run_command as run

PACKAGE = Path(tcr_accuracy.__file__).resolve().parent

#: Library parameters that no option sets as it is (the command line checks its own option, in its
#: own unit, before the library sees the value).
PYTHON_ONLY = {"tolerance_s": "import checks --tolerance-ms [ms] itself; the library's is in s",
               "robot_source": "AsBuiltModel.from_diagnosis's; the command line loads the robot from --robot",
               "measured_q": "plan_discriminating_poses'; plan-poses passes the poses of its measurement files "
                             "and refuses files with no row itself"}


def _every_dest() -> set[str]:
    dests, todo = set(), [build_parser()]
    while todo:
        parser = todo.pop()
        for action in parser._actions:
            if action.option_strings:
                dests.add(action.dest)
            if isinstance(action, argparse._SubParsersAction):
                todo += list(action.choices.values())
    return dests


def _library_parameters() -> dict[str, str]:
    """``parameter="..."`` given to an error below the edges: {name: where}."""
    found = {}
    for path in PACKAGE.rglob("*.py"):
        if path.relative_to(PACKAGE).parts[0] in ("cli", "view"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                for keyword in node.keywords:
                    if keyword.arg == "parameter" and isinstance(keyword.value, ast.Constant):
                        found.setdefault(keyword.value.value, f"{path.name}:{node.lineno}")
    return found


# ---------------------------------------------------------------------------------------
# The rewriting, on sentences written here
# ---------------------------------------------------------------------------------------
FLAGS = {"folds": "--folds", "robot": "--robot", "tool": "--tool", "map": "--map", "effects": "--effects",
         "package_dir": "--package-dir"}


@pytest.mark.parametrize("text, parameter, expected", [
    ("folds=1: need at least 2", "folds", "--folds 1: need at least 2"),
    ("a.csv: measures frame hand; give tool=hand", "tool", "a.csv: measures frame hand; give --tool hand"),
    ("give the robot= and tool= the diagnosis used", None, "give the --robot and --tool the diagnosis used"),
    ("a diagnosis of ur5; give robot=", "robot", "a diagnosis of ur5; give --robot"),
    ('name it with tracker_map["x_mm"]="HEADER"', "tracker_map", 'name it with --map x_mm="HEADER"'),
    ("effects: unknown effect(s) foo", "effects", "--effects: unknown effect(s) foo"),
    ("source=.: a folder", "source", "--robot .: a folder"),
    ("with package_dirs=DIR or in ROS_PACKAGE_PATH", "package_dirs", "with --package-dir DIR or in ROS_PACKAGE_PATH"),
])
def test_keyword_forms_become_flags(text, parameter, expected):
    assert in_flags(text, FLAGS, parameter) == expected


@pytest.mark.parametrize("text, parameter", [
    ("source=.: a folder", None),             # an alias only for the parameter the error is about
    ("x.tool=3, --robot ur5, my_robot=2", "robot"),  # attributes, flags and longer names stay
    ("a.csv: effects: unknown", "effects"),   # a name with a colon only as the message's subject
    ("the robot moves the tool", "robot"),    # words are words
    ("folds=1: need at least 2", "n"),        # a command without --folds leaves the parameter
])
def test_other_text_is_left_as_it_is(text, parameter):
    flags = dict(FLAGS)
    if parameter == "n":
        del flags["folds"]
    assert in_flags(text, flags, parameter) == text


def test_every_alias_names_options_that_exist_and_every_library_parameter_has_a_flag():
    dests = _every_dest()
    for name, targets in ALIASES.items():
        assert set(targets) <= dests, (name, targets)
    aliased = set(ALIASES)
    orphans = {name: where for name, where in _library_parameters().items()
               if name not in dests | aliased | set(PYTHON_ONLY)}
    assert not orphans, orphans
    assert len(_library_parameters()) >= 10  # the walk found the errors


# ---------------------------------------------------------------------------------------
# The library speaks Python
# ---------------------------------------------------------------------------------------
def test_library_errors_carry_the_parameter_and_its_value(ur5):
    from tcr_accuracy.analysis.trajectory import tool_change_motion
    from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
    from tcr_accuracy.model.errors import seed_budget

    measurements = tcr_accuracy.MeasurementSet(joint_names=ur5.joint_names, q=np.zeros((20, 6)),
                                               position=np.zeros((20, 3)))
    with pytest.raises(InputError) as caught:  # scikit-learn's declared constraints, read first
        GapDiagnosis(robot=ur5, folds=1).fit(measurements)
    assert (caught.value.parameter, caught.value.value) == ("folds", 1) and "'folds'" in str(caught.value)
    with pytest.raises(InputError) as caught:
        GapDiagnosis(robot=ur5, effects=["geometry", "nope"]).fit(measurements)
    assert str(caught.value).startswith("effects: unknown effect(s) nope (vocabulary: ")
    assert (caught.value.parameter, caught.value.value) == ("effects", ["geometry", "nope"])
    with pytest.raises(InputError) as caught:
        tcr_accuracy.load_robot("no_such_robot_here")
    assert caught.value.parameter == "source" and caught.value.value == "no_such_robot_here"
    assert str(caught.value).startswith("source=no_such_robot_here: no such file")
    with pytest.raises(InputError) as caught:
        tcr_accuracy.load_robot("ur5", "no_such_frame")
    assert (caught.value.parameter, caught.value.value) == ("tool", "no_such_frame")
    with pytest.raises(InputError) as caught:
        seed_budget(ur5, "table2")
    assert caught.value.parameter == "preset" and "use preset=table1" in str(caught.value)
    with pytest.raises(InputError) as caught:
        tool_change_motion(ur5)
    assert caught.value.parameter == "robot" and "--" not in str(caught.value)


# ---------------------------------------------------------------------------------------
# The command line speaks flags
# ---------------------------------------------------------------------------------------
def test_commands_print_the_flags(tmp_path, capsys):
    tracker = tmp_path / "tracker.csv"
    tracker.write_text("A,B,C\n1,2,3\n")
    timed, log = tmp_path / "timed.csv", tmp_path / "log.csv"
    timed.write_text("X,Y,Z,Time\n1,2,3,0\n")
    log.write_text("Time,Foo\n0,1\n")
    cases = [
        (["trajectory", "--robot", "ur5", "--samples", "10"], "robot ur5 has other joints: give its trajectory with --file"),
        (["view", "--robot", "ur5", "--error-preset", "table2"], "ur5 has 6 joints (R, R, R, R, R, R); use --error-preset table1"),
        (["montecarlo", "--robot", "ur5", "--preset", "table2"], "--preset table2: the seed's Table 2"),
        (["montecarlo", "--robot", "ur5", "--preset", "table2"], "use --preset table1 or a --config file"),
        (["pose", "--robot", "ur5", "--tool", "no_such_frame"], "error: --tool no_such_frame: no such frame in ur5"),
        (["import", str(tracker), "--map", "x_mm=A", "y_mm=B", "z_mm=C", "--joints", str(log), "--out",
          str(tmp_path / "m.csv")], "no timestamp column to join the joint log on: name it with --map time_s=\"HEADER\""),
        (["import", str(timed), "--joints", str(log), "--out", str(tmp_path / "m.csv")],
         "no joint columns: name them like the measurement CSV (j1_deg, ...) or map them with --log-map j1_deg=\"HEADER\""),
    ]
    for argv, message in cases:
        code, out, err = run(argv, capsys)
        assert code == 2 and message in err and err.count("\n") == 1, (argv, err)
    tracker.write_text("Point X,Point Y,Meas Z,Dev Z\n1,2,3,4\n")
    code, out, err = run(["import", str(tracker), "--out", str(tmp_path / "m.csv")], capsys)
    assert code == 2 and err.count("\n") == 1
    assert "columns 'Meas Z', 'Dev Z' could each be the z position: name one with --map z_mm=\"HEADER\"" in err, err
