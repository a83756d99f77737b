"""Figures the mutation run (``scripts/mutation_run.py``) found no test would miss if they were
wrong, each checked against a computation written out here: by hand, in numpy on raw arrays, or
with scipy. Each test names the planted change it catches.
"""

import numpy as np
import pytest

from tcr_accuracy.diagnosis.records import ErrorStats, Step

MM = 1e-3


def test_error_statistics_and_shrink_table_row_in_mm_by_hand():
    """Errors of norms 3, 4 and 12 mm (3-4-5, 0-4-0, 12-0-0): mean 19/3 mm, RMS sqrt(169/3) mm,
    max 12 mm; the shrink table's row gives them in mm. Catches ``heldout.rms % 1e3`` for
    ``* 1e3`` (the held-out RMS written in metres under a ``_mm`` key)."""
    errors = np.array([[3.0, 0.0, 0.0], [0.0, 4.0, 0.0], [12.0, 0.0, 0.0]]) * MM
    errors[0] = [1.8 * MM, 2.4 * MM, 0.0]  # still 3 mm long
    stats = ErrorStats.of(errors)
    expected = {"mean_mm": 19 / 3, "rms_mm": np.sqrt((9 + 16 + 144) / 3), "max_mm": 12.0, "count": 3}
    assert stats.to_dict() == pytest.approx(expected, rel=1e-12)
    train = ErrorStats.of(errors[:2])
    step = Step(effect="geometry", effects=("frames", "geometry"), n_parameters=7, train_rms=train.rms,
                heldout=stats, z_statistic=2.5, gain=(0.5 * MM, 0.1 * MM, 0.9 * MM))
    row = step.to_dict()
    assert row["train_rms_mm"] == pytest.approx(np.sqrt((9 + 16) / 2), rel=1e-12)
    assert row["heldout_rms_mm"] == pytest.approx(expected["rms_mm"], rel=1e-12)
    assert row["heldout_mean_mm"] == pytest.approx(19 / 3, rel=1e-12)
    assert row["heldout_max_mm"] == pytest.approx(12.0, rel=1e-12)
    assert row["gain_heldout_rms_mm"] == pytest.approx(0.5, rel=1e-12)
    assert row["gain_interval_mm"] == pytest.approx([0.1, 0.9], rel=1e-12)


def test_a_dropped_column_names_the_three_columns_it_is_mostly_made_of():
    """A later effect's one column planted as 3 c + 2 d + 1 e + 0.05 a + 0.03 b of an earlier
    effect's unit columns (random, 40 poses): it is dropped as their linear combination, named by
    its three largest planted coefficients in order. Catches ``argsort(np.abs(coef))`` for
    ``argsort(-np.abs(coef))`` (the three smallest named)."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.identifiability import identifiability

    rng = np.random.default_rng(7)
    n_poses = 40
    earlier = rng.normal(size=(n_poses * 3, 5))
    unit = earlier / np.linalg.norm(earlier, axis=0)
    planted = {"c": 3.0, "d": 2.0, "e": 1.0, "a": 0.05, "b": 0.03}
    later = sum(weight * unit[:, "abcde".index(name)] for name, weight in planted.items())

    def basis(columns, names):
        return SimpleNamespace(g=columns.reshape(n_poses, 3, -1), scales=np.ones(len(names)), names=names,
                               n_poses=n_poses)

    keep, report = identifiability({"first": basis(earlier, list("abcde")), "second": basis(later[:, None], ["f"])},
                                   ["first", "second"])
    assert keep["first"].tolist() == [0, 1, 2, 3, 4] and keep["second"].tolist() == []
    removed, = report["effects"]["second"]["removed"]
    assert removed["duplicates"] == ["c", "d", "e"]
    assert removed["reason"] == "linear combination of c, d, e"


def test_learning_curve_in_mm_and_its_prediction_by_hand():
    """A learning curve given in metres: its JSON form in mm, and its expectation at a posterior
    variance v the closed form sqrt(3 sigma^2 + v) (a = b = 1). Catches ``floor_m * 1001.0`` for
    ``* 1e3``."""
    from tcr_accuracy.diagnosis.bayes_design import LearningCurve

    floor = np.sqrt(3) * 0.02 * MM
    curve = LearningCurve(sizes=np.array([10, 20]), rms_m=np.array([0.3, 0.2]) * MM,
                          low_m=np.array([0.25, 0.15]) * MM, high_m=np.array([0.35, 0.25]) * MM,
                          expected_rms_m=np.array([0.28, 0.21]) * MM, noise_weight=1.0, variance_weight=1.0,
                          boot=np.ones((50, 2)), noise_floor_m=floor)
    doc = curve.to_dict()
    assert doc["floor_mm"] == pytest.approx(np.sqrt(3) * 0.02, rel=1e-12)
    assert doc["noise_floor_mm"] == pytest.approx(np.sqrt(3) * 0.02, rel=1e-12)
    assert doc["heldout_rms_mm"] == pytest.approx([0.3, 0.2], rel=1e-12)
    assert doc["heldout_rms_5_mm"] == pytest.approx([0.25, 0.15], rel=1e-12)
    assert doc["heldout_rms_95_mm"] == pytest.approx([0.35, 0.25], rel=1e-12)
    assert doc["expected_rms_mm"] == pytest.approx([0.28, 0.21], rel=1e-12)
    v = (0.1 * MM) ** 2
    assert curve.predict(v) == pytest.approx((np.sqrt(floor**2 + v),) * 3, rel=1e-12)


def test_rigidly_aligned_difference_of_a_moved_copy_is_its_planted_bump():
    """Points moved by a rotation and a translation built with scipy, one of them then pushed 1 mm
    along a direction that no rigid motion undoes much: the aligned differences are ~0 elsewhere
    and the largest at that point. Catches ``trans // reference`` for ``trans - reference``."""
    from scipy.spatial.transform import Rotation

    from tcr_accuracy.diagnosis.compare import rigidly_aligned_difference

    rng = np.random.default_rng(3)
    reference = rng.uniform(-0.8, 0.8, size=(30, 3))
    rot = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    moved = (reference - [0.05, -0.02, 0.1]) @ rot  # moved @ rot.T + t == reference
    assert rigidly_aligned_difference(reference, moved) == pytest.approx(np.zeros(30), abs=1e-12)
    moved[4] += 1.0 * MM * (reference[4] / np.linalg.norm(reference[4])) @ rot
    distance = rigidly_aligned_difference(reference, moved)
    assert int(np.argmax(distance)) == 4 and 0.8 * MM < distance[4] < 1.0 * MM
    assert np.sqrt(np.mean(distance ** 2)) < 1.0 * MM / np.sqrt(30)


def test_a_diagnosis_with_a_non_finite_parameter_is_refused_naming_it(tmp_path):
    """The one non-finite parameter of a diagnosis' JSON named in one line. Catches ``bad[1]`` for
    ``bad[0]`` (an IndexError, a traceback, where the parameter is to be named)."""
    from tcr_accuracy.diagnosis.compare import FittedModel
    from tcr_accuracy.exceptions import InputError

    doc = {"robot": "ur5", "selected_effects": ["geometry"],
           "parameters": {"geometry": {"geometry.j2.dx": 1e-4, "geometry.j3.dy": float("nan")}},
           "parameter_std": {"geometry": {"geometry.j2.dx": 1e-5, "geometry.j3.dy": 1e-5}},
           "parameter_units": {"geometry": {"geometry.j2.dx": "m", "geometry.j3.dy": "m"}}}
    with pytest.raises(InputError, match=r"^d\.json: parameter geometry\.j3\.dy is not a finite number$"):
        FittedModel.from_dict(doc, "d.json")


def test_an_elimination_row_in_mm():
    """Backward elimination's row: the held-out RMS it gained, 0.012 mm, given in mm. Catches
    ``increase / 1e3`` for ``* 1e3``."""
    from tcr_accuracy.diagnosis.stages.select import Elimination

    row = Elimination(effect="backlash", z=0.4, increase=0.012 * MM).to_dict()
    assert row["effect"] == "backlash" and row["z"] == 0.4
    assert row["increase_mm"] == pytest.approx(0.012, rel=1e-12)


def test_a_diagnosis_summary_line_gives_the_last_steps_held_out_rms():
    """The one-line summary of a diagnosis (its repr) quotes the held-out RMS of the last step of the
    shrink table (0.05 mm), not of the first (0.4 mm). Catches ``steps[- 0]`` for ``steps[-1]``."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.result import Diagnosis

    def step(rms_mm):
        return SimpleNamespace(heldout=SimpleNamespace(rms=rms_mm * MM))

    fake = SimpleNamespace(robot_name="ur5", n_measurements=120, gap=SimpleNamespace(rms=0.5 * MM),
                           selected_effects=["frames", "geometry", "gravity"], primary_effect="geometry",
                           steps=[step(0.4), step(0.09), step(0.05)], noise_floor=0.03 * MM, from_file=False)
    assert Diagnosis.__repr__(fake) == ("Diagnosis('ur5', 120 measurements, gap RMS 0.5 mm, selected [frames, "
                                        "geometry, gravity], primary 'geometry', held-out RMS 0.05 mm, noise floor "
                                        "0.03 mm)")
    fake.from_file = True  # a diagnosis read from its JSON says so
    assert Diagnosis.__repr__(fake).endswith("noise floor 0.03 mm, read from file)")


def test_signed_rank_z_with_ties_is_scipys():
    """Wilcoxon's signed-rank z of squared errors with tied differences (4 x3, 2 x3, 6 x2) and a
    zero dropped is scipy's normal approximation with the tie correction, read back from its one-sided
    p-value. Catches ``counts/3 - counts`` for ``counts**3 - counts`` in the tie correction."""
    from scipy import stats

    from tcr_accuracy.diagnosis.paired import signed_rank_z

    before = np.array([5.0, 5.0, 5.0, 3.0, 3.0, 8.0, 1.0, 2.0, 9.0, 4.0, 7.0, 2.0])
    after = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 2.0, 2.0, 0.0, 3.0, 1.0, 7.0, 1.5])
    d = before - after
    p = stats.wilcoxon(d, zero_method="wilcox", correction=False, alternative="greater", method="approx").pvalue
    assert signed_rank_z(before, after) == pytest.approx(stats.norm.isf(p), rel=1e-9)


def test_registration_covariance_against_monte_carlo_kabsch():
    """The covariance a rigid frame fitted to 6 points (+-0.5 m on each axis, 0.1 mm scatter per
    axis) adds to a point ~1 m off their centroid, against 4000 Kabsch fits of noisy copies done
    with scipy (``Rotation.align_vectors``): each term within 10 % of the largest (Monte Carlo's own
    spread ~2 %). Catches a skew matrix of the wrong shape ((N, 3, 4) for (N, 3, 3)) and one entry
    of it written in the wrong place (``skew[:, 0, 2]`` twice)."""
    from scipy.spatial.transform import Rotation

    from tcr_accuracy.frames.uncertainty_budget import PointSet, registration_covariance

    sigma, half = 0.1 * MM, 0.5
    points = np.vstack([np.eye(3), -np.eye(3)]) * half + [0.2, -0.1, 0.3]
    at = points.mean(axis=0) + [0.6, -0.5, 0.7]
    rng = np.random.default_rng(11)
    mapped = []
    for _ in range(4000):
        noisy = points + rng.normal(scale=sigma, size=points.shape)
        rot = Rotation.align_vectors(noisy - noisy.mean(axis=0), points - points.mean(axis=0))[0]
        mapped.append(rot.apply(at - points.mean(axis=0)) + noisy.mean(axis=0))
    simulated = np.cov(np.array(mapped).T)
    computed, = registration_covariance(PointSet.of(points), sigma, at[None, :])
    assert np.abs(computed - simulated).max() < 0.10 * np.abs(simulated).max()


@pytest.mark.parametrize("interval_mm, z, ranked", [((0.01, 0.05), 3.0, True), ((-0.01, 0.05), 3.0, False),
                                                    ((0.01, 0.05), 1.5, False)])
def test_a_share_comparison_in_mm_and_ranked_only_above_zero_and_the_threshold(interval_mm, z, ranked):
    """Two shares compared: the difference and its interval given in mm, each end in its place; the
    larger ranked only when z passes the threshold (2.0) and the interval's low end is above zero.
    Catches ``interval[-1]`` for ``interval[0]`` in the JSON form."""
    from tcr_accuracy.diagnosis.attribution import ShareComparison

    comparison = ShareComparison(larger="gravity", smaller="geometry", difference=0.03 * MM,
                                 interval=(interval_mm[0] * MM, interval_mm[1] * MM), z=z, threshold=2.0)
    doc = comparison.to_dict()
    assert doc["difference_mm"] == pytest.approx(0.03, rel=1e-12)
    assert doc["interval_mm"] == pytest.approx(list(interval_mm), rel=1e-12)
    assert (doc["larger"], doc["smaller"], doc["z"], doc["z_threshold"]) == ("gravity", "geometry", z, 2.0)
    assert comparison.ranked is ranked and doc["ranked"] is ranked


def test_every_rotation_is_a_tool_orientation_and_a_reflection_is_not():
    """50 random rotations from scipy (whose determinants round to 1 +- 1e-15, some below 1) are
    each taken as the plan's tool orientation; a reflection (determinant -1) is refused. Catches
    ``det < 1`` for ``det < 0`` (a valid rotation refused for its round-off)."""
    from scipy.spatial.transform import Rotation

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.plan import _tool_rotation

    rotations = Rotation.random(50, random_state=1).as_matrix()
    assert np.any(np.linalg.det(rotations) < 1.0)  # the case at stake is in the sample
    for rotation in rotations:
        assert np.array_equal(_tool_rotation(rotation), rotation)
    with pytest.raises(InputError, match="determinant"):
        _tool_rotation(rotations[0] @ np.diag([1.0, 1.0, -1.0]))


def test_leave_one_out_own_share_increase_is_the_rise_of_the_held_out_rms_by_hand():
    """Backward elimination's leave-one-out table on an engine whose held-out errors are given:
    final model 1 mm on every row; without geometry, others refitted, 2 mm; the others held to
    their own parameters, 3 mm. The rises, written out in numpy: 1 mm refitted and 2 mm own share.
    Catches ``held_own.rms + final_rms`` for the difference."""
    from tcr_accuracy.diagnosis.stages.select import _backward

    n = 40
    sign = np.where(np.arange(n) % 2, 1.0, -1.0)[:, None]
    errors = {"final": np.hstack([sign * 1.0 * MM, np.zeros((n, 2))]),
              "refitted": np.hstack([np.zeros((n, 1)), sign * 2.0 * MM, np.zeros((n, 1))]),
              "own": np.hstack([np.zeros((n, 2)), sign * 3.0 * MM])}

    def fit(which):
        squares = np.sum(errors[which] ** 2, axis=1)
        norm = np.sqrt(squares)
        return {"heldout_stats": ErrorStats(float(norm.mean()), float(np.sqrt(squares.mean())), float(norm.max()), n),
                "heldout_squares": squares}

    class Engine:
        def evaluate(self, effects, keep=None):
            if list(effects) == ["frames", "geometry"]:
                return fit("final")
            return fit("refitted" if keep is None else "own")

        def identify(self, effects):
            return {e: np.ones(1, bool) for e in effects}, {}

        def kept(self, effects):  # identify's columns without its report
            return self.identify(effects)[0]

    current, loo, eliminated = _backward(Engine(), ["frames", "geometry"], lambda _: None, selection_z=-np.inf)
    assert current == ["frames", "geometry"] and eliminated == [] and [r.effect for r in loo] == ["geometry"]
    rms = {k: np.sqrt(np.mean(np.sum(v**2, axis=1))) for k, v in errors.items()}
    assert loo[0].increase == pytest.approx(rms["refitted"] - rms["final"], rel=1e-12)
    assert loo[0].own_share_increase == pytest.approx(rms["own"] - rms["final"], rel=1e-12)
    assert loo[0].own_share_increase == pytest.approx(2.0 * MM, rel=1e-12)


@pytest.mark.parametrize("left_share, named", [(0.4, None), (0.6, "random scatter")])
def test_scatter_predicted_to_within_half_its_excess_variance_is_structure(monkeypatch, left_share, named):
    """0.3 mm per axis left against 0.02 mm of noise: excess variance (0.3^2 - 0.02^2) mm^2. Predicted
    from the joints out of sample, a leftover whose excess is 0.4 of that is structure (not named
    scatter); one at 0.6 of it is scatter. The leftover's size is planted (the prediction itself has
    its own tests). Catches ``0.5 % excess_before`` for ``0.5 * excess_before``."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis import structure

    sigma, noise = 0.3 * MM, 0.02 * MM
    after = np.sqrt(noise**2 + left_share * (sigma**2 - noise**2))
    monkeypatch.setattr(structure, "predictable_leftover", lambda detector, residual: after)
    scatter = {"detected": True, "estimated_noise_per_axis_mm": sigma / MM}
    notes = []
    structure.name_scatter(scatter, {"verdict": "no"}, [], SimpleNamespace(per_axis=noise), notes,
                           detector=object(), residual=np.zeros((10, 3)))
    assert scatter["named"] == named
    assert scatter["predicted_from_joints_left_per_axis_mm"] == pytest.approx(after / MM, rel=1e-12)


@pytest.mark.parametrize("left_share, named", [(0.4, None), (0.6, "random scatter")])
def test_scatter_predicted_from_the_rows_context_to_within_half_its_excess_is_structure(monkeypatch, left_share,
                                                                                        named):
    """The context's twin of the gate above: the joints predict nothing (the leftover stays whole), the
    rows' measurement order predicts it to a planted 0.4 (structure) or 0.6 (scatter) of its excess
    variance over the instrument's. Catches the context gate's ``0.5`` turned or its product mutated."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis import structure

    sigma, noise = 0.3 * MM, 0.02 * MM
    after = np.sqrt(noise**2 + left_share * (sigma**2 - noise**2))
    monkeypatch.setattr(structure, "predictable_leftover", lambda detector, residual: sigma)
    monkeypatch.setattr(structure, "predictable_from_context", lambda features, residual, split: after)
    detector = SimpleNamespace(restrict=lambda values: values, split=None)
    scatter = {"detected": True, "estimated_noise_per_axis_mm": sigma / MM}
    notes = []
    structure.name_scatter(scatter, {"verdict": "no"}, [], SimpleNamespace(per_axis=noise), notes,
                           detector=detector, residual=np.zeros((10, 3)),
                           context={"measurement order": np.arange(10.0), "constant": np.ones(10)})
    assert scatter["named"] == named
    assert scatter["predicted_from_context_left_per_axis_mm"] == pytest.approx(after / MM, rel=1e-12)
    assert ("measurement order" in " ".join(notes)) == (named is None)
    assert "constant" not in " ".join(notes)  # a context that does not vary predicts nothing


def test_a_stand_in_shape_is_its_columns_times_a_draw_at_the_typical_size():
    """The structure test's stand-in leftover of an unchosen effect: its TCP columns (N, 3, k) per
    unit parameter times a standard normal draw scaled by the typical sizes (here 0.1 mrad and
    0.2 mm), nothing absorbed by a chosen model without columns of its own. Written out in numpy on
    the same draw. Catches the draw divided by the scales."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.ambiguity import stand_in_shapes

    n = 12
    rng = np.random.default_rng(5)
    g = rng.standard_normal((n, 6, 2))  # position rows, then rotation rows the probe ignores
    scales = np.array([1e-4, 2e-4])
    basis = SimpleNamespace(per_part=[SimpleNamespace(g=g)], scales=scales, index=[np.array([0, 1])])
    engine = SimpleNamespace(bases={"joint_offsets": basis},
                             columns=lambda effects: SimpleNamespace(per_part=[(None, np.zeros((n, 3, 0)), [])]))
    shapes = stand_in_shapes(engine, ["frames"], ["frames", "joint_offsets"], np.random.default_rng(9))
    draw = np.random.default_rng(9).standard_normal(2) * scales
    expected = np.einsum("nrk,k->nr", g[:, :3, :], draw)
    assert list(shapes) == ["joint_offsets"]
    np.testing.assert_allclose(shapes["joint_offsets"], expected, rtol=1e-12)
    assert 1e-5 < np.sqrt(np.mean(expected**2)) < 1e-3  # tenths of a millimetre, as the draw's sizes


def test_normal_planes_of_a_coarse_corner_take_each_edge_own_direction():
    """An L path sampled only at its start, its corner and its end (0.2 m along x, then 0.2 m along y):
    every plane's tangent is its own edge's direction, not the chord across the corner, and its centre
    lies on that edge at its arc length. Planes within 5 % of the length of the corner are left out.
    Catches the neighbour beyond a corner taken (``seg + 2`` for ``seg + 1`` as the chord's end, or
    ``seg - 1`` for ``seg`` as its start after the corner)."""
    from tcr_accuracy.iso9283.path import CORNER_ZONE, normal_planes

    points = np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.2, 0.2, 0.0]])
    s = np.array([0.0, 0.2, 0.4])
    s_i, centres, tangents = normal_planes(points, s, 10, corners=[1])
    expected_s = 0.4 * (np.arange(10) + 0.5) / 10
    expected_s = expected_s[np.abs(expected_s - 0.2) >= CORNER_ZONE * 0.4]
    np.testing.assert_allclose(s_i, expected_s, rtol=1e-12)
    on_x = s_i < 0.2
    assert on_x.any() and (~on_x).any()
    np.testing.assert_allclose(tangents[on_x], np.tile([1.0, 0.0, 0.0], (on_x.sum(), 1)), atol=1e-12)
    np.testing.assert_allclose(tangents[~on_x], np.tile([0.0, 1.0, 0.0], ((~on_x).sum(), 1)), atol=1e-12)
    np.testing.assert_allclose(centres[on_x, 0], s_i[on_x], atol=1e-12)
    np.testing.assert_allclose(centres[~on_x, 1], s_i[~on_x] - 0.2, atol=1e-12)


def test_error_stats_of_norms_and_their_millimetre_form_by_hand():
    """Three error vectors of norms 5, 4 and 12 mm (3-4-0, 0-0-4, 12-0-0): mean 7, RMS
    sqrt(185/3), max 12 mm, the dict in mm. Catches a mean, RMS or max not scaled by 1e3 (or
    raised to its power) in ``to_dict``, and the RMS taken over norms not squared."""
    from tcr_accuracy.diagnosis.records import ErrorStats

    errors = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 4.0], [12.0, 0.0, 0.0]]) * MM
    stats = ErrorStats.of(errors)
    got = stats.to_dict()
    assert got["count"] == 3
    assert got["mean_mm"] == pytest.approx(7.0, rel=1e-12)
    assert got["rms_mm"] == pytest.approx(np.sqrt((25.0 + 16.0 + 144.0) / 3.0), rel=1e-12)
    assert got["max_mm"] == pytest.approx(12.0, rel=1e-12)


def test_registration_keeps_the_columns_not_spanned_by_earlier_ones_whatever_their_scale():
    """Five columns over 40 rows: a unit column, one 1e-9 as long and independent (kept: the test is
    relative to each column's own norm), a copy of the first scaled by 7 (dropped), a zero column
    (dropped) and a 10-long independent one (kept). Judged here by least squares on the earlier
    columns, the part of each column they leave against 1e-6 of its own norm. Catches the norms
    taken over rows instead of columns and the tolerance's scale."""
    from tcr_accuracy.frames.registration import IDENTIFIABILITY_TOL, _identifiable

    rng = np.random.default_rng(3)
    a, b, c = rng.standard_normal((3, 40))
    columns = np.column_stack([a, 1e-9 * b, 7.0 * a, np.zeros(40), 10.0 * c])
    expected = []
    for k in range(columns.shape[1]):
        column, earlier = columns[:, k], columns[:, :k]
        left = column - earlier @ np.linalg.lstsq(earlier, column, rcond=None)[0] if k else column
        if np.linalg.norm(column) > 0 and np.linalg.norm(left) > IDENTIFIABILITY_TOL * np.linalg.norm(column):
            expected.append(k)
    assert expected == [0, 1, 4]
    assert _identifiable(columns) == expected


def test_a_variable_whose_quantile_bins_collapse_to_one_has_no_spread():
    """95 rows at 0 and six at 1..6 (more distinct values than bins): the quantile edges collapse to
    0 and 6, one bin holds every row, its mean residual is the rows' mean, and a single bin has no
    spread between bins (0, not 1). Written out by hand."""
    from tcr_accuracy.diagnosis.residuals import _binned

    values = np.r_[np.zeros(95), np.arange(1.0, 7.0)]
    residual = np.random.default_rng(2).normal(0.0, 1e-4, (values.size, 3))
    got = _binned(values, residual, n_bins=5)
    assert len(got["bins"]) == 1 and got["spread_mm"] == 0.0
    (only,) = got["bins"]
    assert only["count"] == values.size and (only["low"], only["high"]) == (0.0, 6.0)
    np.testing.assert_allclose(only["mean_mm"], residual.mean(axis=0) * 1e3, rtol=1e-12)
    assert only["rms_mm"] == pytest.approx(np.sqrt(np.mean(np.sum(residual**2, axis=1))) * 1e3, rel=1e-12)


def test_a_fitted_tcp_offset_against_the_given_one_by_hand():
    """The tool twist's translation fitted at (30, 1, 2) mm with no turn, the given offset (31, 0, 0)
    mm: 2.449 mm apart (sqrt(1 + 1 + 4)), its standard error the difference's unit vector times the
    per-axis errors (0.01, 0.02, 0.03 mm) in quadrature, written out here; beyond a 2 mm tolerance
    and said in mm with that error. Catches the error's squares, the mm scale of the words and of
    the figures written beside them."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.plausibility import _tcp_check

    x = np.zeros(9)
    x[3:6] = [0.030, 0.001, 0.002]  # the tool slice's twist: translation first, no rotation
    given = np.array([0.031, 0.0, 0.0])
    sigma = np.array([0.01, 0.02, 0.03]) * MM
    std_of = {f"tcp.{c}": s for c, s in zip(("dx", "dy", "dz"), sigma)}
    check = _tcp_check(x, SimpleNamespace(tool_slice=slice(3, 9)), std_of, "tcp", given,
                       SimpleNamespace(tcp_offset=2.0 * MM), "tool0")
    difference = np.array([-1.0, 1.0, 2.0]) * MM
    size = np.sqrt(6.0) * MM
    std = np.sqrt(np.sum((difference / size) ** 2 * sigma**2))
    assert check.value == pytest.approx(size, rel=1e-9) and check.std == pytest.approx(std, rel=1e-9)
    assert check.flagged
    assert f"{size / MM:.3g} mm apart (+- {std / MM:.2g})" in check.text
    np.testing.assert_allclose(check.detail["difference_mm"], difference / MM, rtol=1e-9)
    np.testing.assert_allclose(check.detail["fitted_mm"], [30.0, 1.0, 2.0], rtol=1e-9)


@pytest.mark.parametrize("step_share, first_order_enough", [(0.24, True), (0.26, False)])
def test_first_order_is_enough_while_a_fixed_point_step_is_within_a_quarter_of_the_noise_floor(
        monkeypatch, step_share, first_order_enough):
    """A fixed-point step of the deflections planted at 0.24 and 0.26 of a 0.04 mm noise floor (the
    step's own computation has its tests): within range only below a quarter, its ratio to the floor
    and its millimetre figures as planted. Catches the quarter changed and the ratio inverted."""
    from tcr_accuracy.diagnosis.stages import attribute

    floor = 0.04 * MM
    rms, largest = step_share * floor, 3.0 * step_share * floor
    monkeypatch.setattr(attribute, "contributions", lambda *args: {"compliance": 0.5 * MM})
    monkeypatch.setattr(attribute, "fixed_point_check", lambda *args: (rms, largest, None))
    reach = attribute.first_order_reach(None, {}, ["compliance"], {}, np.zeros((3, 3)), floor)
    assert reach.within_range is first_order_enough
    assert reach.over_noise_floor == pytest.approx(step_share, rel=1e-12)
    assert reach.to_dict() == pytest.approx({"fixed_point_step_rms_mm": rms / MM,
                                             "fixed_point_step_max_mm": largest / MM,
                                             "over_noise_floor": step_share, "within_range": first_order_enough})
    assert reach.notes == () and reach.contribution == {"compliance": 0.5 * MM}
