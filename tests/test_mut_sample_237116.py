"""Survivors of the measuring sample drawn with seed 237116, each pinned against a computation written out
here: the path test's closest-point iteration stopping at the first step that moves the frame less than
1e-10; the note that readings were grouped by their joint values said first; a fit with nothing to fit
counted among the engine's fits; compliance without a payload column read as no payload (Pinocchio's
generalised gravity); the stop at the noise floor's figures in mm; the learning curve's progress;
the search's empty margin; the factor cache's byte count."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation
from test_iso9283 import _evaluate_json, _repeat_data, _write
from test_mut_diag_bayes_design import EFFECTS, _curve, _design, _owner
from test_mutb_path_frame import _square

from tcr_accuracy.diagnosis.bayes_design import DesignColumns, EffectPrior, learning_curve, stop_advice
from tcr_accuracy.effects import make_effect
from tcr_accuracy.iso9283 import path_evaluate
from tcr_accuracy.iso9283.path_plan import arc_length
from tcr_accuracy.model.robot import load_robot


def test_the_closest_point_iteration_stops_at_the_first_step_that_moves_the_frame_less_than_its_tolerance(
        monkeypatch):
    """Readings 20 um off a helix and a closed square, moved by a hidden frame: the frames the iteration
    fits, recorded, move by |dt| + |dR|_F from one to the next; the iteration stops at the first that
    moved less than 1e-10 (before its cap), not later. Catches ``new_translation - translation`` turned
    to ``//`` (a quotient near 1 a coordinate: it never stops and runs to the cap)."""
    u = np.linspace(0, 1, 400)
    helix = np.column_stack([0.2 * np.cos(4 * u), 0.2 * np.sin(4 * u), 0.3 * u]) + [0.5, -0.2, 0.4]
    runs = [SimpleNamespace(points=p, s=arc_length(p)) for p in (helix, _square())]
    rotation = Rotation.from_rotvec([0.2, 0.5, -0.9]).as_matrix()
    translation = np.array([1.7, 0.6, -0.25])
    rng = np.random.default_rng(237116)
    positions, cycles, start = [], {}, 0
    for k, run in enumerate(runs):
        s = np.sort(rng.uniform(0, run.s[-1], 250))
        p = np.stack([np.interp(s, run.s, run.points[:, a]) for a in range(3)], axis=1) + rng.normal(0, 20e-6, (250, 3))
        positions.append(p @ rotation.T + translation)
        cycles[k] = [np.arange(start, start + len(p))]
        start += len(p)
    fitted = []
    rigid_fit = path_evaluate.rigid_fit

    def recorded(*args):
        fitted.append(rigid_fit(*args))
        return fitted[-1]

    monkeypatch.setattr(path_evaluate, "rigid_fit", recorded)
    frame = path_evaluate.fit_stream_frame(runs, SimpleNamespace(position=np.vstack(positions)), cycles)
    moves = [np.linalg.norm(t - t_before) + np.linalg.norm(r - r_before)
             for (r_before, t_before), (r, t) in zip(fitted[:-1], fitted[1:])]
    first_still = next(i for i, move in enumerate(moves) if move < 1e-10)
    assert first_still + 1 < path_evaluate.ICP_ITERATIONS  # the tolerance, not the cap, ends it
    assert len(moves) == first_still + 1
    np.testing.assert_array_equal(frame.translation, fitted[-1][1])
    np.testing.assert_allclose(frame.translation, translation, rtol=0, atol=5e-6)


def test_without_pose_ids_the_grouping_is_the_first_note_before_what_the_counts_leave_out(tmp_path, capsys):
    """Five poses read 1, 2, 4, 6 and 5 times, without a pose_id column: the counts leave three notes (a
    pose read once, one read twice, all below the standard's 30 cycles), and the note that the readings
    were grouped by their joint values comes before them. Catches its ``insert(0, ...)`` turned to
    ``insert(-1, ...)`` (then second to last)."""
    rows = _repeat_data(np.random.default_rng(23), counts=(1, 2, 4, 6, 5), orientation=False)
    _write(tmp_path / "labelled.csv", rows, orientation=False)
    lines = (tmp_path / "labelled.csv").read_text().splitlines()
    (tmp_path / "bare.csv").write_text("\n".join(",".join(line.split(",")[:-2]) for line in lines) + "\n")
    notes = _evaluate_json(tmp_path / "bare.csv", capsys)["notes"]
    assert notes[0].startswith("no pose_id column: the readings grouped by their joint values")
    assert any("read once" in note for note in notes[1:]) and any("read twice" in note for note in notes[1:])
    assert any("fewer times than the standard's 30 cycles" in note for note in notes[1:])


def test_a_fit_with_nothing_identifiable_is_one_fit_and_leaves_the_residual_unchanged():
    """A model whose effect kept no column (nothing identifiable at this noise): the engine counts one fit
    (the result's ``n_fits``, what a user reads as the work done), its parameters are empty, and its
    residual is that of the same effect with every kept column at zero (the engine's own model with the
    identifiable columns held at the anchor). Catches that fit's count ``+= 1`` turned to ``+= 0``."""
    from mutd_truth import offset_measurements

    from tcr_accuracy.diagnosis.diagnose import GapDiagnosis

    robot, measured = offset_measurements(12, 237)
    engine = GapDiagnosis(robot=robot, effects=["joint_offsets"], folds=2, stability_replays=2).fit(measured).engine_
    before = engine.n_fits
    nothing = engine.columns(["joint_offsets"], keep={"joint_offsets": np.array([], dtype=int)})
    phi, residual = engine.fit(nothing, None)
    assert engine.n_fits == before + 1 and phi.size == 0
    held = engine.columns(["joint_offsets"])
    at_zero = engine.predict_residual(held, np.zeros(held.scale.size), np.arange(12))
    for got, expected in zip(residual, at_zero):
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)


def test_compliance_without_a_payload_column_is_the_arms_own_gravity():
    """No context (no payload_kg column): the compliance effect's signal is the torque gravity exerts on
    each joint of the arm alone, minus Pinocchio's generalised gravity of the UR5's model. Catches the
    payload's default 0.0 kg turned to -1.0 (a kilogram taken off the tool)."""
    robot = load_robot("ur5")
    effect = make_effect("compliance", robot)
    q = np.random.default_rng(237116).uniform(-2.5, 2.5, (8, 6))
    data = robot.model.createData()
    expected = -np.array([pin.computeGeneralizedGravity(robot.model, data, row) for row in q])
    np.testing.assert_allclose(effect.signal(q, None), expected, rtol=1e-12, atol=1e-9)


def test_a_prismatic_joints_tilt_turns_the_tool_about_its_moving_origin():
    """The tool-changer's telescopic joint (j4, along y) tilted across its axis: the TCP's derivative by each
    of its two lateral compliances is a central difference of Pinocchio's forward kinematics with that joint's
    placement turned, by the tilt the gravity moment makes (compliance x moment across the axis), about the
    point the joint has slid to (q a, in the placement frame), written out here. Catches the tilt's lever
    ``q a`` turned to ``q + a``."""
    from tcr_accuracy.effects.compose import prediction_jacobian

    robot = load_robot()
    effect = make_effect("lateral_compliance", robot)
    j = robot.joint_kinds.index("prismatic")
    rng = np.random.default_rng(129)
    lower, upper = robot.joint_bounds()
    q = rng.uniform(lower, upper, (5, robot.n_joints))
    columns = [k for k, (joint, _, _) in enumerate(effect._axes()) if joint == j]
    jacobian = prediction_jacobian(robot, [effect], [np.zeros(effect.n_params)], q)[:, :, columns]
    moment = effect.moments(q, None)[:, j]  # (N, 3) in the placement frame [Nm]
    model = robot.model
    joint_id = robot.chain_joint_ids[j]
    placement = model.jointPlacements[joint_id].copy()
    axis = robot.joint_axis(j)
    h = 1e-9  # [rad/Nm]: tilts of ~1e-7 rad, second order ~1e-14 m

    def tcp(row, tilt):
        pivot = q[row, j] * axis
        turn = pin.exp3(tilt)
        model.jointPlacements[joint_id] = placement * pin.SE3(turn, pivot - turn @ pivot)
        data = model.createData()
        pin.framesForwardKinematics(model, data, q[row])
        return data.oMf[robot.tool_frame_id].translation.copy()

    try:
        for c, k in enumerate(columns):
            e = effect._axes()[k][2]
            for row in range(q.shape[0]):
                tilt = (moment[row] @ e) * e
                difference = (tcp(row, h * tilt) - tcp(row, -h * tilt)) / (2 * h)
                scale = np.abs(difference).max()
                assert scale > 1e-3  # [m per rad/Nm]: the moment across the axis tilts the tool
                np.testing.assert_allclose(jacobian[row, :, c], difference, rtol=0, atol=1e-6 * scale)
    finally:
        model.jointPlacements[joint_id] = placement


def test_the_stop_at_the_noise_floor_states_both_figures_in_millimetres():
    """A floor of 1.2345 mm and an error now of sqrt(floor^2 + v) = 1.04 x the floor: the advice stops and
    says both in mm to four places, as written out here (1.2839 against 1.2345). Catches the first figure's
    ``* 1e3`` turned to ``* 999.0`` (1.2826 mm: the 0.1 % shows at these sizes) and the point read as an
    end of its interval (``now[1]``, ``now[-1]``)."""
    floor = 1.2345e-3
    v = (1.04**2 - 1) * floor**2
    boot = np.random.default_rng(710).uniform(0.5, 2.0, (20, 2))  # the interval's ends apart from the point
    advice = stop_advice(_curve(boot, floor), _design(np.sqrt(v), np.sqrt(v) / 2), min_gain_m=None)
    now_mm = np.sqrt(floor**2 + v) * 1e3
    assert f"{now_mm:.4f}" == "1.2839"
    assert advice.stop and advice.reason.startswith(f"stop: the noise floor is reached ({now_mm:.4f} mm against "
                                                    f"{floor * 1e3:.4f} mm); ")


def test_the_learning_curve_reports_one_step_of_progress_per_subsample_size():
    """40 poses and four subsample sizes, round(geomspace(20, 32, 4)) = 20, 23, 27, 32 written out here: the
    progress callback is called once per size with one step, so a bar of len(sizes) steps ends full.
    Catches ``progress(1)`` turned to ``progress(2)`` (a bar run past its end)."""
    rng = np.random.default_rng(648)
    owner = _owner(2, 5, 5)
    n = 40
    g = rng.normal(size=(n, 3, owner.size)) * 1e-4
    errors = g @ np.concatenate([rng.normal(0, 20, 2), rng.normal(0, 1.0, 10)]) + rng.normal(0, 3e-5, (n, 3))
    steps = []
    learning_curve(DesignColumns(g, owner, EFFECTS), errors, EffectPrior({"compliance": 1.0, "transmission": 1.0},
                   3e-5), np.random.default_rng(1), n_sizes=4, repeats=2, n_boot=10, progress=steps.append)
    assert steps == [1, 1, 1, 1]


def test_maps_of_different_poses_or_error_vectors_are_not_joined():
    """Maps side by side sum their errors entry by entry, so they must share their poses and their error
    vector: a map of 12 entries beside one of 13, or of 50 poses beside one of 49, is refused with both
    shapes named (the joined size was read off the first map alone, and ``errors`` then failed on the sum or
    on a row past the shorter map)."""
    import re

    from tcr_accuracy.diagnosis.error_map import ErrorMap, JoinedMaps

    rng = np.random.default_rng(225)

    def fixed_map(n, size, k=2):
        return ErrorMap.of(n, size, slice(4, 10), rng.standard_normal((size, k)), None, k)

    for other, named in ((fixed_map(50, 13), "(50, 12), (50, 13)"), (fixed_map(49, 12), "(49, 12), (50, 12)")):
        with pytest.raises(ValueError, match=re.escape(named)):
            JoinedMaps([fixed_map(50, 12), other])
    joined = JoinedMaps([fixed_map(50, 12), fixed_map(50, 12, 3)])
    assert (joined.n_poses, joined.size) == (50, 12) and joined.bounds == [(0, 2), (2, 5)]


def test_a_search_whose_paths_all_end_on_one_set_has_no_alternative_and_a_zero_margin():
    """The restart without joint_offsets grows back to the greedy set itself: one set, no alternative, the
    margin and its standard error 0.0 m^2 (0.0 mm^2 in the JSON), the chosen set said to beat an alternative
    it does not have. Catches the empty margin's ``0.0`` turned to ``-1.0`` (-1e6 mm^2 in the JSON)."""
    from test_mutp2_search import F, J, StandInEngine

    from tcr_accuracy.diagnosis.stages import search

    engine = StandInEngine()
    chosen, report = search.search_sets(engine, [F, J], J, [J], forward=lambda pool, start: [F, J], prune=list,
                                        selection_z=3.0, min_relative_gain=0.03, width=0)
    assert chosen == [F, J] and report.alternative is None
    assert (report.margin, report.margin_se) == (0.0, 0.0) and report.beats_alternative
    out = report.to_dict()
    assert (out["alternative_margin_mm2"], out["alternative_margin_se_mm2"]) == (0.0, 0.0)
    assert report.note().endswith("every path ended on it")


def test_the_factor_caches_byte_count_is_the_sum_of_the_factors_it_holds():
    """A cache of 100 kB: a system that has no factor (None) is kept at no bytes, two factors of 40 kB are
    counted at their nbytes, a third pushes out the least recently used, and the count is always the sum of
    what is held, written out here from the arrays. Catches the None's size ``0`` turned to ``-1``."""
    from tcr_accuracy.diagnosis.least_squares import FactorCache

    cache = FactorCache(max_bytes=100_000, max_columns=100)
    held = {}

    def put(key, factor):
        got = cache.get(key, lambda: factor)
        assert got is factor
        held[key] = factor

    put("none", None)
    assert cache.nbytes() == 0
    for key in ("a", "b"):
        put(key, np.ones((5000,)))  # 40,000 bytes
    assert cache.nbytes() == 80_000
    put("c", np.ones((5000,)))  # 120,000 > 100,000: the oldest ("none", then "a") go
    kept = [key for key in ("none", "a", "b", "c") if key in cache._factors]
    assert kept == ["b", "c"]
    assert cache.nbytes() == sum(held[key].nbytes for key in kept) == 80_000
