"""A result is consistent or refused (issue 37 items 1-5 and 12): the one reader of result files
(``tcr_accuracy.read_result``, and every command through it) holds a file's figures against each
other, each number written once, its robot against its source and the measurements given with it,
before anything uses it. Every decoy is written in ``tmp_path``; each refusal is one line naming
the file and the key, exit 2 on the command line."""

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

import tcr_accuracy as tcr
from tcr_accuracy.cli import main
from tcr_accuracy.exceptions import InputError

from hostile import assert_one_line, run

DEMO = Path(__file__).resolve().parents[1] / "src" / "tcr_accuracy" / "data" / "tool_changer_cutter.csv"


@pytest.fixture(scope="module")
def diagnosis(tmp_path_factory):
    """``diagnose --json`` of the bundled 300 readings (joint offsets and compliance), the CSV beside it."""
    folder = tmp_path_factory.mktemp("consistent")
    (folder / "m.csv").write_bytes(DEMO.read_bytes())
    path = folder / "d.json"
    assert main(["diagnose", str(folder / "m.csv"), "--effects", "joint_offsets,compliance", "--quiet",
                 "--json", str(path)]) == 0
    return path


@pytest.fixture(autouse=True)
def no_printing(monkeypatch):
    monkeypatch.setenv("TCR_CHROMIUM", "/nonexistent/chromium")  # the report's PDF is not what is tested


def _doc(path):
    return json.loads(Path(path).read_text())


def _write(tmp_path, doc, name="forged.json"):
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def _every_reader_refuses(path, diagnosis, tmp_path, capsys, *fragments):
    """export, report, compare and iso9283 evaluate --model refuse ``path`` in one line (exit 2, nothing
    written), and so does tcr_accuracy.read_result."""
    measured = diagnosis.parent / "m.csv"
    readers = {"export": ["export", path, "--to", tmp_path / "to"],
               "report": ["report", path, "--out", tmp_path / "rep", "--limit-mm", "max=0.05"],
               "compare": ["compare", diagnosis, path, "--n-poses", "20"],
               "iso9283 --model": ["iso9283", "evaluate", measured, "--model", path]}
    for reader, argv in readers.items():
        code, out, err = run(argv, capsys)
        assert code == 2, (reader, err)
        assert_one_line(err, str(path), *fragments)
        assert "PASS" not in out
        assert not (tmp_path / "to").exists() and not (tmp_path / "rep").exists()
    with pytest.raises(InputError, match=".*".join(map(_escaped, (str(path), *fragments)))):
        tcr.read_result(path)


def _escaped(text):
    import re

    return re.escape(text)


# ---------------------------------------------------------------------------------------
# Item 1: figures that contradict each other
# ---------------------------------------------------------------------------------------
def test_37_01_a_held_out_max_below_its_own_rms_is_refused(diagnosis, tmp_path, capsys):
    """The forgery of the issue: the final held-out max set below its RMS (the real max fails the
    limit, the forged one would pass)."""
    doc = _doc(diagnosis)
    last = len(doc["steps"]) - 1
    doc["steps"][last]["heldout_max_mm"] = 0.5 * doc["steps"][last]["heldout_rms_mm"]
    _every_reader_refuses(_write(tmp_path, doc), diagnosis, tmp_path, capsys,
                          f"$.steps[{last}]", "heldout_rms_mm", "is above heldout_max_mm")


def test_37_01_an_rms_far_below_the_noise_floor_is_refused(diagnosis, tmp_path, capsys):
    """0.001 mm held-out beside a noise floor of 0.035 mm, every other copy of the figure made to agree."""
    doc = _doc(diagnosis)
    floor = 0.035
    doc["noise_floor_mm"], doc["tracker_noise_mm"] = floor, floor / math.sqrt(3)
    doc["noise"]["per_axis_mm"] = floor / math.sqrt(3)
    for step in doc["steps"]:
        step.update(heldout_mean_mm=0.0009, heldout_rms_mm=0.001, heldout_max_mm=0.002)
    doc["final_heldout_rms_mm"], doc["final_over_noise"] = 0.001, 0.001 / floor
    _every_reader_refuses(_write(tmp_path, doc), diagnosis, tmp_path, capsys,
                          "$.steps[0].heldout_rms_mm: 0.001 mm is below 0.25 x the noise floor 0.035 mm")


def test_37_01_a_count_that_does_not_match_its_list_is_refused(diagnosis, tmp_path, capsys):
    doc = _doc(diagnosis)
    last = len(doc["steps"]) - 1
    n = sum(len(v) for v in doc["parameters"].values())
    doc["steps"][last]["n_parameters"] = n + 5
    _every_reader_refuses(_write(tmp_path, doc), diagnosis, tmp_path, capsys,
                          f"$.steps[{last}].n_parameters: {n + 5}, but $.parameters holds {n}")


@pytest.fixture(scope="module")
def iso_result(tmp_path_factory):
    """``iso9283 evaluate --frame base --json`` of five tool-changer poses read 10 times each, the
    readings the nominal TCP with known per-pose offsets and 10 um noise."""
    folder = tmp_path_factory.mktemp("iso")
    robot = tcr.load_robot()
    rng = np.random.default_rng(3)
    poses = robot.working_pose + rng.uniform(-0.3, 0.3, (5, robot.n_joints))
    poses[:, 3] = robot.working_pose[3]
    offset = rng.normal(0, 0.2e-3, (5, 3))
    rows = ["j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg,x_mm,y_mm,z_mm,pose_id,cycle"]
    nominal = tcr.tcp_poses(robot, poses).position
    for cycle in range(1, 11):
        for k in range(5):
            q = np.degrees(poses[k])
            q[3] = poses[k, 3] * 1e3
            p = (nominal[k] + offset[k] + rng.normal(0, 1e-5, 3)) * 1e3
            rows.append(",".join([*(repr(float(v)) for v in q), *(repr(float(v)) for v in p), str(k + 1), str(cycle)]))
    (folder / "iso.csv").write_text("\n".join(rows) + "\n")
    path = folder / "iso.json"
    assert main(["iso9283", "evaluate", str(folder / "iso.csv"), "--frame", "base", "--json", str(path),
                 "--quiet"]) == 0
    return path


def test_37_01_an_ap_below_the_norm_of_its_components_is_refused(iso_result, tmp_path, capsys):
    """AP_P is the norm of AP_x, AP_y, AP_z: a forged 0.0010 mm beside components of tenths is refused;
    the real file is read back with its figures."""
    result = tcr.read_result(iso_result)
    real = _doc(iso_result)
    first = result.conditions[0].evaluation.figures.poses[0]
    assert first.ap * 1e3 == pytest.approx(real["poses"][0]["ap_mm"], rel=1e-12)
    assert first.ap == pytest.approx(np.linalg.norm(first.ap_xyz), rel=1e-9)
    doc = _doc(iso_result)
    doc["poses"][0]["ap_mm"] = 0.001
    forged = _write(tmp_path, doc)
    code, out, err = run(["report", forged, "--out", tmp_path / "rep"], capsys)
    assert code == 2
    assert_one_line(err, str(forged), "$.poses[0].ap_mm: 0.001 mm, but AP_P is the norm of its components")
    assert not (tmp_path / "rep").exists()
    with pytest.raises(InputError, match=r"\$\.poses\[0\]\.ap_mm"):
        tcr.read_result(forged)


# ---------------------------------------------------------------------------------------
# Item 2: one copy of each number
# ---------------------------------------------------------------------------------------
def test_37_02_two_copies_of_a_parameter_that_disagree_are_refused(diagnosis, tmp_path, capsys):
    """effect_parameters says a j2 offset of 0.1 rad (export reads it), parameters its fitted 0.0005
    rad (report and compare read it): refused by every reader, naming both keys."""
    doc = _doc(diagnosis)
    doc["effect_parameters"]["joint_offsets"]["joint_offsets.j2"] = 0.1
    _every_reader_refuses(_write(tmp_path, doc), diagnosis, tmp_path, capsys,
                          "$.effect_parameters.joint_offsets['joint_offsets.j2']: 0.1, but $.parameters.joint_offsets['joint_offsets.j2'] says")


# ---------------------------------------------------------------------------------------
# Item 3: the training file as the check set
# ---------------------------------------------------------------------------------------
def test_37_03_export_check_with_the_training_rows_is_refused_as_in_sample(diagnosis, tmp_path, capsys):
    """The training file itself, and a copy of it written with 3 decimals: its error is in-sample,
    never printed as held-out."""
    rounded = tmp_path / "rounded.csv"
    _write_rounded(diagnosis.parent / "m.csv", rounded, 3)
    for check in (diagnosis.parent / "m.csv", rounded):
        code, out, err = run(["export", diagnosis, "--to", tmp_path / "to", "--check", check], capsys)
        assert code == 2, err
        assert_one_line(err, f"--check {check}: 300 of its 300 rows are rows of the measurements", "in-sample")
        assert not (tmp_path / "to").exists()


def _write_rounded(source: Path, target: Path, decimals: int, shuffle_positions=False):
    """``source`` with every number written to ``decimals`` decimals (the same campaign re-exported);
    with ``shuffle_positions``, the positions of other rows (measurements of no such robot)."""
    with source.open() as f:
        rows = list(csv.reader(line for line in f if not line.startswith("#")))
    header, body = rows[0], rows[1:]
    xyz = [header.index(c) for c in ("x_mm", "y_mm", "z_mm")]
    if shuffle_positions:
        order = np.random.default_rng(0).permutation(len(body))
        moved = [[body[i][k] for k in xyz] for i in order]
        for row, values in zip(body, moved):
            for k, v in zip(xyz, values):
                row[k] = v

    def cell(text):  # a number with decimals, rounded; labels, whole numbers and directions as they are
        try:
            return f"{float(text):.{decimals}f}" if "." in text else text
        except ValueError:
            return text

    target.write_text("\n".join(",".join([*header]) if i == 0 else ",".join(cell(c) for c in row)
                                for i, row in enumerate([header, *body])) + "\n")


# ---------------------------------------------------------------------------------------
# Item 4: the robot against its source, and against the measurements given with it
# ---------------------------------------------------------------------------------------
def test_37_04_a_diagnosis_named_as_another_robot_is_refused(diagnosis, tmp_path, capsys):
    """robot: ur10 while robot_source loads the tool-changer."""
    doc = _doc(diagnosis)
    doc["robot"] = "ur10"
    path = _write(tmp_path, doc)
    _every_reader_refuses(path, diagnosis, tmp_path, capsys, "ur10", "tool_changer")
    with pytest.raises(InputError, match=r"\$.robot: 'ur10', but the robot is 'tool_changer'"):
        tcr.read_result(path)


def test_37_04_a_model_file_named_as_another_robot_is_refused(diagnosis, tmp_path, capsys):
    code, out, err = run(["export", diagnosis, "--to", tmp_path / "out"], capsys)
    assert code == 0, err
    text = (tmp_path / "out" / "as_built.yaml").read_text()
    assert "\nrobot: tool_changer\n" in text
    forged = tmp_path / "forged.yaml"
    forged.write_text(text.replace("\nrobot: tool_changer\n", "\nrobot: ur10\n"))
    with pytest.raises(InputError, match="robot: 'ur10', but robot_source 'tool_changer' loads 'tool_changer'"):
        tcr.load_as_built(forged)


def test_load_as_built_given_a_diagnosis_says_what_it_is_and_how_to_build_its_model(diagnosis):
    """A diagnosis JSON is valid YAML; load_as_built names it a diagnosis and the two calls that make its model."""
    with pytest.raises(InputError, match=_escaped(f"{diagnosis}: a diagnosis, not an as-built model") +
                       ".*read_result.*AsBuiltModel.from_diagnosis"):
        tcr.load_as_built(diagnosis)


def test_37_04_another_robots_measurements_with_the_right_row_count_are_refused(diagnosis, tmp_path, capsys):
    """The same 300 joint values with the positions of other rows: the fitted model misses them by
    metres where it was fitted to tenths of a millimetre."""
    other = tmp_path / "other.csv"
    _write_rounded(diagnosis.parent / "m.csv", other, 6, shuffle_positions=True)
    code, out, err = run(["export", diagnosis, "--to", tmp_path / "to", "--measurements", other], capsys)
    assert code == 2
    assert_one_line(err, "other.csv: the model of", "misses these measurements by", "not the measurements it was "
                                                                                    "fitted to")
    assert not (tmp_path / "to").exists()


def test_37_04_the_right_measurements_pass_and_the_file_says_what_it_leaves_out(diagnosis, tmp_path, capsys):
    code, out, err = run(["export", diagnosis, "--to", tmp_path / "out"], capsys)
    assert code == 0, err
    model = tcr.load_as_built(tmp_path / "out" / "as_built.yaml")
    text = (tmp_path / "out" / "as_built.yaml").read_text()
    doc = _doc(diagnosis)
    base = [n for n in doc["effect_parameters"]["frames"] if n.startswith("frames.base.")]
    total = sum(len(v) for v in doc["effect_parameters"].values())
    assert len(base) == 6 and f"the file keeps {total - 6} of the {total} parameters of the model" in " ".join(text.split())
    assert sum(len(v) for v in model.parameters.values()) == total - 6


def test_read_result_gives_an_export_its_type_and_refuses_its_contradictions(diagnosis, tmp_path):
    """export's accuracy.json read with tcr_accuracy.read_result: an ExportResult holding the file's
    figures, its full model's k-fold figure the diagnosis' own last step (another file's copy of one
    number); a form whose mean lies above its RMS, or a count its point set does not hold, refused."""
    code = main(["export", str(diagnosis), "--to", str(tmp_path / "out"), "--quiet"])
    assert code == 0
    path = tmp_path / "out" / "accuracy.json"
    result = tcr.read_result(path)
    assert isinstance(result, tcr.ExportResult) and result.to_dict() == _doc(path)
    assert result.forms()[0] == "full model" and result.forms()[-1] == "nominal"
    kfold = [a for a in result.figures("full model") if a.on == "k-fold held-out"]
    last = _doc(diagnosis)["steps"][-1]
    assert len(kfold) == 1 and kfold[0].rms == pytest.approx(last["heldout_rms_mm"] * 1e-3, rel=1e-12)
    measured = [a for a in result.accuracy if a.on == "measured"]
    assert {a.n for a in measured} == {_doc(diagnosis)["n_measurements"]}
    doc = _doc(path)
    i = next(i for i, a in enumerate(doc["accuracy"]) if a["on"] == "measured")
    doc["accuracy"][i]["mean_mm"] = doc["accuracy"][i]["rms_mm"] * 2
    with pytest.raises(InputError, match=_escaped(f"$.accuracy[{i}]: mean_mm") + ".*above rms_mm"):
        tcr.read_result(_write(tmp_path, doc, "forged_mean.json"))
    doc = _doc(path)
    doc["accuracy"][i]["n"] += 1
    with pytest.raises(InputError, match=_escaped(f"$.accuracy[{i}].n: ") + ".*holds"):
        tcr.read_result(_write(tmp_path, doc, "forged_count.json"))


# ---------------------------------------------------------------------------------------
# Item 5: the same campaign re-exported with fewer decimals is not a second session
# ---------------------------------------------------------------------------------------
def test_37_05_the_same_campaign_with_fewer_decimals_is_not_a_second_session(diagnosis, tmp_path, capsys):
    rounded = tmp_path / "m_3dec.csv"
    _write_rounded(diagnosis.parent / "m.csv", rounded, 3)
    code, out, err = run(["diagnose", diagnosis.parent / "m.csv", rounded, "--effects", "joint_offsets", "--quiet",
                          "--json", tmp_path / "never.json"], capsys)
    assert code == 2
    assert_one_line(err, f"{rounded}: its 300 rows are rows of", "the same measurements written twice are one session")
    assert not (tmp_path / "never.json").exists()


def test_37_05_a_genuine_second_session_is_two_sessions(tmp_path, capsys):
    """The same commanded poses measured again (the tracker's 10 um noise, another tracker frame): two
    sessions, as before."""
    robot = tcr.load_robot("ur5")
    rng = np.random.default_rng(1)
    q = rng.uniform(-1.5, 1.5, (40, robot.n_joints))
    nominal = tcr.tcp_poses(robot, q).position
    files = []
    for k, shift in enumerate(([0, 0, 0], [0.5, -0.2, 0.1])):
        position = nominal + np.array(shift) + rng.normal(0, 1e-5, nominal.shape)
        measured = tcr.MeasurementSet(joint_names=list(robot.joint_names), q=q, position=position)
        files.append(tmp_path / f"s{k}.csv")
        tcr.write_measurements(files[-1], robot, measured)
    code, out, err = run(["diagnose", *files, "--robot", "ur5", "--effects", "joint_offsets", "--folds", "3",
                          "--json", tmp_path / "d.json", "--quiet"], capsys)
    assert code == 0, err
    assert len(_doc(tmp_path / "d.json")["sessions"]) == 2


# ---------------------------------------------------------------------------------------
# Item 12: a large result read in bounded time and memory
# ---------------------------------------------------------------------------------------
def test_37_12_a_60_mb_diagnosis_is_read_and_a_forgery_deep_in_it_named(diagnosis, tmp_path):
    """60 MB (under the 256 MB bound): 4 x 99,000 compliance parameters of 1e-9 rad with their standard
    errors, units and intervals, and 90,000 notes of 500 characters. Read whole through the one reader's schema
    (scripts/bench_result_reader.py times it against jsonschema alone); a negative standard error
    at the end of the largest mapping is named by its key."""
    from tcr_accuracy.results.files import read_result_document

    doc = _doc(diagnosis)
    names = [f"compliance.x{i:06d}" for i in range(99_000)]
    doc["parameters"]["compliance"].update(dict.fromkeys(names, 1e-9))
    doc["parameter_std"]["compliance"].update(dict.fromkeys(names, 1e-10))
    doc["parameter_units"]["compliance"].update(dict.fromkeys(names, "rad/Nm"))
    doc["parameter_interval_95"]["compliance"].update({n: [0.0, 2e-9] for n in names})
    doc["steps"][-1]["n_parameters"] += 99_000
    doc["notes"] = doc["notes"] + ["a note of the diagnosis, " * 20] * 90_000
    big = _write(tmp_path, doc, "big.json")
    assert 50e6 < big.stat().st_size < 256 * 2**20
    kind, read = read_result_document(big)
    assert kind == "diagnosis" and len(read["parameters"]["compliance"]) == 99_000 + 4
    doc["parameter_std"]["compliance"][names[-1]] = -1e-10
    forged = _write(tmp_path, doc, "forged.json")
    with pytest.raises(InputError, match=rf"forged.json: \$.parameter_std.compliance\['{names[-1]}'\]: -1e-10 is "
                                         "less than the minimum of 0"):
        read_result_document(forged)
