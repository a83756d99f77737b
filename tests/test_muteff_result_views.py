"""A diagnosis' figures read back from its JSON form (``diagnosis/result_json.py``'s views), by hand (issue 36):
each figure written in mm comes back in m, each interval's missing end as an infinite one, each count as
written. Each test names a planted change it was seen to catch."""

from __future__ import annotations

import math

import pytest

from tcr_accuracy.diagnosis.result_json import STORED_VIEWS


def _doc():
    stats = {"mean_mm": 1.5, "rms_mm": 2.0, "max_mm": 3.25, "count": 40}
    step = {"effect": "geometry", "effects": ["frames", "geometry"], "n_parameters": 30, "train_rms_mm": 0.25,
            "heldout_mean_mm": 0.3, "heldout_rms_mm": 0.35, "heldout_max_mm": 0.9, "z_vs_previous": 7.5,
            "gain_heldout_rms_mm": 1.2, "gain_interval_mm": [0.8, None]}
    first = {"effect": "frames", "n_parameters": 9, "train_rms_mm": 1.9, "heldout_mean_mm": 1.6,
             "heldout_rms_mm": 2.1, "heldout_max_mm": 3.5, "heldout_count": 38}
    return {"gap": stats, "steps": [first, step], "noise_floor_mm": 0.026, "tracker_noise_mm": 0.015,
            "noise": {"per_axis_mm": 0.012, "source": "repeated poses", "independent": True, "detail": "d"},
            "contribution_mm": {"geometry": 0.75, "compliance": 0.05},
            "heldout_by_frame": {"A": stats, "B": {**stats, "rms_mm": 4.0}},
            "parameters": {"geometry": {"j1.dx": 1e-4, "j1.dy": -2e-4}},
            "parameter_std": {"geometry": {"j1.dx": 1e-5, "j1.dy": None}},
            "parameter_interval_95": {"geometry": {"j1.dx": [0.8e-4, 1.2e-4], "j1.dy": [None, 0.0]}},
            "physical": {"geometry": {"range": {"j1.dx": [-0.02, 0.02]}, "fit_range": {"j1.dx": [None, 0.1]},
                                      "pinned": []}}}


def test_the_figures_written_in_mm_come_back_in_metres():
    """The gap (mean 1.5, RMS 2, max 3.25 mm of 40 rows), each step's train RMS, held-out statistics (its own
    count, else the gap's) and gain with its interval (a missing end: infinite), the noise floor, the
    tracker's noise and the noise estimate, the contributions and each measured frame's held-out RMS, all
    in m; a parameter's missing standard error infinite, its interval's missing end infinite. Seen failing
    on ``doc["rms_mm"] * 1e-3`` turned to ``% 1e-3``, ``finite_or(high, math.inf) * 1e-3`` to ``/ 1e-3``,
    ``doc["noise_floor_mm"] * 1e-3`` to ``* 1.001`` and ``v * 1e-3`` (contributions) to ``v ** 1e-3``."""
    doc = _doc()
    gap = STORED_VIEWS["gap"](doc)
    assert (gap.mean, gap.rms, gap.max, gap.count) == pytest.approx((1.5e-3, 2e-3, 3.25e-3, 40), rel=1e-12)
    first, step = STORED_VIEWS["steps"](doc)
    assert (first.effect, first.n_parameters, first.gain) == ("frames", 9, None)
    assert first.train_rms == pytest.approx(1.9e-3, rel=1e-12)
    assert (first.heldout.mean, first.heldout.rms, first.heldout.max) == pytest.approx((1.6e-3, 2.1e-3, 3.5e-3))
    assert first.heldout.count == 38 and step.heldout.count == 40
    assert step.effects == ("frames", "geometry") and step.z_statistic == 7.5
    assert (step.train_rms, step.heldout.rms, step.heldout.max) == pytest.approx((0.25e-3, 0.35e-3, 0.9e-3))
    assert step.gain[:2] == pytest.approx((1.2e-3, 0.8e-3), rel=1e-12) and step.gain[2] == math.inf
    assert STORED_VIEWS["noise_floor"](doc) == pytest.approx(0.026e-3, rel=1e-12)
    assert STORED_VIEWS["tracker_noise"](doc) == pytest.approx(0.015e-3, rel=1e-12)
    noise = STORED_VIEWS["noise"](doc)
    assert noise.per_axis == pytest.approx(0.012e-3, rel=1e-12) and noise.source == "repeated poses"
    assert STORED_VIEWS["noise"]({**doc, "noise": {}}).per_axis == pytest.approx(0.015e-3, rel=1e-12)
    assert STORED_VIEWS["contribution"](doc) == pytest.approx({"geometry": 0.75e-3, "compliance": 0.05e-3}, rel=1e-12)
    by_frame = STORED_VIEWS["heldout_by_frame"](doc)
    assert by_frame["A"].rms == pytest.approx(2e-3, rel=1e-12) and by_frame["B"].rms == pytest.approx(4e-3, rel=1e-12)
    table = STORED_VIEWS["parameter_table"](doc)["geometry"]
    assert table["std"] == {"j1.dx": 1e-5, "j1.dy": math.inf}
    assert table["interval"] == {"j1.dx": [0.8e-4, 1.2e-4], "j1.dy": [-math.inf, 0.0]}
    assert table["range"] == {"j1.dx": [-0.02, 0.02]} and table["fit_range"] == {"j1.dx": [-math.inf, 0.1]}
    one_sided = {**doc, "steps": [{**doc["steps"][1], "gain_interval_mm": [None, 2.0]}]}
    _, low, high = STORED_VIEWS["steps"](one_sided)[0].gain
    assert low == -math.inf and high == pytest.approx(2e-3, rel=1e-12)
