"""The structure test (``diagnosis/structure.py``), second pass (issue 36): the cases the earlier tests left
to chance, each against a figure written out here: a semivariogram that cannot be fitted (its nugget ratio
read as 1, all scatter), a residual that does not vary (the k-NN p-value capped at 1, the ridge's paired z 0),
the scatter test's significance level (a ratio above 1.1 on few numbers, p from scipy's chi-square), and a
verdict on a residual below the noise floor (no excess). Each test names a planted change it was seen to
catch."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tcr_accuracy.diagnosis import structure
from tcr_accuracy.diagnosis.structure import StructureDetector, scatter_test, structure_verdict


@pytest.fixture(scope="module")
def poses():
    return np.random.default_rng(21).uniform(-2, 2, (40, 3))


@pytest.mark.parametrize("error", [ValueError, np.linalg.LinAlgError])
def test_a_semivariogram_that_cannot_be_fitted_reads_as_all_scatter(monkeypatch, poses, error):
    """The report's nugget ratio per axis is 1 (no spatial structure) where the Gaussian variogram's fit fails,
    with either error. Seen failing on ``_nugget_ratio``'s ``return 1.0`` turned to ``2.0`` and ``0.0``."""
    def fails(*args, **kwargs):
        raise error("no fit")

    monkeypatch.setattr(structure, "fit_gaussian_variogram", fails)
    residual = np.random.default_rng(2).normal(0, 1e-5, (40, 3))
    out = StructureDetector(poses, np.random.default_rng(0), n_permutations=5).test(residual, np.random.default_rng(1))
    assert out["semivariogram_nugget_ratio_xyz"] == [1.0, 1.0, 1.0]


def test_a_residual_that_does_not_vary_has_p_one_and_a_ridge_z_of_zero(poses):
    """Every pose off by the same vector (exact binary fractions: centred, exactly 0): the k-NN shares are 1 for
    the residual and its shuffles alike, so the gain and z are 0 and p = min(1, 7 x P(Z > 0)) = min(1, 3.5) = 1;
    the ridge predicts 0 and its per-pose cut is 0 everywhere, spread 0: z 0 (not 0 / 0), share 1; nothing
    remains. Seen failing on ``min(1.0, stats.norm.sf(...) * m)`` turned to ``min(2.0, ...)`` and ``min(0.0,
    ...)``, and on the ridge's ``if d.std() > 0 else 0.0`` turned to ``else 1.0`` and to ``d.std() > -1``."""
    detector = StructureDetector(poses, np.random.default_rng(0), n_permutations=6)
    out = detector.test(np.tile([2.0**-12, -(2.0**-13), 2.0**-11], (40, 1)))
    assert out["n_subsets"] == 7
    assert (out["explained_share"], out["gain_over_null"], out["z"]) == (1.0, 0.0, 0.0)
    assert out["p_value"] == 1.0
    assert (out["ridge_z"], out["ridge_explained_share"]) == (0.0, 1.0)
    assert not (out["local"] or out["global"] or out["remains"])


def test_the_scatter_tests_level_is_one_in_a_thousand():
    """Six numbers (two poses) 1.3 x the noise, no parameters: the ratio sigma / noise = 1.3 is above the 1.1 a
    noise figure is trusted to, but chi^2 = 6 x 1.69 on 6 degrees of freedom has p = 0.12 (scipy): not below
    1e-3, no scatter detected; the same ratio on 600 poses has p far below it: detected. Seen failing on
    ``alpha: float = 1e-3`` turned to ``1.001``."""
    residual = np.array([[1.0, -1.0, 1.0], [-1.0, 1.0, -1.0]]) * 1.3e-5
    out = scatter_test(residual, 0, 1e-5)
    assert out["ratio"] == pytest.approx(1.3, rel=1e-12)
    assert out["p_value"] == pytest.approx(stats.chi2.sf(6 * 1.69, 6), rel=1e-9)
    assert 1e-3 < out["p_value"] < 0.5 and not out["detected"]
    many = scatter_test(np.tile(residual, (300, 1)), 0, 1e-5)
    assert many["p_value"] == pytest.approx(stats.chi2.sf(1800 * 1.69, 1800), rel=1e-9) and many["detected"]


def test_a_residual_below_the_noise_floor_leaves_no_excess():
    """No structure found, scatter beyond the noise said detected, the residual's RMS (0.2 mm) below the floor
    (0.3 mm): nothing is left beyond the noise (excess 0 mm, not the root of a negative number), below any
    detectable size: "cannot tell" naming 0 mm. Seen failing on ``max(residual_rms**2 - noise_floor**2, 0.0)``
    turned to ``max(..., -1.0)`` (a math domain error) and ``max(..., 1.0)`` (1000 mm left)."""
    verdict = structure_verdict({"remains": False}, {"smallest_detectable_mm": 0.05, "n_poses": 12},
                                {"tested": True, "detected": True}, 0.3e-3, 0.2e-3)
    assert verdict == {"verdict": "cannot tell", "reason": "0 mm RMS are left beyond the noise, but with 12 poses "
                                                           "the test only sees structure from 0.05 mm"}


def test_the_probes_noise_and_the_noise_floor_are_said_to_the_digits_they_print():
    """Figures on the edge of their printed 3 digits, so that one read a thousandth too large or too small prints
    otherwise: the power probe's noise 0.0999 mm per axis (0.1, 0.0998) in its method, and the 0.999 mm noise
    floor (1, 0.998) a verdict names when the noise was estimated from the residual and the test only sees from
    1.5 mm. The probe stands in for a detector that sees from 2 x the noise. Seen failing on the method's
    ``noise_per_axis * 1e3`` turned to ``* 999.0`` and the verdict's ``noise_floor * 1e3`` turned to ``* 999.0``
    and ``* 1001.0``."""
    from types import SimpleNamespace

    detector = SimpleNamespace(q=np.zeros((10, 2)), n_total=10, restrict=lambda values: values,
                               probe=lambda noise, shape: (lambda amplitude: amplitude >= 2.0))
    power = structure.smallest_detectable_structure(detector, {"ramp": np.ones((10, 3))}, 9.99e-5,
                                                    np.random.default_rng(0))
    assert power["method"] == ("each shape added to Gaussian noise of 0.0999 mm per axis at RMS 0.5, 1, 2, ... 64 x "
                               "that and tested; the smallest flagged size, largest over the shapes")
    verdict = structure_verdict({"remains": False}, {"smallest_detectable_mm": 1.5, "n_poses": 30}, {"tested": False},
                                0.999e-3, 2e-3)
    assert verdict == {"verdict": "cannot tell", "reason": "the noise was estimated from this residual, and with 30 "
                                                           "poses the test only sees structure from 1.5 mm, above "
                                                           "the 0.999 mm noise floor"}


def test_the_context_that_could_predict_scatter_is_what_varies_however_little(monkeypatch):
    """Scatter beyond the noise that the joints do not predict: the rows' context is offered to the ridge only
    where it varies, a time of 0.5 s in all (spread 0.15, below one) and approach directions of which one column
    varies, not a temperature held at 20 degC; the ridge is handed their (N, 3) columns side by side and the note
    names them. Seen failing on ``np.any(np.std(v, axis=0) > 0)`` turned to ``> 1`` (the time left out) and to
    ``> -1`` (the constant temperature named)."""
    from types import SimpleNamespace

    n = 12
    handed = {}

    def from_context(features, residual, split):
        handed["features"] = features
        return 0.2e-3

    monkeypatch.setattr(structure, "predictable_leftover", lambda detector, residual: 0.6e-3)
    monkeypatch.setattr(structure, "predictable_from_context", from_context)
    time_s = np.linspace(0.0, 0.5, n)
    directions = np.column_stack([np.ones(n), np.where(np.arange(n) % 2, 1.0, -1.0)])
    scatter = {"detected": True, "estimated_noise_per_axis_mm": 0.6}
    notes = []
    structure.name_scatter(scatter, {"verdict": "no"}, [], SimpleNamespace(per_axis=0.1e-3), notes,
                           detector=SimpleNamespace(restrict=lambda values: values, split=None),
                           residual=np.zeros((n, 3)),
                           context={"temperature_c": np.full(n, 20.0), "time_s": time_s,
                                    "approach directions": directions})
    np.testing.assert_array_equal(handed["features"], np.column_stack([time_s, directions]))
    assert scatter["named"] is None
    assert notes == ["0.6000 mm per axis is left against 0.1000 mm of noise, but predicted out of sample from the "
                     "rows' time_s, approach directions it leaves 0.2000 mm: structure along them that the vocabulary "
                     "does not express, not random scatter"]
