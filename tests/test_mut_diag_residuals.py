"""Where a residual lies and how noisy the measurements are (``diagnosis/residuals.py``), each figure
against a computation written out here on raw numpy / scipy: per-axis statistics, octants about the
median, quantile bins, Pearson correlations (scipy.stats), approach-direction differences, k-NN shares
along each joint by brute-force distances, and the pooled scatter of repeated poses. Each test names a
planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.diagnosis.residuals import noise_from_repeats, noise_from_residual, where_analysis
from tcr_accuracy.exceptions import InputError


def _bins_by_hand(values, residual, n_bins=5):
    """Quantile bins [edge_b, edge_b+1) (the last closed), or one bin per level for few distinct values:
    (low, high, count, mean [mm], RMS norm [mm]) each, and the spread: the norm of the per-axis range of
    the bins' means [mm]."""
    levels = np.unique(values)
    if levels.size <= n_bins:
        groups = [(v, v, values == v) for v in levels]
    else:
        edges = np.unique(np.quantile(values, np.linspace(0, 1, n_bins + 1)))
        groups = [(edges[b], edges[b + 1], (values >= edges[b]) & ((values < edges[b + 1]) if b < edges.size - 2
                                                                    else (values <= edges[b + 1])))
                  for b in range(edges.size - 1)]
    rows = [(lo, hi, int(sel.sum()), residual[sel].mean(axis=0) * 1e3,
             np.sqrt(np.mean(np.sum(residual[sel] ** 2, axis=1))) * 1e3) for lo, hi, sel in groups if sel.any()]
    means = np.array([r[3] for r in rows])
    return rows, float(np.linalg.norm(means.max(axis=0) - means.min(axis=0)))


def _check_bins(out, values, residual):
    rows, spread = _bins_by_hand(values, residual)
    assert len(out["bins"]) == len(rows)
    for got, (lo, hi, count, mean, rms) in zip(out["bins"], rows):
        assert (got["low"], got["high"], got["count"]) == (pytest.approx(lo), pytest.approx(hi), count)
        assert got["mean_mm"] == pytest.approx(mean.tolist(), rel=1e-9)
        assert got["rms_mm"] == pytest.approx(rms, rel=1e-9)
    assert out["spread_mm"] == pytest.approx(spread, rel=1e-9)


def _knn_share(points, centred, k=10):
    d = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    np.fill_diagonal(d, np.inf)
    neighbours = np.argsort(d, axis=1)[:, :k]
    return 1.0 - np.sum((centred - centred[neighbours].mean(axis=1)) ** 2) / np.sum(centred**2)


def test_where_analysis_against_numpy_and_scipy_written_out():
    """80 poses of a three-joint robot (the third prismatic): per-axis mean, RMS and largest |error| in
    mm; the octants about the median nominal position (count, mean and RMS of the error's norm); quantile
    bins of the radius, the height, each joint, each loaded joint's gravity torque, the temperature, and
    one bin per payload level; Pearson correlations (scipy.stats.pearsonr); the mean error with each
    joint approached from above minus from below; the share the 10 nearest poses along each joint and
    each pair (standardised) predict; the joints it varies along (share > 0.05, largest first, at most
    three); and the short-lag semivariance (the count-weighted mean over the lags in the lowest quarter).
    Seen failing on ``octant ... @ np.array([4, 2, 1])`` turned to ``[4, 2, 2]``, on the bins'
    ``np.linspace(0, 1, n_bins + 1)`` turned to ``n_bins + 2``, on ``> 0.05`` turned to ``> 1.05`` and
    on ``s.lags <= np.quantile(s.lags, 0.25)`` turned to ``1.25``."""
    rng = np.random.default_rng(3)
    n = 80
    q = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-1, 1, n), rng.uniform(0.0, 0.4, n)])
    nominal = rng.normal(size=(n, 3)) * [0.5, 0.4, 0.3] + [0.2, 0.0, 0.8]
    residual = np.column_stack([np.sin(2 * q[:, 0]), q[:, 2] * 8, np.cos(q[:, 1])]) * 1e-4
    residual += rng.normal(0, 3e-5, (n, 3))
    tau = np.column_stack([rng.normal(size=n) * 20, np.full(n, 5.0), rng.normal(size=n)])
    context = {"payload_kg": np.where(np.arange(n) % 3 == 0, 5.0, 0.0),
               "temperature_c": rng.uniform(18, 26, n),
               "direction": np.column_stack([np.where(np.arange(n) % 2, 1.0, -1.0), np.ones(n),
                                             np.where(np.arange(n) % 4 == 0, -1.0, 1.0)])}
    robot = SimpleNamespace(joint_names=["a", "b", "c"], joint_kinds=["revolute", "revolute", "prismatic"])
    where, semis = where_analysis(robot, q, nominal, residual, tau, context, rng=np.random.default_rng(0))
    norm = np.linalg.norm(residual, axis=1)
    for c, axis in enumerate("xyz"):
        assert where["per_axis"][axis] == pytest.approx(
            {"mean_mm": residual[:, c].mean() * 1e3, "rms_mm": np.sqrt(np.mean(residual[:, c] ** 2)) * 1e3,
             "max_abs_mm": np.abs(residual[:, c]).max() * 1e3}, rel=1e-12)
    centre = np.median(nominal, axis=0)
    assert where["octants"]["centre_m"] == pytest.approx(centre.tolist(), rel=1e-12)
    regions = {}
    for i in range(n):
        label = "".join(("+" if nominal[i, c] > centre[c] else "-") + "xyz"[c] for c in range(3))
        regions.setdefault(label, []).append(norm[i])
    got = {r["region"]: r for r in where["octants"]["regions"]}
    assert set(got) == set(regions)
    for label, norms in regions.items():
        assert got[label]["count"] == len(norms)
        assert got[label]["mean_mm"] == pytest.approx(np.mean(norms) * 1e3, rel=1e-12)
        assert got[label]["rms_mm"] == pytest.approx(np.sqrt(np.mean(np.square(norms))) * 1e3, rel=1e-12)
    _check_bins(where["radius"], np.hypot(nominal[:, 0], nominal[:, 1]), residual)
    _check_bins(where["height"], nominal[:, 2], residual)
    for j, name in enumerate("abc"):
        joint = where["joints"][name]
        assert joint["unit"] == ("m" if name == "c" else "rad")
        _check_bins(joint, q[:, j], residual)
        assert joint["correlation_xyz"] == pytest.approx([stats.pearsonr(q[:, j], residual[:, c])[0]
                                                          for c in range(3)], rel=1e-9)
    assert where["gravity_torque"]["b"] == {"loaded": False}
    for j in (0, 2):
        _check_bins(where["gravity_torque"]["abc"[j]], tau[:, j], residual)
    _check_bins(where["temperature_c"], context["temperature_c"], residual)
    _check_bins(where["payload_kg"], context["payload_kg"], residual)
    assert len(where["payload_kg"]["bins"]) == 2
    assert where["payload_kg"]["correlation_xyz"] == pytest.approx(
        [stats.pearsonr(context["payload_kg"], residual[:, c])[0] for c in range(3)], rel=1e-9)
    assert set(where["approach_direction"]) == {"a", "c"}
    for j, name in ((0, "a"), (2, "c")):
        d = context["direction"][:, j]
        diff = residual[d > 0].mean(axis=0) - residual[d < 0].mean(axis=0)
        row = where["approach_direction"][name]
        assert (row["count_plus"], row["count_minus"]) == (int(np.sum(d > 0)), int(np.sum(d < 0)))
        assert row["mean_plus_minus_minus_mm"] == pytest.approx((diff * 1e3).tolist(), rel=1e-12)
        assert row["difference_norm_mm"] == pytest.approx(np.linalg.norm(diff) * 1e3, rel=1e-12)
    centred = residual - residual.mean(axis=0)
    shares = {name: _knn_share(q[:, [j]], centred) for j, name in enumerate("abc")}
    for j, name in enumerate("abc"):
        along = where["along_joints"][name]
        assert along["knn_explained_share"] == pytest.approx(shares[name], rel=1e-9)
        s = semis[j]
        short = s.lags <= np.quantile(s.lags, 0.25)
        expected = [np.sum(s.semivariance[short, c] * s.counts[short]) / np.sum(s.counts[short]) for c in range(3)]
        assert along["short_lag_semivariance_xyz"] == pytest.approx(expected, rel=1e-12)
    assert where["varies_along"] == [k for k in sorted(shares, key=lambda k: -shares[k]) if shares[k] > 0.05][:3]
    assert len(where["varies_along"]) >= 2
    qs = (q - q.mean(axis=0)) / q.std(axis=0)
    pairs = {tuple(p["joints"]): p["knn_explained_share"] for p in where["along_joint_pairs"]}
    for a, b in ((0, 1), (0, 2), (1, 2)):
        assert pairs["abc"[a], "abc"[b]] == pytest.approx(_knn_share(qs[:, [a, b]], centred), rel=1e-9)
    ranked = [p["knn_explained_share"] for p in where["along_joint_pairs"]]
    assert ranked == sorted(ranked, reverse=True)


def test_pooled_scatter_of_repeated_poses_by_hand():
    """Four poses read 3, 2, 4 and 1 times (the last not a repeat; a fifth pose differs only in its context
    column, so its two readings are separate poses read once): sigma^2 = the sum of squared deviations from
    each pose's mean over 3 x (9 - 3) = 18 degrees of freedom; with fewer than ``min_dof`` None; readings
    that agree to the last digit an input error (it was not: the mean of three equal numbers can differ
    from them in the last bit, and sigma came out 1e-17 m instead of 0, fixed). Catches ``dof = 3 * (repeated.size - groups)`` turned to
    ``4 * ...`` and ``counts[inverse] > 1`` turned to ``> 2``."""
    rng = np.random.default_rng(6)
    poses = rng.uniform(-1, 1, size=(5, 4))
    reads = [3, 2, 4, 1]
    q = np.concatenate([np.repeat(poses[:4], reads, axis=0), np.repeat(poses[4:], 2, axis=0)])
    context = np.concatenate([np.zeros((10, 1)), [[0.0], [5.0]]])
    truth = rng.normal(size=(5, 3))
    position = np.concatenate([np.repeat(truth[:4], reads, axis=0), np.repeat(truth[4:], 2, axis=0)])
    position = position + rng.normal(0, 2e-5, position.shape)
    estimate = noise_from_repeats(q, position, context)
    sq, start = 0.0, 0
    for count in reads:
        block = position[start:start + count]
        sq += np.sum((block - block.mean(axis=0)) ** 2)
        start += count
    assert estimate.per_axis == pytest.approx(math.sqrt(sq / 18), rel=1e-12)
    assert estimate.source == "repeated poses" and estimate.independent
    assert "9 readings of 3 repeated poses (18 dof)" in estimate.detail
    assert noise_from_repeats(q, position, context, min_dof=19) is None
    assert noise_from_repeats(q, position, context, min_dof=18) is not None
    # without the context column the fifth pose is read twice too: 4 repeated poses, 11 readings, 21 dof
    both = noise_from_repeats(q, position)
    last = position[10:]
    assert both.per_axis == pytest.approx(math.sqrt((sq + np.sum((last - last.mean(axis=0)) ** 2)) / 21), rel=1e-12)
    copies = position.copy()
    copies[1:3] = copies[0]
    copies[3:5] = copies[3]
    copies[5:9] = copies[5]
    copies[10:] = copies[10]
    with pytest.raises(InputError, match="agree to the last digit"):
        noise_from_repeats(q, copies)


def test_noise_from_a_residual_without_and_with_structure():
    """Without structure: sqrt(RSS / (3N - p)). With structure, the semivariogram's nugget: a smooth leftover
    of 0.2 mm plus white noise of 0.02 mm per axis on 300 poses gives about the 0.02 mm (within 30 %),
    far below the whole residual's RSS figure, and never above it. Catches ``dof = max(residual.size -
    n_parameters, 1)`` turned to ``+`` and the cap ``min(..., sigma_rss)`` fed ``nugget`` unrooted."""
    rng = np.random.default_rng(8)
    q = rng.uniform(-2, 2, size=(300, 2))
    noise = rng.normal(0, 2e-5, (300, 3))
    plain = noise_from_residual(q, noise, 12, structured=False)
    assert plain.per_axis == pytest.approx(math.sqrt(np.sum(noise**2) / (900 - 12)), rel=1e-12)
    assert plain.source == "residual" and not plain.independent and "888 dof" in plain.detail
    smooth = np.column_stack([np.sin(q[:, 0]), np.cos(q[:, 1]), np.sin(q[:, 0] + q[:, 1])]) * 2e-4
    structured = noise_from_residual(q, smooth + noise, 12, structured=True)
    assert structured.source == "residual nugget"
    assert structured.per_axis == pytest.approx(2e-5, rel=0.3)
    assert structured.per_axis <= math.sqrt(np.sum((smooth + noise) ** 2) / 888)
