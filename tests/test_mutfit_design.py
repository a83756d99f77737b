"""``diagnosis/design.py``'s greedy designs against the greedy written out here on the design columns:
D-optimal picks as the largest log det(M + G_c^T G_c) - log det M (numpy's slogdet of the P x P
information, not the 3 x 3 lemma the code uses), the Ds-optimal sum of each separated effect's gain
beyond the others per its parameter count, the ridge, the plan's log det gain and the resolved parameter
combinations; the rival refit's discrepancy against least squares on the stacked poses. Each test names a
planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.bayes_design import design_columns
from tcr_accuracy.diagnosis.design import _Discrepancy, plan_poses
from tcr_accuracy.model.context import MeasurementContext
from tcr_accuracy.model.robot import load_robot


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def _poses(robot, n, seed):
    low, high = robot.joint_bounds()
    return np.random.default_rng(seed).uniform(low, high, size=(n, robot.n_joints))


def _columns(robot, q, effects):
    columns = design_columns(robot, q, effects, context=MeasurementContext.defaults(len(q), robot.n_joints))
    return columns.g, np.array(columns.owner)


def _logdet(m):
    return np.linalg.slogdet(m)[1]


@pytest.mark.parametrize("separate", [None, ["joint_offsets", "encoder_scale"]])
def test_plan_poses_is_the_greedy_log_det_written_out(robot, separate):
    """3 measured poses (fewer rows than parameters: the ridge 1e-6 x the larger of the measured and the
    candidates' mean squared column carries the unseen directions), 60 candidates, 6 picks: each pick,
    its gain, the plan's log det gain, and the combinations resolved above noise^2 before and after, as
    computed here. Seen failing on ``ridge = 1e-6 * ...`` turned to ``1e-5``, on ``(whole -
    tracker.gains(...)) / size`` turned to ``* size``, on ``- start_logdet`` turned to ``+`` and on
    ``> noise_m**2`` turned to ``noise_m**3``; one pose asked for is planned (seen failing on ``k < 1``
    turned to ``k < 2``)."""
    effects = ["frames", "joint_offsets", "encoder_scale"]
    measured, candidates = _poses(robot, 3, 1), _poses(robot, 60, 2)
    noise = 2e-5
    plan = plan_poses(robot, measured, effects, 6, separate=separate, candidates=candidates, noise_m=noise)
    g_meas, owner = _columns(robot, measured, effects)
    g_cand, _ = _columns(robot, candidates, effects)
    p = owner.size
    ridge = 1e-6 * max(np.sum(g_meas**2) / p, np.mean(np.sum(g_cand**2, axis=(0, 1))))
    flat = g_meas.reshape(-1, p)
    info = flat.T @ flat + ridge * np.eye(p)
    start = info.copy()
    groups = [owner != e for e in (separate or [])]

    def gain(m, columns):
        blocks = [g_cand[c][:, columns] for c in range(len(candidates))]
        base = _logdet(m[np.ix_(columns, columns)])
        return np.array([_logdet(m[np.ix_(columns, columns)] + b.T @ b) - base for b in blocks])

    every = np.arange(p)
    picked, gains = [], []
    for _ in range(6):
        if groups:
            whole = gain(info, every)
            score = sum((whole - gain(info, np.flatnonzero(w))) / np.sum(~w) for w in groups)
        else:
            score = gain(info, every)
        score[picked] = -np.inf
        best = int(np.argmax(score))
        picked.append(best)
        gains.append(score[best])
        info = info + g_cand[best].T @ g_cand[best]
    np.testing.assert_array_equal(plan.q, candidates[picked])
    np.testing.assert_allclose(plan.gain_per_pose, gains, rtol=1e-7)
    assert plan.log_det_gain == pytest.approx(_logdet(info) - _logdet(start), rel=1e-9)
    assert plan.n_parameters == p
    resolved = [int(np.sum(np.linalg.eigvalsh(m - ridge * np.eye(p)) > noise**2)) for m in (start, info)]
    assert (plan.resolved_before, plan.resolved_after) == tuple(resolved)
    assert resolved[0] < resolved[1] < p + 1
    one = plan_poses(robot, measured, effects, 1, separate=separate, candidates=candidates, noise_m=noise)
    np.testing.assert_array_equal(one.q, candidates[picked[:1]])  # one pose asked: the first pick


def test_a_rival_refit_leaves_the_discrepancy_least_squares_leaves(robot):
    """The discrepancy d (between two hypothetical models, drawn here) a refit of the columns G cannot absorb:
    after the measured poses, the candidates' gains (tracked, and given afresh) are the rise of the
    least-squares residual when each is added, and after adding poses one by one the fitted theta and
    the residual are least squares on all of them (numpy's lstsq on the stacked rows). Seen failing on
    ``np.eye(3) + np.matmul(self.h, g.transpose(0, 2, 1))`` turned to ``-``, on ``d - g @ self.theta``
    turned to ``+`` in the fresh gains and on ``self.theta + gain @ residual`` turned to ``-``."""
    rng = np.random.default_rng(3)
    g, _ = _columns(robot, _poses(robot, 40, 5), ["frames", "joint_offsets"])
    d = rng.normal(scale=1e-4, size=(40, 3)) + g @ rng.normal(size=g.shape[2])  # part the columns absorb

    def left(rows):
        a, b = g[rows].reshape(-1, g.shape[2]), d[rows].ravel()
        return float(np.sum((b - a @ np.linalg.lstsq(a, b, rcond=None)[0]) ** 2))

    measured = list(range(12))
    tracker = _Discrepancy(g[measured], d[measured], ridge=1e-14)
    assert tracker.total == pytest.approx(left(measured), rel=1e-6)
    tracker.track(g[20:], d[20:])
    expected = [left(measured + [c]) - left(measured) for c in range(20, 40)]
    # (the expected rises are differences of totals ~50 times larger: compared to 1e-4 of the largest)
    np.testing.assert_allclose(tracker.gains(), expected, rtol=0, atol=1e-4 * max(expected))
    np.testing.assert_allclose(tracker.gains(g[20:], d[20:]), expected, rtol=0, atol=1e-4 * max(expected))
    for c in (25, 31, 12, 33):
        tracker.add(g[c], d[c])
        measured.append(c)
    a, b = g[measured].reshape(-1, g.shape[2]), d[measured].ravel()
    theta = np.linalg.lstsq(a, b, rcond=None)[0]
    np.testing.assert_allclose(tracker.theta, theta, rtol=0, atol=1e-6 * np.abs(theta).max())
    assert tracker.total == pytest.approx(left(measured), rel=1e-6)
    expected = [left(measured + [c]) - left(measured) for c in range(20, 40)]
    np.testing.assert_allclose(tracker.gains(), expected, rtol=0, atol=1e-4 * max(expected))
