"""simulate: the stand-in robot. Zero effects give the nominal model; noise, units and truth are right."""

import json
import math
import re

import numpy as np
import pytest
import yaml

from tcr_accuracy.cli import main
from tcr_accuracy.effects import effect_classes, prediction_jacobian
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.kinematics import tcp_poses
from tcr_accuracy.io.measurements import allowed_columns, read_measurements
from tcr_accuracy.analysis.scenario import load_scenario, resolve_effect, truth_as_scenario
from tcr_accuracy.analysis.simulate import dominant_candidates, random_scenario, simulate_measurements

from conftest import REPO


def test_no_effects_no_noise_gives_nominal_kinematics(tool_changer):
    mset, truth = simulate_measurements(tool_changer, {}, 50, np.random.default_rng(0), noise_m=0.0)
    np.testing.assert_allclose(mset.position, tcp_poses(tool_changer, mset.q).position, atol=1e-15)
    assert truth["effects"] == {}
    lo, hi = tool_changer.lower_limits, tool_changer.upper_limits
    assert np.all((mset.q >= lo) & (mset.q <= hi))


def test_noise_std_is_recovered(ur5):
    mset, _ = simulate_measurements(ur5, {}, 4000, np.random.default_rng(1), noise_m=2e-5)
    residual = mset.position - tcp_poses(ur5, mset.q).position
    # 12000 normal draws: the sample std is within 3 % of the truth with overwhelming probability
    assert np.std(residual) == pytest.approx(2e-5, rel=0.03)
    assert np.all(np.abs(residual.mean(axis=0)) < 3e-6)


def test_explicit_values_carry_their_units(tool_changer):
    spec = {"effects": {"joint_offsets": {"offsets_deg": {"j2": 0.05}, "offsets_mm": {"j4": 0.1}},
                        "frames": {"base_mm": {"dx": 25.0}, "tool_mm": {"dx": 1.0}, "base_mrad": {"rz": 8.0}},
                        "compliance": {"compliance_deg_per_knm": {"j2": 0.01}},
                        "thermal": {"alpha_ppm_per_k": 12.0}}}
    rng = np.random.default_rng(2)
    _, truth = simulate_measurements(tool_changer, spec, 5, rng, noise_m=0.0)
    offsets = truth["effects"]["joint_offsets"]["parameters"]
    assert offsets["joint_offsets.j2"] == pytest.approx(math.radians(0.05))
    assert offsets["joint_offsets.j4"] == pytest.approx(1e-4)
    assert offsets["joint_offsets.j1"] == 0.0
    frames = truth["effects"]["frames"]["parameters"]
    assert frames["frames.base.dx"] == pytest.approx(0.025) and frames["frames.tool.dx"] == pytest.approx(1e-3)
    assert frames["frames.base.rz"] == pytest.approx(8e-3)
    assert truth["effects"]["compliance"]["parameters"]["compliance.j2"] == pytest.approx(math.radians(0.01) / 1e3)
    assert truth["effects"]["thermal"]["parameters"]["thermal.alpha"] == pytest.approx(1.2e-5)


def test_scenario_errors_name_file_and_key(tool_changer, tmp_path):
    cases = {
        "effects: {gravity_sag: {}}": "unknown effect 'gravity_sag'",
        "effects: {joint_offsets: {offsets_per_k: 1}}": "effects.joint_offsets.offsets_per_k: no parameter",
        "effects: {joint_offsets: {offsets_deg: {j9: 1}}}": "'j9' selects no rad parameter",
        "effects: {backlash: {band_deg: -5}}": "outside what any mechanism of backlash explains",
        "context: {humidity: 3}": "context: unknown key(s) humidity",
        "noise_mm: [1, 2]": "noise_mm",
        "effects: [1, 2": "not valid YAML",
    }
    for text, expected in cases.items():
        path = tmp_path / "bad.yaml"
        path.write_text(text)
        with pytest.raises(InputError) as info:
            scenario = load_scenario(path)
            simulate_measurements(tool_changer, scenario, 3, np.random.default_rng(0))
        assert str(path) in str(info.value) and expected in str(info.value), str(info.value)


def test_tcp_rms_scaling_hits_the_target(tool_changer):
    spec = {"effects": {"compliance": {"tcp_rms_mm": 1.5}}, "context": {"payload_fraction": 1.0}}
    mset, truth = simulate_measurements(tool_changer, spec, 200, np.random.default_rng(3), noise_m=0.0)
    sag = mset.position - tcp_poses(tool_changer, mset.q).position
    # parameters scale linearly; the TCP follows to first order (dq of 1e-3 rad: 1e-6 relative)
    assert np.sqrt(np.mean(np.sum(sag**2, axis=1))) == pytest.approx(1.5e-3, rel=1e-4)
    assert np.all(np.array(list(truth["effects"]["compliance"]["parameters"].values())) >= 0)
    assert np.mean(sag[:, 2]) < 0  # the cutter pulls the arm down


def test_truth_recreates_the_same_measurements(tool_changer):
    spec = {"effects": {"geometry": {"spread_mm": 0.2, "spread_mrad": 0.2}, "backlash": {},
                        "compliance": {"options": {"link_mass_spread": 0.1}}}}
    mset, truth = simulate_measurements(tool_changer, spec, 30, np.random.default_rng(4), noise_m=0.0)
    factors = truth["effects"]["compliance"]["options"]["link_mass_factors"]
    assert len(factors) == 6 and np.std(factors) > 0
    again, _ = simulate_measurements(tool_changer, truth_as_scenario(truth), 30, np.random.default_rng(5),
                                     noise_m=0.0, q=mset.q, context=mset.context)
    np.testing.assert_allclose(again.position, mset.position, atol=1e-15)


def test_a_truth_file_read_back_as_a_scenario_is_the_same_robot(tool_changer, tmp_path):
    """``simulate --truth`` then ``--scenario`` of that file: more poses of the same hidden robot
    (a test set), every parameter as written."""
    from tcr_accuracy.analysis.simulate import truth_text

    spec = {"effects": {"geometry": {"spread_mm": 0.2, "spread_mrad": 0.2}, "compliance": {}, "transmission": {}}}
    mset, truth = simulate_measurements(tool_changer, spec, 30, np.random.default_rng(4), noise_m=0.0)
    (tmp_path / "truth.yaml").write_text(truth_text(truth, "truth.yaml"))
    scenario = load_scenario(tmp_path / "truth.yaml")
    again, _ = simulate_measurements(tool_changer, scenario, 30, np.random.default_rng(9), noise_m=0.0,
                                     q=mset.q, context=mset.context)
    np.testing.assert_allclose(again.position, mset.position, atol=1e-12)
    # a unit changed by hand is refused, naming it: the values stay SI whatever the file says
    text = (tmp_path / "truth.yaml").read_text().replace("geometry.j1.dx: m\n", "geometry.j1.dx: mm\n", 1)
    (tmp_path / "edited.yaml").write_text(text)
    with pytest.raises(InputError, match=r"effects.geometry.units.geometry.j1.dx: 'mm', but the parameter is in m"):
        simulate_measurements(tool_changer, load_scenario(tmp_path / "edited.yaml"), 5, np.random.default_rng(0))


def test_unmodelled_effect_leaves_structure_the_vocabulary_cannot_fit(tool_changer):
    """Least squares over every deterministic effect of the vocabulary (linearised)."""
    spec = {"effects": {"unmodelled": {"amplitude_mm": 0.5}}}
    mset, _ = simulate_measurements(tool_changer, spec, 400, np.random.default_rng(6), noise_m=0.0)
    ctx = mset.context
    effects = [cls(tool_changer) for cls in list(effect_classes().values())[:-1]]
    jac = prediction_jacobian(tool_changer, effects, [e.zeros() for e in effects], mset.q, ctx)
    gap = (mset.position - tcp_poses(tool_changer, mset.q).position).reshape(-1)
    a = jac.reshape(-1, jac.shape[2])
    a = a / np.abs(a).max(axis=0).clip(1e-12)  # column scaling; lstsq's SVD drops dependent columns
    coef, *_ = np.linalg.lstsq(a, gap, rcond=1e-10)
    residual = gap - a @ coef
    assert np.sqrt(np.mean(residual**2)) > 0.3 * np.sqrt(np.mean(gap**2))


def test_random_scenario_makes_the_dominant_effect_dominate(tool_changer):
    rng = np.random.default_rng(7)
    scenario = random_scenario(tool_changer, rng, outside="unmodelled")
    assert 1 <= len(scenario["dominant"]) <= 2 and set(scenario["dominant"]) <= set(dominant_candidates())
    assert {"frames", "geometry", "joint_offsets", "unmodelled"} <= set(scenario["effects"])
    assert scenario["outside_vocabulary"] == ["unmodelled"]
    mset, truth = simulate_measurements(tool_changer, scenario, 300, rng)
    # judged independently here: TCP displacement left after the best rigid frame fit
    ctx = mset.context
    frames = effect_classes()["frames"](tool_changer)
    fj = prediction_jacobian(tool_changer, [frames], [frames.zeros()], mset.q, ctx).reshape(-1, 9)

    def after_frames(names):
        effects, params = [], []
        for name in names:
            effect, p, _ = resolve_effect(tool_changer, name, scenario["effects"][name], rng)
            effects.append(effect)
            params.append(p)
        from tcr_accuracy.effects import predict_positions

        d = (predict_positions(tool_changer, effects, params, mset.q, ctx)
             - tcp_poses(tool_changer, mset.q).position).reshape(-1)
        coef, *_ = np.linalg.lstsq(fj, d, rcond=None)
        return np.sqrt(np.mean((d - fj @ coef) ** 2))

    assert after_frames(scenario["dominant"][:1]) > 2.0 * after_frames(["geometry", "joint_offsets"])
    assert truth["outside_vocabulary"] == ["unmodelled"]


def test_random_scenario_on_an_arm_without_prismatic_joints(ur5):
    scenario = random_scenario(ur5, np.random.default_rng(8), dominant=["compliance"])
    mset, truth = simulate_measurements(ur5, scenario, 20, np.random.default_rng(9))
    sag = truth["effects"]["compliance"]["tcp_rms_m"]
    assert 0.3e-3 < sag < 20e-3


def run(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def test_cli_writes_csv_and_truth_apart(tmp_path, capsys, tool_changer):
    out, truth_path = tmp_path / "meas.csv", tmp_path / "truth.yaml"
    code, stdout, err = run(["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"),
                             "--n", "60", "--seed", "3", "--out", str(out), "--truth", str(truth_path)], capsys)
    assert code == 0, err
    assert "60 simulated measurements" in stdout
    truth = yaml.safe_load(truth_path.read_text())
    assert truth["seed"] == 3 and "compliance" in truth["effects"]
    text = out.read_text()
    header = text.splitlines()[0].split(",")
    assert set(header) <= set(allowed_columns(tool_changer))
    assert "compliance" not in text and "geometry" not in text and "#" not in text
    mset = read_measurements(out, tool_changer)  # passes every validation, the unit check included
    assert len(mset) == 60 and mset.payload_kg is not None and set(np.unique(mset.payload_kg)) <= {0.0, 150.0}
    # same seed, same file
    again = tmp_path / "again.csv"
    run(["simulate", "--scenario", str(REPO / "examples" / "scenario_compliance.yaml"), "--n", "60",
         "--seed", "3", "--out", str(again)], capsys)
    assert again.read_text() == text


def test_cli_random_with_outside_effect_and_json_truth(tmp_path, capsys):
    out, truth_path = tmp_path / "m.csv", tmp_path / "t.json"
    code, _, err = run(["simulate", "--random", "backlash", "--outside", "unmodelled", "--n", "30",
                        "--out", str(out), "--truth", str(truth_path), "--orientation"], capsys)
    assert code == 0, err
    truth = json.loads(truth_path.read_text())
    assert truth["dominant"] == ["backlash"] and truth["outside_vocabulary"] == ["unmodelled"]
    assert "qw" in out.read_text().splitlines()[0]


def test_cli_poses_file_and_bad_input(tmp_path, capsys, tool_changer):
    poses = tmp_path / "poses.csv"
    poses.write_text("j1_deg,j2_deg,j3_deg,j4_mm,j5_deg,j6_deg,payload_kg\n"
                     "15,30,-10,0,-20,0,150\n0,10,20,100,0,0,0\n")
    out = tmp_path / "m.csv"
    code, _, err = run(["simulate", "--scenario", str(REPO / "examples" / "scenario_unmodelled.yaml"),
                        "--poses", str(poses), "--out", str(out), "--noise-mm", "0"], capsys)
    assert code == 0, err
    mset = read_measurements(out, tool_changer)
    np.testing.assert_allclose(mset.q[0], tool_changer.working_pose, atol=1e-12)
    np.testing.assert_array_equal(mset.payload_kg, [150.0, 0.0])
    code, _, err = run(["simulate", "--scenario", str(tmp_path / "missing.yaml"), "--out", str(out)], capsys)
    assert code == 2 and "no such scenario file" in err and len(err.strip().splitlines()) == 1
    code, _, err = run(["simulate", "--n", "5", "--box", "0", "1", "0", "1", "0", "1", "--random", "thermal",
                        "--out", str(tmp_path / "x.csv"), "--noise-mm", "-1"], capsys)
    assert code == 2 and "--noise-mm" in err
    assert not (tmp_path / "x.csv").exists()


def _lowest_points(robot, q):
    """(N,) the lowest z [m] of every joint origin and the TCP at each row of q, base frame: Pinocchio's
    forward kinematics, each joint set by name (a continuous joint as its cos and sin), none of the
    package's kinematics."""
    import pinocchio as pin

    model, out = robot.model, []
    data = model.createData()
    for row in q:
        qp = pin.neutral(model)
        for name, value in zip(robot.joint_names, row):
            joint = model.joints[model.getJointId(name)]
            qp[joint.idx_q:joint.idx_q + joint.nq] = [value] if joint.nq == 1 else [np.cos(value), np.sin(value)]
        pin.framesForwardKinematics(model, data, qp)
        tcp = data.oMf[model.getFrameId(robot.tool_frame)].translation[2]
        out.append(min([data.oMi[j].translation[2] for j in range(1, model.njoints)] + [tcp]))
    return np.array(out)


@pytest.mark.parametrize("name", ["kinova", "ur5"])
def test_simulate_keeps_the_robot_above_the_plane_it_stands_on(name, tmp_path, capsys):
    """Issue 42: 'simulate --random --n 300' on a Kinova put 42 of 300 tool positions below the mounting
    plane (to -446 mm). Now no joint origin and no TCP of the commanded poses lies below z = 0 of the
    base; with --below-mounting-plane a fair share does again (the draw is uniform in the joints), and the
    printed line says how many were drawn again."""
    from tcr_accuracy.model.robot import load_robot

    robot = load_robot(name)
    lowest = {}
    for flag in ([], ["--below-mounting-plane"]):
        out = tmp_path / f"m{len(flag)}.csv"
        assert main(["simulate", "--robot", name, "--random", "--n", "300", "--seed", "3", "--out", str(out),
                     "--quiet", *flag]) == 0
        printed = capsys.readouterr().out
        q = read_measurements(out, robot).q
        lowest[bool(flag)] = _lowest_points(robot, q)
        if not flag:
            assert "TCP and joints above the mounting plane (z >= 0 mm)" in printed
            assert re.search(r"\d+ below the mounting plane", printed)
    assert lowest[False].min() >= -1e-9
    assert np.mean(lowest[True] < 0.0) > 0.05


def test_the_tool_changer_works_below_its_base_unless_told():
    """The built-in tool-changer reaches into the cutterhead below its base (its demo data go to z = -281 mm):
    no plane by default; a PoseFilter given one keeps its poses above it."""
    from tcr_accuracy.analysis.reachable import PoseFilter, draw_poses
    from tcr_accuracy.model.robot import load_robot

    robot = load_robot()
    assert robot.mounting_plane_z is None
    drawn = draw_poses(PoseFilter.for_robot(robot, collision=False), 200, np.random.default_rng(0)).q
    assert (_lowest_points(robot, drawn) < 0).any()
    kept = draw_poses(PoseFilter.for_robot(robot, collision=False, floor_z=0.0), 200, np.random.default_rng(0))
    assert _lowest_points(robot, kept.q).min() >= -1e-9 and kept.rejected["mounting plane"] > 0


def test_unmodelled_named_without_values_is_drawn_at_tenths_of_a_millimetre(tool_changer):
    """A scenario naming ``unmodelled`` with no values draws its amplitude around the effect's
    typical size: a link distortion a tracker calibration meets is tenths of a millimetre (the
    example scenario hides 0.6 mm), not metres nor microns. Catches the typical scale ``3e-4``
    changed to 1.0003 or -0.9997."""
    rng = np.random.default_rng(21)
    amplitudes = np.array([resolve_effect(tool_changer, "unmodelled", {}, rng)[1][0] for _ in range(400)])
    rms = float(np.sqrt(np.mean(amplitudes**2)))
    assert 0.05e-3 < rms < 2e-3
