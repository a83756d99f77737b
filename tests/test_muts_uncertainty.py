"""How sure the diagnosis is (``diagnosis/uncertainty.py``): the cases the earlier tests did not enter, each
figure against a computation written out here (issue 36): the side a pinned parameter sits on for bounds of
either sign, the interval of a parameter without a bound, the bootstrap's replicate count and its draws re-made
from the same seed, the sessions drawn within strata, and the selection replays' progress messages. Each test
names a planted change it was seen to catch."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.diagnosis.uncertainty import (MIN_SESSION_CLUSTERS, PoseBootstrap, implausibility, parameter_table,
                                                selection_frequency)


def _result(values, std, lower, upper, at_bound, names, keep, effects):
    n = len(values)
    return {"phi": np.asarray(values, dtype=float), "phi_std": np.asarray(std, dtype=float), "scale": np.ones(n),
            "lower": np.asarray(lower, dtype=float), "upper": np.asarray(upper, dtype=float),
            "at_bound": np.asarray(at_bound), "names": np.array(names), "keep": keep, "effects": effects}


def test_a_pinned_parameter_is_said_on_the_bound_it_sits_on_for_bounds_of_either_sign():
    """Four parameters held on a bound, the nearer bound named by hand: 2 on [2, 3] (lower), 3 on [2, 3]
    (upper), -3 on [-3, -2] (lower), -2 on [-3, -2] (upper); one on a one-sided range [0, inf) at 0 (lower)
    and one flagged at a bound with no finite bound (not listed). The intervals value +- Phi^-1(0.975) std
    (scipy) cut to the range. Seen failing on ``abs(v - lo) <= abs(v - hi)`` turned to ``abs(v + lo)`` and
    to ``abs(v - hi)`` turned to ``abs(v + hi)`` (the side of a bound of the value's own sign)."""
    values = [2.0, 3.0, -3.0, -2.0, 0.0, 5.0]
    lower = [2.0, 2.0, -3.0, -3.0, 0.0, -np.inf]
    upper = [3.0, 3.0, -2.0, -2.0, np.inf, np.inf]
    std = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    names = list("abcdef")
    result = _result(values, std, lower, upper, [True] * 6, names, {"geometry": np.arange(6)}, ["geometry"])
    bases = {"geometry": SimpleNamespace(names=names, lower=lower, upper=upper)}
    table = parameter_table(result, bases, ["geometry"])["geometry"]
    assert table["pinned"] == [{"parameter": "a", "bound": "lower"}, {"parameter": "b", "bound": "upper"},
                               {"parameter": "c", "bound": "lower"}, {"parameter": "d", "bound": "upper"},
                               {"parameter": "e", "bound": "lower"}]
    z = stats.norm.ppf(0.975)
    for name, v, s, lo, hi in zip(names, values, std, lower, upper):
        assert table["interval"][name] == pytest.approx([max(v - z * s, lo), min(v + z * s, hi)], rel=1e-12)
        assert table["fit_range"][name] == [lo, hi] and table["range"][name] == [lo, hi]
    assert table["interval"]["f"] == pytest.approx([5.0 - z * 0.6, 5.0 + z * 0.6], rel=1e-12)


def test_replicate_count_between_its_floor_and_ceiling_and_the_draws_remade_from_the_seed():
    """The replicate count 40e6 // clusters held within [1000, 2000]: 19,000 poses 2000, 20,001 poses 1999,
    40,001 poses 1000 (the floor); every replicate's counts re-made here from the same seed (each replicate
    draws the rows with rng.integers(0, N, size=(B, N)), counted by np.bincount), and its method's words.
    Seen failing on ``MIN_BOOTSTRAP_REPLICATES = 1000`` turned to 999, ``BOOTSTRAP_REPLICATES = 2000`` turned
    to 2001 and on the draw's ``rng.integers(0, members.size, ...)`` turned to ``rng.integers(1, ...)``."""
    assert PoseBootstrap.draw(19_000, random_state=0, n_replicates=None).n_replicates == 2000
    assert PoseBootstrap.draw(20_001, random_state=0).n_replicates == 40_000_000 // 20_001 == 1999
    assert PoseBootstrap.draw(40_001, random_state=0).n_replicates == 1000
    n, b = 37, 500
    boot = PoseBootstrap.draw(n, n_parts=3, n_replicates=b, random_state=11)
    picked = np.random.default_rng(11).integers(0, n, size=(b, n))
    expected = np.stack([np.bincount(row, minlength=n) for row in picked])
    np.testing.assert_array_equal(boot.counts, expected)
    assert boot.counts.dtype == np.uint8 and boot.n_parts == 3
    np.testing.assert_array_equal(boot.rows_in, np.ones(n))
    np.testing.assert_array_equal(boot.cluster_of, np.arange(n))
    assert boot.method == ("percentile bootstrap, 500 replicates: poses drawn with replacement, every measured frame "
                           "of a pose with it; the held-out errors of the fits on all rows reweighed, not refitted")


def test_sessions_as_strata_below_twenty_and_as_clusters_from_twenty_drawn_as_written_here():
    """19 sessions (one fewer than the 20 a cluster bootstrap wants): the poses drawn within each session, in
    the sessions' order, each stratum drawing as many as it has, re-made here from the seed; 20 sessions:
    the sessions drawn as clusters. Seen failing on ``MIN_SESSION_CLUSTERS = 20`` turned to 19 or 21 and on
    ``n_sessions > 1`` in the words turned to ``> 2``."""
    assert MIN_SESSION_CLUSTERS == 20
    session = np.repeat(np.arange(19), 2)
    b = 50
    strata = PoseBootstrap.draw(38, session_of=session, n_replicates=b, random_state=4)
    rng = np.random.default_rng(4)
    expected = np.zeros((b, 38), dtype=int)
    for s in range(19):
        members = np.flatnonzero(session == s)
        picked = members[rng.integers(0, members.size, size=(b, members.size))]
        for r in range(b):
            expected[r] += np.bincount(picked[r], minlength=38)
    np.testing.assert_array_equal(strata.counts, expected)
    assert "poses drawn with replacement within each of the 19 sessions" in strata.method
    clusters = PoseBootstrap.draw(40, session_of=np.repeat(np.arange(20), 2), n_replicates=b, random_state=4)
    picked = np.random.default_rng(4).integers(0, 20, size=(b, 20))
    np.testing.assert_array_equal(clusters.counts, np.stack([np.bincount(row, minlength=20) for row in picked]))
    assert "(20 sessions as clusters)" in clusters.method
    two = PoseBootstrap.draw(6, session_of=[0, 0, 0, 1, 1, 1], n_replicates=5, random_state=0)
    assert "within each of the 2 sessions" in two.method


def test_replicate_rms_over_many_clusters_read_in_blocks_is_the_weighted_rms():
    """With 2100 poses the replicates are read in blocks of 2e6 // 2100 = 952 (three blocks for 2000): every
    replicate's RMS sqrt(sum w r^2 / sum w / n_parts) written out row by row, the first and last of each block.
    Seen failing on the block's ``self.counts[first:first + step]`` turned to ``first + step + 1`` (a
    replicate's weights read from the next)."""
    n = 2100
    squares = np.random.default_rng(2).gamma(2.0, 1.0, n)
    boot = PoseBootstrap.draw(n, n_parts=2, random_state=5)
    assert boot.n_replicates == 2000
    got = boot.replicate_rms(squares)
    for r in (0, 951, 952, 1903, 1904, 1999):
        w = boot.counts[r].astype(float)
        assert got[r] == pytest.approx(math.sqrt(w @ squares / w.sum() / 2), rel=1e-12)


def test_implausibility_reads_its_own_effects_parameters_after_the_others():
    """An effect after two others in the fit (3 and 2 parameters before it): its values read at offset 5, each
    over the bound on its side; a negative value against its lower bound: (-1/-4, 3/6) -> sqrt((1/16 + 1/4)
    / 2). Seen failing on ``offset += size`` turned to ``offset += size + 1`` and ``-lower`` turned to
    ``lower`` (the bound's sign)."""
    result = {"phi": np.array([9.0, 9.0, 9.0, 7.0, 7.0, -1.0, 3.0]), "scale": np.ones(7),
              "keep": {"frames": np.arange(3), "geometry": np.arange(2), "cyclic": np.array([0, 2])},
              "effects": ["frames", "geometry", "cyclic"]}
    bases = {"cyclic": SimpleNamespace(lower=np.array([-4.0, -1.0, -2.0]), upper=np.array([4.0, 1.0, 6.0]))}
    assert implausibility(result, bases, "cyclic") == pytest.approx(math.sqrt((1 / 16 + 1 / 4) / 2), rel=1e-12)


class _Engine:
    def __init__(self, squares):
        self.squares, self.n_rows = squares, len(squares[("frames",)])

    def evaluate(self, effects):
        return {"heldout_squares": self.squares[tuple(sorted(effects))]}


def test_selection_replays_say_their_progress_every_tenth_and_a_perfect_cut_passes():
    """25 replays say "replay 1, 11, 21 of 25"; an effect that lowers every row's error by the same amount (the
    cut's spread 0: z infinite) is taken in every replay, one that does nothing never. Seen failing on
    ``replay % 10 == 0`` turned to ``% 11`` and ``replay + 1`` turned to ``replay + 2``."""
    n = 8
    base = np.linspace(1.0, 2.0, n)
    squares = {("frames",): base, ("compliance", "frames"): base - 0.5, ("frames", "thermal"): base,
               ("compliance", "frames", "thermal"): base - 0.5}
    said = []
    out = selection_frequency(_Engine(squares), ["compliance", "thermal"], 3.0, 0.05, 25, np.random.default_rng(0),
                              said.append)
    assert said == [f"selection stability: replay {k} of 25" for k in (1, 11, 21)]
    assert out["frequency"] == {"compliance": 1.0, "thermal": 0.0}
    assert out["sets"] == {"frames, compliance": 1.0}


def _strata_draws(n, session, replicates, chunk, seed):
    """The counts of poses drawn within each session, the replicates drawn a block of ``chunk`` at a time
    (every session's draws for a block, then the next block), written out here."""
    rng = np.random.default_rng(seed)
    counts = np.zeros((replicates, n), dtype=int)
    strata = [np.flatnonzero(session == s) for s in np.unique(session)]
    for first in range(0, replicates, chunk):
        b = min(chunk, replicates - first)
        for members in strata:
            picked = members[rng.integers(0, members.size, size=(b, members.size))]
            np.add.at(counts[first:first + b], (np.arange(b)[:, None], picked), 1)
    return counts


@pytest.mark.parametrize("n, replicates", [(41, 97_561), (4000, 1100)])
def test_strata_draw_their_replicates_in_blocks_of_four_million_cells(n, replicates):
    """With sessions as strata the replicates are drawn in blocks of 4e6 // clusters (97,560 for 41 poses,
    1000 for 4000), each block's draws session after session: the counts re-made here block by block from
    the same seed. Seen failing on ``4_000_000`` turned to ``4000001`` (41 poses: one block of 97,561) and to
    ``3999999`` (4000 poses: blocks of 999)."""
    session = np.arange(n) % 2
    boot = PoseBootstrap.draw(n, session_of=session, n_replicates=replicates, random_state=9)
    np.testing.assert_array_equal(boot.counts, _strata_draws(n, session, replicates, 4_000_000 // n, 9))
