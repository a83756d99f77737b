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
