"""The learning curve's documented defaults (``diagnosis/bayes_design.py``: 5 training sizes, 8 subsamples per
size, 400 bootstrap resamples) counted in the random draws it takes, replayed here on a generator of the same
seed. Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import numpy as np

from tcr_accuracy.diagnosis.bayes_design import DesignColumns, EffectPrior, learning_curve


def test_a_default_learning_curve_takes_five_sizes_of_eight_subsamples_and_four_hundred_resamples():
    """30 poses of 8 parameters: the sizes are round(geomspace(N/2, 4N/5, 5)) (numpy here); the curve draws 8
    subsamples of N - size left-out poses per size (``Generator.choice`` without replacement), then 400 bootstrap
    resamples of the 40 (size, subsample) results (``Generator.integers``): replayed on a generator of the same
    seed, both generators stand at the same draw afterwards, and the bootstrap holds 400 rows. Seen failing on
    the default ``repeats: int = 8`` turned to ``7``, ``n_sizes: int = 5`` turned to ``6`` and ``n_boot: int =
    400`` turned to ``401``."""
    rng = np.random.default_rng(1596)
    n = 30
    owner = np.array(["frames"] * 3 + ["compliance"] * 5)
    g = rng.normal(size=(n, 3, owner.size)) * 1e-4
    errors = g @ rng.normal(0, 1.0, owner.size) + rng.normal(0, 3e-5, (n, 3))
    prior = EffectPrior({"compliance": 1.0}, 3e-5)
    draws = np.random.default_rng(7)
    curve = learning_curve(DesignColumns(g, owner, ["frames", "compliance"]), errors, prior, draws)
    sizes = np.unique(np.round(np.geomspace(n / 2, 0.8 * n, 5)).astype(int))
    np.testing.assert_array_equal(curve.sizes, sizes)
    assert curve.boot.shape == (400, 2)
    replay = np.random.default_rng(7)
    for size in sizes:
        for _ in range(8):
            replay.choice(n, n - size, replace=False)
    for _ in range(400):
        replay.integers(0, 8 * sizes.size, 8 * sizes.size)
    assert draws.random() == replay.random()
