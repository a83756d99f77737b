"""``diagnosis/bayes_design.py``: the fitted prior's upper bounds (issue 36, third pass). Each test names a
planted change it was seen to catch."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.bayes_design import DesignColumns, fit_prior

EFFECTS = ["frames", "compliance", "transmission"]


def test_a_prior_fitted_to_errors_far_beyond_typical_sizes_rests_on_the_upper_bounds():
    """Columns of 1 um per typical size and parameters drawn at 10^4 typical sizes (errors of some 10 mm): the
    evidence grows with tau up to 10^4, so every non-geometric tau rests on TAU_BOUNDS' upper end, 100
    typical sizes, exactly, and what the prior cannot reach goes to the noise, which rests on
    NOISE_BOUNDS_M's upper end, 1e-2 m, exactly. Seen failing on ``TAU_BOUNDS = (1e-2, 1e2)`` turned to
    ``(1e-2, 99.0)`` (a measuring sample's survivor, seed 4200) and on ``NOISE_BOUNDS_M = (1e-7, 1e-2)``
    turned to ``(1e-7, 0.011)`` (planted by hand)."""
    rng = np.random.default_rng(3)
    owner = np.array(["frames"] * 2 + ["compliance"] * 4 + ["transmission"] * 4)
    g = rng.normal(size=(30, 3, owner.size)) * 1e-6
    theta = np.concatenate([[1.0, 1.0], rng.normal(0, 1e4, 8)])
    errors = g @ theta + rng.normal(0, 1e-7, (30, 3))
    prior = fit_prior(DesignColumns(g, owner, EFFECTS), errors)
    assert prior.tau == pytest.approx({"compliance": 100.0, "transmission": 100.0}, rel=1e-12)
    assert prior.noise_m == pytest.approx(1e-2, rel=1e-12)


@pytest.mark.parametrize("criterion", ["I", "D"])
def test_a_design_after_measured_poses_starts_from_their_information(criterion):
    """Eight poses measured, four of twelve candidates to choose: the task's spread before the design is that of
    the posterior after the measured poses, ``S = (Lambda + G^T G / sigma^2)^-1`` (a plain inverse here), after
    it that of the posterior with the chosen poses added, and the log-determinant gain is the log-det of the
    information with the chosen poses less that with the measured ones alone (numpy's slogdet), to 1e-9; the
    measured poses lower the task's spread (the figures differ from the prior's alone). Seen failing on
    ``information += beta * (flat.T @ flat)`` turned to ``beta ** (...)`` (a measuring sample's survivor,
    seed 4200) and on ``beta = 1.0 / prior.noise_m**2`` turned to ``** 3`` (planted by hand)."""
    from tcr_accuracy.diagnosis.bayes_design import EffectPrior, plan_design

    rng = np.random.default_rng(17)
    owner = np.array(["frames"] * 2 + ["compliance"] * 3 + ["transmission"] * 3)
    p = owner.size
    measured = DesignColumns(rng.normal(size=(8, 3, p)) * 1e-4, owner, EFFECTS)
    candidates = DesignColumns(rng.normal(size=(12, 3, p)) * 1e-4, owner, EFFECTS)
    prior = EffectPrior({"compliance": 2.0, "transmission": 0.5}, 3e-5)
    precision = np.array([1e-6 if e == "frames" else 1.0 / prior.tau[e] ** 2 for e in owner])
    design = plan_design(measured, candidates, candidates, prior, 4, criterion=criterion)
    flat = measured.g.reshape(-1, p)
    before = np.diag(precision) + flat.T @ flat / prior.noise_m**2
    chosen = candidates.g[design.picked].reshape(-1, p)
    after = before + chosen.T @ chosen / prior.noise_m**2

    def spread(information):
        s = np.linalg.inv(information)
        return np.array([np.trace(g @ s @ g.T) for g in candidates.g])

    prior_alone = spread(np.diag(precision))
    assert np.sqrt(prior_alone.mean()) > 1.5 * np.sqrt(spread(before).mean())
    assert design.task_std_before_m == pytest.approx(np.sqrt(spread(before).mean()), rel=1e-9)
    assert design.task_worst_std_before_m == pytest.approx(np.sqrt(spread(before).max()), rel=1e-9)
    assert design.task_std_after_m == pytest.approx(np.sqrt(spread(after).mean()), rel=1e-9)
    assert design.task_worst_std_after_m == pytest.approx(np.sqrt(spread(after).max()), rel=1e-9)
    assert design.log_det_gain == pytest.approx(np.linalg.slogdet(after)[1] - np.linalg.slogdet(before)[1], rel=1e-9)


def test_the_learning_curves_calibration_takes_one_ratio_only_for_one_variance():
    """Misses made of 0.7 x the noise term and 1.6 x the posterior variance, exactly: with variances spread
    over the rows (mean 3e-10 m^2, a spread as large) the non-negative least squares gives (0.7, 1.6) back; with
    one variance on every row (2e-9 m^2) the two cannot be told apart and both weights are the one ratio
    sum(observed) / sum(3 sigma^2 + v), written out. Seen failing on ``np.ptp(variance) <= 1e-9 * max(...)``
    turned to ``1e-9 - max(...)`` (a measuring sample's survivor, seed 4201), to ``1e-9 / max(...)`` and to
    ``1e-9 ** max(...)`` (planted by hand)."""
    from tcr_accuracy.diagnosis.bayes_design import _calibration

    noise3 = 3 * (1e-5) ** 2
    spread = np.linspace(1.5e-10, 4.5e-10, 12)
    a, b = _calibration(0.7 * noise3 + 1.6 * spread, spread, noise3)
    assert (a, b) == pytest.approx((0.7, 1.6), rel=1e-9)
    one = np.full(12, 2e-9)
    observed = 0.7 * noise3 + 1.6 * one + np.linspace(-1e-11, 1e-11, 12)
    ratio = observed.sum() / np.sum(noise3 + one)
    assert _calibration(observed, one, noise3) == pytest.approx((ratio, ratio), rel=1e-12)
