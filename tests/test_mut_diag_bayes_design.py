"""The Bayesian pose design's figures (``diagnosis/bayes_design.py``) each against a computation written
out here on raw numpy / scipy: the type-II maximum-likelihood prior against the log evidence of a
multivariate normal written out and maximised here (scipy), every number a greedy design reports against plain
inverses, the learning curve against refits and non-negative least squares done here on the same
draws, and the stop rule and the campaign order at their thresholds. Each test names a planted change
it was seen to catch (issue 36)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from tcr_accuracy.diagnosis.bayes_design import (DEFAULT_NOISE_M, Design, DesignColumns, EffectPrior,
                                                 LearningCurve, campaign_order, fit_prior, learning_curve,
                                                 plan_design, separating_order, stop_advice, task_variance,
                                                 typical_prior)

EFFECTS = ["frames", "compliance", "transmission"]


def _owner(n_frames, n_compliance, n_transmission):
    return np.array(["frames"] * n_frames + ["compliance"] * n_compliance + ["transmission"] * n_transmission)


def _precision(owner, tau):
    """1e-6 for the flat (setup) columns, 1 / tau_e^2 for the others: the prior written out."""
    return np.array([1e-6 if e == "frames" else 1.0 / tau[e] ** 2 for e in owner])


def _neg_log_evidence(g, y, precision, sigma):
    """-log N(y; 0, C) with C = sigma^2 I + G diag(1/precision) G^T on the stacked rows, written out:
    (y^T C^-1 y + log det C + n log 2 pi) / 2 (scipy.stats' multivariate normal refuses C's condition
    number, 1e8, as singular)."""
    flat = g.reshape(-1, g.shape[2])
    covariance = sigma**2 * np.eye(flat.shape[0]) + (flat / precision) @ flat.T
    y = y.ravel()
    return 0.5 * (y @ np.linalg.solve(covariance, y) + np.linalg.slogdet(covariance)[1] + y.size * np.log(2 * np.pi))


def test_fitted_prior_maximises_the_evidence_written_with_scipy():
    """The prior's tau_e and noise are where the marginal likelihood of the errors (a multivariate normal
    with covariance sigma^2 I + G Lambda^-1 G^T, written out here) is largest:
    Nelder-Mead on it here lands on the same tau (1 %) and noise (0.5 %); with the noise held, the taus
    again. Seen failing on ``1.0 - precision * (theta**2 + ...)`` turned to ``2.0 - ...`` (a gradient
    off: L-BFGS-B stops elsewhere), and on ``gram.rows * np.log(sigma**2)`` turned to ``np.log(sigma**3)``."""
    rng = np.random.default_rng(11)
    owner = _owner(2, 8, 8)
    g = rng.normal(size=(25, 3, owner.size)) * 1e-3
    theta = np.concatenate([rng.normal(0, 30.0, 2), rng.normal(0, 2.0, 8), rng.normal(0, 0.3, 8)])
    errors = g @ theta + rng.normal(0, 1e-4, (25, 3))
    columns = DesignColumns(g, owner, EFFECTS)

    def objective(h, sigma=None):
        s = np.exp(h[0]) if sigma is None else sigma
        taus = np.exp(h[-2:])
        return _neg_log_evidence(g, errors, _precision(owner, dict(zip(EFFECTS[1:], taus))), s)

    fitted = fit_prior(columns, errors)
    best = optimize.minimize(objective, np.log([1e-4, 1.0, 1.0]), method="Nelder-Mead",
                             options={"xatol": 1e-7, "fatol": 1e-10, "maxiter": 4000})
    assert fitted.fitted and fitted.n_poses == 25
    assert fitted.noise_m == pytest.approx(np.exp(best.x[0]), rel=5e-3)
    assert [fitted.tau["compliance"], fitted.tau["transmission"]] == pytest.approx(np.exp(best.x[1:]), rel=1e-2)

    held = fit_prior(columns, errors, noise_m=2e-4)
    best_held = optimize.minimize(lambda h: objective(np.r_[0.0, h], sigma=2e-4), np.zeros(2), method="Nelder-Mead",
                                  options={"xatol": 1e-7, "fatol": 1e-10, "maxiter": 4000})
    assert held.noise_m == 2e-4
    assert [held.tau["compliance"], held.tau["transmission"]] == pytest.approx(np.exp(best_held.x), rel=1e-2)
    doc = held.to_dict()
    assert doc["noise_mm"] == pytest.approx(0.2, rel=1e-12)
    assert doc["tau_typical_sizes"] == pytest.approx({"compliance": held.tau["compliance"],
                                                      "transmission": held.tau["transmission"]})


def test_typical_prior_and_precision_by_hand():
    """A first campaign's prior: tau = 1 for every non-geometric effect, the flat ones at precision 1e-6,
    the noise 0.02 mm (a tracker). Catches ``1.0 / tau ** 2`` turned to ``** 3`` and the default noise
    changed."""
    prior = typical_prior(["frames", "geometry", "compliance", "cyclic"])
    assert prior.tau == {"compliance": 1.0, "cyclic": 1.0}
    assert prior.noise_m == DEFAULT_NOISE_M == pytest.approx(2e-5, rel=1e-12)
    assert typical_prior(["frames"], noise_m=1e-5).noise_m == 1e-5
    owner = np.array(["frames", "geometry", "joint_offsets", "compliance", "cyclic", "thermal"])
    precision = EffectPrior({"compliance": 0.5, "cyclic": 3.0}, 1e-5).precision(owner)
    np.testing.assert_allclose(precision, [1e-6, 1e-6, 1e-6, 4.0, 1 / 9.0, 1.0], rtol=1e-12)


def _design_case(rng, n_measured, n_candidates, n_task, owner, scale=1e-4):
    def columns(n):
        return DesignColumns(rng.normal(size=(n, 3, owner.size)) * scale, owner, EFFECTS)
    return (columns(n_measured) if n_measured else None), columns(n_candidates), columns(n_task)


@pytest.mark.parametrize("criterion", ["I", "G", "D"])
def test_every_figure_of_a_greedy_design_against_plain_inverses(criterion):
    """Each pick's gain (I: the task's mean prediction variance removed; G: the same over the ten task poses
    of largest variance; D: log det of the information gained), the task's RMS and worst prediction std
    before and after, and the log det gain of the whole design, all with np.linalg.inv / slogdet here.
    Twelve picks from no measurement take the variance below a tenth of its start, so the design's own
    recomputation (REFRESH) runs too. Seen failing on ``gains.append(float(gain[best]))`` against
    ``-gain`` and ``task_std_before_m=sqrt(mean)`` against ``sqrt(max)`` (planted by hand), and on
    ``G_WORST = 10`` turned to 11."""
    rng = np.random.default_rng(5)
    owner = _owner(3, 4, 5)
    measured, candidates, task = _design_case(rng, 0, 30, 25, owner)
    prior = EffectPrior({"compliance": 2.0, "transmission": 0.5}, 3e-5)
    design = plan_design(measured, candidates, task, prior, 12, criterion=criterion)
    beta = 1 / prior.noise_m**2
    information = np.diag(_precision(owner, prior.tau))
    start = information.copy()
    weight = sum(g.T @ g for g in task.g) / len(task.g)

    def variances(covariance):
        return np.array([np.trace(g @ covariance @ g.T) for g in task.g])

    before = variances(np.linalg.inv(information))
    picked, gains = [], []
    for _ in range(12):
        covariance = np.linalg.inv(information)
        worst = np.argsort(variances(covariance))[-10:]
        scores = {}
        for c in sorted(set(range(30)) - set(picked)):
            grown = information + beta * candidates.g[c].T @ candidates.g[c]
            after = np.linalg.inv(grown)
            scores[c] = {"I": np.trace(weight @ (covariance - after)),
                         "D": np.linalg.slogdet(grown)[1] - np.linalg.slogdet(information)[1],
                         "G": np.mean([np.trace(task.g[t] @ (covariance - after) @ task.g[t].T) for t in worst])
                         }[criterion]
        best = max(scores, key=scores.get)
        picked.append(best)
        gains.append(scores[best])
        information = information + beta * candidates.g[best].T @ candidates.g[best]
    after = variances(np.linalg.inv(information))
    assert design.criterion == criterion
    assert list(design.picked) == picked
    np.testing.assert_allclose(design.gain_per_pose, gains, rtol=1e-5)
    assert design.task_std_before_m == pytest.approx(np.sqrt(before.mean()), rel=1e-9)
    assert design.task_worst_std_before_m == pytest.approx(np.sqrt(before.max()), rel=1e-9)
    assert design.task_std_after_m == pytest.approx(np.sqrt(after.mean()), rel=1e-7)
    assert design.task_worst_std_after_m == pytest.approx(np.sqrt(after.max()), rel=1e-7)
    assert design.log_det_gain == pytest.approx(np.linalg.slogdet(information)[1] - np.linalg.slogdet(start)[1],
                                                rel=1e-9)
    assert after.mean() < 0.1 * before.mean()  # the recomputation was reached


def test_task_variance_is_the_mean_trace_of_the_posterior_prediction_covariance():
    """``task_variance``: mean over the task poses of trace(g S g^T), S = (G^T G / s^2 + Lambda)^-1 after the
    measured poses, or Lambda^-1 with none. Catches ``/ prior.noise_m**2`` turned to ``* ...``."""
    rng = np.random.default_rng(6)
    owner = _owner(2, 3, 3)
    measured, _, task = _design_case(rng, 6, 1, 9, owner)
    prior = EffectPrior({"compliance": 1.5, "transmission": 0.7}, 4e-5)
    precision = np.diag(_precision(owner, prior.tau))
    flat = measured.g.reshape(-1, owner.size)
    for info, given in ((precision, None), (precision + flat.T @ flat / prior.noise_m**2, measured)):
        covariance = np.linalg.inv(info)
        expected = np.mean([np.trace(g @ covariance @ g.T) for g in task.g])
        assert task_variance(given, task, prior) == pytest.approx(expected, rel=1e-7)


def test_learning_curve_against_refits_and_nnls_on_the_same_draws():
    """Every figure of the learning curve recomputed here on the same random draws (the same seed): each
    subsample refitted with np.linalg.solve, the held-out mean squared 3D miss and the posterior variance
    at the left-out poses, the 5-95 % range over the repeats, the model's expectation sqrt(3 s^2 + v),
    the calibration (a, b) by scipy's nnls on a 3 s^2 + b v, and each bootstrap's (a, b). Seen failing on
    ``np.geomspace(n / 2, 0.8 * n, ...)`` turned to ``n / 3`` and ``noise3 = 3.0 * ...`` turned to
    ``4.0 * ...``."""
    rng = np.random.default_rng(8)
    owner = _owner(2, 5, 5)
    n = 24
    g = rng.normal(size=(n, 3, owner.size)) * 1e-4
    theta = np.concatenate([rng.normal(0, 20, 2), rng.normal(0, 1.0, 10)])
    errors = g @ theta + rng.normal(0, 3e-5, (n, 3))
    prior = EffectPrior({"compliance": 1.0, "transmission": 1.0}, 3e-5)
    curve = learning_curve(DesignColumns(g, owner, EFFECTS), errors, prior, np.random.default_rng(9),
                           n_sizes=3, repeats=4, n_boot=30)
    draws = np.random.default_rng(9)
    precision = np.diag(_precision(owner, prior.tau))
    sizes = np.unique(np.round(np.geomspace(n / 2, 0.8 * n, 3)).astype(int))
    observed, variance = np.empty((len(sizes), 4)), np.empty((len(sizes), 4))
    for i, size in enumerate(sizes):
        for r in range(4):
            test = np.sort(draws.choice(n, n - size, replace=False))
            train = np.setdiff1d(np.arange(n), test)
            flat = g[train].reshape(-1, owner.size)
            information = flat.T @ flat / prior.noise_m**2 + precision
            fit = np.linalg.solve(information, flat.T @ errors[train].ravel() / prior.noise_m**2)
            miss = errors[test] - g[test] @ fit
            observed[i, r] = np.mean(np.sum(miss**2, axis=1))
            covariance = np.linalg.inv(information)
            variance[i, r] = np.mean([np.trace(gi @ covariance @ gi.T) for gi in g[test]])
    noise3 = 3 * prior.noise_m**2

    def calibrate(obs, var):
        return optimize.nnls(np.column_stack([np.full_like(var, noise3), var]), obs)[0]

    np.testing.assert_array_equal(curve.sizes, sizes)
    np.testing.assert_allclose(curve.rms_m, np.sqrt(observed.mean(axis=1)), rtol=1e-6)
    np.testing.assert_allclose(curve.low_m, np.quantile(np.sqrt(observed), 0.05, axis=1), rtol=1e-6)
    np.testing.assert_allclose(curve.high_m, np.quantile(np.sqrt(observed), 0.95, axis=1), rtol=1e-6)
    np.testing.assert_allclose(curve.expected_rms_m, np.sqrt(noise3 + variance.mean(axis=1)), rtol=1e-6)
    assert curve.noise_floor_m == pytest.approx(np.sqrt(noise3), rel=1e-12)
    a, b = calibrate(observed.ravel(), variance.ravel())
    assert [curve.noise_weight, curve.variance_weight] == pytest.approx([a, b], rel=1e-5, abs=1e-9)
    boot = []
    for _ in range(30):
        pick = draws.integers(0, observed.size, observed.size)
        boot.append(calibrate(observed.ravel()[pick], variance.ravel()[pick]))
    np.testing.assert_allclose(curve.boot, boot, rtol=1e-5, atol=1e-9)


def test_one_posterior_variance_calibrates_as_one_ratio():
    """Subsamples that all leave the same posterior variance: (a, b) is the one ratio sum(observed) /
    sum(3 s^2 + v), for both. Catches the ratio's ``noise3 + variance`` turned to ``noise3 - variance``."""
    from tcr_accuracy.diagnosis.bayes_design import _calibration

    observed = np.array([3.0, 5.0, 4.0]) * 1e-9
    a, b = _calibration(observed, np.full(3, 1e-9), 2e-9)
    assert a == b == pytest.approx(12e-9 / (3 * 3e-9), rel=1e-12)


def _curve(boot, floor_m):
    return LearningCurve(sizes=np.array([10]), rms_m=np.array([1e-4]), low_m=np.array([1e-4]),
                         high_m=np.array([1e-4]), expected_rms_m=np.array([1e-4]), noise_weight=1.0,
                         variance_weight=1.0, boot=boot, noise_floor_m=floor_m)


def test_learning_curve_prediction_gain_and_interval_by_hand():
    """predict(v): sqrt(floor^2 + v) with the 5 and 95 % quantiles of sqrt(a floor^2 + b v) over the
    bootstrap's (a, b), widened to hold the point; gain(v1, v2) the same for the difference. Catches
    ``np.quantile(boot, [0.05, 0.95])`` turned to ``[0.05, 1.95]`` ... and ``_rms(1.0, 1.0, ...)``
    turned to ``_rms(2.0, ...)``."""
    rng = np.random.default_rng(2)
    boot = np.column_stack([rng.uniform(0.5, 1.5, 200), rng.uniform(0.2, 3.0, 200)])
    floor = 3e-5
    curve = _curve(boot, floor)
    v_now, v_then = 4e-9, 1e-9
    point = np.sqrt(floor**2 + v_now)
    spread = np.sqrt(boot[:, 0] * floor**2 + boot[:, 1] * v_now)
    low, high = np.quantile(spread, [0.05, 0.95])
    assert curve.predict(v_now) == pytest.approx((point, min(low, point), max(high, point)), rel=1e-12)
    drop = spread - np.sqrt(boot[:, 0] * floor**2 + boot[:, 1] * v_then)
    point_drop = point - np.sqrt(floor**2 + v_then)
    low, high = np.quantile(drop, [0.05, 0.95])
    assert curve.gain(v_now, v_then) == pytest.approx((point_drop, min(low, point_drop), max(high, point_drop)),
                                                      rel=1e-12)
    assert curve.floor_m == floor
    # a bootstrap all above the point: the interval is widened down to it
    assert curve_low(_curve(np.full((5, 2), 4.0), floor), v_now) == pytest.approx(point, rel=1e-12)


def curve_low(curve, v):
    return curve.predict(v)[1]


def _design(before_m, after_m):
    return Design(picked=np.arange(5), criterion="I", gain_per_pose=np.ones(5), task_std_before_m=before_m,
                  task_std_after_m=after_m, task_worst_std_before_m=before_m, task_worst_std_after_m=after_m,
                  log_det_gain=1.0)


def test_stop_rule_at_its_thresholds():
    """With a = b = 1 everywhere: the held-out error now is sqrt(floor^2 + v_before); stop when it is within
    5 % of the floor (1.049 x: stop; 1.051 x and no limit: go on), or when the expected gain is under the
    limit (limit 1 % above the gain: stop; 1 % below: continue). Catches ``1.05 * floor`` turned to
    ``2.05 * floor`` and ``gain[0] < min_gain_m`` read on the interval's end."""
    floor = 3e-5
    curve = _curve(np.ones((20, 2)), floor)
    for ratio, stop in ((1.049, True), (1.051, False)):
        v = (ratio**2 - 1) * floor**2
        advice = stop_advice(curve, _design(np.sqrt(v), np.sqrt(v) / 2), min_gain_m=None)
        assert advice.stop is stop
        assert advice.now_m[0] == pytest.approx(ratio * floor, rel=1e-12)
        assert ("noise floor is reached" in advice.reason) is stop
    v_before, v_after = (4 * floor) ** 2, floor**2
    gain = np.sqrt(floor**2 + v_before) - np.sqrt(floor**2 + v_after)
    design = _design(np.sqrt(v_before), np.sqrt(v_after))
    assert stop_advice(curve, design, min_gain_m=1.01 * gain).stop
    advice = stop_advice(curve, design, min_gain_m=0.99 * gain)
    assert not advice.stop and advice.reason.startswith("continue")
    assert advice.gain_m == pytest.approx((gain, gain, gain), rel=1e-12)
    assert advice.then_m[0] == pytest.approx(np.sqrt(2) * floor, rel=1e-12)
    assert f"{gain * 1e3:.4f} mm" in advice.reason


def test_campaign_order_places_the_central_reference_evenly_and_scores_the_order_with_corrcoef():
    """The reference is the pose nearest the standardised mean (chosen here by hand: the centre of a
    cloud); it is measured at the places round(linspace(0, K - 1, n)) of the K - 1 others, plus its own
    earlier repeats; the returned correlation is the largest |np.corrcoef| of a joint with the place.
    With no tries, the order is the identity and its correlation that of the poses as given. Catches
    the reference's places spread by ``linspace(0, len(rows), repeats)`` turned to ``repeats + 1``, and
    ``max(int(n_references), 1)`` turned to ``max(..., 0)`` (no rows at all for 0 references)."""
    rng = np.random.default_rng(12)
    q = rng.uniform(-1, 1, size=(21, 3))
    q[7] = q.mean(axis=0) + 1e-3  # near the centre: the reference
    rows, reference, largest_r = campaign_order(q, 3, np.random.default_rng(1))
    assert reference == int(np.argmin(np.sum(((q - q.mean(0)) / q.std(0)) ** 2, axis=1))) == 7
    places = np.flatnonzero(rows == reference)
    assert places.tolist() == [0, 11, 22] and len(rows) == 23
    others = rows[rows != reference]
    assert sorted(others) == sorted(set(range(21)) - {7})
    r = max(abs(np.corrcoef(np.arange(20), q[others][:, j])[0, 1]) for j in range(3))
    assert largest_r == pytest.approx(r, abs=1e-12)
    # once: the reference first, the rest after it
    rows_once, _, _ = campaign_order(q, 1, np.random.default_rng(1))
    assert rows_once[0] == 7 and len(rows_once) == 21
    rows_none, _, _ = campaign_order(q, 0, np.random.default_rng(1))  # no repeats asked: the reference once
    np.testing.assert_array_equal(rows_none, rows_once)
    # the identity scored
    ramp = np.column_stack([np.arange(10.0), rng.normal(size=10)])
    order, r_identity = separating_order(ramp, np.random.default_rng(0), tries=0)
    assert order.tolist() == list(range(10)) and r_identity == pytest.approx(1.0, abs=1e-12)
    order, r_mixed = separating_order(ramp, np.random.default_rng(0))
    expected = max(abs(np.corrcoef(np.arange(10), ramp[order][:, j])[0, 1]) for j in range(2))
    assert r_mixed == pytest.approx(expected, abs=1e-12) and r_mixed < 0.5
