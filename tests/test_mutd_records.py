"""The diagnosis' records as the result file holds them: every length of each record's ``to_dict`` in mm (the
record's metres times 1000), every angle in deg or mrad, every squared length in mm^2, written out here key by key
on records built with distinct figures; and the verdicts the records read (``ranked``, ``beats_alternative``,
``confounds``, ``within_range``) at their thresholds. Each test names planted changes it was seen to catch
(issue 36)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tcr_accuracy.diagnosis.attribution import ShareComparison
from tcr_accuracy.diagnosis.bayes_design import EffectPrior, LearningCurve
from tcr_accuracy.diagnosis.compare import TcpEffect
from tcr_accuracy.diagnosis.confounding import Confounding
from tcr_accuracy.diagnosis.records import ErrorStats, Step
from tcr_accuracy.diagnosis.stages.attribute import FamilyShare, FirstOrder
from tcr_accuracy.diagnosis.stages.candidates import Candidate
from tcr_accuracy.diagnosis.stages.residual import OrientationFigures
from tcr_accuracy.diagnosis.stages.search import SearchPath, SearchReport
from tcr_accuracy.diagnosis.stages.select import Elimination, LeaveOneOut
from tcr_accuracy.diagnosis.stages.setup import SessionSetup


class near:  # noqa: N801 (read as pytest.approx is)
    """Equal to a figure within 1e-12 relative, through nested dicts and lists (pytest.approx stops at lists
    in dicts)."""

    def __init__(self, expected):
        self.expected = expected

    def __eq__(self, actual) -> bool:
        return _close(actual, self.expected)

    def __repr__(self) -> str:
        return f"near({self.expected!r})"


def _close(actual, expected) -> bool:
    if isinstance(expected, dict):
        return isinstance(actual, dict) and set(actual) == set(expected) and all(
            _close(actual[k], v) for k, v in expected.items())
    if isinstance(expected, (list, tuple)):
        return isinstance(actual, (list, tuple)) and len(actual) == len(expected) and all(
            _close(a, e) for a, e in zip(actual, expected))
    if isinstance(expected, bool) or not isinstance(expected, (int, float)):
        return actual == expected
    return actual == pytest.approx(expected, rel=1e-12, abs=0)

STATS = ErrorStats(mean=1.25e-4, rms=1.5e-4, max=3.75e-4, count=42)
OTHER = ErrorStats(mean=2.25e-4, rms=2.5e-4, max=4.75e-4, count=42)
STATS_MM = {"mean_mm": 0.125, "rms_mm": 0.15, "max_mm": 0.375, "count": 42}


def test_error_stats_step_and_selection_records_in_mm():
    """ErrorStats, a shrink-table Step, a LeaveOneOut, an Elimination, a tried and an untried Candidate and a
    SearchPath, each figure in mm written out. Seen failing on ``self.max * 1e3`` turned to ``/ 1e3`` in
    ``ErrorStats.to_dict``, on ``self.gain[2] * 1e3`` turned to ``+ 1e3`` in ``Step.to_dict``, on
    ``self.own_share_increase * 1e3`` turned to ``** 1e3`` and on ``self.gain * 1e3`` turned to ``1001.0`` in
    ``Candidate.to_dict``."""
    assert STATS.to_dict() == near(STATS_MM)
    step = Step(effect="joint_offsets", effects=("frames", "joint_offsets"), n_parameters=12, train_rms=1.0e-4,
                heldout=STATS, z_statistic=4.5, gain=(3.0e-5, 1.0e-5, 5.0e-5))
    assert step.to_dict() == near(
        {"effect": "joint_offsets", "effects": ["frames", "joint_offsets"], "n_parameters": 12, "train_rms_mm": 0.1,
         "heldout_rms_mm": 0.15, "heldout_mean_mm": 0.125, "heldout_max_mm": 0.375, "heldout_count": 42,
         "z_vs_previous": 4.5, "gain_heldout_rms_mm": 0.03, "gain_interval_mm": [0.01, 0.05]})
    assert "gain_heldout_rms_mm" not in Step("frames", ("frames",), 6, 2e-4, STATS, None).to_dict()
    loo = LeaveOneOut(effect="drift", heldout=OTHER, increase=1.0e-4, z=3.25, own_share_heldout=STATS,
                      own_share_increase=-2.0e-5)
    assert loo.to_dict() == near(
        {"dropped": "drift", "heldout_rms_mm": 0.25, "heldout_mean_mm": 0.225, "heldout_max_mm": 0.475,
         "increase_mm": 0.1, "z": 3.25, "own_share_heldout_rms_mm": 0.15, "own_share_heldout_mean_mm": 0.125,
         "own_share_increase_mm": -0.02})
    assert Elimination("backlash", 1.5, 7.0e-6).to_dict() == near(
        {"effect": "backlash", "z": 1.5, "increase_mm": 0.007})
    tried = Candidate(effect="drift", tried=True, heldout_rms=1.75e-4, gain=2.5e-5, z=2.75, n_parameters=3,
                      added_to=("frames", "joint_offsets"))
    assert tried.to_dict() == near(
        {"tried": True, "heldout_rms_mm_with_frames": 0.175, "gain_mm": 0.025, "z": 2.75, "n_parameters": 3,
         "added_to": ["frames", "joint_offsets"]})
    assert Candidate(effect="backlash", tried=False, why="no direction column").to_dict() == {
        "tried": False, "why": "no direction column"}
    assert SearchPath("beam", ("frames", "drift"), OTHER, 9).to_dict() == near(
        {"path": "beam", "effects": ["frames", "drift"], "heldout_rms_mm": 0.25, "n_parameters": 9})


def test_search_report_margin_in_square_mm_and_beaten_by_more_than_one_standard_error():
    """The alternative's margin per row is in mm^2 (m^2 times 10^6); the chosen set beats the alternative when
    the margin exceeds its standard error, not when equal, and always without an alternative; its sentence names
    the alternative's held-out RMS in mm. Seen failing on ``self.margin * 1e6`` turned to ``* 1000001.0``, on
    ``self.margin > self.margin_se`` turned to ``>=`` and on the note's ``heldout.rms * 1e3`` turned to ``/ 1e3``."""
    greedy = SearchPath("greedy", ("frames", "joint_offsets"), STATS, 12)
    beam = SearchPath("beam", ("frames", "drift"), OTHER, 9)
    report = SearchReport(n_sets=31, paths=(greedy, beam), chosen_path="greedy", chosen=("frames", "joint_offsets"),
                          alternative=beam, margin=2.5e-9, margin_se=1.25e-9)
    out = report.to_dict()
    assert out["alternative_margin_mm2"] == near(2.5e-3)
    assert out["alternative_margin_se_mm2"] == near(1.25e-3)
    assert out["sets_evaluated"] == 31 and out["beats_alternative"]
    assert out["paths"][1]["heldout_rms_mm"] == near(0.25)
    tie = SearchReport(31, (greedy, beam), "greedy", ("frames", "joint_offsets"), beam, 1.25e-9, 1.25e-9)
    assert not tie.beats_alternative
    assert SearchReport(31, (greedy,), "greedy", ("frames",), None, 0.0, 0.0).beats_alternative
    head = "search beyond the greedy path: 31 models fitted, 2 paths compared; chosen [frames, joint_offsets] from the "
    other = "the best set on another path, [frames, drift] (beam), held-out RMS 0.25 mm"
    assert report.note() == head + f"greedy path; it beats {other}, by more than one standard error"
    assert tie.note() == head + (f"greedy path; a tie with {other}: within one standard error, the held-out rows "
                                 "cannot rank them")


def test_family_share_and_share_comparison_in_mm_ranked_only_above_the_threshold_and_zero():
    """A family's share, its interval and its held-out RMS without it in mm; the comparison with the largest in
    mm, ranked when its z exceeds the threshold and its interval's low end exceeds 0: not at z equal to the
    threshold, not with the low end at 0 or at -0.01 mm; ranked with it at +0.01 mm. Seen failing on
    ``self.interval[0] > 0.0`` turned to ``> 1.0`` and ``> -1.0``, on ``self.z > self.threshold`` turned to
    ``>=``, and on ``self.difference * 1e3`` turned to ``- 1e3``."""
    comparison = ShareComparison(larger="geometric", smaller="scale", difference=4.0e-5, interval=(1.0e-5, 7.0e-5),
                                 z=3.5, threshold=3.0)
    assert comparison.ranked
    assert comparison.to_dict() == near(
        {"larger": "geometric", "smaller": "scale", "difference_mm": 0.04, "interval_mm": [0.01, 0.07], "z": 3.5,
         "z_threshold": 3.0, "ranked": True})
    for low, z, ranked in ((0.0, 3.5, False), (-1.0e-5, 3.5, False), (1.0e-5, 3.0, False), (1.0e-5, 3.0001, True)):
        assert ShareComparison("a", "b", 4.0e-5, (low, 7.0e-5), z, 3.0).ranked is ranked
    share = FamilyShare(family="geometric", effects=("joint_offsets",), share=6.0e-5, interval=(2.0e-5, 9.0e-5),
                        heldout_without=OTHER, stand_ins=("geometry",), below_largest=comparison)
    out = share.to_dict()
    assert out["share_mm"] == near(0.06)
    assert out["interval_mm"] == near([0.02, 0.09])
    assert out["heldout_rms_without_mm"] == near(0.25)
    assert out["below_largest"]["difference_mm"] == near(0.04)
    assert (out["effects"], out["stand_ins"]) == (["joint_offsets"], ["geometry"])


def test_first_order_orientation_setup_and_comparison_figures_in_mm_and_degrees():
    """The first-order reach's fixed-point steps in mm; the held-out orientation errors in degrees (math.degrees
    here); the setups compared and each session's frame against the first in mm and mrad, its TCP offset in mm;
    a comparison's TCP effect in mm; a prior's noise in mm. Seen failing on ``size["rotation_std"] * 1e3``
    turned to ``- 1e3`` and ``c["heldout_rms"] * 1e3`` turned to ``* 1001.0`` in the setup's record, on
    ``self.fixed_point_step_max * 1e3`` turned to ``% 1e3`` and on ``self.noise_m * 1e3`` turned to ``999.0``."""
    first = FirstOrder(contribution={"joint_offsets": 1e-4}, fixed_point_step_rms=2.0e-6, fixed_point_step_max=5.0e-6,
                       over_noise_floor=0.1, within_range=True, notes=())
    assert first.to_dict() == near({"fixed_point_step_rms_mm": 0.002, "fixed_point_step_max_mm": 0.005,
                                             "over_noise_floor": 0.1, "within_range": True})
    orientation = OrientationFigures(weight=0.5, heldout_mean=1.0e-3, heldout_rms=2.0e-3, heldout_max=5.0e-3)
    assert orientation.to_dict() == near(
        {"weight_m_per_rad": 0.5, "heldout_mean_deg": 1.0e-3 * 180 / math.pi, "heldout_rms_deg": 2.0e-3 * 180 / math.pi,
         "heldout_max_deg": 5.0e-3 * 180 / math.pi})
    sizes = ({"session": "B", "first": "A", "translation": 1.5e-3, "translation_std": 2.0e-5, "rotation": 3.0e-4,
              "rotation_std": 4.0e-6, "tool_offset": (1.0e-3, -2.0e-3, 2.5e-2), "tool_offset_std": (1e-5, 2e-5, 3e-5)},
             {"session": "C", "first": "A"})
    setup = SessionSetup(chosen="frames per session", session_frames=True, session_tools=True, forced="",
                         compared=({"setup": "one frame", "n_parameters": 6, "heldout_rms": 3.0e-4,
                                    "within_one_se": False},),
                         judged_with=("frames",), sizes=sizes)
    out = setup.to_dict()
    assert out["compared"] == [near({"setup": "one frame", "n_parameters": 6, "heldout_rms_mm": 0.3,
                                              "within_one_se": False})]
    assert out["sessions"][0] == near(
        {"session": "B", "against": "A", "translation_mm": 1.5, "translation_std_mm": 0.02, "rotation_mrad": 0.3,
         "rotation_std_mrad": 0.004, "tool_offset_mm": [1.0, -2.0, 25.0], "tool_offset_std_mm": [0.01, 0.02, 0.03]})
    assert out["sessions"][1] == {"session": "C", "against": "A"}
    assert "forced" not in out and "preferred" not in out
    assert TcpEffect.of(np.array([3e-5, 4e-5, 1.2e-4])).to_dict() == near(
        {"mean_mm": 0.19 / 3, "rms_mm": math.sqrt((9 + 16 + 144) / 3) * 1e-2,
         "max_mm": 0.12})
    assert EffectPrior(tau={"drift": 2.0}, noise_m=3.0e-5, fitted=True, n_poses=50).to_dict() == near(
        {"tau_typical_sizes": {"drift": 2.0}, "noise_mm": 0.03, "fitted": True, "n_poses": 50})


def test_learning_curve_record_in_mm():
    """Every RMS of a learning curve in mm, the floor too. Seen failing on ``self.high_m * 1e3`` turned to
    ``+ 1e3`` and ``self.noise_floor_m * 1e3`` turned to ``// 1e3``."""
    curve = LearningCurve(sizes=np.array([10, 20]), rms_m=np.array([2e-4, 1e-4]), low_m=np.array([1.5e-4, 0.5e-4]),
                          high_m=np.array([2.5e-4, 1.5e-4]), expected_rms_m=np.array([2.1e-4, 1.1e-4]),
                          noise_weight=0.75, variance_weight=1.25, boot=np.ones((4, 2)), noise_floor_m=4e-5)
    assert curve.to_dict() == near(
        {"sizes": [10, 20], "heldout_rms_mm": [0.2, 0.1], "heldout_rms_5_mm": [0.15, 0.05],
         "heldout_rms_95_mm": [0.25, 0.15], "expected_rms_mm": [0.21, 0.11], "noise_weight": 0.75,
         "variance_weight": 1.25, "floor_mm": 0.04, "noise_floor_mm": 0.04})


def test_a_confounded_variable_from_nine_tenths_of_the_signature():
    """A variable that follows the clock confounds an effect the drift reproduces at least 90 % of (not
    at 89.9 %), and one whose share was not measured; its words give the share in per cent. Seen failing on
    ``CONFOUNDED_SHARE = 0.9`` turned to ``1.9`` and on ``100 * share`` turned to ``101 * share``."""
    confounding = Confounding(variable="temperature_c", clock="measurement order", r=0.93,
                              effects=("thermal_growth", "encoder_scale", "joint_scale"),
                              reproduced={"thermal_growth": 0.9, "encoder_scale": 0.899})
    assert confounding.confounds("thermal_growth") and not confounding.confounds("encoder_scale")
    assert confounding.confounds("joint_scale") and not confounding.confounds("drift")
    out = confounding.to_dict()
    assert out["confounded_effects"] == ["thermal_growth"]
    assert out["confounded_from"] == 0.9
    assert out["why"] == ("temperature_c follows the measurement order (r = +0.93): drift reproduces 90 % of "
                          "thermal_growth's signature on these poses (confounded from 90 %): cannot be told from it; "
                          "drift reproduces 90 % of encoder_scale's signature on these poses (confounded from 90 %): "
                          "told apart, named")
