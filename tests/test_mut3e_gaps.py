"""Gaps the last measuring sample found in ``frames/``, ``effects/`` and ``iso9283/``, each pinned
against a computation written out here: the tracker drift's default significance threshold at a z
computed by numpy's lstsq, one fixed-point step with no context given, a pose test whose file
has a load column and no speed column evaluated against clause 7.2's formulas, and an instrument's
description word for word. Each test names a planted change it was seen to catch.
"""

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest

import tcr_accuracy as tcr
from tcr_accuracy.effects import make_effect
from tcr_accuracy.effects.compose import fixed_point_motion
from tcr_accuracy.frames.drift import tracker_drift
from tcr_accuracy.frames.instrument import Instrument
from tcr_accuracy.iso9283.evaluate import condition_blocks, evaluate_conditions

UM, MM = 1e-6, 1e-3


def _drift_at_z(z_wanted, rows=30, seed=5):
    """Two still base references read over ``rows`` rows (no times: the measurement order), their
    noise's own fitted slope taken off, then a drift added whose z (|v| over its standard error
    sigma / sqrt(sum (t - mean t)^2), sigma from the residuals over 3 (readings - references - 1)
    dof, written out here) is exactly ``z_wanted``."""
    rng = np.random.default_rng(seed)
    order = np.arange(rows, dtype=float)
    centred = order - order.mean()
    noise = [rng.normal(0, 5 * UM, (rows, 3)) for _ in range(2)]
    slope = sum(centred @ (y - y.mean(axis=0)) for y in noise) / (2 * centred @ centred)
    noise = [y - np.outer(centred, slope) for y in noise]  # no slope left: the residuals are the noise
    ssr = sum(float(np.sum((y - y.mean(axis=0)) ** 2)) for y in noise)
    sigma = math.sqrt(ssr / (3 * (2 * rows - 2 - 1)))
    std = sigma / math.sqrt(2 * centred @ centred)
    direction = np.array([2.0, -1.0, 2.0]) / 3.0
    velocity = z_wanted * std * direction
    refs = [(name, p, np.asarray(p) + y + np.outer(order, velocity), None)
            for name, p, y in (("ref_a", [0.8, -0.3, 0.0], noise[0]), ("ref_b", [-0.4, 0.9, 0.05], noise[1]))]
    return refs, velocity, sigma


@pytest.mark.parametrize("z_wanted, corrected", [(3.55, True), (3.45, False), (4.2, True)])
def test_the_drift_is_corrected_past_three_and_a_half_standard_errors_by_default(z_wanted, corrected):
    """A drift along the measurement order at z = 3.45, 3.55 and 4.2 (computed here, the distance moved
    over the session above the scatter): corrected past the default ``min_z`` 3.5 only, the
    correction (t - mean t) v. Seen failing on the default ``min_z: float = 3.5`` as 4.5 (z = 4.2 not
    corrected) and as 2.5 (z = 3.45 corrected)."""
    refs, velocity, sigma = _drift_at_z(z_wanted)
    correction, report, _ = tracker_drift(refs, np.zeros(30, dtype=int), 1, [])
    got = report[0]
    assert got["z"] == pytest.approx(z_wanted, rel=1e-9)
    assert got["moved_over_session_mm"] == pytest.approx(np.linalg.norm(velocity) * 29 * 1e3, rel=1e-9)
    assert got["moved_over_session_mm"] > sigma * 1e3  # the other condition holds: z decides
    assert got["corrected"] is corrected
    order = np.arange(30.0)
    expected = np.outer(order - order.mean(), velocity) if corrected else np.zeros((30, 3))
    np.testing.assert_allclose(correction, expected, atol=1e-15)


def test_one_fixed_point_step_with_no_context_takes_the_defaults_for_its_own_rows():
    """Five poses of the six-joint UR5, compliances 20 x typical and no context given: the TCP moves
    between q + dq1 and q + dq2 (dq = c x -(Pinocchio's generalized gravity), the second at q + dq1)
    as Pinocchio says. Seen failing on ``_as_context(context, q.shape[0], ...)`` as ``q.shape[1]``
    (a default context of 6 rows for 5 poses)."""
    robot = tcr.load_robot("ur5")
    rng = np.random.default_rng(11)
    q = rng.uniform(-1.5, 1.5, (5, 6))
    effect = make_effect("compliance", robot)
    c = 20 * effect.parameter_scales()
    model, data = robot.model, robot.model.createData()

    def sag(joints):
        return np.array([-c * pin.computeGeneralizedGravity(model, data, robot.to_pinocchio_q(row)) for row in joints])

    def tcp(joints):
        return tcr.tcp_poses(robot, joints).position

    expected = tcp(q + sag(q + sag(q))) - tcp(q + sag(q))
    got = fixed_point_motion(robot, [effect], [c], q)
    np.testing.assert_allclose(got, expected, atol=1e-13)
    assert np.abs(expected).max() > 1e-7


def test_a_pose_test_with_a_load_column_and_no_speed_column_gives_each_load_its_figures():
    """The UR5 cube, 3 cycles at 100 % load then 3 at 40 %, a ``load_pct`` column and none for the
    speed, read in the base frame with a known error per pose and load and 20 um of noise: two
    blocks (100 % first, its words naming only the load), each pose's AP_P, AP_xyz and RP_l equal
    clause 7.2's barycentre and l-bar + 3 S_l written out here. Seen failing on ``[None] *
    len(mset)`` as ``[None] // len(mset)`` (no file without a speed column could be read)."""
    robot = tcr.load_robot("ur5")
    plan = tcr.plan_iso_cube(robot, random_state=0, centre=[-0.13, -0.44, 0.32], size=0.2)
    series = plan.series(cycles=3)
    n = len(series)
    both = series.subset(np.concatenate([np.arange(n), np.arange(n)]))
    pose_id = both.annotations["pose_id"]
    load = np.r_[np.full(n, 40.0), np.full(n, 100.0)]  # the light block first in the file
    labels = {k: v for k, v in both.annotations.items() if k not in ("load_pct", "speed_pct")}
    labels["load_pct"] = load
    rng = np.random.default_rng(29)
    error = {(p, w): rng.normal(0, 0.7 * MM, 3) for p in set(pose_id) for w in (40.0, 100.0)}
    nominal = tcr.tcp_poses(robot, both.q).position
    base = nominal + np.array([error[p, w] for p, w in zip(pose_id, load)]) + rng.normal(0, 0.02 * MM, (2 * n, 3))
    mset = dataclasses.replace(both, position=base, annotations=labels)
    blocks = condition_blocks(mset)
    assert [(b.load_pct, b.speed_pct, b.rows.tolist()) for b in blocks] == [
        (100.0, None, list(range(n, 2 * n))), (40.0, None, list(range(n)))]
    assert [b.words() for b in blocks] == ["100 % rated load", "40 % rated load"]
    results = evaluate_conditions(robot, mset, frame="base")
    for (block, result), w in zip(results, (100.0, 40.0)):
        assert block.load_pct == w
        for f in result.figures.poses:
            rows = (pose_id == f.pose_id) & (load == w)
            bar = base[rows].mean(axis=0)
            ap_xyz = bar - nominal[rows][0]
            distance = np.linalg.norm(base[rows] - bar, axis=1)
            assert f.n == 3
            assert f.ap == pytest.approx(math.sqrt(ap_xyz @ ap_xyz), abs=1e-12)
            np.testing.assert_allclose(f.ap_xyz, ap_xyz, atol=1e-12)
            assert f.rp == pytest.approx(distance.mean() + 3 * distance.std(ddof=1), abs=1e-12)


def test_an_instrument_of_one_micrometre_is_described_in_whole_micrometres():
    """An instrument of MPE 1 um + 1 um/m both along and across the beam: described word for word
    with "1 um" four times, its dict in um. Seen failing on the description's ``ta * 1e6`` as ``ta *
    999999.0`` (0.999999 um printed), and the same of ``ra``, ``rb`` and ``tb``."""
    spec = Instrument("unit", (1e-6, 1e-6), (1e-6, 1e-6), "a test")
    assert spec.describe() == "unit: MPE 1 um + 1 um/m along the beam, 1 um + 1 um/m across it (a test)"
    assert Instrument("bare", (2e-6, 3e-6), (1e-6, 5e-6)).describe() == (
        "bare: MPE 2 um + 3 um/m along the beam, 1 um + 5 um/m across it")
    assert spec.to_dict() == {"name": "unit", "radial_mpe_um": [1.0, 1.0], "transverse_mpe_um": [1.0, 1.0],
                              "mpe_units": "um + um/m x distance", "source": "a test"}


def test_a_point_sets_distance_is_from_the_origin_and_a_contribution_in_mm_by_default():
    """Four points: with no origin given, the distance's RMS is sqrt(mean |p|^2), its bounds the nearest
    point of the box and its farthest corner from (0, 0, 0), written out here; a contribution's dict
    with no scale is in mm. Seen failing on the default ``origin=(0.0, 0.0, 0.0)`` with any of its
    zeros as 1.0 and on the default ``scale: float = 1e3`` as 1001.0."""
    from tcr_accuracy.frames.uncertainty_budget import Contribution, PointSet

    points = np.array([[0.4, 0.3, 0.2], [0.6, 0.1, 0.5], [0.5, 0.7, 0.3], [0.45, 0.2, 0.9]])
    rms, least, largest = PointSet.of(points).distance()
    assert rms == pytest.approx(math.sqrt(np.mean(np.sum(points ** 2, axis=1))), rel=1e-12)
    lo, hi = points.min(axis=0), points.max(axis=0)
    assert least == pytest.approx(np.linalg.norm(lo), rel=1e-12)  # the box lies in the positive octant
    assert largest == pytest.approx(np.linalg.norm(hi), rel=1e-12)
    doc = Contribution("instrument MPE", 12e-6, "spec").to_dict()
    assert doc == {"source": "instrument MPE", "standard_uncertainty": pytest.approx(0.012, rel=1e-12),
                   "how": "spec", "evaluation": "B"}
