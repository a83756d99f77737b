"""Which parameters the measurements tell apart (``diagnosis/identifiability.py``), second pass (issue 36), on
the columns of known independent motions that tests/test_mutfit_identifiability.py builds (orthonormal
directions: each column's own motion a closed form). Each test names a planted change it was seen to catch."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from test_identifiability_gram import _expected_kept
from test_mutfit_identifiability import N_POSES, _bases

from tcr_accuracy.diagnosis.identifiability import GRAM_PIVOTING, identifiability


@pytest.mark.parametrize("report", [True, False])
def test_an_effect_missing_from_a_threshold_dict_is_held_to_no_threshold(report):
    """Thresholds per effect with b left out: a at 5 um keeps its three columns, b is judged at 0 m (only the
    rank tolerance), so it keeps b2 (0.63 um RMS of its own: under a's threshold, over none) and b4, with the
    report and without; the report's threshold is the largest given, 5 um. Seen failing on
    ``threshold = thresholds.get(name, 0.0)`` turned to ``1.0`` (b judged at 1 m RMS keeps nothing), in the
    report's loop and in the quick one."""
    bases, _, _ = _bases()
    own = 2e-6 / math.sqrt(N_POSES)
    assert own < 5e-6
    keep, out = identifiability(bases, ["a", "b"], 1e-6, {"a": 5e-6}, report=report)
    assert keep["a"].tolist() == [0, 1, 2] and keep["b"].tolist() == [1, 3]
    if report:
        assert out["min_motion_mm"] == pytest.approx(5e-3, rel=1e-12)
        assert out["effects"]["b"]["n_identifiable"] == 2
    # the same b held to 5 um by name: b2 goes
    assert identifiability(bases, ["a", "b"], 1e-6, {"a": 5e-6, "b": 5e-6}, report=report)[0]["b"].tolist() == [3]


def _large_case(seed, tie):
    """A small block a (4 columns) and a large one t (GRAM_PIVOTING + 4 columns, norms a hundredfold apart) over
    100 poses x 3 rows, as identifiability reads them (g (rows, 1, P), unit scales): t5 repeats a1, t60 and t61
    add to a2, a3 a part of their own of 8e-3 and 5e-4 RMS (some 3e-3 and 2e-4 of it beyond
    the other columns of t: resolved at 1e-3, not), and with ``tie`` t9 repeats
    t7 exactly (the earlier of two tied columns is kept)."""
    rng = np.random.default_rng(seed)
    rows, k_t = 300, GRAM_PIVOTING + 4
    a = rng.standard_normal((rows, 4))
    t = rng.standard_normal((rows, k_t)) * np.logspace(-1, 1, k_t)
    t[:, 5] = a[:, 1]
    own = rng.standard_normal((rows, 2))
    own -= a @ np.linalg.lstsq(a, own, rcond=None)[0]
    own /= np.linalg.norm(own, axis=0) / math.sqrt(rows)
    t[:, 60] = a[:, 2] + 8e-3 * own[:, 0]
    t[:, 61] = a[:, 3] + 5e-4 * own[:, 1]
    if tie:
        t[:, 9] = t[:, 7]

    def block(columns, name):
        return SimpleNamespace(names=[f"{name}{i}" for i in range(columns.shape[1])], g=columns[:, None, :],
                               scales=np.ones(columns.shape[1]), n_poses=None)

    return a, t, {"a": block(a, "a"), "t": block(t, "t")}


@pytest.mark.parametrize("report, min_motion", [(False, 0.0), (False, 1e-3), (True, 1e-3)])
def test_a_large_block_after_a_small_one_keeps_what_pivoting_its_projected_columns_keeps(report, min_motion):
    """Pivoted through its own Gram matrix less its part in a's span (the route of a block of more than
    GRAM_PIVOTING columns), the large block keeps what scipy's pivoted QR of its columns projected off a's span
    keeps (tests/test_identifiability_gram.py's judgement, written out on the columns): t5 (a repeat) and t9 (t7's
    twin) never, t61 only without a threshold; of the tied pair the earlier. Seen failing on ``scaled = cols *
    tie_break`` turned to ``cols / tie_break`` (the later twin kept), on ``gram - coordinates.T @ coordinates``
    turned to ``+`` and on ``rank_tol * norms[piv[k]]`` turned to ``rank_tol / norms[...]``."""
    a, t, bases = _large_case(3, tie=True)
    expected = _expected_kept(a, t, min_motion)
    assert {5, 9}.isdisjoint(expected.tolist()) and {7, 60} <= set(expected.tolist())
    assert (61 in expected.tolist()) == (min_motion == 0.0)
    keep, _ = identifiability(bases, ["a", "t"], 1e-6, min_motion, report=report)
    np.testing.assert_array_equal(keep["a"], np.arange(4))
    np.testing.assert_array_equal(keep["t"], expected)


def test_a_large_block_first_gives_the_span_the_next_is_judged_against():
    """The large block first (no span before it: its basis made from its own pivoted columns), then a, whose a1
    t repeats and whose a2 and a3 it nearly repeats: a keeps what scipy's pivoted QR of its columns projected off
    t's span keeps (a0, and a2 for the part of t60's own motion beyond t's other columns). Seen failing on the basis' ``factor[:rank, :rank]`` turned to ``factor[:rank, :rank + 1]``
    and on ``piv = piv - 1`` turned to ``piv - 2``."""
    _, t, bases = _large_case(4, tie=False)
    keep, _ = identifiability(bases, ["t", "a"], 1e-6, 1e-3, report=False)
    assert keep["t"].size == t.shape[1]
    expected = _expected_kept(t, bases["a"].g[:, 0, :], 1e-3)
    assert expected.tolist() == [0, 2]
    np.testing.assert_array_equal(keep["a"], expected)
