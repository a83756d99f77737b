"""``diagnosis/identifiability.py``'s report against columns built here with known independent motions:
orthonormal directions u_i (numpy's QR of a random matrix) make each column's own motion, what it
duplicates and its TCP motion closed forms; the condition number is numpy's SVD of the kept unit columns.
Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.identifiability import compressed, gram_factor, identifiability

N_POSES = 10


def _bases(scales_a=(2.0, 0.5, 1.0), scales_b=(1.0, 4.0, 1.0, 0.25)):
    """Effect a: three independent, non-orthogonal columns. Effect b: b1 = 0.5 a1 + 0.25 a2 + 0.1 a3 (an
    exact linear combination: 0.82, 0.21 and 0.04 of the unit columns), b2 = a3's direction at 1 mm plus
    2 um of its own (u5), b3 = nothing, b4 = 3 mm of a direction of its own (u4). Columns in metres of TCP
    motion at the typical size (g * scales)."""
    u = np.linalg.qr(np.random.default_rng(0).standard_normal((3 * N_POSES, 6)))[0].T  # orthonormal rows
    a = np.stack([2e-3 * u[0], 1e-3 * (0.6 * u[0] + 0.8 * u[1]),
                  5e-4 * (0.3 * u[0] + 0.4 * u[1] + np.sqrt(0.75) * u[2])], axis=1)
    b = np.stack([0.5 * a[:, 0] + 0.25 * a[:, 1] + 0.1 * a[:, 2],
                  1e-3 * a[:, 2] / np.linalg.norm(a[:, 2]) + 2e-6 * u[4], np.zeros(3 * N_POSES), 3e-3 * u[3]], axis=1)

    def block(columns, names, scales):
        scales = np.asarray(scales)
        return SimpleNamespace(names=names, g=(columns / scales).reshape(N_POSES, 3, -1), scales=scales,
                               n_poses=N_POSES)

    return {"a": block(a, ["a1", "a2", "a3"], scales_a), "b": block(b, ["b1", "b2", "b3", "b4"], scales_b)}, a, b


def test_the_report_says_what_each_dropped_column_duplicates_and_its_own_motion_in_um():
    """At 5 um RMS: a keeps its three columns, b its fourth; b1 is a linear combination of a1, a2, a3
    (largest coefficient first: a coefficient of 0.04 is named); b2's own motion 2 um / sqrt(10) of its
    sqrt(1 mm^2 + 2 um^2) / sqrt(10), both in um, the rest a3's; b3 does not move; the rank, the
    threshold in mm, the condition number and smallest singular value of the kept unit columns by numpy's
    SVD. Seen failing on ``free * 1e6`` turned to ``1e5``, on ``abs(coef[t]) > 1e-2`` turned to
    ``1e-1``, on ``motion * 1e6`` turned to ``1e7``, on ``norms[k] / math.sqrt(n_pose)`` turned to ``*
    math.sqrt``, on ``* 1e3`` of ``min_motion_mm`` turned to ``1e4``, on ``sv[0] / sv[-1]`` turned to
    ``sv[1]`` and on ``free < 1e-3 * motion`` turned to ``1e-2``."""
    bases, a, b = _bases()
    keep, report = identifiability(bases, ["a", "b"], 1e-6, 5e-6)
    assert keep["a"].tolist() == [0, 1, 2] and keep["b"].tolist() == [3]
    assert report["min_motion_mm"] == pytest.approx(5e-3, rel=1e-12) and report["rank_tol"] == 1e-6
    effect = report["effects"]["b"]
    assert (effect["n_parameters"], effect["n_identifiable"]) == (4, 1)
    removed = {r["parameter"]: r for r in effect["removed"]}
    assert list(removed) == ["b1", "b2", "b3"]
    assert removed["b1"]["reason"] == "linear combination of a1, a2, a3"
    assert removed["b1"]["duplicates"] == ["a1", "a2", "a3"]
    own, motion = 2e-6 / math.sqrt(N_POSES), math.hypot(1e-3, 2e-6) / math.sqrt(N_POSES)
    assert removed["b2"]["reason"] == (f"only {own * 1e6:.3g} um RMS of its {motion * 1e6:.3g} um TCP motion (at its "
                                       "typical size) is its own: below what the measurements resolve; the rest "
                                       "duplicates a3")
    assert removed["b3"] == {"parameter": "b3", "reason": "does not move the TCP position", "duplicates": []}
    kept = np.concatenate([a, b[:, 3:]], axis=1)
    sv = np.linalg.svd(kept / np.linalg.norm(kept, axis=0), compute_uv=False)
    assert report["rank"] == 4
    assert report["condition_number"] == pytest.approx(sv[0] / sv[-1], rel=1e-9)
    assert report["smallest_singular_value"] == pytest.approx(sv[-1], rel=1e-9)
    assert report["condition_number"] > 2.0  # the kept columns are far from orthogonal: a figure to get right


def test_a_column_is_kept_by_its_own_motion_against_the_threshold_and_the_rank_tolerance():
    """b2's own motion is 0.632 um RMS, 2e-3 of its TCP motion: kept at a threshold of 0.6 um and not at
    0.7 um; kept at rank_tol 1.9e-3 and not at 2.1e-3 (no threshold); the same columns whatever the
    typical sizes the columns are given at, without the report, and from the compressed columns or a
    factor of their Gram matrix. Seen failing on ``diag[k] / math.sqrt(n_pose) > threshold`` turned to
    ``* math.sqrt`` and on ``rank_tol * norms[col]`` turned to ``rank_tol / norms[col]``."""
    own = 2e-6 / math.sqrt(N_POSES)
    for threshold, rank_tol, kept_b in ((0.95 * own, 1e-6, [1, 3]), (1.05 * own, 1e-6, [3]),
                                        (0.0, 1.9e-3, [1, 3]), (0.0, 2.1e-3, [3])):
        for scales in (((2.0, 0.5, 1.0), (1.0, 4.0, 1.0, 0.25)), ((1.0,) * 3, (1.0,) * 4)):
            bases, a, b = _bases(*scales)
            keep, _ = identifiability(bases, ["a", "b"], rank_tol, threshold)
            assert keep["a"].tolist() == [0, 1, 2] and keep["b"].tolist() == kept_b, (threshold, rank_tol)
            quick, _ = identifiability(bases, ["a", "b"], rank_tol, {"a": 0.0, "b": threshold}, report=False)
            assert quick["b"].tolist() == kept_b
            folded, _ = identifiability(compressed(bases), ["a", "b"], rank_tol, threshold)
            assert folded["b"].tolist() == kept_b
        columns = np.concatenate([a, b], axis=1)
        factor = gram_factor(columns.T @ columns, {"a": (["a1", "a2", "a3"], np.arange(3)),
                                                   "b": (["b1", "b2", "b3", "b4"], np.arange(3, 7))}, N_POSES)
        assert identifiability(factor, ["a", "b"], rank_tol, threshold)[0]["b"].tolist() == kept_b
