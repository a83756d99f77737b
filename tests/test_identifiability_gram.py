"""A large block's identifiability taken through Gram matrices (its own, kept per bases, less its part
in the kept span) against the same judgement written out here on the projected columns themselves:
numpy's QR of the kept columns, the block projected off them, scipy's pivoted QR of what is left."""

import math

import numpy as np
from scipy import linalg

from tcr_accuracy.diagnosis.identifiability import GRAM_PIVOTING, gram_factor, identifiability


def _bases(rng):
    """A small block ``a`` (12 columns) and a large one ``t`` (GRAM_PIVOTING + 30 columns, norms a
    hundredfold apart) of which 3 columns repeat a's exactly and 2 add to one of a's columns a part
    of their own just above or below what the measurements resolve; as the diagnosis hands them over
    (a factor of their Gram matrix)."""
    rows, k_t = 900, GRAM_PIVOTING + 30
    a = rng.standard_normal((rows, 12))
    t = rng.standard_normal((rows, k_t)) * np.logspace(-1, 1, k_t)
    t[:, 5] = a[:, 2]
    t[:, 40] = a[:, 7] - 0.5 * a[:, 3]
    t[:, 100] = 2.0 * a[:, 0]
    own = rng.standard_normal((rows, 2))
    own -= a @ np.linalg.lstsq(a, own, rcond=None)[0]
    own /= np.linalg.norm(own, axis=0) / math.sqrt(rows)  # RMS 1 across the rows, none of it in a's span
    t[:, 60] = a[:, 4] + 2e-3 * own[:, 0]  # 2e-3 RMS of its own: resolved at 1e-3
    t[:, 61] = a[:, 5] + 5e-4 * own[:, 1]  # 5e-4: not resolved
    whole = np.hstack([a, t])
    columns = {"a": ([f"a{i}" for i in range(12)], np.arange(12)),
               "t": ([f"t{i}" for i in range(k_t)], np.arange(12, 12 + k_t))}
    return whole, gram_factor(whole.T @ whole, columns, n_poses=rows)


def _expected_kept(first: np.ndarray, second: np.ndarray, min_motion: float, rank_tol: float = 1e-6) -> np.ndarray:
    """The second block's kept columns judged on the columns themselves: projected off the first
    block's span (all its columns independent here), pivoted QR of what is left."""
    q = np.linalg.qr(first)[0]
    projected = second - q @ (q.T @ second)
    tie_break = 1.0 + 1e-9 * np.arange(second.shape[1], 0, -1) / second.shape[1]
    _, r, piv = linalg.qr(projected * tie_break, mode="economic", pivoting=True)
    diag = np.abs(np.diag(r)) / tie_break[piv]
    norms = np.linalg.norm(second, axis=0)
    rank = 0
    while rank < diag.size and diag[rank] / math.sqrt(first.shape[0]) > min_motion \
            and diag[rank] > rank_tol * norms[piv[rank]]:
        rank += 1
    return np.sort(piv[:rank])


def test_a_large_block_keeps_what_projecting_its_columns_keeps():
    rng = np.random.default_rng(11)
    whole, bases = _bases(rng)
    prefixes: dict = {}
    for min_motion in (0.0, 1e-3):
        expected = _expected_kept(whole[:, :12], whole[:, 12:], min_motion)
        dropped = set(range(whole.shape[1] - 12)) - set(expected.tolist())
        # the exact repeats of a's columns always go; the small own part only where it is below the threshold
        assert {5, 40, 100} <= dropped and 60 not in dropped
        assert (61 in dropped) == (min_motion > 0)
        for prefix in (None, prefixes, prefixes):  # fresh, then the own Gram matrix kept, then reused
            kept, _ = identifiability(bases, ["a", "t"], 1e-6, min_motion, report=False, prefixes=prefix)
            np.testing.assert_array_equal(kept["t"], expected)
            np.testing.assert_array_equal(kept["a"], np.arange(12))
        keep, report = identifiability(bases, ["a", "t"], 1e-6, min_motion, prefixes=prefixes)
        np.testing.assert_array_equal(keep["t"], expected)
        assert report["effects"]["t"]["n_identifiable"] == expected.size
    assert "own_grams" in prefixes and prefixes["own_grams"]["t"].shape == (whole.shape[1] - 12,) * 2


def test_a_large_block_ahead_of_another_gives_the_span_it_keeps():
    """The large block first: its kept columns' basis is made from its columns (the Gram route gives
    only pivots), and the block after it is judged against that span as against the columns."""
    rng = np.random.default_rng(12)
    whole, bases = _bases(rng)
    kept, _ = identifiability(bases, ["t", "a"], 1e-6, 0.0, report=False, prefixes={})
    assert kept["t"].size == GRAM_PIVOTING + 30  # alone, t's columns are independent
    expected = _expected_kept(whole[:, 12:], whole[:, :12], 0.0)
    # a0 and a2 repeat t's columns, and a7 - 0.5 a3 is one: three of a's columns go
    assert expected.size == 9 and {0, 2}.isdisjoint(expected.tolist())
    np.testing.assert_array_equal(kept["a"], expected)
