"""``predict`` and ``compensate`` on measurements in a tracker's own frame, checked against the
hidden truth of simulated robots and against sums written out here."""

import json

import numpy as np
import pinocchio as pin
import pytest

from tcr_accuracy.cli import main
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.analysis.scenario import truth_as_scenario
from tcr_accuracy.analysis.simulate import simulate_measurements
from conftest import run_command as run
from conftest import write_measurement_csv as _write

UR5_REF = np.array([0.3, -1.2, 1.5, -1.9, -1.57, 0.4])
NOISE_M = 2e-5
#: a tracker 1.5 m away and turned 35 deg, a 25 mm TCP offset, and a robot with small
#: geometric errors and gravity compliance under a 5 kg payload
SCENARIO = {
    "effects": {
        "frames": {"base_mm": {"dx": 1500.0, "dy": 800.0, "dz": -250.0}, "base_deg": {"rx": 2.0, "rz": 35.0},
                   "tool_mm": {"dx": 0.8, "dy": -0.5, "dz": 25.0}},
        "geometry": {"spread_mm": 0.1, "spread_mrad": 0.1},
        "compliance": {"tcp_rms_mm": 0.5},
    },
    "context": {"payload_kg": 5.0, "payload_fraction": 1.0, "temperature_spread_c": 0.0, "directions": "none"},
}




@pytest.fixture(scope="module")
def tracked(ur5, tmp_path_factory):
    d = tmp_path_factory.mktemp("tracked")
    rng = np.random.default_rng(31)
    q_train = UR5_REF + rng.uniform(-0.3, 0.3, (120, 6))
    q_query = UR5_REF + rng.uniform(-0.25, 0.25, (40, 6))
    train, truth = simulate_measurements(ur5, SCENARIO, 0, rng, noise_m=NOISE_M, q=q_train)
    replay = truth_as_scenario(truth)
    query, _ = simulate_measurements(ur5, replay, 0, rng, noise_m=NOISE_M, q=q_query)
    p = truth["effects"]["frames"]["parameters"]
    twist = np.array([p[f"frames.base.{c}"] for c in ("dx", "dy", "dz", "rx", "ry", "rz")])

    def true_tracker_positions(q):
        mset, _ = simulate_measurements(ur5, replay, 0, np.random.default_rng(0), noise_m=0.0, q=np.atleast_2d(q))
        return mset.position

    return {
        "dir": d, "q_train": q_train, "q_query": q_query, "p_query": query.position,
        "hidden_frame": pin.exp6(pin.Motion(twist[:3], twist[3:])), "true_tracker_positions": true_tracker_positions,
        "train": _write(d / "train.csv", ur5, q_train, train.position),
        "query": _write(d / "query.csv", ur5, q_query, query.position),
        "poses": _write(d / "poses.csv", ur5, q_query),
    }


def _tracker_prediction(ur5, payload, predicted_mm, q):
    """Predicted tracker readings, summed out by hand: R (FK(q) + e) + t with the JSON's frame."""
    frame = payload["tracker_frame"]
    rotation, translation = np.array(frame["rotation_matrix"]), np.array(frame["translation_mm"]) * 1e-3
    return (tcp_poses(ur5, q).position + np.asarray(predicted_mm) * 1e-3) @ rotation.T + translation


def test_predict_scores_itself_on_measured_queries_in_a_tracker_frame(ur5, tracked, capsys):
    d = tracked["dir"]
    code, out, err = run(["predict", "--robot", "ur5", "--train", tracked["train"], "--query", tracked["query"],
                          "--method", "gp", "--csv", str(d / "gp.csv"), "--json", str(d / "gp.json"),
                          "--plots", str(d / "plots")], capsys)
    assert code == 0, err
    assert (d / "plots" / "predicted_errors.png").read_bytes().startswith(b"\x89PNG")  # std band, measured marks
    payload = json.loads((d / "gp.json").read_text())
    held = payload["heldout"]
    assert set(held) >= {"mean_mm", "max_mm", "rms_mm", "count"} and held["count"] == 40
    # the held-out figure, recomputed from the CSV's predictions and the JSON's frame
    csv = np.loadtxt(d / "gp.csv", delimiter=",", skiprows=1)
    header = (d / "gp.csv").read_text().splitlines()[0].split(",")
    predicted = csv[:, header.index("ex_mm"):header.index("ez_mm") + 1]
    query = np.loadtxt(tracked["query"], delimiter=",", skiprows=1)  # what the command read
    q, measured = query[:, :6] / ur5.display_scale, query[:, 6:9] * 1e-3
    miss = np.linalg.norm(measured - _tracker_prediction(ur5, payload, predicted, q), axis=1) * 1e3
    # (to 1 nm: the CSV holds 9 significant digits of errors that include the 25 mm TCP offset)
    assert held["mean_mm"] == pytest.approx(miss.mean(), abs=1e-6)
    assert held["max_mm"] == pytest.approx(miss.max(), abs=1e-6)
    assert held["rms_mm"] == pytest.approx(np.sqrt(np.mean(miss**2)), abs=1e-6)
    np.testing.assert_allclose(csv[:, header.index("heldout_miss_mm")], miss, atol=1e-6)
    # against the hidden truth: the frame is the tracker's up to the rigid share of the robot's own
    # errors over this small workspace (0.3 mm over 0.2 m: milliradians), the predicted errors are the
    # TCP offset and tenths of a millimetre (not the metres of the tracker offset), and the held-out
    # miss is near the tracker noise (mean |noise| 0.032 mm)
    hidden = tracked["hidden_frame"]
    assert np.linalg.norm(pin.log3(hidden.rotation.T @ np.array(payload["tracker_frame"]["rotation_matrix"]))) < 5e-3
    np.testing.assert_allclose(np.array(payload["tracker_frame"]["translation_mm"]), hidden.translation * 1e3,
                               atol=5.0)
    assert payload["predicted_error_max_mm"] < 30.0 and np.abs(hidden.translation).max() > 1.0
    assert f"held-out error against the 40 measured query positions: mean {held['mean_mm']:.4f} mm" in out
    # against the hidden truth the command never sees: the predicted tracker readings are the
    # noise-free ones to 17 um RMS (30 um at worst; measured), and the held-out miss is the tracker
    # noise drawn in the fixture (31 um RMS) to that accuracy
    truth = tracked["true_tracker_positions"](q)
    prediction_error = _tracker_prediction(ur5, payload, predicted, q) - truth
    prediction_rms = np.sqrt(np.mean(np.sum(prediction_error ** 2, axis=1))) * 1e3
    assert prediction_rms < 0.035
    noise = np.linalg.norm(measured - truth, axis=1) * 1e3
    assert np.abs(miss - noise).max() < 0.05 and noise.mean() > 0.025
    assert held["rms_mm"] == pytest.approx(np.sqrt(np.mean(noise ** 2) + prediction_rms ** 2), abs=0.01)
    # the GP's standard deviation covers the true prediction error (base-frame axes); it is cautious
    # here (all 120 axis errors within 2 std, RMS 0.46 std; measured)
    std = csv[:, header.index("ex_std_mm"):header.index("ez_std_mm") + 1]
    rotation = np.array(payload["tracker_frame"]["rotation_matrix"])
    z = (prediction_error @ rotation) * 1e3 / std
    assert np.mean(np.abs(z) <= 2.0) >= 0.9 and np.sqrt(np.mean(z ** 2)) < 1.5
    assert payload["uncertainty"] == "Gaussian process predictive standard deviation"
    assert 0.8 <= held["within_2std"] <= 1.0


def test_predict_without_measured_queries_has_no_heldout_and_methods_without_std_say_none(ur5, tracked, capsys):
    d = tracked["dir"]
    code, out, err = run(["predict", "--robot", "ur5", "--train", tracked["train"], "--query", tracked["poses"],
                          "--method", "idw-joint", "--csv", str(d / "idw.csv"), "--json", "-"], capsys)
    assert code == 0, err
    payload = json.loads(out)
    assert payload["heldout"] is None and payload["uncertainty"] == "none" and payload["predicted_std_mm"] is None
    header = (d / "idw.csv").read_text().splitlines()[0].split(",")
    assert header[6:] == ["ex_mm", "ey_mm", "ez_mm", "e_norm_mm"]
    code, out, err = run(["predict", "--robot", "ur5", "--train", tracked["train"], "--query", tracked["poses"],
                          "--method", "idw-joint"], capsys)
    assert "uncertainty: none (idw-joint gives no standard deviation)" in out and "held-out" not in out


def test_compensate_lands_on_the_targets_as_the_tracker_sees_them(ur5, tracked, capsys):
    """Targets measured at their uncompensated commands: compensation must move the real robot,
    read by the tracker, onto the targets placed in the tracker frame by the fitted frame."""
    d = tracked["dir"]
    code, out, err = run(["compensate", "--robot", "ur5", "--train", tracked["train"], "--targets", tracked["query"],
                          "--method", "gp", "--csv", str(d / "comp.csv"), "--json", str(d / "comp.json")], capsys)
    assert code == 0, err
    payload = json.loads((d / "comp.json").read_text())
    q_comp = np.loadtxt(d / "comp.csv", delimiter=",", skiprows=1)[:, :6] / ur5.display_scale
    frame = payload["tracker_frame"]
    rotation, translation = np.array(frame["rotation_matrix"]), np.array(frame["translation_mm"]) * 1e-3
    # the targets are where the model puts the measured point (a reflector 25 mm off the flange here):
    # the nominal TCP plus the fitted TCP offset turned by the TCP's rotation, in the tracker frame
    pose = tcp_poses(ur5, tracked["q_query"])
    point = pose.position + pose.rotation @ (np.array(frame["tool_offset_mm"]) * 1e-3)
    targets = point @ rotation.T + translation
    before = np.linalg.norm(tracked["true_tracker_positions"](tracked["q_query"]) - targets, axis=1) * 1e3
    after = np.linalg.norm(tracked["true_tracker_positions"](q_comp) - targets, axis=1) * 1e3
    # the 25 mm reflector offset is the measured point's, not an error: what is left to correct is
    # the robot's own error beyond the fitted frame (0.035 mm here)
    assert before.mean() > 0.025
    assert after.mean() < 0.02 and after.mean() < before.mean() / 2
    # the predicted error before compensation is the measured one (held out), to the prediction's accuracy
    measured = np.linalg.norm((tracked["p_query"] - translation) @ rotation - point, axis=1) * 1e3
    held = payload["heldout"]
    assert held["measured_error_before_mean_mm"] == pytest.approx(measured.mean(), rel=1e-6)
    assert payload["predicted_error_before_mean_mm"] == pytest.approx(measured.mean(), abs=0.02)
    assert held["mean_mm"] < 0.1 and "about what compensation leaves" in out


def test_the_default_method_runs_the_diagnosis_and_a_gp_of_what_it_leaves(ur5, tracked, capsys):
    code, out, err = run(["predict", "--robot", "ur5", "--train", tracked["train"], "--query", tracked["query"],
                          "--json", "-"], capsys)
    assert code == 0, err
    payload = json.loads(out)
    assert payload["method"] == "diagnosis+gp" and payload["frame"] == "fit"
    assert payload["uncertainty"] == "Gaussian process predictive standard deviation"
    assert payload["heldout"]["mean_mm"] < 0.1


def test_bad_query_and_training_files_are_one_line_exit_2_and_write_nothing(ur5, tracked, tmp_path, capsys):
    lines = (tracked["dir"] / "query.csv").read_text().splitlines()
    header = lines[0].split(",")

    def variant(name, text):
        path = tmp_path / name
        path.write_text(text)
        return str(path)

    cells = lines[4].split(",")
    cells[header.index("elbow_joint_deg")] = "nan"
    nan_query = variant("nan.csv", "\n".join(lines[:4] + [",".join(cells)] + lines[5:]) + "\n")
    cells = lines[3].split(",")
    cells[header.index("y_mm")] = "NaN"
    nan_position = variant("nan_position.csv", "\n".join(lines[:3] + [",".join(cells)] + lines[4:]) + "\n")
    keep = [i for i, h in enumerate(header) if h != "wrist_2_joint_deg"]
    no_wrist = variant("no_wrist.csv", "\n".join(",".join(line.split(",")[i] for i in keep) for line in lines) + "\n")
    keep = [i for i, h in enumerate(header) if h not in ("y_mm", "z_mm")]
    only_x = variant("only_x.csv", "\n".join(",".join(line.split(",")[i] for i in keep) for line in lines) + "\n")
    train_lines = (tracked["dir"] / "train.csv").read_text().splitlines()
    five = variant("five.csv", "\n".join(train_lines[:6]) + "\n")
    ten = variant("ten.csv", "\n".join(train_lines[:11]) + "\n")
    train = tracked["train"]
    cases = [
        (["--train", train, "--query", nan_query], f"{nan_query}: row 5, column elbow_joint_deg: non-finite value 'nan'"),
        (["--train", train, "--query", nan_position], f"{nan_position}: row 4, column y_mm: non-finite value 'NaN'"),
        (["--train", train, "--query", no_wrist], f"{no_wrist}: row 1: missing joint column wrist_2_joint_deg"),
        (["--train", train, "--query", only_x], f"{only_x}: row 1: missing position column y_mm, z_mm"),
        (["--train", five, "--query", tracked["query"]], f"{five}: 5 training poses for 6 joints"),
        (["--train", ten, "--query", tracked["query"]],
         f"{ten}: 10 measurements are too few to diagnose with 5-fold cross-validation"),
    ]
    for extra, message in cases:
        outputs = [tmp_path / "never.csv", tmp_path / "never.json", tmp_path / "never_report"]
        code, out, err = run(["predict", "--robot", "ur5", *extra, "--csv", str(outputs[0]), "--json", str(outputs[1]),
                              "--out", str(outputs[2])], capsys)
        assert code == 2, (extra, err)
        assert err.count("\n") == 1 and err.startswith("tcr-accuracy predict: error: ") and message in err, err
        assert "Traceback" not in err and out == "" and not any(p.exists() for p in outputs)
    code, out, err = run(["compensate", "--robot", "ur5", "--train", train, "--targets", nan_query], capsys)
    assert code == 2 and out == "" and err.count("\n") == 1 and "non-finite value 'nan'" in err


@pytest.fixture(scope="module")
def reflector(ur5, tmp_path_factory):
    """The robot of SCENARIO with the reflector 150 mm off the flange: the offset is where the
    measured point sits, not an error of the robot."""
    d = tmp_path_factory.mktemp("reflector")
    scenario = json.loads(json.dumps(SCENARIO))
    scenario["effects"]["frames"]["tool_mm"] = {"dx": 0.8, "dy": -0.5, "dz": 150.0}
    rng = np.random.default_rng(7)
    q_train = UR5_REF + rng.uniform(-0.3, 0.3, (120, 6))
    q_query = UR5_REF + rng.uniform(-0.25, 0.25, (30, 6))
    train, truth = simulate_measurements(ur5, scenario, 0, rng, noise_m=NOISE_M, q=q_train)
    query, _ = simulate_measurements(ur5, truth_as_scenario(truth), 0, rng, noise_m=NOISE_M, q=q_query)
    return {"dir": d, "q_query": q_query, "p_query": query.position,
            "train": _write(d / "train.csv", ur5, q_train, train.position),
            "query": _write(d / "query.csv", ur5, q_query, query.position)}


def test_the_predict_headline_is_the_error_beyond_the_reflector_offset_not_the_offset(ur5, reflector, capsys):
    d = reflector["dir"]
    code, out, err = run(["predict", "--robot", "ur5", "--train", reflector["train"], "--query", reflector["query"],
                          "--method", "gp", "--json", str(d / "p.json")], capsys)
    assert code == 0, err
    payload = json.loads((d / "p.json").read_text())
    frame = payload["tracker_frame"]
    assert frame["tool_offset_mm"][2] == pytest.approx(150.0, abs=1.0)
    # independent: the measured point mapped into the base frame with the fitted frame, minus where
    # the nominal robot carrying the fitted offset puts it, summed out here
    rotation, translation = np.array(frame["rotation_matrix"]), np.array(frame["translation_mm"]) * 1e-3
    pose = tcp_poses(ur5, reflector["q_query"])
    point = pose.position + pose.rotation @ (np.array(frame["tool_offset_mm"]) * 1e-3)
    measured = np.linalg.norm((reflector["p_query"] - translation) @ rotation - point, axis=1) * 1e3
    assert measured.mean() < 3.0  # tenths of a millimetre, against a 150 mm offset
    mean, peak = payload["predicted_error_mean_mm"], payload["predicted_error_max_mm"]
    assert mean == pytest.approx(measured.mean(), abs=0.03) and peak < 3.0
    assert (f"predicted |error| at 30 query poses: mean {mean:.4f} mm, max {peak:.4f} mm "
            "(beyond the nominal robot with the fitted TCP offset") in out
    # the per-pose CSV/JSON errors keep their documented sense: real minus nominal TCP, offset included
    assert np.linalg.norm(payload["predicted_errors_mm"], axis=1).min() > 140.0


def test_compensate_prints_what_it_leaves_before_the_models_own_miss(ur5, tracked, capsys):
    code, out, err = run(["compensate", "--robot", "ur5", "--train", tracked["train"], "--targets", tracked["query"],
                          "--method", "gp"], capsys)
    assert code == 0, err
    lines = out.splitlines()
    realistic = next(i for i, line in enumerate(lines) if "about what compensation leaves" in line)
    own = next(i for i, line in enumerate(lines) if "the model's own miss after compensation" in line)
    assert realistic < own and "not a measurement" in lines[own]
