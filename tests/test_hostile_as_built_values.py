"""Issue 29, item 5: values read back from a diagnosis JSON or an as-built model file.

``export``, ``tcr_accuracy.load_as_built`` and ``iso9283 evaluate --model`` must refuse, in one
line naming the file and the key (exit code 2 for the commands, nothing written), a boolean or
text where a number belongs (``true``, YAML's ``yes``, ``0x10``, ``1:30``), numbers beyond what a
diagnosis can fit (1e308, geometry of 5 m, a compliance of 1e3, a TCP offset of a kilometre), a
tracker frame of the wrong shape, NaN or not rigid, and options of the wrong type. Decoy files in
a temporary folder only.
"""

import json
import re

import pytest

import tcr_accuracy as tcr
from tcr_accuracy.cli import main
from tcr_accuracy.exceptions import InputError

from hostile import assert_one_line, run


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A diagnosis JSON of the example tool-changer (joint offsets and geometry) and its export folder."""
    import shutil
    from pathlib import Path

    folder = tmp_path_factory.mktemp("values")
    csv = folder / "m.csv"
    shutil.copy(Path(__file__).resolve().parents[1] / "examples" / "measured.csv", csv)
    assert main(["diagnose", str(csv), "--effects", "joint_offsets,geometry", "--quiet",
                 "--json", str(folder / "d.json")]) == 0
    assert main(["export", str(folder / "d.json"), "--to", str(folder / "out"), "--quiet"]) == 0
    return folder


#: (what, edit of the model file's text, the key named, the reason named)
YAML_CASES = [
    ("yes", ("joint_offsets.j2: ", "joint_offsets.j2: yes #"), "effects.joint_offsets.joint_offsets.j2", "'yes' is not a number"),
    ("true", ("joint_offsets.j2: ", "joint_offsets.j2: true #"), "effects.joint_offsets.joint_offsets.j2", "True is not a number"),
    ("hex", ("joint_offsets.j2: ", "joint_offsets.j2: 0x10 #"), "effects.joint_offsets.joint_offsets.j2", "'0x10' is not a number"),
    ("sexagesimal", ("joint_offsets.j2: ", "joint_offsets.j2: 1:30 #"), "effects.joint_offsets.joint_offsets.j2",
     "'1:30' is not a number"),
    ("1e308", ("joint_offsets.j2: ", "joint_offsets.j2: 1.0e+308 #"), "effects.joint_offsets.joint_offsets.j2",
     "beyond what a diagnosis can fit"),
    ("5 m of geometry", ("geometry.j3.dx: ", "geometry.j3.dx: 5.0 #"), "effects.geometry.geometry.j3.dx",
     "beyond what a diagnosis can fit"),
    ("TCP 1 km", ("frames.tool.dz: ", "frames.tool.dz: 1000.0 #"), "effects.frames.frames.tool.dz",
     "beyond what a diagnosis can fit"),
    ("NaN", ("frames.tool.dz: ", "frames.tool.dz: .nan #"), "effects.frames.frames.tool.dz", "not a finite number"),
    ("text option", ("options: {}", "options: {thermal: {reference_temperature_c: warm}}"),
     "options.thermal.reference_temperature_c", "'warm' is not a number"),
]


def _edited(folder, text, old, new, tmp_path):
    # an effect with an option, and geometry (not chosen in these data)
    text = text.replace("effects:\n", "effects:\n  thermal: {}\n  geometry:\n    geometry.j3.dx: 0.0\n", 1)
    assert old in text, old
    target = tmp_path / "as_built.yaml"
    target.write_text(text.replace(old, new, 1))
    return target


@pytest.mark.parametrize("what, edit, key, reason", YAML_CASES, ids=[c[0] for c in YAML_CASES])
def test_load_as_built_refuses_a_forged_value_naming_file_and_key(exported, tmp_path, what, edit, key, reason):
    text = (exported / "out" / "as_built.yaml").read_text()
    path = _edited(exported, text, *edit, tmp_path)
    with pytest.raises(InputError) as info:
        tcr.load_as_built(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path)) and key in message and reason in message, message


@pytest.mark.parametrize("matrix, reason", [
    ("[[1.0, 0.0], [0.0, 1.0]]", "must be 4 rows of 4 numbers"),
    ("[[2.0, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, 2.0, 0], [0, 0, 0, 1]]", "not a rigid transform"),
    ("[[1, 0, 0, .nan], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]", "not a finite number"),
    ("[[1, 0, 0, 5000.0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]", "5e+03 m from the robot's base"),
], ids=["shape", "scaled", "nan", "far"])
def test_load_as_built_refuses_a_tracker_frame_that_is_no_rigid_transform(exported, tmp_path, matrix, reason):
    import yaml

    doc = yaml.safe_load((exported / "out" / "as_built.yaml").read_text())
    doc["trackerMbase"] = "PLACEHOLDER"
    path = tmp_path / "as_built.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False).replace("PLACEHOLDER", matrix))
    with pytest.raises(InputError, match=re.escape(reason)) as info:
        tcr.load_as_built(path)
    assert "trackerMbase" in str(info.value)


def test_an_integer_option_is_bounded(exported, tmp_path):
    import yaml

    doc = yaml.safe_load((exported / "out" / "as_built.yaml").read_text())
    doc["effects"]["cyclic"] = {}
    for value, reason in ((1e9, "not a whole number"), (1000000000, "not a whole number from 0 to 1000")):
        doc["options"]["cyclic"] = {"max_order": value}
        path = tmp_path / "as_built.yaml"
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        with pytest.raises(InputError, match=reason):
            tcr.load_as_built(path)


def test_a_joint_angle_table_needs_a_travel_per_joint_that_runs_forward(exported, tmp_path):
    import yaml

    doc = yaml.safe_load((exported / "out" / "as_built.yaml").read_text())
    doc["effects"]["angle_table"] = {}
    n = tcr.load_as_built(exported / "out" / "as_built.yaml").robot.n_joints
    for options, reason in (({"lower": [0.0, 1.0], "upper": [1.0, 2.0]}, f"2 values for {n} joints"),
                            ({"lower": [1.0] * n, "upper": [0.0] * n}, "ends below where it starts"),
                            ({"lower": ["a"] * n}, "lower[0]: 'a' is not of type 'number'"),
                            ({"upper": [True] * n}, "upper[0]: True"),
                            ({"intervals": 2}, "intervals: 2 is less than the minimum of 4"),
                            ({"intervals": 8, "knots": [[0.5, 0.1, 0.2, 0.3, 0.4, 0.6, 0.7] for _ in range(n)]},
                             "knots[0]: 7 increasing angles [rad]"),
                            ({"intervals": 8, "knots": [[0.1, 0.2] for _ in range(n)]},
                             "knots[0]: 7 increasing angles [rad]")):
        doc["options"]["angle_table"] = options
        path = tmp_path / "as_built.yaml"
        path.write_text(yaml.safe_dump(doc, sort_keys=False))
        with pytest.raises(InputError, match=re.escape(reason)):
            tcr.load_as_built(path)


#: (what, a change to the diagnosis JSON, the key named)
JSON_CASES = [
    ("true", lambda d: d["effect_parameters"]["joint_offsets"].update({"joint_offsets.j2": True}),
     "$.effect_parameters.joint_offsets['joint_offsets.j2']: true is not of type 'number'"),
    ("text", lambda d: d["effect_parameters"]["joint_offsets"].update({"joint_offsets.j2": "0x10"}),
     "$.effect_parameters.joint_offsets['joint_offsets.j2']: \"0x10\" is not of type 'number'"),
    ("1e308", lambda d: d["effect_parameters"].update(geometry={"geometry.j3.dx": 1e308}),
     "$.effect_parameters: effect geometry is in one of effect_parameters and parameters only"),
    ("TCP 1 km", lambda d: d["effect_parameters"]["frames"].update({"frames.tool.dz": 1000.0}),
     "$.effect_parameters.frames['frames.tool.dz']: 1000, but $.parameters.frames['frames.tool.dz'] says"),
    ("tracker shape", lambda d: d.update(trackerMbase=[[1, 0], [0, 1]]), "$.trackerMbase: [[1, 0], [0, 1]] is too short"),
    ("tracker not rigid", lambda d: d["trackerMbase"][0].__setitem__(0, 3.0), "trackerMbase: not a rigid"),
    ("text option", lambda d: d.update(effect_parameters={**d["effect_parameters"], "thermal": {}},
                                       effect_options={"thermal": {"reference_temperature_c": "warm"}}),
     "$.effect_options.thermal.reference_temperature_c: \"warm\" is not of type 'number'"),
]


@pytest.mark.parametrize("what, change, fragment", JSON_CASES, ids=[c[0] for c in JSON_CASES])
def test_export_refuses_a_forged_diagnosis_value_in_one_line(exported, tmp_path, capsys, what, change, fragment):
    data = json.loads((exported / "d.json").read_text())
    data["measurement_files"] = [str(exported / "m.csv")]
    change(data)
    forged = tmp_path / "d.json"
    forged.write_text(json.dumps(data))
    code, out, err = run(["export", str(forged), "--to", str(tmp_path / "never")], capsys)
    assert code == 2
    assert_one_line(err, str(forged), fragment)
    assert not (tmp_path / "never").exists()


@pytest.mark.parametrize("value, fragment", [(True, "true is not of type 'number'"),
                                             ("1:30", "\"1:30\" is not of type 'number'"),
                                             (1e308, "says 1e+308: one fitted value, written twice")])
def test_iso9283_model_refuses_a_forged_diagnosis_value_in_one_line(exported, tmp_path, capsys, value, fragment):
    data = json.loads((exported / "d.json").read_text())
    data["parameters"]["joint_offsets"]["joint_offsets.j2"] = value
    forged = tmp_path / "d.json"
    forged.write_text(json.dumps(data))
    code, out, err = run(["iso9283", "evaluate", str(exported / "m.csv"), "--model", str(forged),
                          "--json", str(tmp_path / "never.json")], capsys)
    assert code == 2
    assert_one_line(err, str(forged), "$.parameters.joint_offsets['joint_offsets.j2']", fragment)
    assert not (tmp_path / "never.json").exists()


def test_a_model_file_with_an_unknown_key_or_nested_deep_is_one_line(exported, tmp_path):
    text = (exported / "out" / "as_built.yaml").read_text()
    path = tmp_path / "as_built.yaml"
    path.write_text(text.replace("effects:", "efects: {}\neffects:", 1))
    with pytest.raises(InputError, match="key 'efects' is not part of the format"):
        tcr.load_as_built(path)
    path.write_text("[" * 50000 + "]" * 50000)
    with pytest.raises(InputError) as info:
        tcr.load_as_built(path)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("text, fragment", [
    ("x_mm,y_mm,z_mm,seed_j1_deg\n1000,200,300,10\n", "column seed_j2_... is missing"),
    ("x_mm,y_mm,z_mm,qw,qx\n1000,200,300,1,0\n", "needs all of qw, qx, qy, qz"),
    ("x_mm,y_mm,z_mm,qw,qx,qy,qz\n1000,200,300,2,0,0,0\n", "quaternion norm is 2"),
    ("x_mm,y_mm,z_mm\n1000,200,0x10\n", "row 2, column z_mm: '0x10' is not a finite number"),
    ("x_mm,y_mm,z_mm,payload_kg\n1000,200,300,-5\n", "column payload_kg: -5 kg is not a load"),
    ("x_mm,y_mm,z_mm,colour\n1000,200,300,1\n", "column 'colour' is not a target column"),
], ids=["partial seeds", "partial quaternion", "quaternion norm", "hex", "negative load", "unknown column"])
def test_cartesian_targets_at_fault_are_one_line(exported, tmp_path, capsys, text, fragment):
    targets = tmp_path / "targets.csv"
    targets.write_text(text)
    code, out, err = run(["export", str(exported / "d.json"), "--to", str(tmp_path / "never"), "--targets",
                          str(targets)], capsys)
    assert code == 2
    assert_one_line(err, str(targets), fragment)
    assert not (tmp_path / "never").exists()
