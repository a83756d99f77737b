"""The paired tests the selection reads (``diagnosis/paired.py``) against scipy: the paired mean's z is
``scipy.stats.ttest_rel``'s statistic of the per-row squared errors (parts of a row added up here with
numpy), Wilcoxon's signed-rank z is read back from ``scipy.stats.wilcoxon``'s one-sided normal
approximation, and the degenerate cases (no spread, no difference) at their closed forms. Each test names
a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.diagnosis.paired import entry_z, paired_z, row_squares, signed_rank_z, stacked


def _errors(seed: int, n: int = 23, parts: int | None = None):
    """Position errors before and after (one part: (n, 3); several: (parts, n, 3)), the after ones smaller
    on most rows and larger on a few."""
    rng = np.random.default_rng(seed)
    shape = (n, 3) if parts is None else (parts, n, 3)
    before = 1e-4 * rng.standard_normal(shape)
    after = before * rng.uniform(0.2, 1.3, size=shape[:-1] + (1,))
    return before, after


@pytest.mark.parametrize("parts", [None, 2])
def test_paired_z_is_the_paired_t_statistic_of_the_rows_squared_errors(parts):
    """z = mean(d) / (sd(d, ddof=1) / sqrt(n)) with d the per-row squared error before less after, the
    parts of a row added up: ``scipy.stats.ttest_rel``'s statistic on the squares summed here. A (N,)
    array is read as the squares themselves. Seen failing on ``d.std(ddof=1)`` turned to ``ddof=2``, on
    ``sd / math.sqrt(d.size)`` turned to ``* math.sqrt``, on the parts' squares summed over ``axis=(0, 2)`` turned to
    ``(0, 1)``."""
    before, after = _errors(31, parts=parts)
    axes = 1 if parts is None else (0, 2)
    b, a = np.sum(before**2, axis=axes), np.sum(after**2, axis=axes)
    assert b.shape == (23,)
    np.testing.assert_allclose(row_squares(before), b, rtol=1e-14)
    expected = stats.ttest_rel(b, a).statistic
    assert paired_z(before, after) == pytest.approx(expected, rel=1e-12)
    assert paired_z(b, a) == pytest.approx(expected, rel=1e-12)
    assert paired_z(a, b) == pytest.approx(-expected, rel=1e-12)


def test_signed_rank_z_without_ties_is_scipys_with_zero_differences_dropped():
    """Wilcoxon's one-sided z (normal approximation, zeros dropped, no ties) is scipy's, read back from its
    p-value, on (N, 3) errors with three rows unchanged (n counts only the 20 others); equal squares give
    0; and entry_z is the larger of the two z values (here the ranks' and the mean's, one case each). Seen
    failing on ``n * (n + 1) / 4.0`` turned to ``/ 5.0``, on ``(2 * n + 1)`` turned to ``(2 * n - 1)``, on
    ``d[d != 0]`` turned to ``d[d != 1]`` and on the no-difference ``return 0.0`` turned to ``1.0``."""
    before, after = _errors(32)
    after[[2, 9, 17]] = before[[2, 9, 17]]
    d = row_squares(before) - row_squares(after)
    assert np.count_nonzero(d) == 20 and np.unique(np.abs(d[d != 0])).size == 20
    p = stats.wilcoxon(d, zero_method="wilcox", correction=False, alternative="greater", method="approx").pvalue
    z = signed_rank_z(before, after)
    assert z == pytest.approx(stats.norm.isf(p), rel=1e-9)
    # written out: W+ less its mean n(n+1)/4 over sqrt(n(n+1)(2n+1)/24)
    nz = d[d != 0]
    ranks = stats.rankdata(np.abs(nz))
    n = nz.size
    assert z == pytest.approx((ranks[nz > 0].sum() - n * (n + 1) / 4) / math.sqrt(n * (n + 1) * (2 * n + 1) / 24),
                              rel=1e-12)
    assert signed_rank_z(before, before) == 0.0
    t = paired_z(before, after)
    assert entry_z(before, after) == max(z, t)
    # one row carrying most of the gain: the ranks see little, the mean a lot (or the other way round)
    spiky_after = before.copy()
    spiky_after[0] = 0.0
    spiky_after[1:] *= 1.0001
    assert entry_z(before, spiky_after) == max(paired_z(before, spiky_after), signed_rank_z(before, spiky_after))
    assert paired_z(before, spiky_after) != signed_rank_z(before, spiky_after)


def test_without_spread_the_paired_z_is_zero_or_infinite_with_the_sign_of_the_cut():
    """Every row cut by the same amount: the z of a sure cut is +inf, of a sure rise -inf, of no change 0.
    Seen failing on ``return 0.0 if d.mean() == 0`` turned to ``1.0`` and on ``copysign(math.inf, d.mean())``
    turned to ``-d.mean()``."""
    before = np.full(6, 4.0)
    assert paired_z(before, before - 1.0) == math.inf
    assert paired_z(before, before + 1.0) == -math.inf
    assert paired_z(before, before) == 0.0


def test_stacked_parts_are_their_points_one_after_another():
    """(n_parts, N, 3) errors read as n_parts * N points, part by part; (N, 3) as they are. Seen failing on
    ``reshape(-1, 3)`` turned to ``reshape(-1, 4)``."""
    before, _ = _errors(33, n=5, parts=2)
    np.testing.assert_array_equal(stacked(before), np.concatenate([before[0], before[1]]))
    one = before[0]
    assert stacked(one) is one
