"""The ISO 9283 result file's units (``iso9283/result_file.py``) and the stabilisation figures
(``iso9283/formulas.py``), against numbers written out here. Each test names a planted change it
was seen to catch.
"""

import math

import numpy as np
import pytest

from tcr_accuracy.iso9283.evaluate import IsoEvaluation
from tcr_accuracy.iso9283.formulas import (DirectionalVariation, DistanceFigures, IsoFigures, PoseFigures,
                                           Stabilisation, settling, stabilisation_figures)
from tcr_accuracy.iso9283.result_file import IsoCondition, IsoTestResult, evaluation_dict, evaluation_from_dict

MM = 1e-3
DEG = math.pi / 180


def _evaluation():
    """An evaluation with every kind of figure, its values chosen here (SI)."""
    poses = [PoseFigures("1", "2", 5, np.array([0.1, 0.2, 0.3]), np.array([0.1003, 0.1996, 0.3012]), 0.0013,
                         np.array([0.3e-3, -0.4e-3, 1.2e-3]), 0.05e-3, 0.02e-3, 0.01e-3,
                         np.array([0.2, -0.1, 0.05]) * DEG, np.array([0.03, 0.06, 0.09]) * DEG),
             PoseFigures("P2", None, 2, np.array([0.0, 0.2, 0.3]), np.array([0.0001, 0.2, 0.3]), 0.1e-3,
                         np.array([0.1e-3, 0.0, 0.0]), None, 0.04e-3, None, np.array([0.1, 0.2, 0.3]) * DEG, None)]
    figures = IsoFigures(
        poses=poses,
        directional=[DirectionalVariation("1", ("1", "2"), 0.07e-3, np.array([0.01, 0.02, 0.04]) * DEG)],
        distances=[DistanceFigures("1", "P2", 4, 0.1, 0.1002, 0.2e-3, np.array([0.1e-3, -0.2e-3, 0.3e-3]), 0.06e-3,
                                   "2")],
        notes=["a note"],
        stabilisation=[Stabilisation("1", "2", 3, 0.05e-3, 0.4, 0.7, 0.03e-3, 0.08e-3, 1)])
    return IsoEvaluation(figures=figures, frame="base", registration=None, how="given", orientation_offset=None,
                         n_readings=12, pose_q={}, n_visits=7, frame_source="base", absolute=True,
                         instrument_distance={"1": 2.5, "P2": 3.25})


def test_the_json_form_states_every_figure_in_mm_deg_and_s_and_reads_back_in_si():
    """Every figure of an evaluation written in the JSON form is its SI value times 1000 (mm) or
    180 / pi (deg), seconds as they are; the summary is the largest and mean AP and the largest RP;
    read back, every figure equals the SI value. Catches any ``* 1e3`` as ``/ 1e3`` or ``1e-3`` as
    ``1e-2`` in the writing and the reading (AP, its components, RP, l̄, S_l, barycentre, vAP, AD,
    RD, D_c, D̄, the band, the overshoots, the instrument distance) and the summary's mean as a
    sum."""
    result = _evaluation()
    doc = evaluation_dict(result)
    p1, p2 = doc["poses"]
    assert p1["pose_id"] == 1 and p1["approach"] == 2 and p2["pose_id"] == "P2" and p2["pose"] == "P2"
    assert p1["ap_mm"] == pytest.approx(1.3, rel=1e-12)
    assert [p1["ap_x_mm"], p1["ap_y_mm"], p1["ap_z_mm"]] == pytest.approx([0.3, -0.4, 1.2], rel=1e-12)
    assert (p1["rp_mm"], p1["l_mean_mm"], p1["s_l_mm"]) == pytest.approx((0.05, 0.02, 0.01), rel=1e-12)
    assert p1["barycentre_mm"] == pytest.approx([100.3, 199.6, 301.2], rel=1e-12)
    assert p1["commanded_mm"] == pytest.approx([100.0, 200.0, 300.0], rel=1e-12)
    assert [p1[f"ap_{a}_deg"] for a in "abc"] == pytest.approx([0.2, -0.1, 0.05], rel=1e-12)
    assert [p1[f"rp_{a}_deg"] for a in "abc"] == pytest.approx([0.03, 0.06, 0.09], rel=1e-12)
    assert p1["instrument_distance_mm"] == pytest.approx(2500.0) and p2["instrument_distance_mm"] == pytest.approx(3250.0)
    assert p2["rp_mm"] is None and p2["s_l_mm"] is None and p2["l_mean_mm"] == pytest.approx(0.04, rel=1e-12)
    assert [p2[f"rp_{a}_deg"] for a in "abc"] == [None, None, None]
    assert doc["summary"]["ap_max_mm"] == pytest.approx(1.3, rel=1e-12)
    assert doc["summary"]["ap_mean_mm"] == pytest.approx((1.3 + 0.1) / 2, rel=1e-12)
    assert doc["summary"]["rp_max_mm"] == pytest.approx(0.05, rel=1e-12)
    (vap,) = doc["directional"]
    assert vap["vap_mm"] == pytest.approx(0.07, rel=1e-12) and vap["approaches"] == [1, 2]
    assert [vap[f"vap_{a}_deg"] for a in "abc"] == pytest.approx([0.01, 0.02, 0.04], rel=1e-12)
    (dist,) = doc["distances"]
    assert (dist["commanded_mm"], dist["mean_mm"], dist["ad_mm"], dist["rd_mm"]) == pytest.approx(
        (100.0, 100.2, 0.2, 0.06), rel=1e-12)
    assert [dist[f"ad_{a}_mm"] for a in "xyz"] == pytest.approx([0.1, -0.2, 0.3], rel=1e-12)
    (stab,) = doc["stabilisation"]
    assert (stab["band_mm"], stab["overshoot_mean_mm"], stab["overshoot_max_mm"]) == pytest.approx(
        (0.05, 0.03, 0.08), rel=1e-12)
    assert (stab["time_mean_s"], stab["time_max_s"], stab["visits"], stab["never_entered"]) == (0.4, 0.7, 3, 1)
    assert (doc["n_readings"], doc["n_visits"], doc["standard_cycles"]) == (12, 7, 30)

    back = evaluation_from_dict(doc)
    for got, want in zip(back.figures.poses, result.figures.poses):
        for name in ("ap", "rp", "l_mean", "l_std"):
            assert getattr(got, name) == (None if getattr(want, name) is None else
                                          pytest.approx(getattr(want, name), rel=1e-12))
        for name in ("ap_xyz", "barycentre", "commanded", "ap_abc"):
            np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=1e-12)
        assert (got.pose_id, got.approach, got.n) == (want.pose_id, want.approach, want.n)
    np.testing.assert_allclose(back.figures.poses[0].rp_abc, result.figures.poses[0].rp_abc, rtol=1e-12)
    assert back.figures.poses[1].rp_abc is None
    d, w = back.figures.directional[0], result.figures.directional[0]
    assert d.vap == pytest.approx(w.vap, rel=1e-12) and d.approaches == ("1", "2")
    np.testing.assert_allclose(d.vap_abc, w.vap_abc, rtol=1e-12)
    d, w = back.figures.distances[0], result.figures.distances[0]
    assert (d.commanded, d.mean, d.ad, d.rd) == pytest.approx((w.commanded, w.mean, w.ad, w.rd), rel=1e-12)
    np.testing.assert_allclose(d.ad_xyz, w.ad_xyz, rtol=1e-12)
    s, w = back.figures.stabilisation[0], result.figures.stabilisation[0]
    assert (s.band, s.overshoot_mean, s.overshoot_max, s.time_mean, s.time_max) == pytest.approx(
        (w.band, w.overshoot_mean, w.overshoot_max, w.time_mean, w.time_max), rel=1e-12)
    assert s.never_entered == 1 and s.n == 3
    assert back.instrument_distance == pytest.approx({"1": 2.5, "P2": 3.25}, rel=1e-12)
    assert (back.n_readings, back.n_visits) == (12, 7)


def test_a_result_of_two_conditions_and_a_compensation_round_trips():
    """Two test conditions, the first with a compensated evaluation: the file has the first at the
    top and both under ``conditions`` with their load and speed; read back, each condition's AP
    is as written."""
    measured, compensated = _evaluation(), _evaluation()
    conditions = (IsoCondition(100.0, 100.0, measured, compensated, "diag.json"), IsoCondition(10.0, 100.0, measured))
    doc = IsoTestResult("ur5", None, "tool0", "m.csv", conditions).to_dict()
    assert "robot_source" not in doc and doc["condition"] == {"load_pct": 100.0, "speed_pct": 100.0}
    assert doc["compensated"]["model"] == "diag.json" and doc["compensated"]["poses"][0]["ap_mm"] == pytest.approx(1.3)
    assert [c["condition"]["load_pct"] for c in doc["conditions"]] == [100.0, 10.0]
    again = IsoTestResult.from_dict(doc)
    assert [c.load_pct for c in again.conditions] == [100.0, 10.0]
    assert again.conditions[0].compensated.figures.poses[0].ap == pytest.approx(1.3e-3, rel=1e-12)
    assert again.conditions[1].compensated is None


def test_settling_time_and_overshoot_of_a_visit_written_out():
    """A visit's readings 0.1 s apart, distances from the last reading 5, 0.8, 1.5, 0.6, 0.2, 1.1,
    0.3, 0 (x 0.1 mm) with a band of 0.1 mm: the robot enters at the second reading (0.1 s), last
    leaves after the sixth (1.1 mm) and stays in from the seventh (0.6 s): stabilisation 0.5 s,
    overshoot 0.15 mm (the largest distance after entering). A visit that never leaves: 0, 0; one
    that never enters (band below every distance but the last's, the last itself entering):
    entering at the last reading. Catches ``first + int(left[-1]) + 1`` as ``+ 2`` or ``- 1``."""
    times = 0.1 * np.arange(8)
    distances = np.array([5.0, 0.8, 1.5, 0.6, 0.2, 1.1, 0.3, 0.0]) * 0.1 * MM
    direction = np.array([2.0, -1.0, 2.0]) / 3.0
    positions = np.array([0.4, 0.1, 0.6]) + distances[:, None] * direction
    t, overshoot = settling(times, positions, 0.1 * MM)
    assert t == pytest.approx(0.5, rel=1e-12)
    assert overshoot == pytest.approx(0.15 * MM, rel=1e-9)
    assert settling(times, positions, 0.2 * MM) == (0.0, 0.0)
    t, overshoot = settling(times, positions, 0.01 * MM)
    assert t == 0.0 and overshoot == 0.0  # only the attained reading is within 0.001 mm


def test_stabilisation_figures_are_the_mean_and_largest_over_the_visits():
    """Three visits of one pose and one of another, settling 0.2, 0.3 and 0 s with overshoots 0.15,
    0.3 and 0 mm: the pose's mean 0.5 / 3 s and 0.45 / 3 mm, largest 0.3 s and 0.3 mm, in natural
    pose order. Catches the mean of times as their sum (``np.mean`` -> ``np.sum``)."""
    band = 0.1 * MM
    direction = np.array([0.0, 0.6, 0.8])

    def visit(distances_mm):
        distances_mm = np.asarray(distances_mm)
        return 0.1 * np.arange(len(distances_mm)), np.array([0.1, 0.2, 0.3]) + distances_mm[:, None] * MM * direction

    visits = [visit([0.5, 0.08, 0.15, 0.09, 0.05, 0.0]),  # in at 0.1 s, out at 0.2 s, in for good at 0.3 s
              visit([1.0, 0.05, 0.3, 0.2, 0.0]), visit([0.02, 0.01, 0.0]), visit([0.3, 0.0])]
    expected_times = [0.3 - 0.1, 0.4 - 0.1, 0.0]
    expected_overshoot = [0.15 * MM, 0.3 * MM, 0.0]
    for v, t, o in zip(visits[:3], expected_times, expected_overshoot):
        assert settling(*v, band) == pytest.approx((t, o), rel=1e-9, abs=1e-15)
    out = stabilisation_figures(["P10", "P10", "P10", "P2"], ["1", "1", "1", "1"], visits,
                                {("P10", "1"): band, ("P2", "1"): 2 * band})
    assert [s.pose_id for s in out] == ["P2", "P10"]
    p10 = out[1]
    assert p10.n == 3 and p10.band == pytest.approx(band) and p10.never_entered == 0
    assert p10.time_mean == pytest.approx(sum(expected_times) / 3, rel=1e-9)
    assert p10.time_max == pytest.approx(max(expected_times), rel=1e-9)
    assert p10.overshoot_mean == pytest.approx(sum(expected_overshoot) / 3, rel=1e-9)
    assert p10.overshoot_max == pytest.approx(max(expected_overshoot), rel=1e-9)
    assert out[0].band == pytest.approx(2 * band) and out[0].time_mean == 0.0


def test_a_pose_read_twice_in_a_cycle_is_left_out_of_ad_rd_and_said():
    """Poses 1, 2 and 3 read in cycles 1-4, pose 2 twice in cycle 3: the pairs with pose 2 use its
    three single cycles (n = 3), the pair 1-3 all four, and the note names the first pose and cycle read
    twice. Catches the note's string joined with ``*`` instead of ``+`` (a TypeError) and
    ``MIN_REPEATS`` changed."""
    from tcr_accuracy.iso9283.formulas import MIN_REPEATS, iso_figures

    pose = ["1", "2", "3"] * 4 + ["2"]
    cycle = [str(c) for c in np.repeat([1, 2, 3, 4], 3)] + ["3"]
    rng = np.random.default_rng(0)
    commanded = {"1": [0.0, 0.0, 0.0], "2": [0.1, 0.0, 0.0], "3": [0.0, 0.2, 0.0]}
    positions = np.array([commanded[p] for p in pose]) + rng.normal(0, 1e-5, (13, 3))
    figures = iso_figures(pose, positions, np.array([commanded[p] for p in pose]), cycle=cycle)
    assert MIN_REPEATS == 3
    assert [(d.pose_a, d.pose_b, d.n) for d in figures.distances] == [("1", "2", 3), ("1", "3", 4), ("2", "3", 3)]
    assert "1 (pose, cycle) pair(s) read more than once, left out of AD and RD (first: pose P2, cycle 3)" in figures.notes
