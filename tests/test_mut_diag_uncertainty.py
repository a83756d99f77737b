"""How sure the diagnosis is (``diagnosis/uncertainty.py``), each figure against a computation written out
here: the pose bootstrap's replicates re-expanded row by row, its percentile interval by np.quantile, the
parameter intervals with scipy's normal quantile, the joint-function bands with the covariance sandwich
written out, the implausibility by hand, and the selection replays by a forward selection written here on
a stand-in engine. Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.diagnosis.uncertainty import (BOOTSTRAP_REPLICATES, Z95, PoseBootstrap, implausibility,
                                                joint_function_bands, parameter_table, selection_frequency)


def _weights(boot, b):
    """Each row's weight in replicate b: how many times its cluster was drawn."""
    return boot.counts[b].astype(float)[boot.cluster_of]


def test_bootstrap_replicates_are_resamples_of_the_poses_and_their_rms_the_weighted_rms():
    """Poses drawn with replacement (2000 replicates for 40 poses, each replicate 40 draws, every pose
    drawn about once on average with the multinomial's variance 1 - 1/40), each replicate's held-out RMS
    per point sqrt(sum w r^2 / sum w / n_parts) written out row by row, the point sqrt(mean r^2 /
    n_parts), and a paired difference's percentile interval by np.quantile at 2.5 / 97.5 %. Seen failing
    on ``np.sqrt(np.maximum(out, 0.0) / self.n_parts)`` turned to ``* self.n_parts`` and on the
    difference's ``(1.0 + level) / 2.0`` turned to ``(2.0 + level) / 2.0``."""
    rng = np.random.default_rng(0)
    squares = rng.gamma(2.0, 1e-9, size=(40, 2)) * [1.0, 0.7]
    boot = PoseBootstrap.draw(40, n_parts=2, random_state=3)
    assert boot.n_replicates == BOOTSTRAP_REPLICATES == 2000
    assert boot.counts.shape == (2000, 40) and np.all(boot.counts.sum(axis=1) == 40)
    assert boot.counts.mean() == pytest.approx(1.0, rel=1e-12)
    assert np.all(np.abs(boot.counts.mean(axis=0) - 1.0) < 0.12)  # every pose drawn once per replicate on average
    assert boot.counts.astype(float).var(axis=0).mean() == pytest.approx(1 - 1 / 40, rel=0.05)
    assert "2000 replicates: poses drawn with replacement" in boot.method
    replicates = boot.replicate_rms(squares)
    for b in (0, 1, 777, 1999):
        w = _weights(boot, b)
        np.testing.assert_allclose(replicates[b], np.sqrt(w @ squares / w.sum() / 2), rtol=1e-12)
    assert boot.rms(squares[:, 0]) == pytest.approx(math.sqrt(squares[:, 0].mean() / 2), rel=1e-12)
    table = boot.read({"a": squares[:, 0], "b": squares[:, 1]})
    assert table.point["b"] == pytest.approx(math.sqrt(squares[:, 1].mean() / 2), rel=1e-12)
    np.testing.assert_allclose(table.replicates["a"], replicates[:, 0], rtol=1e-12)
    spread = replicates[:, 0] - replicates[:, 1]
    value, low, high = boot.difference(squares[:, 0], squares[:, 1])
    assert value == pytest.approx(math.sqrt(squares[:, 0].mean() / 2) - math.sqrt(squares[:, 1].mean() / 2),
                                  rel=1e-12)
    assert (low, high) == pytest.approx(tuple(np.quantile(spread, [0.025, 0.975])), rel=1e-12)
    assert tuple(table.difference("a", "b", level=0.8))[1:] == pytest.approx(tuple(np.quantile(spread, [0.1, 0.9])),
                                                                      rel=1e-12)
    np.testing.assert_allclose(boot.replicate_rms(squares[:, 1]), replicates[:, 1], rtol=1e-12)


def test_bootstrap_keeps_each_session_whole_or_its_pose_count():
    """Three sessions (fewer than 20): poses drawn within each, so every replicate keeps each session's pose
    count; 25 sessions: whole sessions drawn, 25 per replicate, a row's weight its session's. The
    replicate count for many clusters: 40e6 // clusters within [1000, 2000] (25,000 poses: 1600). Seen
    failing on ``MIN_SESSION_CLUSTERS = 20`` turned to 26 and ``BOOTSTRAP_CELLS = 40_000_000`` turned to
    39_999_999 (the replicate count of a 25,000-pose campaign: 1600 exactly)."""
    session = np.repeat([4, 9, 2], [5, 7, 3])
    boot = PoseBootstrap.draw(15, session_of=session, n_replicates=300, random_state=1)
    for label in (4, 9, 2):
        assert np.all(boot.counts[:, session == label].sum(axis=1) == np.sum(session == label))
    assert "within each of the 3 sessions" in boot.method
    many = np.repeat(np.arange(25), 3)
    clustered = PoseBootstrap.draw(75, session_of=many, n_replicates=400, random_state=2)
    assert clustered.counts.shape == (400, 25) and np.all(clustered.counts.sum(axis=1) == 25)
    np.testing.assert_array_equal(clustered.rows_in, np.full(25, 3.0))
    squares = np.random.default_rng(5).gamma(2.0, 1.0, 75)
    w = clustered.counts[17].astype(float)[many]
    assert clustered.replicate_rms(squares)[17] == pytest.approx(math.sqrt(w @ squares / w.sum()), rel=1e-12)
    assert "25 sessions as clusters" in clustered.method
    assert PoseBootstrap.draw(25_000, random_state=0).n_replicates == 40_000_000 // 25_000 == 1600
    assert PoseBootstrap.draw(50_000, random_state=0, n_replicates=None).n_replicates == 1000


def _result(values, std, lower, upper, at_bound, names, keep, effects, scale=None):
    scale = np.ones(len(values)) if scale is None else np.asarray(scale, dtype=float)
    return {"phi": np.asarray(values, dtype=float) / scale, "phi_std": np.asarray(std, dtype=float) / scale,
            "scale": scale, "lower": np.asarray(lower, dtype=float) / scale,
            "upper": np.asarray(upper, dtype=float) / scale, "at_bound": np.asarray(at_bound),
            "names": np.array(names), "keep": keep, "effects": effects}


def test_parameter_table_intervals_with_scipys_normal_quantile_cut_to_the_fit_range():
    """value +- Phi^-1(0.975) std (scipy), cut to the fit range; the pinned side the nearer bound; the
    fit in scaled units read back in SI. Catches ``max(v - Z95 * s_, lo)`` turned to ``v + Z95 ...`` and
    the scale's ``result["phi"] * result["scale"]`` turned to ``/``."""
    assert Z95 == pytest.approx(stats.norm.ppf(0.975), rel=1e-15)
    result = _result(values=[1e-3, -2e-4, 5e-5], std=[1e-4, 2e-4, 1e-5], lower=[-1.0, -3e-4, 0.0],
                     upper=[1.0, 3e-4, 5e-5], at_bound=[False, False, True], names=["a", "b", "c"],
                     keep={"one": np.array([0]), "two": np.array([0, 1])}, effects=["one", "two"],
                     scale=[1e-3, 1e-4, 1e-5])
    bases = {"one": SimpleNamespace(names=["a"], lower=[-0.5], upper=[0.5]),
             "two": SimpleNamespace(names=["b", "c"], lower=[-1e-3, 0.0], upper=[1e-3, 1e-4])}
    table = parameter_table(result, bases, ["one", "two"])
    z = stats.norm.ppf(0.975)
    assert table["one"]["values"]["a"] == pytest.approx(1e-3, rel=1e-12)
    assert table["one"]["interval"]["a"] == pytest.approx([1e-3 - z * 1e-4, 1e-3 + z * 1e-4], rel=1e-12)
    assert table["one"]["range"]["a"] == [-0.5, 0.5] and table["one"]["fit_range"]["a"] == pytest.approx([-1, 1])
    assert table["two"]["std"]["b"] == pytest.approx(2e-4, rel=1e-12)
    assert table["two"]["interval"]["b"] == pytest.approx([-3e-4, -2e-4 + z * 2e-4], rel=1e-12)
    assert table["two"]["interval"]["c"] == pytest.approx([5e-5 - z * 1e-5, 5e-5], rel=1e-12)
    assert table["two"]["pinned"] == [{"parameter": "c", "bound": "upper"}]
    assert table["one"]["pinned"] == []


class _HarmonicEffect:
    """A function of each joint's own angle: a sin q + b cos q per joint (the cyclic error's first order)."""

    robot = SimpleNamespace(joint_names=["j1", "j2"])

    def joint_basis(self, joint, angles):
        return [f"{joint}_s", f"{joint}_c"], np.column_stack([np.sin(angles), np.cos(angles)])


def test_joint_function_bands_are_the_basis_times_the_parameters_with_the_sandwich_spread():
    """value(q) = B(q) theta per joint over 361 angles from the measured least to the largest; its spread
    sqrt(diag(B C B^T)) with C the parameters' covariance in SI (the scaled one times scale scale^T), or,
    without one, sqrt(B^2 std^2) with unknown (NaN) std read as 0. Catches ``n_points: int = 361`` turned
    to 362 and the covariance's ``np.outer(scale, scale)`` turned to ``np.outer(scale, 1 / scale)`` ...
    (the spread in the wrong units)."""
    q = np.array([[-0.5, 1.0], [0.3, 2.0], [1.2, 1.5]])
    scale = np.array([2.0, 3.0, 0.5, 4.0])
    theta = np.array([1e-4, -2e-4, 5e-5, 3e-5])
    rng = np.random.default_rng(1)
    root = rng.normal(size=(4, 4)) * 1e-5
    cov = root @ root.T
    result = {"phi": theta / scale, "scale": scale, "phi_std": np.sqrt(np.diag(cov)) / scale,
              "phi_cov": cov / np.outer(scale, scale), "names": ["j1_s", "j1_c", "j2_s", "j2_c"]}
    bases = {"cyclic": SimpleNamespace(per_part=[SimpleNamespace(effect=_HarmonicEffect())]),
             "geometry": SimpleNamespace(per_part=[SimpleNamespace(effect=object())])}
    bands = joint_function_bands(result, bases, ["geometry", "cyclic"], q)
    assert list(bands) == ["cyclic"]
    for j, joint in enumerate(["j1", "j2"]):
        angles = np.linspace(q[:, j].min(), q[:, j].max(), 361)
        b = np.column_stack([np.sin(angles), np.cos(angles)])
        rows = slice(2 * j, 2 * j + 2)
        band = bands["cyclic"][joint]
        np.testing.assert_allclose(band["angle_rad"], angles, rtol=1e-15)
        np.testing.assert_allclose(band["value_rad"], b @ theta[rows], rtol=1e-12)
        np.testing.assert_allclose(band["std_rad"], np.sqrt(np.einsum("mi,ij,mj->m", b, cov[rows, rows], b)),
                                   rtol=1e-10)
    del result["phi_cov"]
    result["phi_std"] = np.array([1e-5, np.nan, 2e-5, 1e-5]) / scale
    bands = joint_function_bands(result, bases, ["cyclic"], q)
    angles = np.linspace(-0.5, 1.2, 361)
    np.testing.assert_allclose(bands["cyclic"]["j1"]["std_rad"], np.abs(np.sin(angles)) * 1e-5, rtol=1e-12)


def test_implausibility_is_the_rms_of_value_over_its_sides_bound():
    """RMS over an effect's kept parameters of value / bound, the bound on the value's side (or the
    other side's where the physics allows one sign only), by hand: values 2, -1, 3 against [-4, 8],
    [-2, 8], [0, 6] give (2/8, -1/-2... ) -> sqrt((0.25^2 + 0.5^2 + 0.5^2) / 3); an effect without finite
    bounds 0. Catches ``np.where(values >= 0, upper, -lower)`` turned to ``lower`` and ``** 2`` turned to
    ``** 3``."""
    result = _result(values=[7.0, 2.0, -1.0, 3.0, 9.0], std=np.ones(5), lower=-np.ones(5), upper=np.ones(5),
                     at_bound=np.zeros(5, bool), names=list("vabcd"),
                     keep={"frames": np.array([0]), "cyclic": np.array([0, 1, 2]), "free": np.array([0])},
                     effects=["frames", "cyclic", "free"])
    bases = {"cyclic": SimpleNamespace(lower=np.array([-4.0, -2.0, 0.0, -1.0]), upper=np.array([8.0, 8.0, 6.0, 1.0])),
             "free": SimpleNamespace(lower=np.array([-np.inf]), upper=np.array([np.inf]))}
    assert implausibility(result, bases, "cyclic") == pytest.approx(math.sqrt((0.25**2 + 0.5**2 + 0.5**2) / 3),
                                                                     rel=1e-12)
    assert implausibility(result, bases, "free") == 0.0
    assert implausibility(result, {**bases, "thermal": bases["free"]}, "thermal") == 0.0  # not in the fit
    # a negative value where the physics allows only positive ones: against the upper bound
    one_sided = _result(values=[-3.0], std=[1.0], lower=[-1.0], upper=[1.0], at_bound=[False], names=["a"],
                        keep={"cyclic": np.array([0])}, effects=["cyclic"])
    assert implausibility(one_sided, {"cyclic": SimpleNamespace(lower=np.array([0.0]), upper=np.array([6.0]))},
                          "cyclic") == pytest.approx(0.5, rel=1e-12)


class _Engine:
    """A stand-in fit engine: each model's per-row held-out squared errors are fixed arrays."""

    def __init__(self, squares):
        self.squares = squares
        self.n_rows = len(next(iter(squares.values())))

    def evaluate(self, effects):
        return {"heldout_squares": self.squares[tuple(sorted(effects))]}


def test_selection_replays_are_forward_selections_on_resampled_rows_written_here():
    """Each replay draws the rows (rng.integers, the seed shared) and adds the effect whose mean held-out
    square is least while the paired z of the cut (mean / (sd / sqrt n), ddof 1) exceeds the threshold and
    the RMS falls by more than the relative gain; ``late`` effects offered after the others. Written here
    and compared replay by replay on a stand-in engine whose gains sit near the thresholds. Seen failing
    on the z's ``d.std(ddof=1)`` turned to ``ddof=2`` and ``(1.0 - min_relative_gain)`` turned to
    ``(2.0 - ...)``."""
    rng = np.random.default_rng(4)
    n = 12  # few rows: a z's ddof moves it by 4 %, which moves some replays' decisions
    base = rng.gamma(2.0, 1.0, n) + 1.0
    a, b, c = "compliance", "cyclic", "thermal"
    squares = {("frames",): base,
               (a, "frames"): base - 0.45 + rng.normal(0, 1.0, n),
               (b, "frames"): base - 0.3 + rng.normal(0, 1.0, n),
               (c, "frames"): base - 0.3 + rng.normal(0, 0.3, n)}
    squares[(a, b, "frames")] = squares[(a, "frames")] - 0.3 + rng.normal(0, 0.8, n)
    squares[(a, c, "frames")] = squares[(a, "frames")] - 0.3 + rng.normal(0, 0.8, n)
    squares[(b, c, "frames")] = squares[(c, "frames")] - 0.3 + rng.normal(0, 0.8, n)
    squares[(a, b, c, "frames")] = squares[(a, c, "frames")] - 0.25 + rng.normal(0, 0.8, n)
    squares = {tuple(sorted(k)): np.maximum(v, 0.01) for k, v in squares.items()}
    engine = _Engine(squares)
    z_limit, relative = 2.0, 0.05

    def forward(rows, current, pool):
        pool = list(pool)
        while pool:
            prev = squares[tuple(sorted(current))][rows]
            trials = {e: squares[tuple(sorted(current + [e]))][rows] for e in pool}
            best = min(trials, key=lambda e: trials[e].mean())
            d = prev - trials[best]
            z = d.mean() / (d.std(ddof=1) / np.sqrt(d.size))
            if not (z > z_limit and np.sqrt(trials[best].mean()) < np.sqrt(prev.mean()) * (1 - relative)):
                return
            current.append(best)
            pool.remove(best)

    out = selection_frequency(engine, [a, b, c], z_limit, relative, 100, np.random.default_rng(9), late=(c,))
    draws = np.random.default_rng(9)
    counts, sets = {a: 0, b: 0, c: 0}, {}
    for _ in range(100):
        rows = draws.integers(0, n, n)
        current = ["frames"]
        forward(rows, current, [a, b])
        forward(rows, current, [c])
        for e in current[1:]:
            counts[e] += 1
        key = ", ".join(e for e in ("frames", a, c, b) if e in current)  # the vocabulary's order
        sets[key] = sets.get(key, 0) + 1
    assert out["frequency"] == pytest.approx({e: k / 100 for e, k in counts.items()}, abs=1e-12)
    assert out["sets"] == pytest.approx({k: v / 100 for k, v in sets.items()}, abs=1e-12)
    assert out["n_replays"] == 100
    assert all(0 < k < 100 for k in counts.values()) and len(sets) >= 3  # the thresholds decide differently on different replays
