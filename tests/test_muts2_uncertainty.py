"""The pose bootstrap over millions of poses (``diagnosis/uncertainty.py``), second pass (issue 36): the blocks
its replicates are drawn and read in never shrink to nothing, and the draws are re-made here block by block
from the same seed. Each test names a planted change it was seen to catch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from test_muts_uncertainty import _strata_draws

from tcr_accuracy.diagnosis.uncertainty import PoseBootstrap


def test_more_poses_than_a_block_holds_are_drawn_and_read_a_replicate_at_a_time():
    """4,000,001 poses (more than the 4e6 cells a drawing block holds, and the 2e6 a reading block holds), one
    replicate: drawn as one block of one replicate (rng.integers(0, N, size=(1, N)) of the same seed, counted by
    np.bincount) and read as one (the replicate's RMS sqrt(sum w r^2 / sum w), written out). Seen failing on the
    drawing block's ``max(1, ...)`` and the reading block's ``max(1, ...)`` turned to ``max(0, ...)`` (a block of
    no replicates: range() refuses a step of 0)."""
    n = 4_000_001
    boot = PoseBootstrap.draw(n, n_replicates=1, random_state=3)
    expected = np.bincount(np.random.default_rng(3).integers(0, n, size=n), minlength=n)
    np.testing.assert_array_equal(boot.counts[0], expected)
    squares = np.linspace(1.0, 2.0, n)
    w = expected.astype(float)
    assert boot.replicate_rms(squares)[0] == pytest.approx(math.sqrt(w @ squares / w.sum()), rel=1e-12)


def test_two_replicates_over_two_million_poses_in_two_sessions_are_drawn_one_block_each():
    """2,000,001 poses in two sessions (strata) and two replicates: 4e6 // N = 1 replicate per block, each block's
    draws session after session, re-made here block by block from the same seed (two blocks of one replicate
    draw the sessions in another order than one block of two). Seen failing on the drawing block's ``max(1,
    ...)`` turned to ``max(2, ...)``."""
    n = 2_000_001
    session = np.arange(n) % 2
    boot = PoseBootstrap.draw(n, session_of=session, n_replicates=2, random_state=8)
    np.testing.assert_array_equal(boot.counts, _strata_draws(n, session, 2, 1, 8))


def test_by_default_a_row_is_one_measured_point():
    """Without ``n_parts`` each row holds one measured frame: the held-out RMS of rows' squared errors (1, 4, 4)
    mm^2 is sqrt(9 / 3) = sqrt(3) mm, on the rows and in every replicate (sqrt(sum w r^2 / sum w), written out).
    Seen failing on ``n_parts: int = 1`` turned to ``2`` (every RMS a root two too small)."""
    squares = np.array([1.0, 4.0, 4.0]) * 1e-6
    boot = PoseBootstrap.draw(3, n_replicates=50, random_state=1)
    assert boot.n_parts == 1 and boot.rms(squares) == pytest.approx(math.sqrt(3.0) * 1e-3, rel=1e-12)
    w = boot.counts.astype(float)
    np.testing.assert_allclose(boot.replicate_rms(squares), np.sqrt(w @ squares / w.sum(axis=1)), rtol=1e-12)


def test_implausibility_of_small_bounds_reads_each_on_the_values_side():
    """Physical bounds of a few mrad (an SI effect's usual size, below one): 0.5e-3 against the upper 1e-3 and
    -1e-3 against the lower -2e-3 give sqrt((0.5^2 + 0.5^2) / 2) = 0.5; a one-sided range [0, 3e-3] read on its
    own side for a negative value (-1.5e-3 / 3e-3). Seen failing on ``np.where(bound > 0, ...)`` turned to
    ``bound > 1`` (every bound below a unit replaced by the wider side)."""
    from types import SimpleNamespace

    from tcr_accuracy.diagnosis.uncertainty import implausibility

    result = {"phi": np.array([0.5e-3, -1e-3, -1.5e-3]), "scale": np.ones(3), "keep": {"compliance": np.arange(3)},
              "effects": ["compliance"]}
    bases = {"compliance": SimpleNamespace(lower=np.array([-2e-3, -2e-3, 0.0]), upper=np.array([1e-3, 1e-3, 3e-3]))}
    assert implausibility(result, bases, "compliance") == pytest.approx(math.sqrt((0.25 + 0.25 + 0.25) / 3),
                                                                        rel=1e-12)
