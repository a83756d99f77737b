"""``diagnosis/bayes_design.py``'s remaining figures against computations written out here on raw numpy:
the leave-one-pose-out residuals against a refit without each pose, the predictive spread against
``g S g^T + sigma^2`` with S a plain inverse, a long greedy design whose prediction variance falls by
orders of magnitude (its recomputation rule then decides whether the gains are right) against plain
inverses, the stop advice's every millimetre figure from a bootstrap whose interval ends differ from
its point, and the learning curve's JSON in mm. Each test names a planted change it was seen to catch
(issue 36)."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.bayes_design import (BayesianErrorModel, Design, DesignColumns, EffectPrior,
                                                 LearningCurve, plan_design, stop_advice, task_variance)

EFFECTS = ["frames", "compliance", "transmission"]


def _owner(n_frames, n_compliance, n_transmission):
    return np.array(["frames"] * n_frames + ["compliance"] * n_compliance + ["transmission"] * n_transmission)


def _precision(owner, tau):
    """The prior written out: 1e-6 for the flat (setup) columns, 1 / tau_e^2 for the others."""
    return np.array([1e-6 if e == "frames" else 1.0 / tau[e] ** 2 for e in owner])


def _problem(seed, n=14, scale=1e-3):
    rng = np.random.default_rng(seed)
    owner = _owner(3, 4, 4)
    g = rng.normal(size=(n, 3, owner.size)) * scale
    theta = np.concatenate([rng.normal(0, 5.0, 3), rng.normal(0, 1.0, 8)])
    errors = g @ theta + rng.normal(0, 4e-5, (n, 3))
    prior = EffectPrior({"compliance": 1.5, "transmission": 0.6}, 4e-5)
    return DesignColumns(g, owner, EFFECTS), errors, prior


def test_leave_one_out_residuals_are_those_of_refits_without_each_pose():
    """Pose i's leave-one-out residual: its error minus what the posterior mean fitted on the other poses
    (np.linalg.solve on their information here, the prior held) predicts there, for every pose, to 1e-8
    of the largest residual. Fourteen poses of 11 parameters: each pose's hat block is far from zero, so
    ``(I - H_ii)^-1`` matters. Seen failing on ``np.eye(3) - hat`` turned to ``np.eye(3) + hat`` and on
    ``/ self.prior.noise_m**2`` turned to ``** 3`` (planted by hand)."""
    columns, errors, prior = _problem(21)
    g, owner = columns.g, columns.owner
    model = BayesianErrorModel(prior).fit(columns, errors)
    loo = model.leave_one_out(columns, errors)
    expected = np.empty_like(errors)
    for i in range(len(g)):
        keep = np.arange(len(g)) != i
        flat = g[keep].reshape(-1, owner.size)
        information = flat.T @ flat / prior.noise_m**2 + np.diag(_precision(owner, prior.tau))
        theta = np.linalg.solve(information, flat.T @ errors[keep].ravel() / prior.noise_m**2)
        expected[i] = errors[i] - g[i] @ theta
    fitted_residual = errors - g @ model.theta_
    assert np.max(np.abs(expected - fitted_residual)) > 0.2 * np.max(np.abs(expected))  # the hat matters here
    np.testing.assert_allclose(loo, expected, rtol=0, atol=1e-8 * np.max(np.abs(expected)))


def test_predictive_mean_and_spread_against_plain_inverses_in_several_chunks():
    """predict(): g theta with theta = A^-1 G^T y / s^2, and the spread sqrt(diag(g S g^T) + s^2) per axis with
    S = A^-1 (np.linalg.inv here), over 7 poses predicted in chunks of 3 (the last one short); the
    covariance_ is that S. Seen failing on ``np.sqrt(variance + self.prior.noise_m**2)`` turned to ``- ...``
    and on the chunk's ``start:start + chunk`` turned to ``start:start - chunk`` (planted by hand)."""
    columns, errors, prior = _problem(22)
    g, owner = columns.g, columns.owner
    model = BayesianErrorModel(prior).fit(columns, errors)
    flat = g.reshape(-1, owner.size)
    information = flat.T @ flat / prior.noise_m**2 + np.diag(_precision(owner, prior.tau))
    covariance = np.linalg.inv(information)
    theta = covariance @ flat.T @ errors.ravel() / prior.noise_m**2
    new = DesignColumns(np.random.default_rng(5).normal(size=(7, 3, owner.size)) * 1e-3, owner, EFFECTS)
    mean, std = model.predict(new, return_std=True, chunk=3)
    np.testing.assert_allclose(mean, new.g @ theta, rtol=1e-8, atol=1e-12)
    spread = np.array([np.sqrt(np.diag(gi @ covariance @ gi.T) + prior.noise_m**2) for gi in new.g])
    np.testing.assert_allclose(std, spread, rtol=1e-8)
    np.testing.assert_allclose(model.covariance_, covariance, rtol=1e-7, atol=1e-9 * np.abs(covariance).max())
    np.testing.assert_array_equal(model.predict(new), mean)


def test_an_empty_measured_set_is_the_prior_alone():
    """Measured poses given as columns with no rows: the task variance and the design are those of the prior
    alone (None), and one measured pose (written out here) lowers the task variance by what np.linalg.inv
    says. Seen failing on ``information += (flat.T @ flat) / prior.noise_m**2`` turned to ``-=``."""
    rng = np.random.default_rng(7)
    owner = _owner(2, 3, 3)
    task = DesignColumns(rng.normal(size=(9, 3, owner.size)) * 1e-4, owner, EFFECTS)
    empty = DesignColumns(np.zeros((0, 3, owner.size)), owner, EFFECTS)
    prior = EffectPrior({"compliance": 1.5, "transmission": 0.7}, 4e-5)
    precision = np.diag(_precision(owner, prior.tau))
    alone = np.mean([np.trace(g @ np.linalg.inv(precision) @ g.T) for g in task.g])
    assert task_variance(empty, task, prior) == pytest.approx(alone, rel=1e-7)
    one = DesignColumns(rng.normal(size=(1, 3, owner.size)) * 1e-4, owner, EFFECTS)
    grown = np.linalg.inv(precision + one.g[0].T @ one.g[0] / prior.noise_m**2)
    assert task_variance(one, task, prior) == pytest.approx(np.mean([np.trace(g @ grown @ g.T) for g in task.g]),
                                                            rel=1e-7)
    a = plan_design(empty, task, task, prior, 3)
    b = plan_design(None, task, task, prior, 3)
    assert a.picked.tolist() == b.picked.tolist()
    assert a.task_std_before_m == pytest.approx(np.sqrt(alone), rel=1e-9)
    np.testing.assert_allclose(a.gain_per_pose, b.gain_per_pose, rtol=1e-12)


def test_a_long_design_recomputes_its_products_and_keeps_every_gain_right():
    """Thirty picks from sixty candidates whose columns are 1 mm per typical size (the flat prior's variance
    falls by some twelve orders of magnitude): each pick's gain (the task's mean prediction variance
    removed) against plain inverses to 1e-6. Without the recomputation from the information (REFRESH), the
    rank-3 downdates' rounding makes the late gains wrong by orders of magnitude. Seen failing on
    ``if float(np.sum(weight * s)) < REFRESH * refreshed_at`` turned to ``>`` (never refreshed) and on
    ``REFRESH = 0.1`` turned to ``-0.9``."""
    rng = np.random.default_rng(3)
    owner = _owner(3, 4, 5)
    prior = EffectPrior({"compliance": 2.0, "transmission": 0.5}, 3e-5)
    candidates = DesignColumns(rng.normal(size=(60, 3, owner.size)) * 1e-3, owner, EFFECTS)
    task = DesignColumns(rng.normal(size=(40, 3, owner.size)) * 1e-3, owner, EFFECTS)
    design = plan_design(None, candidates, task, prior, 30, criterion="I")
    beta = 1 / prior.noise_m**2
    information = np.diag(_precision(owner, prior.tau))
    weight = sum(g.T @ g for g in task.g) / len(task.g)
    gains = []
    for best in design.picked:
        grown = information + beta * candidates.g[best].T @ candidates.g[best]
        gains.append(np.trace(weight @ (np.linalg.inv(information) - np.linalg.inv(grown))))
        information = grown
    assert gains[-1] < 1e-10 * gains[0]
    np.testing.assert_allclose(design.gain_per_pose, gains, rtol=1e-6)


def _curve(boot, floor_m):
    one = np.array([1e-4])
    return LearningCurve(sizes=np.array([10]), rms_m=one, low_m=one, high_m=one, expected_rms_m=one,
                         noise_weight=1.0, variance_weight=1.0, boot=boot, noise_floor_m=floor_m)


def test_stop_advice_words_with_an_interval_apart_from_its_point():
    """The reason word for word, each figure written out here: the point sqrt(floor^2 + v) and the 5 and
    95 % quantiles of sqrt(a floor^2 + b v) over a bootstrap of (a, b) spread around 1, in mm to four
    places, for the held-out error after and the gain; the errors are millimetres, so a factor 1001 for
    1000 shows. Seen failing on ``(gain {gain[0] * 1e3:.4f} mm`` turned to ``gain[1]`` and to ``1001.0``,
    and on ``{then[2] * 1e3:.4f}`` turned to ``then[1]``."""
    rng = np.random.default_rng(17)
    boot = np.column_stack([rng.uniform(0.6, 1.4, 300), rng.uniform(0.5, 1.8, 300)])
    floor = 3e-5
    curve = _curve(boot, floor)
    std_before, std_after = 2.1e-3, 0.7e-3
    design = Design(picked=np.arange(9), criterion="I", gain_per_pose=np.ones(9), task_std_before_m=std_before,
                    task_std_after_m=std_after, task_worst_std_before_m=std_before,
                    task_worst_std_after_m=std_after, log_det_gain=1.0)

    def spread(v):
        return np.sqrt(boot[:, 0] * floor**2 + boot[:, 1] * v)

    now = np.sqrt(floor**2 + std_before**2)
    then = np.sqrt(floor**2 + std_after**2)
    then_low, then_high = np.quantile(spread(std_after**2), [0.05, 0.95])
    gain_low, gain_high = np.quantile(spread(std_before**2) - spread(std_after**2), [0.05, 0.95])
    gain = now - then
    assert then_low < then < then_high and gain_low < gain < gain_high  # the ends differ from the points
    mm = [x * 1e3 for x in (now, then, then_low, then_high, gain, gain_low, gain_high)]
    words = ("measuring the 9 poses would take the held-out RMS error over the task from {:.4f} mm to {:.4f} mm "
             "[{:.4f}, {:.4f}] (gain {:.4f} mm [{:.4f}, {:.4f}], 90 % interval)").format(*mm)
    advice = stop_advice(curve, design, min_gain_m=None)
    assert advice.reason == f"expected: {words} (no limit given to stop at)" and not advice.stop
    assert advice.now_m[0] == pytest.approx(now, rel=1e-12)
    assert advice.then_m == pytest.approx((then, then_low, then_high), rel=1e-12)
    assert advice.gain_m == pytest.approx((gain, gain_low, gain_high), rel=1e-12)
    advice = stop_advice(curve, design, min_gain_m=2e-3)
    assert advice.stop and advice.reason == f"stop: {words}, below the limit of 2 mm"


def test_learning_curve_json_in_mm():
    """to_dict(): every figure in mm (x 1000 of its metres) and the two weights as they are. Seen failing on
    ``"floor_mm": self.floor_m * 1e3`` turned to ``* 1001.0`` (a survivor of seed 1 by the lead)."""
    curve = LearningCurve(sizes=np.array([10, 14]), rms_m=np.array([1e-4, 8e-5]), low_m=np.array([9e-5, 7e-5]),
                          high_m=np.array([1.2e-4, 9e-5]), expected_rms_m=np.array([1.1e-4, 8.5e-5]),
                          noise_weight=0.9, variance_weight=1.3, boot=np.ones((3, 2)), noise_floor_m=3.1e-5)
    doc = curve.to_dict()
    assert doc["sizes"] == [10, 14]
    assert doc["heldout_rms_mm"] == pytest.approx([0.1, 0.08], rel=1e-12)
    assert doc["heldout_rms_5_mm"] == pytest.approx([0.09, 0.07], rel=1e-12)
    assert doc["heldout_rms_95_mm"] == pytest.approx([0.12, 0.09], rel=1e-12)
    assert doc["expected_rms_mm"] == pytest.approx([0.11, 0.085], rel=1e-12)
    assert doc["floor_mm"] == doc["noise_floor_mm"] == pytest.approx(0.031, rel=1e-12)
    assert (doc["noise_weight"], doc["variance_weight"]) == (0.9, 1.3)


def test_a_g_optimal_design_follows_at_most_two_thousand_task_poses():
    """A G-optimal design over a task of 2000 poses uses them all (the generator is never drawn from:
    two generators give the same design, that over the task as given); over 2001 poses it follows the 2000
    that ``rng.choice(2001, 2000, replace=False)`` picks (sorted), as a design over that subset does.
    The progress callback is called once per pose chosen. Seen failing on ``G_TASK_MAX = 2000`` turned to
    2001 and 1999, and on ``progress(1)`` turned to ``progress(2)``."""
    from tcr_accuracy.diagnosis.bayes_design import G_TASK_MAX

    assert G_TASK_MAX == 2000
    rng = np.random.default_rng(31)
    owner = _owner(2, 2, 2)
    prior = EffectPrior({"compliance": 1.0, "transmission": 0.5}, 3e-5)
    candidates = DesignColumns(rng.normal(size=(12, 3, owner.size)) * 1e-4, owner, EFFECTS)
    task = DesignColumns(rng.normal(size=(2001, 3, owner.size)) * 1e-4, owner, EFFECTS)
    subset = DesignColumns(task.g[:2000], owner, EFFECTS)
    ticks = []
    a = plan_design(None, candidates, subset, prior, 3, criterion="G", rng=np.random.default_rng(1),
                    progress=ticks.append)
    b = plan_design(None, candidates, subset, prior, 3, criterion="G", rng=np.random.default_rng(2))
    assert ticks == [1, 1, 1]
    assert a.picked.tolist() == b.picked.tolist()
    np.testing.assert_array_equal(a.gain_per_pose, b.gain_per_pose)
    drawn = np.sort(np.random.default_rng(5).choice(2001, 2000, replace=False))
    c = plan_design(None, candidates, task, prior, 3, criterion="G", rng=np.random.default_rng(5))
    d = plan_design(None, candidates, DesignColumns(task.g[drawn], owner, EFFECTS), prior, 3, criterion="G")
    assert c.picked.tolist() == d.picked.tolist()
    np.testing.assert_allclose(c.gain_per_pose, d.gain_per_pose, rtol=1e-12)
    assert c.task_std_before_m == pytest.approx(d.task_std_before_m, rel=1e-12)


def test_a_design_refuses_an_unknown_criterion_and_k_outside_the_candidates():
    """The refusals word for word: criterion "A"; k of 0 and of M + 1 (M = 5 candidates), while k = M and
    k = 1 are designed. Seen failing on ``1 <= k <= m`` turned to ``2 <= k`` and ``k <= m`` to ``k < m``."""
    from tcr_accuracy.exceptions import InputError

    rng = np.random.default_rng(9)
    owner = _owner(1, 1, 1)
    prior = EffectPrior({"compliance": 1.0, "transmission": 1.0}, 3e-5)
    candidates = DesignColumns(rng.normal(size=(5, 3, owner.size)) * 1e-4, owner, EFFECTS)
    with pytest.raises(InputError, match=r"^criterion 'A': choose I, G or D$"):
        plan_design(None, candidates, candidates, prior, 2, criterion="A")
    for k in (0, 6):
        with pytest.raises(InputError, match=rf"^-k {k}: choose between 1 and the 5 candidates$"):
            plan_design(None, candidates, candidates, prior, k)
    assert sorted(plan_design(None, candidates, candidates, prior, 5).picked.tolist()) == [0, 1, 2, 3, 4]
    assert len(plan_design(None, candidates, candidates, prior, 1).picked) == 1


def test_a_prior_fitted_to_noise_alone_rests_on_its_bounds():
    """Errors of pure noise (1e-4 m) on columns of 1e-3 m per typical size: the evidence falls as tau
    grows, so every non-geometric tau rests on TAU_BOUNDS' lower end, 1e-2 typical sizes, exactly; errors
    of nothing (all zero) drive the noise to NOISE_BOUNDS_M's lower end, 1e-7 m. Errors of the wrong shape
    are refused naming both shapes; no effect to fit with the noise held gives the noise back. Seen failing on
    ``TAU_BOUNDS = (1e-2, 1e2)`` turned to ``(1.01, ...)`` and ``NOISE_BOUNDS_M = (1e-7, ...)`` to
    ``(1.0000001, ...)`` (planted by hand)."""
    from tcr_accuracy.diagnosis.bayes_design import fit_prior
    from tcr_accuracy.exceptions import InputError

    rng = np.random.default_rng(13)
    owner = _owner(2, 4, 4)
    columns = DesignColumns(rng.normal(size=(30, 3, owner.size)) * 1e-3, owner, EFFECTS)
    noise = fit_prior(columns, rng.normal(0, 1e-4, (30, 3)))
    assert noise.tau == pytest.approx({"compliance": 1e-2, "transmission": 1e-2}, rel=1e-12)
    assert noise.noise_m == pytest.approx(1e-4, rel=0.2)
    nothing = fit_prior(columns, np.zeros((30, 3)))
    assert nothing.noise_m == pytest.approx(1e-7, rel=1e-12)
    with pytest.raises(InputError, match=r"^fit_prior: errors of shape \(29, 3\), expected \(30, 3\)$"):
        fit_prior(columns, np.zeros((29, 3)))
    frames_only = DesignColumns(columns.g[:, :, :2], owner[:2], ["frames"])
    held = fit_prior(frames_only, np.zeros((30, 3)), noise_m=3e-5)
    assert (held.tau, held.noise_m, held.fitted, held.n_poses) == ({}, 3e-5, True, 30)


def test_a_campaign_of_fewer_than_three_poses_by_hand():
    """One pose: the reference alone, measured n_references times (once for 0); none: no rows. Two poses
    (both equally central, up to rounding): the reference at places round(linspace(0, 1, 3)) = 0, 0, 1
    of the one other, so rows ref, ref, other, ref. Seen failing on ``if len(q) < 2`` turned to ``< 3``
    and on ``max(int(n_references), 1) if len(q) else 0`` turned to ``else 1``."""
    from tcr_accuracy.diagnosis.bayes_design import campaign_order

    q = np.array([[0.1, 0.2], [0.3, -0.1]])
    rows, reference, r = campaign_order(q[:1], 3, np.random.default_rng(0))
    assert rows.tolist() == [0, 0, 0] and reference == 0 and r == 0.0
    assert campaign_order(q[:1], 0, np.random.default_rng(0))[0].tolist() == [0]
    assert campaign_order(q[:0], 3, np.random.default_rng(0))[0].tolist() == []
    rows, reference, r = campaign_order(q, 3, np.random.default_rng(0))
    centre = int(np.argmin(np.sum(((q - q.mean(axis=0)) / q.std(axis=0)) ** 2, axis=1)))
    assert reference == centre and r == 0.0
    assert rows.tolist() == [centre, centre, 1 - centre, centre]


def test_the_jitter_added_is_exactly_the_second_try():
    """An information matrix whose smallest eigenvalue is -5e-12 of its mean diagonal: the first try
    (1e-13 of the mean diagonal) fails, the second (100 times more, 1e-11) succeeds, so the factor is that
    of the matrix plus exactly 1e-11 x its mean diagonal on the diagonal (to 1e-4 of the jitter). Seen
    failing on ``jitter / scale * 100`` turned to ``* 101`` and on ``1e-13`` turned to ``1.0000000000001``."""
    from tcr_accuracy.diagnosis.bayes_design import _cholesky

    information = np.array([[2.0, 2.0, 0.0], [2.0, 2.0 - 2e-11, 0.0], [0.0, 0.0, 2.0]])
    scale = np.mean(np.diag(information))
    factor, lower = _cholesky(information)
    triangle = np.tril(factor) if lower else np.triu(factor)
    rebuilt = triangle @ triangle.T if lower else triangle.T @ triangle
    added = np.diag(rebuilt - information)
    np.testing.assert_allclose(added, np.full(3, 1e-11 * scale), rtol=1e-4)
    np.testing.assert_allclose(rebuilt - np.diag(np.diag(rebuilt)), information - np.diag(np.diag(information)),
                               atol=1e-15)


def test_a_prior_fitted_to_no_poses_stays_where_it_started():
    """No measured poses: the evidence is flat in every scale (no data), so the fit stays at its start:
    tau = 1 typical size for every non-geometric effect and the noise at twice NOISE_BOUNDS_M's lower end
    (2e-7 m: the start sqrt(y^T y / max(rows, 1)) / 3 = 0 raised to it). Seen failing on ``max(gram.rows,
    1)`` turned to ``max(gram.rows, 0)`` (0 / 0) and on ``2 * NOISE_BOUNDS_M[0]`` turned to ``3 * ...``."""
    from tcr_accuracy.diagnosis.bayes_design import fit_prior

    owner = _owner(2, 2, 2)
    with np.errstate(all="ignore"):
        prior = fit_prior(DesignColumns(np.zeros((0, 3, owner.size)), owner, EFFECTS), np.zeros((0, 3)))
    assert prior.noise_m == pytest.approx(2e-7, rel=1e-12)
    assert prior.tau == pytest.approx({"compliance": 1.0, "transmission": 1.0}, rel=1e-12)
    assert prior.n_poses == 0 and prior.fitted


def test_a_joint_that_never_moves_does_not_choose_the_reference():
    """Poses whose third joint is the same everywhere: the reference is the pose nearest the mean of the two
    joints that move, each over its standard deviation (written out here: pose 5), the still joint left out
    rather than divided by its zero spread; the order's largest |correlation| that of the moving joints (by
    np.corrcoef here), found among the permutations. Before the fix, the still joint's std was rounding
    (1.1e-16) over all the joints but 0 over the moving ones' copy: 0 / 0, a NaN correlation, no permutation
    ever better than it, and NaN reported. Seen failing on the fix undone (``np.std(q, axis=0) > 0``), on
    ``spread[...] = 1.0`` turned to ``0.0``, its ``np.ptp(q,
    axis=0) == 0`` turned to ``== -1`` (a still joint at 0.5), and on ``np.ptp(q, axis=0) > 0`` turned to ``> -1``."""
    from tcr_accuracy.diagnosis.bayes_design import campaign_order

    rng = np.random.default_rng(4)
    q = np.column_stack([rng.uniform(-1, 1, 9), rng.uniform(-2, 2, 9), np.full(9, 0.7)])
    q[5, :2] = q[:, :2].mean(axis=0) + [0.01, -0.01]
    moving = q[:, :2]
    centre = int(np.argmin(np.sum(((moving - moving.mean(axis=0)) / moving.std(axis=0)) ** 2, axis=1)))
    assert centre == 5
    rows, reference, largest_r = campaign_order(q, 2, np.random.default_rng(0))
    assert reference == 5 and rows[0] == rows[-1] == 5 and len(rows) == 10
    others = rows[1:-1]
    r = max(abs(np.corrcoef(np.arange(8), q[others][:, j])[0, 1]) for j in range(2))
    assert largest_r == pytest.approx(r, abs=1e-12) and largest_r < 0.5
    q[:, 2] = 0.5  # a still joint whose std is exactly 0 (0.5 sums exactly): not divided by it either
    assert np.std(q, axis=0)[2] == 0.0
    assert campaign_order(q, 2, np.random.default_rng(0))[1] == 5
