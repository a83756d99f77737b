"""compare: two simulated campaigns of one tool-changer, seen from two tracker stations.

The second campaign's robot has joint j3's offset moved by 0.05 deg (a crash, a remastering);
a third campaign changes nothing. The comparison reads only the diagnoses (or the CSVs) and is
judged on what the scenarios hid; the TCP effect against Pinocchio's forward kinematics with a
hand-written Kabsch fit.
"""

import copy
import json

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.analysis.simulate import simulate_measurements
from tcr_accuracy.cli import main
from tcr_accuracy.diagnosis.compare import FittedModel, parameter_changes
from tcr_accuracy.diagnosis.diagnose import diagnose
from tcr_accuracy.cli.writers import write_measurements
from conftest import run_command as _run

NOISE_MM = 0.02
J3_CHANGE_DEG = 0.05
STATION_A = {"base_mm": {"dx": 1250.0, "dy": -830.0, "dz": -410.0}, "base_deg": {"rz": 35.0}}
STATION_B = {"base_mm": {"dx": -900.0, "dy": 1400.0, "dz": -300.0}, "base_deg": {"rz": -60.0, "rx": 0.4}}
#: the robot as built: the same in every campaign but for what a test changes
OFFSETS_DEG = {"j2": 0.03, "j3": -0.02, "j5": 0.04}
GEOMETRY = {"errors_mm": {"j2.dx": 0.08, "j3.dz": -0.1, "j5.dy": 0.06}, "errors_mrad": {"j3.rx": 0.1}}


def _campaign(robot, station, offsets_deg, seed, n=300):
    scenario = {"effects": {"frames": {**station, "tool_mm": {"dx": 0.8, "dy": -0.5, "dz": 1.2}},
                            "joint_offsets": {"offsets_deg": offsets_deg},
                            "geometry": GEOMETRY},
                "noise_mm": NOISE_MM}
    mset, _ = simulate_measurements(robot, scenario, n, np.random.default_rng(seed))
    return mset


@pytest.fixture(scope="module")
def campaigns(tool_changer, tmp_path_factory):
    """CSV and diagnosis JSON of: old (station A), changed (station B, j3 + 0.05 deg), same (station B,
    nothing changed, other noise and poses)."""
    folder = tmp_path_factory.mktemp("campaigns")
    moved = {**OFFSETS_DEG, "j3": OFFSETS_DEG["j3"] + J3_CHANGE_DEG}
    sets = {"old": _campaign(tool_changer, STATION_A, OFFSETS_DEG, seed=1),
            "changed": _campaign(tool_changer, STATION_B, moved, seed=2),
            "same": _campaign(tool_changer, STATION_B, OFFSETS_DEG, seed=3)}
    files = {}
    for name, mset in sets.items():
        csv = folder / f"{name}.csv"
        write_measurements(csv, tool_changer, mset)
        files[name] = csv
        if name != "same":  # the unchanged pair is compared from its CSVs
            doc = diagnose(tool_changer, mset, random_state=0).to_dict()
            files[f"{name}.json"] = folder / f"{name}.json"
            files[f"{name}.json"].write_text(json.dumps(doc))
    return files


@pytest.fixture(scope="module")
def poses(tool_changer, tmp_path_factory):
    """200 joint vectors [SI] and the same as a pose CSV (deg, mm)."""
    rng = np.random.default_rng(42)
    lo, hi = tool_changer.joint_bounds()
    q = rng.uniform(lo, hi, size=(200, tool_changer.n_joints))
    path = tmp_path_factory.mktemp("poses") / "poses.csv"
    header = [f"{n}_{u}" for n, u in zip(tool_changer.joint_names, tool_changer.display_units)]
    rows = [",".join(f"{v:.12g}" for v in row) for row in q * tool_changer.display_scale]
    path.write_text(",".join(header) + "\n" + "\n".join(rows) + "\n")
    return q, path


@pytest.fixture(scope="module")
def changed_report(campaigns, poses, tmp_path_factory):
    target = tmp_path_factory.mktemp("report") / "compare.json"
    code = main(["compare", str(campaigns["old.json"]), str(campaigns["changed.json"]), "--poses", str(poses[1]),
                 "--json", str(target), "--quiet"])
    assert code == 0
    return json.loads(target.read_text())


def test_the_changed_joint_offset_is_the_only_change_beyond_uncertainty(changed_report):
    report = changed_report
    assert report["significant"] == ["joint_offsets.j3"]
    changes = {c["parameter"]: c for c in report["changes"]}
    j3 = changes["joint_offsets.j3"]
    assert j3["unit"] == "rad"
    assert np.degrees(j3["change"]) == pytest.approx(J3_CHANGE_DEG, rel=0.05)
    assert j3["z"] > 3 and j3["std_error"] > 0
    # other robot parameters were compared, and none of them flagged
    others = [c for n, c in changes.items() if n != "joint_offsets.j3"]
    assert len(others) >= 3 and any(c["effect"] == "geometry" for c in others)
    assert all(not c["significant"] and c["z"] <= 3 for c in others)
    # the tracker frame is the setup's: not compared at all; the TCP offset is listed apart
    assert not any(n.startswith("frames.") for n in changes)
    assert {c["parameter"] for c in report["setup_changes"]} >= {"frames.tool.dx", "frames.tool.dy"}


def _kabsch_residual(reference, moved):
    """|R moved + t - reference| (N,) for the best rotation R, translation t (SVD, written out)."""
    a, b = moved - moved.mean(axis=0), reference - reference.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return np.linalg.norm(a @ rot.T - b, axis=1)


def test_tcp_effect_of_the_change_matches_pinocchio(changed_report, poses, tool_changer):
    """The j3 offset's TCP motion, with the fitted change, straight from Pinocchio on the same poses."""
    q, _ = poses
    change = next(c["change"] for c in changed_report["changes"] if c["parameter"] == "joint_offsets.j3")
    model, data = tool_changer.model, tool_changer.model.createData()
    j3 = tool_changer.joint_names.index("j3")

    def tcp(qs):
        out = []
        for row in qs:
            pin.framesForwardKinematics(model, data, row)
            out.append(data.oMf[tool_changer.tool_frame_id].translation.copy())
        return np.array(out)

    moved = q.copy()
    moved[:, j3] += change
    expected = _kabsch_residual(tcp(q), tcp(moved))
    effect = changed_report["tcp_effect"]
    assert effect["n_poses"] == 200
    significant = effect["significant_changes"]
    assert significant["mean_mm"] == pytest.approx(expected.mean() * 1e3, rel=0.02)
    assert significant["max_mm"] == pytest.approx(expected.max() * 1e3, rel=0.02)
    assert significant["mean_mm"] > 0.3  # 0.05 deg on a metre of arm: a real effect to match
    # the other changes are within noise: all changes together do about what j3 alone does
    assert effect["all_changes"]["mean_mm"] == pytest.approx(significant["mean_mm"], rel=0.05)


def test_two_campaigns_with_nothing_changed_flag_nothing(campaigns, capsys):
    """From the CSVs (diagnosed first, the same options), other stations, noise and poses."""
    code, out, err = _run(["compare", str(campaigns["old"]), str(campaigns["same"]), "--json", "-", "--quiet"],
                          capsys)
    assert code == 0, err
    report = json.loads(out)
    assert report["significant"] == []
    assert len(report["changes"]) >= 4
    assert all(c["z"] <= 3 for c in report["changes"])
    # and what the fits' differences do to the TCP is small against the 0.05 deg change's ~0.8 mm
    assert report["tcp_effect"]["all_changes"]["max_mm"] < 0.05
    assert report["tcp_effect"]["significant_changes"]["max_mm"] < 1e-9


def test_printed_summary_names_the_change_in_degrees(campaigns, capsys):
    code, out, _ = _run(["compare", str(campaigns["old.json"]), str(campaigns["changed.json"]), "--n-poses", "50"],
                        capsys)
    assert code == 0
    line = next(l for l in out.splitlines() if l.strip().startswith("joint_offsets.j3"))
    assert line.rstrip().endswith("deg  <- beyond")
    assert "beyond uncertainty: joint_offsets.j3 +0.05" in out
    assert "what it does to the tcp over 50 random poses" in out.lower()


def test_an_effect_in_one_fit_only_is_named(campaigns):
    old = json.loads(campaigns["old.json"].read_text())
    new = copy.deepcopy(old)
    for key in ("parameters", "parameter_std", "parameter_units"):
        new[key].pop("geometry")
    _, _, one_sided = parameter_changes(FittedModel.from_dict(old, "old"), FittedModel.from_dict(new, "new"))
    assert [(o.effect, o.present_in, o.what) for o in one_sided] == [("geometry", "old", "effect vanished")]
    assert set(one_sided[0].parameters) == set(old["parameters"]["geometry"])


def test_a_missing_standard_error_is_never_significant(campaigns):
    old = json.loads(campaigns["old.json"].read_text())
    new = copy.deepcopy(old)
    new["parameters"]["joint_offsets"]["joint_offsets.j2"] += 1e-3
    new["parameter_std"]["joint_offsets"]["joint_offsets.j2"] = None
    changes, _, _ = parameter_changes(FittedModel.from_dict(old, "old"), FittedModel.from_dict(new, "new"))
    j2 = next(c for c in changes if c.name == "joint_offsets.j2")
    assert j2.std_error == np.inf and not j2.significant


@pytest.mark.parametrize("edit, message", [
    (lambda d: {"robot": "tool_changer", "mean_mm": 1.0}, "not a diagnosis"),
    (lambda d: {**d, "robot": "ur5"}, "compare two diagnoses of the same robot"),
    (lambda d: {**d, "parameter_units": {**d["parameter_units"],
                                         "joint_offsets": {**d["parameter_units"]["joint_offsets"],
                                                           "joint_offsets.j2": "m"}}}, "in m in"),
])
def test_bad_input_is_one_line_and_exit_2(campaigns, tmp_path, capsys, edit, message):
    doc = json.loads(campaigns["old.json"].read_text())
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(edit(doc)))
    code, out, err = _run(["compare", str(campaigns["old.json"]), str(bad)], capsys)
    assert code == 2
    assert len(err.strip().splitlines()) == 1 and message in err
