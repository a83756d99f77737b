"""How noisy the measurements are when nobody says (``diagnosis/residuals.py``), second pass (issue 36): the
structured residual whose semivariogram cannot be fitted falls back on the whole residual's RSS figure, written
out here at a scale below and above one (where a square and a root of it change sides). Each test names a
planted change it was seen to catch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tcr_accuracy.diagnosis import residuals
from tcr_accuracy.diagnosis.residuals import noise_from_residual


@pytest.mark.parametrize("error", [ValueError, np.linalg.LinAlgError])
@pytest.mark.parametrize("scale", [0.3, 3.0])
def test_a_semivariogram_that_cannot_be_fitted_leaves_the_rss_figure(monkeypatch, error, scale):
    """A structured residual whose Gaussian variogram fit fails (either error): its nugget is taken as the RSS
    figure's square, so the noise is sqrt(RSS / (3N - p)) itself (the cap min(sqrt(nugget), sigma_rss) then
    changes nothing); the words keep the whole residual's figure in mm. The residual is scaled so that sigma_rss
    is 0.3 and 3 (m: numbers, not a robot): below one a nugget of sigma_rss ** 3 or sigma_rss // 2 gives a
    smaller noise, above one sigma_rss ** 1, + 2, * 2, / 2 and % 2 do. Seen failing on ``nugget = sigma_rss**2``
    turned to ``sigma_rss**3``, ``sigma_rss**1``, ``sigma_rss * 2``, ``sigma_rss - 2`` and ``sigma_rss % 2``."""
    def fails(*args, **kwargs):
        raise error("no fit")

    monkeypatch.setattr(residuals, "fit_gaussian_variogram", fails)
    rng = np.random.default_rng(3)
    q = rng.uniform(-2, 2, (40, 2))
    raw = np.column_stack([np.sin(q[:, 0]), np.cos(q[:, 1]), q[:, 0] * q[:, 1]]) + rng.normal(0, 0.1, (40, 3))
    dof = 120 - 9
    residual = raw * (scale / math.sqrt(np.sum(raw**2) / dof))
    estimate = noise_from_residual(q, residual, 9, structured=True)
    assert estimate.per_axis == pytest.approx(scale, rel=1e-12)
    assert estimate.source == "residual nugget" and not estimate.independent
    assert f"the whole residual is {scale * 1e3:.4g} mm per axis" in estimate.detail
