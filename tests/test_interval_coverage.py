"""Intervals that hold their estimates and cover (issue 36, part 4).

Simulated UR5s written here on Pinocchio alone (nothing of the package models an error): the real
joints sit at ``q + o + s q - b / 2 dir`` (an encoder offset ``o``, a gear-ratio error ``s``, a dead
band ``b`` taken up against the approach direction ``dir``), the tracker sees the measured points in
its own frame with Gaussian noise, one point per row or three reflectors on the flange. The
diagnosis' stages fit the fixed model ``frames + joint_offsets + backlash + encoder_scale`` (three
families: geometric, direction, scale) on 200 replicates of each campaign, and we count how often
the 95 % intervals hold the truth:

* a parameter's truth is the value written here (offsets, ratios, bands);
* a family's share is "how much the held-out RMS rises without it" (5-fold cross-validation), so
  its truth is that rise for fits on as many poses as a fold trains on: the RMS error at a new pose
  (new noise) of the model without the family, least-squares fitted on ``0.8 n`` poses drawn from the
  same distribution, less the same for the whole model, each averaged over 300 such fits and
  evaluated on 6000 poses (:func:`_expected_share`, with the models' first-order columns from
  Pinocchio's Jacobians). The population value (fits on infinitely many poses) is 4-8 % lower at these
  sizes: a held-out error includes the error of the fit it comes from, and that is what the printed
  figure means.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from scipy.stats import norm

from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.paired import row_squares
from tcr_accuracy.diagnosis.stages.attribute import family_shares
from tcr_accuracy.diagnosis.stages.candidates import build_candidates
from tcr_accuracy.diagnosis.stages.register import MeasuredFrame, register_measurements
from tcr_accuracy.diagnosis.uncertainty import MIN_SESSION_CLUSTERS, PoseBootstrap, bootstrap_for, parameter_table
from tcr_accuracy.io.measurement_set import MeasurementSet
from tcr_accuracy.model.robot import load_robot, robot_from_urdf_text

from conftest import REPO, run_command
from hidden_robot import frame_id, in_tracker, random_poses, tracker_frame
from independent_truths import urdf_with_reflectors

REAL = Path(os.environ.get("TCR_REAL_DATA", REPO.parent / "shared" / "real"))

#: three reflectors on the UR5's flange [m], in wrist_3_link's frame
REFLECTORS = {"smr_1": (0.05, 0.0, 0.03), "smr_2": (0.0, 0.06, 0.03), "smr_3": (-0.04, -0.04, 0.05)}
NOISE = 3e-5  # the tracker's noise per axis [m]
MODEL = ["frames", "joint_offsets", "backlash", "encoder_scale"]
FAMILIES = ("geometric", "scale", "direction")
REPLICATES = 200


class HiddenUR5:
    """The truth: joint errors of a UR5 (``seed`` draws them) and its measured frames."""

    def __init__(self, n_frames: int, seed: int = 123):
        rng = np.random.default_rng(seed)
        self.offsets = np.radians(rng.uniform(0.02, 0.05, 6) * rng.choice([-1, 1], 6))
        self.scales = rng.uniform(1e-4, 3e-4, 6) * rng.choice([-1, 1], 6)
        self.bands = np.radians(rng.uniform(0.02, 0.04, 6))
        if n_frames == 1:
            self.robots = [load_robot("ur5")]
        else:
            text = urdf_with_reflectors(load_robot("ur5").urdf_text, "wrist_3_link", REFLECTORS)
            self.robots = [robot_from_urdf_text(text, f, name="ur5") for f in list(REFLECTORS)[:n_frames]]

    def real_joints(self, q, direction):
        return q + self.offsets + self.scales * q - self.bands / 2 * direction

    def truth(self, names) -> dict:
        out = {}
        for j, joint in enumerate(names):
            out[f"joint_offsets.{joint}"] = self.offsets[j]
            out[f"encoder_scale.{joint}"] = self.scales[j]
            out[f"backlash.{joint}"] = self.bands[j]
        return out


def _frame_kinematics(robot, q):
    """Position (N, 3), rotation (N, 3, 3) and position Jacobian in the chain joints (N, 3, 6) of the
    robot's measured frame, by Pinocchio."""
    model = robot.full_model
    data = model.createData()
    fid = frame_id(model, robot.tool_frame)
    columns = [model.joints[j].idx_v for j in robot.chain_joint_ids]
    position, rotation, jacobian = np.empty((len(q), 3)), np.empty((len(q), 3, 3)), np.empty((len(q), 3, 6))
    for i, config in enumerate(robot.full_configurations(q)):
        jacobian[i] = pin.computeFrameJacobian(model, data, config, fid, pin.LOCAL_WORLD_ALIGNED)[:3, columns]
        position[i], rotation[i] = data.oMf[fid].translation, data.oMf[fid].rotation
    return position, rotation, jacobian


def _expected_share(hidden: HiddenUR5, n_train: int, n_eval: int = 6000, fits: int = 300) -> dict:
    """Each family's share as the held-out figure means it (see the module docstring): sqrt of the
    expected squared error per point at new poses of a least-squares fit on ``n_train`` poses without
    the family, less the same with it. The models are first order: tracker frame (translation and
    rotation of the base), each frame's offset in its own axes, and one column per joint and effect
    (the frame's Jacobian times 1, q_j or -dir_j / 2); the gap is the exact motion of the frames."""
    rng = np.random.default_rng(7)
    q = random_poses(hidden.robots[0], n_eval, rng)
    direction = rng.choice([-1.0, 1.0], (n_eval, 6))
    n_parts = len(hidden.robots)
    blocks = {name: [] for name in ("base", "tool", "geometric", "scale", "direction")}
    gap = []
    for k, robot in enumerate(hidden.robots):
        position, rotation, jacobian = _frame_kinematics(robot, q)
        gap.append(_frame_kinematics(robot, hidden.real_joints(q, direction))[0] - position)
        base = np.zeros((n_eval, 3, 6))
        base[:, :, :3] = np.eye(3)
        base[:, :, 3:] = -np.array([pin.skew(p) for p in position])  # w x p
        tool = np.zeros((n_eval, 3, 3 * n_parts))
        tool[:, :, 3 * k:3 * k + 3] = rotation
        for name, block in (("base", base), ("tool", tool), ("geometric", jacobian),
                            ("scale", jacobian * q[:, None, :]), ("direction", jacobian * -direction[:, None, :] / 2)):
            blocks[name].append(block)
    columns = {name: np.stack(b) for name, b in blocks.items()}  # (parts, N, 3, c)
    gap = np.stack(gap)

    def design(names, rows):
        return np.concatenate([columns[c][:, rows] for c in names], axis=-1).reshape(-1, sum(
            columns[c].shape[-1] for c in names))

    def expected(names):
        everywhere, total = design(names, slice(None)), 0.0
        draws = np.random.default_rng(11)
        for _ in range(fits):
            rows = draws.choice(n_eval, n_train, replace=False)
            a = design(names, rows)
            theta = np.linalg.lstsq(a, gap[:, rows].ravel() + NOISE * draws.standard_normal(a.shape[0]), rcond=None)[0]
            total += float(np.mean(np.sum((gap.ravel() - everywhere @ theta).reshape(-1, 3) ** 2, axis=1)))
        return total / fits + 3 * NOISE**2

    every = list(columns)
    whole = math.sqrt(expected(every))
    return {f: math.sqrt(expected([c for c in every if c != f])) - whole for f in FAMILIES}


def _campaign(hidden: HiddenUR5, n: int, seed: int, tracker: list | None = None):
    """One measured campaign: the measured frames (their robots and MeasurementSets); ``tracker``, a
    list, receives the tracker's frame ``trackerMbase``."""
    rng = np.random.default_rng([seed, 11])
    q = random_poses(hidden.robots[0], n, rng)
    direction = rng.choice([-1.0, 1.0], (n, 6))
    frame = tracker_frame(rng, 3.0)
    if tracker is not None:
        tracker.append(frame)
    frames = []
    for robot in hidden.robots:
        seen = in_tracker(frame, _frame_kinematics(robot, hidden.real_joints(q, direction))[0])
        measured = MeasurementSet(joint_names=list(robot.joint_names), q=q, direction=direction,
                                  position=seen + NOISE * rng.standard_normal((n, 3)))
        frames.append(MeasuredFrame(robot, measured, robot.tool_frame))
    return frames


def _fixed_model(frames, seed: int):
    """The diagnosis' stages on the fixed model: (family shares, parameter table)."""
    registered = register_measurements(frames)
    engine = build_candidates(registered, MODEL, folds=5, rank_tol=1e-6, tracker_noise=None,
                              rng=np.random.default_rng([seed, 12]), fold_repeats=5).engine
    shares = family_shares(engine, MODEL, bootstrap=bootstrap_for(engine, [seed, 13]))
    return shares, parameter_table(engine.evaluate(MODEL), engine.bases, MODEL)


@pytest.mark.slow
@pytest.mark.parametrize("n_frames, n_poses", [(1, 150), (3, 60)])
def test_95_percent_intervals_cover_the_truth(n_frames, n_poses):
    """Over 200 campaigns, the 95 % intervals of the family shares and of the parameters hold the
    truth in 92-98 % of them (pooled over the three families, and over the 16 parameters; each
    family and parameter alone in at least 85 %), with one measured point per row and with three
    reflectors per row; every share's interval holds the share itself."""
    hidden = HiddenUR5(n_frames)
    truth_shares = _expected_share(hidden, int(0.8 * n_poses))
    truth = hidden.truth(hidden.robots[0].joint_names)
    share_hits = {f: [] for f in FAMILIES}
    parameter_hits: dict = {}
    for seed in range(REPLICATES):
        shares, table = _fixed_model(_campaign(hidden, n_poses, seed), seed)
        assert {s.family for s in shares} == set(FAMILIES)
        for s in shares:
            low, high = s.interval
            assert low <= s.share <= high
            share_hits[s.family].append(low <= truth_shares[s.family] <= high)
        for effect in MODEL[1:]:
            for name, (low, high) in table[effect]["interval"].items():
                value, std = table[effect]["values"][name], table[effect]["std"][name]
                # value +- the two-sided 95 % normal quantile times the standard error (inside the fit range)
                assert low == pytest.approx(max(value - norm.ppf(0.975) * std, table[effect]["fit_range"][name][0]))
                parameter_hits.setdefault(name, []).append(low <= truth[name] <= high)
    pooled_shares = np.mean([h for hits in share_hits.values() for h in hits])
    pooled_parameters = np.mean([h for hits in parameter_hits.values() for h in hits])
    print(f"{n_frames} frame(s): shares {pooled_shares:.3f} "
          + ", ".join(f"{f} {np.mean(h):.3f}" for f, h in share_hits.items())
          + f"; parameters {pooled_parameters:.3f} over {len(parameter_hits)}")
    assert 0.92 <= pooled_shares <= 0.98
    assert 0.92 <= pooled_parameters <= 0.98
    assert len(parameter_hits) >= 14  # j1's and j6's offsets go to the tracker frame and the tool offset
    assert all(np.mean(h) >= 0.85 for h in [*share_hits.values(), *parameter_hits.values()])


def test_standard_errors_are_the_least_squares_ones_with_n_minus_k_degrees_of_freedom():
    """40 poses, one measured point each (120 coordinates, 23 parameters: the measured point is tool0,
    on wrist_3's axis, which no wrist_3 parameter moves): every joint parameter's standard error is
    that of an ordinary least-squares fit written here on Pinocchio's Jacobians,
    sqrt(s^2 [(A^T A)^-1]_jj) with s^2 = RSS / (n - rank A), within 0.2 % (over n alone they would be
    10 % smaller)."""
    hidden = HiddenUR5(1)
    tracker: list = []
    frames = _campaign(hidden, 40, seed=3, tracker=tracker)
    _, table = _fixed_model(frames, 3)
    robot, measured = frames[0].robot, frames[0].measurements
    in_base = (measured.position - tracker[0].translation) @ tracker[0].rotation  # R^T (p - t)
    position, rotation, jacobian = _frame_kinematics(robot, measured.q)
    columns = np.concatenate([np.broadcast_to(np.eye(3), (40, 3, 3)), -np.array([pin.skew(p) for p in position]),
                              rotation, jacobian, jacobian * measured.q[:, None, :],
                              jacobian * -measured.direction[:, None, :] / 2], axis=2).reshape(120, -1)
    y = (in_base - position).ravel()
    theta, *_ = np.linalg.lstsq(columns, y, rcond=None)
    rank = np.linalg.matrix_rank(columns)
    s2 = np.sum((y - columns @ theta) ** 2) / (120 - rank)
    assert rank == 23
    covariance = s2 * np.linalg.pinv(columns.T @ columns)
    compared = 0
    for effect, first in (("joint_offsets", 9), ("encoder_scale", 15), ("backlash", 21)):
        for j, joint in enumerate(robot.joint_names):
            name = f"{effect}.{joint}"
            if name in table[effect]["std"]:
                assert table[effect]["std"][name] == pytest.approx(math.sqrt(covariance[first + j, first + j]),
                                                                   rel=0.002), name
                compared += 1
    assert compared == 14


# ---------------------------------------------------------------------------------------
# The bootstrap against independent calculations
# ---------------------------------------------------------------------------------------
def test_the_bootstrap_interval_of_a_difference_of_two_rms_has_the_delta_method_width():
    """For 4000 rows, the 95 % percentile interval of sqrt(mean a / 3) - sqrt(mean b / 3) (three
    measured frames a row) has the width 2 x 1.96 x the delta method's standard error, written out
    here from the rows' variances and covariance, within 10 %; it holds the point; and the point is
    the RMS per measured point, taken from the points themselves."""
    rng = np.random.default_rng(3)
    n = 4000
    before_points = rng.normal(0.0, 1e-4, (3, n, 3)) * rng.uniform(0.5, 2.0, (1, n, 1))
    after_points = 0.5 * before_points + rng.normal(0.0, 2e-5, (3, n, 3))
    a, b = row_squares(before_points), row_squares(after_points)
    bootstrap = PoseBootstrap.draw(n, n_parts=3, random_state=0)
    value, low, high = bootstrap.difference(a, b)
    rms = lambda points: math.sqrt(np.mean(np.sum(points**2, axis=-1)))  # noqa: E731 (per measured point)
    assert value == pytest.approx(rms(before_points) - rms(after_points), rel=1e-12)
    assert low <= value <= high
    mean_a, mean_b = a.mean() / 3, b.mean() / 3
    cov = np.cov(a / 3, b / 3)
    gradient = np.array([0.5 / math.sqrt(mean_a), -0.5 / math.sqrt(mean_b)])
    se = math.sqrt(gradient @ cov @ gradient / n)
    assert (high - low) / (2 * norm.ppf(0.975) * se) == pytest.approx(1.0, abs=0.1)


def test_the_bootstrap_keeps_each_session_whole_or_draws_sessions():
    """Few sessions: every replicate keeps each session's number of poses (drawn within it); from
    MIN_SESSION_CLUSTERS sessions on, whole sessions are drawn (as many as there are)."""
    few = np.repeat([0, 1, 2], [10, 20, 5])
    strata = PoseBootstrap.draw(35, session_of=few, n_replicates=50, random_state=1)
    per_session = np.stack([strata.counts[:, few == s].sum(axis=1) for s in range(3)], axis=1)
    assert np.all(per_session == [10, 20, 5])
    many = np.repeat(np.arange(MIN_SESSION_CLUSTERS), 4)
    clusters = PoseBootstrap.draw(many.size, session_of=many, n_replicates=50, random_state=1)
    assert clusters.counts.shape == (50, MIN_SESSION_CLUSTERS)
    assert np.all(clusters.counts.sum(axis=1) == MIN_SESSION_CLUSTERS)
    assert "sessions as clusters" in clusters.method


# ---------------------------------------------------------------------------------------
# Every printed interval holds its point
# ---------------------------------------------------------------------------------------
def assert_intervals_hold(doc: dict) -> int:
    """Every interval of a diagnosis' JSON holds its estimate: family shares and their differences,
    step gains, own shares (leave one out) and their differences, parameters. Returns how many."""
    pairs = []
    for f in doc["families"]:
        pairs.append((f"family {f['family']}", f["share_mm"], f["interval_mm"]))
        if f.get("below_largest"):
            pairs.append((f"family {f['family']} below", f["below_largest"]["difference_mm"],
                          f["below_largest"]["interval_mm"]))
    for s in doc["steps"][1:]:
        pairs.append((f"step {s['effect']}", s["gain_heldout_rms_mm"], s["gain_interval_mm"]))
    for r in doc["leave_one_out"]:
        pairs.append((f"without {r['dropped']}", r["own_share_increase_mm"], r["own_share_interval_mm"]))
    for c in doc["own_share_ranking"]:
        pairs.append((f"{c['larger']} over {c['smaller']}", c["difference_mm"], c["interval_mm"]))
    for effect, values in doc["parameters"].items():
        for name, value in values.items():
            pairs.append((name, value, doc["parameter_interval_95"][effect][name]))
    outside = [(what, value, interval) for what, value, interval in pairs
               if not interval[0] - 1e-12 * abs(value) <= value <= interval[1] + 1e-12 * abs(value)]
    assert not outside, outside
    return len(pairs)


def _diagnose_json(tmp_path, capsys, argv) -> dict:
    out = tmp_path / "d.json"
    code, _, err = run_command(["diagnose", *argv, "--quiet", "--json", str(out)], capsys)
    assert code == 0, err
    return json.loads(out.read_text())


@pytest.mark.slow
def test_every_interval_of_a_three_reflector_diagnosis_holds_its_estimate(tmp_path, capsys):
    """The whole diagnosis (command line, full vocabulary) of a campaign with three reflectors per row:
    every interval in its JSON holds its estimate (before, every family share was printed below its
    own interval: the point was per measured point, the interval per row of three), and the families
    and the steps carry the bootstrap's intervals."""
    hidden = HiddenUR5(3)
    frames = _campaign(hidden, 60, seed=0)
    lines = ["# three reflectors on a simulated UR5, tests/test_interval_coverage.py",
             ",".join([f"{j}_deg" for j in hidden.robots[0].joint_names] + [f"{j}_dir" for j in
                                                                             hidden.robots[0].joint_names]
                      + [f"{f.label}.{a}_mm" for f in frames for a in "xyz"])]
    q, direction = frames[0].measurements.q, frames[0].measurements.direction
    for i in range(len(q)):
        lines.append(",".join([f"{v:.10f}" for v in np.degrees(q[i])] + [f"{v:+.0f}" for v in direction[i]]
                              + [f"{v * 1e3:.6f}" for f in frames for v in f.measurements.position[i]]))
    (tmp_path / "m.csv").write_text("\n".join(lines) + "\n")
    urdf = tmp_path / "ur5_smr.urdf"
    urdf.write_text(urdf_with_reflectors(load_robot("ur5").urdf_text, "wrist_3_link", REFLECTORS))
    doc = _diagnose_json(tmp_path, capsys, [str(tmp_path / "m.csv"), "--robot", str(urdf), "--tool", "smr_1"])
    assert doc["frames_measured"] == list(REFLECTORS)
    assert assert_intervals_hold(doc) > 20
    assert doc["families"] and all(s.get("gain_interval_mm") for s in doc["steps"][1:])
    assert "percentile bootstrap" in doc["interval_method"] and "every measured frame of a pose" in \
        doc["interval_method"]


@pytest.mark.slow
def test_the_pipeline_gives_the_stages_intervals_and_they_cover(capsys):
    """One full diagnosis (GapDiagnosis, the fixed model's effects offered) of a three-reflector
    campaign: it chooses all three families, and their shares' intervals hold the expected shares
    of :func:`_expected_share`; its parameters' intervals hold the truth."""
    hidden = HiddenUR5(3)
    frames = _campaign(hidden, 60, seed=1000)
    d = GapDiagnosis(robot=hidden.robots[0], effects=MODEL[1:], random_state=0).fit(
        [(f.robot, f.measurements) for f in frames]).result_
    truth_shares = _expected_share(hidden, 48)
    shares = {f["family"]: f for f in d.families}
    assert set(shares) == set(FAMILIES)
    for family, truth in truth_shares.items():
        low, high = shares[family]["interval_mm"]
        assert low <= truth * 1e3 <= high, (family, truth * 1e3, low, high)
    truth = hidden.truth(hidden.robots[0].joint_names)
    inside = [low <= truth[name] <= high for e in MODEL[1:]
              for name, (low, high) in d.parameter_table[e]["interval"].items()]
    assert np.mean(inside) >= 0.8
    assert_intervals_hold(d.to_dict())


def _needs(folder: Path):
    return pytest.mark.skipif(not folder.is_dir(), reason=f"real data not here: {folder} (set TCR_REAL_DATA)")


@pytest.mark.slow
@_needs(REAL / "justin")
def test_every_interval_of_the_justin_diagnosis_holds_its_estimate(tmp_path, capsys):
    """DLR's Agile Justin under Vicon (500 poses): every interval in the JSON holds its estimate."""
    doc = _diagnose_json(tmp_path, capsys, [str(REAL / "justin" / "justin_right_hand.csv"), "--robot",
                                            str(REAL / "justin" / "justin.urdf"), "--tool", "right_marker"])
    assert assert_intervals_hold(doc) > 30
