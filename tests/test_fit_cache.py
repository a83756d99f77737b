"""The fit engine caches each fit without its per-row residual arrays and makes them again when a
stage reads them (:mod:`tcr_accuracy.diagnosis.fit_result`): the remade arrays are the floats the fit
had when it was made, and the figures kept in their place (each row's squared held-out error, the
error statistics, the cost) are those of the arrays, written out here."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.bases import ordered
from tcr_accuracy.diagnosis.diagnose import GapDiagnosis
from tcr_accuracy.diagnosis.fit_result import RESIDUAL_KEYS, FitResult
from tcr_accuracy.io.measurements import parse_measurements

from hidden_robot import MM, HiddenRobot, fixed_tracker, geometric_errors, in_tracker, measurement_csv, noisy, \
    random_poses

NOISE = 2e-5


@pytest.fixture(scope="module")
def fitted(ur5):
    """A diagnosis of a hidden UR5 (joint placement errors, a TCP offset, the tracker's frame, 0.02 mm
    noise) with two fold assignments, so that the held-out arrays are several."""
    rng = np.random.default_rng(5)
    q = random_poses(ur5, 240, rng)
    _, placements = geometric_errors(ur5, rng, offset_deg=0.0, offset_mm=0.0, placement_mm=0.1,
                                     placement_deg=0.1)
    tcp = ur5.tool_frame
    hidden = HiddenRobot(ur5, placements, {tcp: np.array([0.8, -0.5, 1.2]) * MM})
    measured = noisy(rng, in_tracker(fixed_tracker(), hidden.positions(q, [tcp])[tcp]), NOISE)
    mset = parse_measurements(measurement_csv(ur5, q, {tcp: measured}, {}, per_frame=False), ur5)
    return GapDiagnosis(robot=ur5, folds=3, fold_repeats=2, random_state=3, tracker_noise=NOISE,
                        effects=["frames", "joint_offsets", "geometry", "compliance"]).fit(mset)


def _arrays(result) -> dict:
    return {k: result[k] for k in RESIDUAL_KEYS}


def _assert_same(a, b) -> None:
    if isinstance(a, list):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            _assert_same(x, y)
    elif a is None:
        assert b is None
    else:
        assert np.array_equal(a, b)


def test_cached_fits_hold_no_residual_arrays_and_remake_the_same_floats(fitted):
    engine = fitted.engine_
    cached = list(engine._full_cache.values())
    assert cached and all(isinstance(r, FitResult) for r in cached)
    assert not any(k in dict.keys(r) for r in cached for k in RESIDUAL_KEYS)  # not stored: made when read
    effects = tuple(ordered(fitted.selected_effects_))
    engine.reset()  # forget it, fit it again: the arrays read first are those made with the fit
    for exact in (False, True):
        made = engine.evaluate(effects, exact=exact)
        kept = _arrays(made)
        other = engine.evaluate(("frames", "geometry"), exact=exact)
        _arrays(other)  # another fit's arrays read in between: the first fit's are made again
        again = engine.evaluate(effects, exact=exact)
        assert again is made
        for key in RESIDUAL_KEYS:
            _assert_same(again[key], kept[key])


def test_kept_figures_are_those_of_the_arrays(fitted):
    engine = fitted.engine_
    for result in list(engine._full_cache.values()):
        train = result["train_residual"]
        repeats = result["heldout_repeats"]
        assert len(repeats) == 2
        # each row's squared held-out error, the mean over the two fold assignments
        squares = (np.sum(repeats[0] ** 2, axis=1) + np.sum(repeats[1] ** 2, axis=1)) / 2.0
        assert np.allclose(result["heldout_squares"], squares, rtol=1e-14, atol=0.0)
        norms = np.linalg.norm(train, axis=1)
        assert result["train_stats"].rms == pytest.approx(np.sqrt(np.mean(norms**2)), rel=1e-12)
        assert result["train_stats"].max == pytest.approx(norms.max(), rel=1e-12)
        pooled = np.linalg.norm(np.concatenate(repeats), axis=1)
        assert result["heldout_stats"].rms == pytest.approx(np.sqrt(np.mean(pooled**2)), rel=1e-12)
        assert result["heldout_stats"].mean == pytest.approx(pooled.mean(), rel=1e-12)
        assert result["heldout_stats"].count == train.shape[0]
        assert result["cost"] == pytest.approx(np.sum(train**2), rel=1e-12)
        assert np.array_equal(result["heldout_residual"], repeats[0])


def test_ladder_reads_remade_held_out_rows(fitted):
    steps = fitted.ladder([e for e in ordered(fitted.selected_effects_) if e != "frames"])
    final = fitted.engine_.evaluate(tuple(ordered(fitted.selected_effects_)), exact=True)
    first = final["heldout_repeats"][0]
    assert steps[-1].heldout.rms == pytest.approx(np.sqrt(np.mean(np.sum(first**2, axis=1))), rel=1e-12)
    assert all(s.z_statistic is not None for s in steps[1:])
