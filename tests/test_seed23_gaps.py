"""Edge cases of figures a person reads, each checked against a computation written out here.

Written after the seed-23 mutation sample (so they do not count towards that sample's kill rate):
an instrument's MPE of two zeros, the multidirectional orientation variation vAP_a, vAP_b, vAP_c,
drift's time axis where nothing varies, a path point's foot on the segment before its nearest sample,
the approach-direction split where a joint did not move, two whole turns back within a joint's limits,
the scatter notes' millimetres.
"""

from itertools import combinations

import numpy as np
import pytest

from tcr_accuracy.exceptions import InputError
from tcr_accuracy.frames.instrument import instrument_from
from tcr_accuracy.iso9283.formulas import iso_figures


@pytest.mark.parametrize("label", ["mpe", "radial_mpe"])
def test_an_mpe_of_two_zeros_is_refused_naming_its_flag(label):
    """An instrument with no error at all (a = 0 m and b = 0 m/m) would weight its readings infinitely:
    refused, naming the flag. Planted bug caught: ``values.sum() <= 0`` -> ``<= -1``."""
    kwargs = {"mpe": (15e-6, 6e-6)}
    kwargs[label] = (0.0, 0.0)
    with pytest.raises(InputError, match=f"instrument_{label} \\[0.0, 0.0\\]: need two numbers"):
        instrument_from(**kwargs)
    # one of the two may be zero
    kwargs[label] = (0.0, 6e-6)
    assert instrument_from(**kwargs) is not None


def test_multidirectional_orientation_variation_per_axis_over_every_pair_of_approaches():
    """vAP_a, vAP_b, vAP_c of ISO 9283 clause 7.2.3: for each orientation axis, the largest difference
    between the mean deviations reached from two approach directions, over every pair of directions.
    Three approaches with mean deviations chosen so that each axis has its largest difference in a
    different pair (a per-pair maximum over the axes, or one pair's differences, gives other numbers).
    Planted bug caught: ``axis=0`` -> ``axis=1`` (a (pairs,) array of per-pair maxima)."""
    rng = np.random.default_rng(5)
    means = {"A": np.array([0.0, 0.0, 0.0]), "B": np.array([3e-4, -1e-4, 0.5e-4]),
             "C": np.array([1e-4, 2e-4, -4e-4])}
    pose_id, labels, positions, deviations = [], [], [], []
    for label, mean in means.items():
        spread = rng.normal(0.0, 1e-5, (30, 3))
        spread -= spread.mean(axis=0)  # each approach's mean deviation exactly as chosen
        deviations.append(mean + spread)
        positions.append(np.array([0.5, 0.1, 0.4]) + rng.normal(0.0, 1e-5, (30, 3)))
        pose_id += ["P1"] * 30
        labels += [label] * 30
    figures = iso_figures(np.array(pose_id), np.vstack(positions), np.tile([0.5, 0.1, 0.4], (90, 1)),
                          deviations=np.vstack(deviations), approach=np.array(labels))
    (variation,) = figures.directional
    expected = np.max([np.abs(means[a] - means[b]) for a, b in combinations("ABC", 2)], axis=0)
    np.testing.assert_allclose(expected, [3e-4, 3e-4, 4.5e-4], rtol=1e-12)  # a different pair for each axis
    np.testing.assert_allclose(variation.vap_abc, expected, rtol=1e-9, atol=1e-15)


def test_drift_has_no_time_axis_where_neither_time_nor_order_varies():
    """Drift is fitted along ``time_s`` where it varies, else the measurement order where that varies,
    else along nothing (its columns would be 0/0). Start and span written out by hand.
    Planted bug caught: the order's ``np.ptp(order) > 0`` -> ``> -1`` (a constant order taken as an axis
    of span 0)."""
    from types import SimpleNamespace

    from tcr_accuracy.effects.drift import DriftFitPolicy

    policy = DriftFitPolicy()
    constant = SimpleNamespace(time_s=None, order=np.full(12, 7.0))
    assert policy.options_for_data(None, None, constant) == {}
    assert policy.options_for_data(None, None, None) == {}
    ordered_rows = SimpleNamespace(time_s=np.full(12, 3.0), order=np.arange(3.0, 15.0))
    assert policy.options_for_data(None, None, ordered_rows) == {"time_axis": "order", "start": 3.0, "span": 11.0}
    timed = SimpleNamespace(time_s=np.array([40.0, 10.0, 25.0]), order=np.arange(3.0))
    assert policy.options_for_data(None, None, timed) == {"time_axis": "time_s", "start": 10.0, "span": 30.0}


def test_a_point_nearest_the_second_sample_projects_on_the_first_segment():
    """A measured point nearest the path's second sample whose foot lies on the segment before it:
    its foot and arc length, by hand on a straight path of 1 m samples. Planted bug caught: the segment
    before the nearest sample taken from ``max(k - 1, 1)`` (the first segment never looked at)."""
    from tcr_accuracy.iso9283.path_evaluate import project_on_path

    path = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]])
    s = np.array([0.0, 1.0, 2.0, 3.0])
    points = np.array([[0.6, 0.1, 0.0], [2.3, -0.2, 0.05], [0.2, 0.0, 0.3]])
    foot, arc = project_on_path(points, path, s)
    np.testing.assert_allclose(foot, [[0.6, 0.0, 0.0], [2.3, 0.0, 0.0], [0.2, 0.0, 0.0]], atol=1e-15)
    np.testing.assert_allclose(arc, [0.6, 2.3, 0.2], atol=1e-15)


def test_approach_direction_leaves_out_the_rows_of_a_joint_that_did_not_move():
    """The mean error with a joint approached from above minus from below, by hand, on a direction
    column holding +1, -1 and 0 (a joint that did not move before the reading): the rows of 0 belong to
    neither side. Planted bug caught: ``minus = d < 0`` -> ``d < 1`` (the still rows counted as from
    below)."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.residuals import where_analysis

    rng = np.random.default_rng(11)
    n = 60
    q = rng.uniform(-1.5, 1.5, (n, 2))
    nominal = rng.normal(size=(n, 3)) * 0.3 + [0.3, 0.0, 0.6]
    residual = rng.normal(0.0, 5e-5, (n, 3))
    direction = np.column_stack([np.resize([1.0, -1.0, 0.0], n), np.resize([0.0, 0.0, 1.0, -1.0], n)])
    residual[direction[:, 0] == 0] += 4e-4  # the still rows far off: counted on a side, they move its mean
    robot = SimpleNamespace(joint_names=["a", "b"], joint_kinds=["revolute", "revolute"])
    tau = np.zeros((n, 2))
    where, _ = where_analysis(robot, q, nominal, residual, tau, {"direction": direction},
                              rng=np.random.default_rng(0))
    for j, name in enumerate("ab"):
        plus, minus = direction[:, j] == 1.0, direction[:, j] == -1.0
        diff = residual[plus].mean(axis=0) - residual[minus].mean(axis=0)
        got = where["approach_direction"][name]
        assert (got["count_plus"], got["count_minus"]) == (plus.sum(), minus.sum())
        np.testing.assert_allclose(got["mean_plus_minus_minus_mm"], diff * 1e3, rtol=1e-12)
        assert got["difference_norm_mm"] == pytest.approx(np.linalg.norm(diff) * 1e3, rel=1e-12)


def test_two_whole_turns_bring_a_joint_two_turns_away_back_within_its_limits(ur5):
    """A UR5 shoulder (limits +-2 pi) read two turns up, at 1 + 4 pi rad, with home 0: a turn down
    (1 + 2 pi) is still beyond its limit, two turns down (1.0 rad) are within and nearest home; the
    same two turns up for a joint read at -(1 + 4 pi). Planted bug caught: the turns tried
    ``(-2, -1, 1, 2)`` -> ``(2, -1, 1, 2)`` (the joint left two turns up)."""
    from tcr_accuracy.iso9283.reach import Reach, Workspace

    reach = Reach(ur5, None, Workspace(), np.zeros(6), "exact")
    q = np.array([[1.0 + 4 * np.pi, 0.1, 0.2, -(1.0 + 4 * np.pi), 0.3, 0.4]])
    got = reach.nearest_home(q)
    np.testing.assert_allclose(got, [[1.0, 0.1, 0.2, -1.0, 0.3, 0.4]], atol=1e-12)


@pytest.mark.parametrize("verdict, clearance_effect, named, words", [
    ("no", [], "random scatter", "0.3000 mm per axis vs 0.0200 mm, without spatial structure"),
    ("no", ["clearance"], "clearance", "0.3000 mm per axis vs 0.0200 mm, without spatial structure"),
    ("cannot tell", [], None, "0.3000 mm per axis left against 0.0200 mm of noise: whether it is structure"),
])
def test_scatter_is_said_in_millimetres_against_the_instruments_noise(verdict, clearance_effect, named, words):
    """Scatter of 0.3 mm per axis against an instrument's 0.02 mm, with no detector to ask: named
    random scatter (or clearance where the vocabulary holds it) when the structure test says no, left
    unnamed when it cannot tell; both notes quote both figures in mm to 4 decimals, written out here.
    Planted bug caught: the noise's ``per_axis * 1e3`` -> ``per_axis / 1e3`` in the first note."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.structure import name_scatter

    scatter = {"detected": True, "estimated_noise_per_axis_mm": 0.3}
    notes = []
    name_scatter(scatter, {"verdict": verdict, "reason": "too few poses"}, clearance_effect,
                 SimpleNamespace(per_axis=0.02e-3), notes)
    assert scatter.get("named") == named
    assert len(notes) == 1 and words in notes[0]
