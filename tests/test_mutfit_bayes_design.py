"""``diagnosis/bayes_design.py``'s words and limits against figures written out here: the stop advice's
reason in each of its four cases, every millimetre figure formatted from the closed form sqrt(floor^2 + v)
of a curve whose bootstrap is all ones; which effects move the TCP; the learning curve's fewest poses.
Each test names a planted change it was seen to catch (issue 36)."""

from __future__ import annotations

import numpy as np
import pytest

from tcr_accuracy.diagnosis.bayes_design import (Design, DesignColumns, EffectPrior,
                                                 LearningCurve, learning_curve, nonzero_effects, stop_advice)
from tcr_accuracy.exceptions import InputError

FLOOR = 3e-5  # [m]


def _curve() -> LearningCurve:
    """A curve with a = b = 1 in every bootstrap: predict(v) = sqrt(floor^2 + v) and its interval alike."""
    one = np.array([1e-4])
    return LearningCurve(sizes=np.array([10]), rms_m=one, low_m=one, high_m=one, expected_rms_m=one,
                         noise_weight=1.0, variance_weight=1.0, boot=np.ones((20, 2)), noise_floor_m=FLOOR)


def _design(before_m: float, after_m: float, picked: int = 7) -> Design:
    return Design(picked=np.arange(picked), criterion="I", gain_per_pose=np.ones(picked), task_std_before_m=before_m,
                  task_std_after_m=after_m, task_worst_std_before_m=before_m, task_worst_std_after_m=after_m,
                  log_det_gain=1.0)


def _words(v_before: float, v_after: float, picked: int = 7) -> str:
    now, then = np.hypot(FLOOR, np.sqrt(v_before)) * 1e3, np.hypot(FLOOR, np.sqrt(v_after)) * 1e3
    gain = now - then
    return (f"measuring the {picked} poses would take the held-out RMS error over the task from {now:.4f} mm to "
            f"{then:.4f} mm [{then:.4f}, {then:.4f}] (gain {gain:.4f} mm [{gain:.4f}, {gain:.4f}], 90 % interval)")


def test_stop_advice_says_its_figures_in_mm_in_each_case():
    """The four reasons word for word: the noise floor reached (now within 5 % of it), a gain below the
    limit, above it, and no limit; each figure the closed form in mm. Seen failing on ``now[0] * 1e3``
    turned to ``// 1e3`` in the floor's reason, on ``floor * 1e3`` turned to ``% 1e3``, on ``gain[2] *
    1e3`` turned to ``+ 1e3`` and on ``min_gain_m * 1e3`` turned to ``1e4``."""
    curve = _curve()
    v = (1.04**2 - 1) * FLOOR**2  # 4 % above the floor
    advice = stop_advice(curve, _design(np.sqrt(v), np.sqrt(v) / 2), min_gain_m=None)
    assert advice.stop
    assert advice.reason == (f"stop: the noise floor is reached ({np.hypot(FLOOR, np.sqrt(v)) * 1e3:.4f} mm against "
                             f"{FLOOR * 1e3:.4f} mm); {_words(v, v / 4)}")
    v_before, v_after = (4 * FLOOR) ** 2, (1.5 * FLOOR) ** 2
    design = _design(np.sqrt(v_before), np.sqrt(v_after))
    words = _words(v_before, v_after)
    advice = stop_advice(curve, design, min_gain_m=0.2e-3)
    assert advice.stop and advice.reason == f"stop: {words}, below the limit of 0.2 mm"
    advice = stop_advice(curve, design, min_gain_m=0.01e-3)
    assert not advice.stop and advice.reason == f"continue: {words}, above the limit of 0.01 mm"
    advice = stop_advice(curve, design, min_gain_m=None)
    assert not advice.stop and advice.reason == f"expected: {words} (no limit given to stop at)"


def test_nonzero_effects_are_those_whose_columns_move_the_tcp_anywhere():
    """An effect whose only non-zero entry is one pose's z row of one column still moves the TCP; one
    whose columns are all zero does not. Seen failing on ``max(axis=(0, 1))`` turned to ``(0, 0)``."""
    g = np.zeros((6, 3, 5))
    g[:, :, 0] = 1e-4
    g[4, 2, 3] = -1e-9
    owner = np.array(["frames", "compliance", "compliance", "transmission", "transmission"])
    assert nonzero_effects(DesignColumns(g, owner, ["frames", "compliance", "transmission"])) == [
        "frames", "transmission"]


def test_a_learning_curve_needs_twenty_poses():
    """19 poses: refused, naming both numbers; 20: drawn, its smallest subsample half of them. Seen
    failing on ``LEARNING_CURVE_MIN_POSES = 20`` turned to ``21`` and to ``19``."""
    rng = np.random.default_rng(4)
    owner = np.array(["frames"] * 2 + ["compliance"] * 3)
    prior = EffectPrior({"compliance": 1.0}, 3e-5)
    g = rng.normal(size=(20, 3, owner.size)) * 1e-4
    errors = g @ rng.normal(size=owner.size) + rng.normal(0, 3e-5, (20, 3))
    with pytest.raises(InputError, match="^19 measured poses: a learning curve needs at least 20$"):
        learning_curve(DesignColumns(g[:19], owner, ["frames", "compliance"]), errors[:19], prior,
                       np.random.default_rng(1), n_sizes=2, repeats=2, n_boot=5)
    curve = learning_curve(DesignColumns(g, owner, ["frames", "compliance"]), errors, prior, np.random.default_rng(1),
                           n_sizes=2, repeats=2, n_boot=5)
    assert curve.sizes.tolist() == [10, 16]


def test_a_posterior_information_indefinite_in_rounding_is_factored_with_a_growing_jitter():
    """An information matrix whose smallest eigenvalue is -5e-12 of its mean diagonal (two columns alike
    but for rounding): the jitter grows from 1e-13 of the mean diagonal a hundredfold a try until the
    Cholesky factor exists, and the factor is that of the matrix to 1e-10. Seen failing on ``jitter /
    scale * 100`` turned to ``jitter / scale ** 100`` (the jitter falls back to 0 and never grows)."""
    from scipy import linalg

    from tcr_accuracy.diagnosis.bayes_design import _cholesky

    information = np.array([[1.0, 1.0, 0.0], [1.0, 1.0 - 1e-11, 0.0], [0.0, 0.0, 1.0]])
    assert np.linalg.eigvalsh(information)[0] < 0
    with pytest.raises(linalg.LinAlgError):
        linalg.cho_factor(information + 1e-13 * np.mean(np.diag(information)) * np.eye(3))
    factor, lower = _cholesky(information)
    triangle = np.tril(factor) if lower else np.triu(factor)
    rebuilt = triangle @ triangle.T if lower else triangle.T @ triangle
    np.testing.assert_allclose(rebuilt, information, rtol=0, atol=1e-10)
