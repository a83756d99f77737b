"""One validation of each result JSON on read (issue 29 items 6, 7, 8): export, report, compare
and ``iso9283 evaluate --model`` read a diagnosis through :mod:`tcr_accuracy.results.files`;
a key of the wrong type, a forged value or a foreign file is one line naming the key, exit 2,
never an unexpected error, never ``None`` or ``nan`` on the customer's page.
"""

import copy
import inspect
import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from hostile import assert_one_line, run
from tcr_accuracy.cli import main
from tcr_accuracy.results.files import (FIT_KEYS, MODEL_KEYS, PAGE_KEYS, check_physics, read_result_document,
                                           validate_result)
from tcr_accuracy.effects import effect_class, vocabulary
from tcr_accuracy.effects.option_schema import OPTIONS
from tcr_accuracy.exceptions import InputError


DEMO = Path(__file__).resolve().parents[1] / "src" / "tcr_accuracy" / "data" / "tool_changer_cutter.csv"


@pytest.fixture(scope="module")
def diagnosis(tmp_path_factory):
    """A diagnosis JSON as ``diagnose --json`` writes it (the bundled 300 readings with the disc
    cutter on: joint offsets and compliance found), and a measurement CSV beside it."""
    folder = tmp_path_factory.mktemp("results")
    path = folder / "d.json"
    (folder / "m.csv").write_bytes(DEMO.read_bytes())
    assert main(["diagnose", str(folder / "m.csv"), "--effects", "joint_offsets,compliance", "--noise-mm", "0.02",
                 "--quiet", "--json", str(path)]) == 0
    doc = json.loads(path.read_text())
    assert {"joint_offsets", "compliance"} <= set(doc["parameters"])
    return path


@pytest.fixture(autouse=True)
def no_printing(monkeypatch):
    monkeypatch.setenv("TCR_CHROMIUM", "/nonexistent/chromium")  # the report's PDF is not what is tested


def _doc(diagnosis):
    return json.loads(diagnosis.read_text())


def _write(tmp_path, doc, name="forged.json"):
    path = tmp_path / name
    path.write_text(json.dumps(doc))
    return path


def _readers(path, diagnosis, tmp_path):
    """Every command that reads a diagnosis, reading ``path``."""
    measured = diagnosis.parent / "m.csv"
    return {"export": ["export", path, "--to", tmp_path / "to"],
            "report": ["report", path, "--out", tmp_path / "rep"],
            "compare": ["compare", diagnosis, path, "--n-poses", "20"],
            "iso9283 --model": ["iso9283", "evaluate", measured, "--model", path]}


def assert_every_reader_refuses(path, diagnosis, tmp_path, capsys, *fragments):
    for reader, argv in _readers(path, diagnosis, tmp_path).items():
        code, out, err = run(argv, capsys)
        assert code == 2, (reader, err)
        assert_one_line(err, str(path), *fragments)
        assert "unexpected error" not in err
        assert not (tmp_path / "to").exists() and not (tmp_path / "rep").exists()


# ---------------------------------------------------------------------------------------
# Item 6: keys of the wrong type or null, numbers of 1e308, in every reader
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("path, value, said", [
    (("parameters",), None, "$.parameters: null is not of type 'object'"),
    (("parameters", "compliance"), [1, 2], "$.parameters.compliance: [1, 2] is not of type 'object'"),
    (("parameters", "compliance", "compliance.j2"), "0.1", "is not of type 'number'"),
    (("parameters", "compliance", "compliance.j2"), True, "is not of type 'number'"),
    (("parameters", "compliance", "compliance.j2"), 1e308, "says 1e+308: one fitted value, written twice"),
    (("robot",), 5, "$.robot: 5 is not of type 'string'"),
    (("effect_options", "cyclic"), {"max_order": 10**9}, "is greater than the maximum of 200"),
    (("effect_options", "angle_table"), {"intervals": 10**6}, "is greater than the maximum of 1000"),
    (("effect_options", "angle_table"), {"lower": ["0"]}, "angle_table.lower[0]: \"0\" is not of type 'number'"),
    (("effect_options", "compliance"), {"rng": 1}, "Additional properties are not allowed"),
    (("parameters", "nosuch"), {}, "$.parameters: 'nosuch' is not one of"),
])
def test_29_06_a_forged_key_is_one_line_in_every_reader(path, value, said, diagnosis, tmp_path, capsys):
    doc = _doc(diagnosis)
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    assert_every_reader_refuses(_write(tmp_path, doc), diagnosis, tmp_path, capsys, said)


# ---------------------------------------------------------------------------------------
# Item 7: no forged value on the customer's page
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("key, value, said", [
    ("n_measurements", None, "$.n_measurements: null is not of type 'integer'"),
    ("folds", "nan", "$.folds: \"nan\" is not of type 'integer'"),
    ("folds", 1, "$.folds: 1 is less than the minimum of 2"),
    ("noise_floor_mm", -0.1, "$.noise_floor_mm: -0.1 is less than the minimum of 1e-06"),
    ("noise_floor_mm", 0, "$.noise_floor_mm: 0 is less than the minimum of 1e-06"),
    ("noise_floor_mm", None, "$.noise_floor_mm: null is not of type 'number'"),
    ("steps", [], "$.steps: [] should be non-empty"),
])
def test_29_07_the_page_never_prints_a_forged_value(key, value, said, diagnosis, tmp_path, capsys):
    doc = _doc(diagnosis)
    doc[key] = value
    path = _write(tmp_path, doc)
    code, out, err = run(["report", path, "--out", tmp_path / "rep"], capsys)
    assert code == 2
    assert_one_line(err, said)
    assert not (tmp_path / "rep").exists()


def test_29_07_results_of_other_robots_or_tcp_frames_are_not_one_report(diagnosis, tmp_path, capsys):
    other = _doc(diagnosis)
    other["tool_frame"] = "j6"
    code, out, err = run(["report", diagnosis, _write(tmp_path, other), "--out", tmp_path / "rep"], capsys)
    assert code == 2
    assert_one_line(err, "results of different TCP frames")


# ---------------------------------------------------------------------------------------
# Item 8: compare trusts no forged standard error and no other TCP frame
# ---------------------------------------------------------------------------------------
def test_29_08_a_missing_or_negative_standard_error_is_refused(diagnosis, tmp_path, capsys):
    doc = _doc(diagnosis)
    name = next(iter(doc["parameters"]["compliance"]))
    missing = copy.deepcopy(doc)
    del missing["parameter_std"]["compliance"][name]
    code, out, err = run(["compare", diagnosis, _write(tmp_path, missing, "m.json"), "--n-poses", "20"], capsys)
    assert code == 2
    assert_one_line(err, f"$.parameter_std.compliance: no entry for {name}")
    negative = copy.deepcopy(doc)
    negative["parameter_std"]["compliance"][name] = -1e-9
    code, out, err = run(["compare", diagnosis, _write(tmp_path, negative, "n.json"), "--n-poses", "20"], capsys)
    assert code == 2
    assert_one_line(err, f"$.parameter_std.compliance['{name}']: -1e-09 is less than the minimum of 0")


def test_29_08_diagnoses_of_different_tcp_frames_are_not_compared(diagnosis, tmp_path, capsys):
    doc = _doc(diagnosis)
    doc["tool_frame"] = "j6"
    code, out, err = run(["compare", diagnosis, _write(tmp_path, doc), "--n-poses", "20"], capsys)
    assert code == 2
    assert_one_line(err, "of the TCP frame tool", "of j6: compare two diagnoses of one TCP frame")


# ---------------------------------------------------------------------------------------
# Physics and structure
# ---------------------------------------------------------------------------------------
def test_each_parameter_is_held_to_its_effects_fit_range(diagnosis, tool_changer):
    """A fit stays within its effect's fit range (its physics and the mechanisms it can stand for,
    e.g. a controller's gravity compensation giving compliance the other sign): a value just
    outside it is forged; one inside it but outside the effect's own physics is a reading, not a forgery."""
    doc = _doc(diagnosis)
    check_physics(doc, tool_changer, "d.json")  # the real one passes
    compliance = effect_class("compliance")(tool_changer)
    low, high = compliance.fit_range()
    physical_low, _ = compliance.physical_range()
    names = compliance.parameter_names()
    assert low[0] < physical_low[0]  # the fit range reaches past the physics (the other sign)
    for k, bound in ((0, low[0] * 1.01 - 1e-12), (1, high[1] * 1.01)):  # just outside, computed from the effect
        forged = copy.deepcopy(doc)
        forged["parameters"]["compliance"][names[k]] = bound
        with pytest.raises(InputError, match=rf"\['{names[k]}'\]: .* is outside the range"):
            check_physics(forged, tool_changer, "d.json")
    inside = copy.deepcopy(doc)
    inside["parameters"]["compliance"][names[0]] = 0.5 * low[0]  # the other sign, within a mechanism's reach
    inside.get("parameter_interval_95", {}).get("compliance", {}).pop(names[0], None)
    check_physics(inside, tool_changer, "d.json")


def test_the_tracker_transform_must_be_rigid(diagnosis):
    doc = _doc(diagnosis)
    doc["trackerMbase"][0][0] *= 1.5
    with pytest.raises(InputError, match=r"\$.trackerMbase: not a rigid transform"):
        validate_result(doc, "diagnosis", "d.json", MODEL_KEYS)
    doc["trackerMbase"] = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    with pytest.raises(InputError, match=r"\$.trackerMbase: .* is too short"):
        validate_result(doc, "diagnosis", "d.json", MODEL_KEYS)


def test_a_json_number_beyond_float_is_refused_on_read(diagnosis, tmp_path):
    text = diagnosis.read_text().replace('"folds": 5', '"folds": 5, "extra": 1e400', 1)
    with pytest.raises(InputError, match="1e400 is beyond the range of a number"):
        read_result_document(_write_text(tmp_path, text), "diagnosis")


def _write_text(tmp_path, text):
    path = tmp_path / "t.json"
    path.write_text(text)
    return path


def test_every_keyword_option_of_every_effect_has_a_schema():
    """A new effect option must be bounded before a file may set it (cyclic's max_order sizes the model)."""
    missing = []
    for name in vocabulary():
        cls = effect_class(name)
        for option, parameter in inspect.signature(cls.__init__).parameters.items():
            if parameter.kind is inspect.Parameter.KEYWORD_ONLY and option != "rng" and \
                    option not in OPTIONS.get(name, {}):
                missing.append(f"{name}.{option}")
    assert not missing, missing


#: Values that confuse a reader that trusts the file's types.
_HOSTILE = st.sampled_from([None, True, -1, 0, 1e308, -1e308, "", "x" * 5, [], [None], {}, {"a": None}])


def _leaves(node, path=()):
    if isinstance(node, dict):
        for key, value in node.items():
            yield path + (key,)
            yield from _leaves(value, path + (key,))
    elif isinstance(node, list):
        for k, value in enumerate(node[:3]):
            yield path + (k,)
            yield from _leaves(value, path + (k,))


@pytest.fixture(scope="module")
def leaves(diagnosis):
    return sorted(_leaves(_doc(diagnosis)), key=str)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(data=st.data())
def test_fuzz_type_confusion_of_any_key_is_refused_or_read_without_harm(data, diagnosis, leaves, tool_changer):
    """Any key of a real diagnosis replaced by a hostile value: the validation refuses it in one
    InputError line, or what passes is read by compare's model and the report's page without
    an exception and without printing None, nan or inf."""
    from tcr_accuracy.diagnosis.compare import FittedModel
    from tcr_accuracy.view.calibration_report import Campaign, RobotFacts, first_page

    doc = _doc(diagnosis)
    path = data.draw(st.sampled_from(leaves))
    node = doc
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = data.draw(_HOSTILE)
    try:
        validate_result(doc, "diagnosis", "d.json", (*PAGE_KEYS, *MODEL_KEYS, *FIT_KEYS))
        check_physics(doc, tool_changer, "d.json")
    except InputError as exc:
        assert "\n" not in str(exc) and str(exc).startswith("d.json: ")
        return
    FittedModel.from_dict(doc, "d.json")
    html, markdown = first_page(Campaign(RobotFacts.from_documents([("d.json", doc)]), [("d.json", doc)]),
                                "2026-01-01 00:00:00 UTC")
    for word in ("None measured", "nan", "inf mm", "None-fold"):
        assert word not in markdown, (path, word)
    assert all(math.isfinite(v) for v in doc["parameters"].get("compliance", {}).values())
