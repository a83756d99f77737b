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
