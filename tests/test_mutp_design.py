"""``diagnosis/design.py``'s T-optimal design between rival fitted models against the greedy written out here:
each rival refitted (ridge least squares on the stacked rows, np.linalg.lstsq) to the other's predictions,
the squared discrepancy it cannot absorb, each candidate's worth the sum over both directions of log(1 + its
added discrepancy / the discrepancy so far, at least noise^2), the best taken pose by pose; and plan_poses'
default candidates. Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import numpy as np
import pytest
from test_mutfit_design import _poses

from tcr_accuracy.diagnosis.bayes_design import design_columns
from tcr_accuracy.diagnosis.design import candidate_configurations, plan_discriminating_poses, plan_poses
from tcr_accuracy.effects import make_effect, predict_positions
from tcr_accuracy.exceptions import InputError
from tcr_accuracy.model.context import MeasurementContext
from tcr_accuracy.model.robot import load_robot

NOISE_M = 2e-5


@pytest.fixture(scope="module")
def robot():
    return load_robot()


def _rivals(robot):
    """A hidden encoder scale error against a transmission error (both with frames), their parameters [SI]."""
    scale, transmission = make_effect("encoder_scale", robot), make_effect("transmission", robot)
    rng = np.random.default_rng(8)
    truth = ([make_effect("frames", robot), scale], [np.zeros(9), np.array([0.0, 4e-4, -3e-4, 0.0, 2e-4, 0.0])])
    rival = ([make_effect("frames", robot), transmission],
             [np.zeros(9), rng.normal(scale=1e-4, size=transmission.n_params)])
    return truth, rival


def _greedy_written_out(robot, measured, candidates, rivals, k, noise_m):
    def context(n):
        return MeasurementContext.defaults(n, robot.n_joints)

    directions = []
    for model_a, model_b in rivals:
        for truth, refit in ((model_a, model_b), (model_b, model_a)):
            names = [e.name for e in refit[0]]
            d = [predict_positions(robot, *truth, q, context(len(q)))
                 - predict_positions(robot, *refit, q, context(len(q)))
                 for q in (measured, candidates)]
            g = [design_columns(robot, q, names, context=context(len(q))).g for q in (measured, candidates)]
            p = g[0].shape[2]
            ridge = 1e-6 * max(float(np.sum(g[0] ** 2)) / p, 1e-300)
            directions.append((g, d, ridge, p))

    def objective(g, d, ridge, p, rows):
        """min over theta of |d - G theta|^2 + ridge |theta|^2 on the rows (measured, then candidates), and theta."""
        a = np.vstack([g[0].reshape(-1, p)] + [g[1][c] for c in rows] + [np.sqrt(ridge) * np.eye(p)])
        b = np.concatenate([d[0].ravel()] + [d[1][c] for c in rows] + [np.zeros(p)])
        theta = np.linalg.lstsq(a, b, rcond=None)[0]
        return float(np.sum((b - a @ theta) ** 2)), theta

    picked = []
    for _ in range(k):
        worth = np.zeros(len(candidates))
        for g, d, ridge, p in directions:
            start, theta0 = objective(g, d, ridge, p, [])
            so_far = objective(g, d, ridge, p, picked)[0]
            total = so_far - ridge * float(theta0 @ theta0)  # the measured rows' misfit, then each pose's rise
            added = np.array([objective(g, d, ridge, p, picked + [c])[0] - so_far for c in range(len(candidates))])
            worth += np.log1p(added / max(total, noise_m**2))
        worth[picked] = -np.inf
        picked.append(int(np.argmax(worth)))
    return picked


@pytest.mark.parametrize("n_measured", [3, 25])
def test_discriminating_poses_are_the_greedy_t_optimal_written_out(robot, n_measured):
    """Among 40 given candidates, 4 poses picked after 3 measured (the rivals absorb the measured rows: the
    noise^2 floor decides the scale) and after 25 (the discrepancy so far decides): the same poses in the
    same order as the greedy written out with lstsq refits. Seen failing on ``max(t.total, noise_m**2)``
    turned to ``noise_m * 2``, on ``ridge = 1e-6 * ...`` turned to ``1.000001`` and its ``/ g_meas.shape[2]`` to ``*``,
    on ``t.gains() / max(...)`` turned to ``*`` and on ``d_cand = (truth - refit)`` and ``d_meas`` turned to ``+``
    (planted by hand)."""
    measured, candidates = _poses(robot, n_measured, 1), _poses(robot, 40, 2)
    rivals = [_rivals(robot)]
    planned = plan_discriminating_poses(robot, measured, rivals, 4, candidates=candidates, noise_m=NOISE_M)
    expected = _greedy_written_out(robot, measured, candidates, rivals, 4, NOISE_M)
    np.testing.assert_array_equal(planned, candidates[expected])
    assert len(set(expected)) == 4


def test_the_designs_default_candidates_and_noise_are_those_plan_poses_documents(robot):
    """Without candidates, both designs draw the 3000 the ``plan-poses`` command documents (``--n-candidates``,
    default 3000) from ``default_rng(0)`` unless given a generator, and count resolved combinations at a laser
    tracker's 0.02 mm: the same poses and counts as with those given explicitly. Seen failing on
    ``n_candidates: int = 3000`` turned to ``3001`` in plan_poses and in plan_discriminating_poses, on
    ``np.random.default_rng(0)`` turned to ``(1)``, on ``noise_m: float = 2e-5`` turned to ``1.00002`` and
    on ``if k < 1`` turned to ``k < 2`` (planted by hand; 3001 candidates were caught only by the count the
    refusal of k = 3001 says)."""
    measured = _poses(robot, 3, 3)
    drawn = candidate_configurations(robot, 3000, np.random.default_rng(0))
    default = plan_poses(robot, measured, ["joint_offsets"], 3)
    given = plan_poses(robot, measured, ["joint_offsets"], 3, candidates=drawn, noise_m=2e-5, payload_kg=0.0)
    np.testing.assert_array_equal(default.q, given.q)
    assert (default.resolved_before, default.resolved_after) == (given.resolved_before, given.resolved_after)
    assert given.resolved_after > given.resolved_before > 0
    other = plan_poses(robot, measured, ["joint_offsets"], 3, rng=np.random.default_rng(9))
    again = plan_poses(robot, measured, ["joint_offsets"], 3,
                       candidates=candidate_configurations(robot, 3000, np.random.default_rng(9)))
    np.testing.assert_array_equal(other.q, again.q)
    rivals = [_rivals(robot)]
    for design, between in ((plan_poses, ["joint_offsets"]), (plan_discriminating_poses, rivals)):
        with pytest.raises(InputError, match=r"^3000 candidate configurations for -k 3001: need at least k$"):
            design(robot, measured, between, 3001)
        with pytest.raises(InputError, match=r"^-k 0: need at least one pose$"):
            design(robot, measured, between, 0, candidates=drawn[:5])
        assert len(design(robot, measured, between, 1, candidates=drawn[:5]).__getattribute__("q")
                   if design is plan_poses else design(robot, measured, between, 1, candidates=drawn[:5])) == 1
    np.testing.assert_array_equal(plan_discriminating_poses(robot, measured, rivals, 2),
                                  plan_discriminating_poses(robot, measured, rivals, 2, candidates=drawn,
                                                            noise_m=2e-5, payload_kg=0.0))


def test_with_more_measured_poses_than_candidates_the_ridge_is_the_measured_columns(robot):
    """40 measured poses, 4 candidates: the ridge is 1e-6 x the measured rows' squared columns per parameter
    (here 11 times the candidates' mean), which turns the gains of directions the measured poses barely move
    by 2 %: each pick's gain log det(M + G_c^T G_c) - log det M (slogdet of the P x P information, written
    out) and the plan's log det gain to 1e-7. Seen failing on ``np.sum(g_measured**2) / p`` turned to
    ``g_measured ** 3`` and to ``* p`` (planted by hand; with fewer measured poses the candidates' term
    decides and those changed nothing)."""
    effects = ["frames", "joint_offsets", "encoder_scale"]
    measured, candidates = _poses(robot, 40, 1), _poses(robot, 4, 2)
    plan = plan_poses(robot, measured, effects, 2, candidates=candidates, noise_m=NOISE_M)
    g_meas, g_cand = (design_columns(robot, q, effects, context=MeasurementContext.defaults(len(q), robot.n_joints)).g
                      for q in (measured, candidates))
    p = g_meas.shape[2]
    by_measured, by_candidates = np.sum(g_meas**2) / p, np.mean(np.sum(g_cand**2, axis=(0, 1)))
    assert by_measured > 10 * by_candidates
    flat = g_meas.reshape(-1, p)
    info = flat.T @ flat + 1e-6 * by_measured * np.eye(p)
    start, picked, gains = info.copy(), [], []
    for _ in range(2):
        score = np.array([np.linalg.slogdet(info + g.T @ g)[1] - np.linalg.slogdet(info)[1] for g in g_cand])
        score[picked] = -np.inf
        picked.append(int(np.argmax(score)))
        gains.append(score[picked[-1]])
        info = info + g_cand[picked[-1]].T @ g_cand[picked[-1]]
    np.testing.assert_array_equal(plan.q, candidates[picked])
    np.testing.assert_allclose(plan.gain_per_pose, gains, rtol=1e-7)
    assert plan.log_det_gain == pytest.approx(np.linalg.slogdet(info)[1] - np.linalg.slogdet(start)[1], rel=1e-7)


def test_a_discriminating_design_without_measured_poses_is_refused_in_one_line(robot):
    """No measured pose: one line naming the argument, not an IndexError from the kinematic chain (as
    it was before this test)."""
    from tcr_accuracy.exceptions import InputError

    with pytest.raises(InputError, match=r"^plan_discriminating_poses: measured_q holds no pose;") as refused:
        plan_discriminating_poses(robot, np.empty((0, robot.n_joints)), [_rivals(robot)], 4,
                                  candidates=_poses(robot, 40, 2), noise_m=NOISE_M)
    assert refused.value.parameter == "measured_q"
