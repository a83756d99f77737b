"""What a new user reads on the terminal: progress, files written, names they chose."""

import io

import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.cli.diagnose import PROGRESS_FORMAT
from tcr_accuracy.model.robot import load_robot

from conftest import REPO


def run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_diagnose_progress_line_reads_as_words():
    from tqdm import tqdm

    stream = io.StringIO()
    bar = tqdm(desc="diagnose", file=stream, bar_format=PROGRESS_FORMAT)
    bar.set_postfix_str("step 1: trying geometry")
    line = str(bar)
    bar.close()
    assert line.startswith("diagnose, step 1: trying geometry [") and ": ," not in line


def test_diagnose_says_where_the_as_built_urdf_went(tmp_path, capsys):
    csv = tmp_path / "m.csv"
    assert main(["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"), "--n", "60",
                 "--seed", "2", "--out", str(csv), "--quiet"]) == 0
    urdf = tmp_path / "asbuilt.urdf"
    code, _, err = run(["diagnose", str(csv), "--effects", "frames,joint_offsets", "--folds", "2",
                        "--as-built-urdf", str(urdf)], capsys)
    assert code == 0 and urdf.is_file()
    assert f"as-built URDF written to {urdf} (the whole model, every effect and the tracker frame: " \
           f"{tmp_path / 'asbuilt.effects.yaml'})" in err
    # loaded again, it is labelled by the name inside the URDF, not by the file name
    assert load_robot(urdf).name == "tool_changer_as_built"


def test_a_urdf_file_is_named_after_its_robot_element(tmp_path):
    text = (REPO / "robots" / "tool_changer.urdf").read_text().replace('<robot name="tool_changer">',
                                                                      '<robot name="cutter_arm_2">')
    path = tmp_path / "anything.urdf"
    path.write_text(text)
    assert load_robot(path).name == "cutter_arm_2"


def test_predict_says_what_it_fits_before_the_long_part(tmp_path, capsys, monkeypatch):
    import sys

    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)  # progress lines are for a terminal
    code, _, err = run(["predict", "--train", str(REPO / "examples" / "measured.csv"),
                        "--query", str(REPO / "examples" / "poses.csv"), "--method", "idw-joint"], capsys)
    assert code == 0
    lines = err.splitlines()
    assert lines[0] == (f"fitting idw-joint to 200 measured poses of {REPO / 'examples' / 'measured.csv'} "
                        "(tracker frame and TCP offset first) ...")
    assert lines[1].startswith("fitted in ") and lines[1].endswith(" s")


def test_view_takes_view_like_every_other_command_and_html_still(tmp_path, capsys):
    for option, name in (("--view", "a.html"), ("--html", "b.html")):
        code, _, err = run(["view", option, str(tmp_path / name)], capsys)
        assert code == 0 and (tmp_path / name).is_file()
        assert f"3D view written to {tmp_path / name}" in err


def test_no_internal_jargon_in_what_scripts_and_commands_print():
    for folder in ("src", "scripts"):
        for path in (REPO / folder).rglob("*.py"):
            text = path.read_text(encoding="utf-8")
            assert "the lead " not in text, f"{path}: 'the lead' is this project's internal role, not the user's"


def test_predict_progress_stays_off_a_pipe_so_bad_input_is_one_line(tmp_path, capsys):
    bad = tmp_path / "query.csv"
    bad.write_text("j1_deg,j2_deg\n1,2\n")
    code, _, err = run(["predict", "--train", str(REPO / "examples" / "measured.csv"), "--query", str(bad),
                        "--method", "idw-joint"], capsys)
    assert code == 2 and len(err.splitlines()) == 1 and err.startswith("tcr-accuracy predict: error: ")


def test_montecarlo_angle_tolerance_in_degrees_like_every_angle_at_the_cli(tmp_path, capsys):
    import json
    import math

    runs = {}
    for name, option in (("deg", ["--angle-tol-deg", "0.5"]), ("rad", ["--angle-tol", "0.008726646259971648"])):
        out = tmp_path / f"{name}.json"
        code, printed, _ = run(["montecarlo", "--samples", "500", "--tail-samples", "0", *option,
                                "--json", str(out), "--quiet"], capsys)
        assert code == 0
        runs[name] = (json.loads(out.read_text()), printed)
    data, printed = runs["deg"]
    assert data["angle_tolerance_rad"] == pytest.approx(math.radians(0.5), rel=1e-12)
    assert data["reliability_angle"] == runs["rad"][0]["reliability_angle"]
    assert "P(|d angle| < 0.00872665 rad = 0.5 deg)" in printed
    code, _, err = run(["montecarlo", "--angle-tol-deg", "0"], capsys)
    assert code == 2 and "--angle-tol-deg 0: want a number > 0 deg" in err
