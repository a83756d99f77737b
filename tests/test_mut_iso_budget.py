"""The uncertainty budget's pieces (``frames/uncertainty_budget.py``) and the instrument's
specification (``frames/instrument.py``), each against a computation written out here: the GUM's
formulas on raw numbers, a Kabsch fit on numpy's SVD differentiated by finite differences, the
points' own moments and box. Each test names a planted change it was seen to catch.
"""

import math
from itertools import product

import numpy as np
import pytest

from tcr_accuracy.frames.instrument import INSTRUMENTS, Instrument, instrument_from
from tcr_accuracy.frames.uncertainty_budget import (COVERAGE_FACTOR, EXPANSION_PER_K, TYPE_A, TYPE_B, Contribution,
                                                     PointSet, UncertaintyBudget, axis_sigma, fit_uncertainty,
                                                     mpe_uncertainty, registration_covariance,
                                                     registration_uncertainty, statistic_noise,
                                                     temperature_uncertainty)

UM = 1e-6


def _kabsch(nominal, measured):
    """measured ~ R nominal + t by numpy's SVD (Arun, Huang and Blostein 1987), written out here."""
    mn, mm = nominal.mean(axis=0), measured.mean(axis=0)
    h = (nominal - mn).T @ (measured - mm)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, mm - r @ mn


def _kabsch_covariance(points, at, sigma):
    """(N, 3, 3) covariance of ``R at + t`` when each coordinate of the fitted points scatters by
    sigma: the Jacobian of the mapped point by central finite differences of :func:`_kabsch`, then
    sigma^2 J J^T (first order)."""
    h = 1e-7
    jac = np.zeros((len(at), 3, points.size))
    for k in range(points.size):
        plus, minus = points.copy(), points.copy()
        plus.flat[k] += h
        minus.flat[k] -= h
        rp, tp = _kabsch(points, plus)
        rm, tm = _kabsch(points, minus)
        jac[:, :, k] = ((at @ rp.T + tp) - (at @ rm.T + tm)) / (2 * h)
    return sigma ** 2 * jac @ jac.transpose(0, 2, 1)


@pytest.fixture(scope="module")
def cloud():
    rng = np.random.default_rng(101)
    fitted = rng.normal(size=(12, 3)) * [0.4, 0.25, 0.15] + [0.5, -0.2, 0.8]
    evaluated = rng.uniform(-0.3, 0.3, (9, 3)) + [0.9, 0.3, 0.4]
    return fitted, evaluated


def test_registration_covariance_is_the_kabsch_fits_first_order_covariance(cloud):
    """A Kabsch frame fitted on 12 points with per-axis scatter 20 um: the covariance it gives nine
    other points equals sigma^2 J J^T of a numpy-SVD Kabsch fit differentiated by finite
    differences (to 1e-5 relative). Catches the translation term ``I / n`` as ``I * n`` and the
    skew matrix's ``-r[:, 2]`` as ``r[:, 2]`` (the cross product turned into a symmetric one)."""
    fitted, evaluated = cloud
    sigma = 20 * UM
    got = registration_covariance(PointSet.of(fitted), sigma, evaluated)
    expected = _kabsch_covariance(fitted, evaluated, sigma)
    assert got.shape == (9, 3, 3)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6 * sigma ** 2)


def test_registration_uncertainty_rms_and_corner_maximum_from_the_points(cloud):
    """The RMS per-axis uncertainty over the evaluated points is sqrt(mean trace / 3) of the
    finite-difference Kabsch covariance at each of them (exact from the moments), and the largest
    is that at the worst corner of their bounding box. Catches ``3.0 / fitted.n`` as
    ``3.0 * fitted.n``, ``mean_trace / 3.0`` as ``/ 4.0`` and the corners' ``/ 3.0`` mutated."""
    fitted, evaluated = cloud
    sigma = 15 * UM
    rms, largest = registration_uncertainty(PointSet.of(fitted), sigma, PointSet.of(evaluated))
    at_points = np.trace(_kabsch_covariance(fitted, evaluated, sigma), axis1=1, axis2=2)
    assert rms == pytest.approx(math.sqrt(at_points.mean() / 3.0), rel=1e-5)
    lo, hi = evaluated.min(axis=0), evaluated.max(axis=0)
    box = np.array([[(lo, hi)[s][i] for i, s in enumerate(signs)] for signs in product((0, 1), repeat=3)])
    at_corners = np.trace(_kabsch_covariance(fitted, box, sigma), axis1=1, axis2=2)
    assert largest == pytest.approx(math.sqrt(at_corners.max() / 3.0), rel=1e-5)
    assert largest >= rms


def test_point_set_moments_box_and_distances_from_the_points(cloud):
    """PointSet of 9 points against numpy on the points: mean, covariance over n, box; the
    distance's RMS exactly sqrt(mean |p - o|^2), its bounds those of the box (farthest corner,
    nearest box point), and the mm dict and back. Catches ``centred.T @ centred / len`` as
    ``* len``, the corners' bit test ``(k >> i) & 1`` as ``& 2``, ``mean_mm * 1e3`` as ``/ 1e3`` and
    the covariance's ``1e6`` as ``1e5``."""
    _, points = cloud
    ps = PointSet.of(points)
    centred = points - points.mean(axis=0)
    assert ps.n == 9
    np.testing.assert_allclose(ps.mean, points.mean(axis=0), rtol=1e-14)
    np.testing.assert_allclose(ps.covariance, np.cov(points.T, bias=True), rtol=1e-12)
    np.testing.assert_allclose(ps.second_moment([0.1, 0.2, -0.3]),
                               np.mean([np.outer(p, p) for p in points - [0.1, 0.2, -0.3]], axis=0), rtol=1e-12)
    lo, hi = points.min(axis=0), points.max(axis=0)
    corners = {tuple(c) for c in ps.corners()}
    assert corners == {(x, y, z) for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])}
    origin = np.array([0.2, -0.1, 0.5])
    rms, least, largest = ps.distance(origin)
    assert rms == pytest.approx(math.sqrt(np.mean(np.sum((points - origin) ** 2, axis=1))), rel=1e-12)
    assert largest == pytest.approx(max(np.linalg.norm(np.array(c) - origin) for c in corners), rel=1e-12)
    nearest = np.minimum(np.maximum(origin, lo), hi)
    assert least == pytest.approx(np.linalg.norm(nearest - origin), rel=1e-12)
    assert least <= np.linalg.norm(points - origin, axis=1).min() <= largest
    doc = ps.to_dict()
    assert doc["mean_mm"] == pytest.approx((points.mean(axis=0) * 1e3).tolist(), rel=1e-12)
    np.testing.assert_allclose(doc["covariance_mm2"], centred.T @ centred / 9 * 1e6, rtol=1e-12)
    assert doc["lower_mm"] == pytest.approx((lo * 1e3).tolist()) and doc["upper_mm"] == pytest.approx((hi * 1e3).tolist())
    back = PointSet.from_dict(doc)
    for a, b in ((back.mean, ps.mean), (back.covariance, ps.covariance), (back.lower, lo), (back.upper, hi)):
        np.testing.assert_allclose(a, b, rtol=1e-12)


def test_the_gum_pieces_written_out():
    """Each closed form of the budget on numbers written here: an MPE 15 um + 6 um/m at 2.5 m read
    as a rectangular half-width (30 um / sqrt 3); a residual RMS of 3-D norms 0.05 mm over 20
    points of a 9-parameter fit (per axis 0.05 sqrt(60/51) / sqrt 3 mm); a 9-parameter fit on 60
    coordinates (sigma sqrt(9/60)); aluminium (23e-6 /K) over 18-26 degC at 1.2 m (a rectangle of
    full width alpha dT R); a mean and a max of 25 error norms. Catches ``/ math.sqrt(3.0)``
    mutated in each, ``3 * n_points`` as ``4 * n_points``, ``/ 2.0`` as ``/ 3.0`` in the temperature,
    ``EXPANSION_PER_K`` 23e-6 changed, and ``min(p / m, 1.0)`` as ``min(p / m, 2.0)``."""
    assert mpe_uncertainty((15 * UM, 6 * UM), [0.0, 2.5]) == pytest.approx([15 * UM / math.sqrt(3),
                                                                            30 * UM / math.sqrt(3)], rel=1e-12)
    assert axis_sigma(0.05e-3, 20, 9) == pytest.approx(0.05e-3 * math.sqrt(60 / 51) / math.sqrt(3), rel=1e-12)
    assert axis_sigma(0.05e-3, 2, 9) == pytest.approx(0.05e-3 * math.sqrt(6 / 1) / math.sqrt(3), rel=1e-12)
    assert fit_uncertainty(0.02e-3, 9, 60) == pytest.approx(0.02e-3 * math.sqrt(9 / 60), rel=1e-12)
    assert fit_uncertainty(0.02e-3, 90, 60) == pytest.approx(0.02e-3, rel=1e-12)  # as many parameters as data
    assert fit_uncertainty(0.02e-3, 3, 0) == pytest.approx(0.02e-3, rel=1e-12)
    assert EXPANSION_PER_K == 23e-6  # aluminium, the largest of the structural metals'
    assert temperature_uncertainty((18.0, 26.0), 1.2) == pytest.approx(23e-6 * 8.0 * 1.2 / 2 / math.sqrt(3), rel=1e-12)
    assert temperature_uncertainty((18.0, 26.0), 1.2, 11.7e-6) == pytest.approx(11.7e-6 * 8 * 1.2 / 2 / math.sqrt(3))
    assert statistic_noise(0.03e-3, 25, "mean") == pytest.approx(0.03e-3 / 5, rel=1e-12)
    assert statistic_noise(0.03e-3, 25, "rms") == pytest.approx(0.03e-3 / 5, rel=1e-12)
    assert statistic_noise(0.03e-3, 25, "max") == pytest.approx(0.03e-3, rel=1e-12)
    assert statistic_noise(0.03e-3, 0, "mean") == pytest.approx(0.03e-3, rel=1e-12)


def test_a_budget_combines_expands_and_writes_mm():
    """Three evaluated contributions 3, 4 and 12 um and one not evaluated: combined 13 um (root sum
    of squares, GUM 5.1.2), expanded 26 um (k = 2), in mm in the dict; a budget in rad keeps its
    unit and scale. Catches ``COVERAGE_FACTOR`` 2.0 changed, ``** 2`` as ``** 3`` in the
    combination, the dict's ``* scale`` as ``/ scale`` and ``u / scale`` read back as ``u * scale``."""
    parts = (Contribution("instrument MPE", 3 * UM, "spec"), Contribution("noise", 4 * UM, "scatter", TYPE_A),
             Contribution("fit", 12 * UM, "hat matrix", TYPE_A), Contribution("temperature", None, "not recorded"))
    budget = UncertaintyBudget("mean on 20 poses", 0.08e-3, "m", parts)
    assert COVERAGE_FACTOR == 2.0
    assert budget.combined == pytest.approx(13 * UM, rel=1e-12)
    assert budget.expanded == pytest.approx(26 * UM, rel=1e-12)
    assert budget.not_evaluated == ["temperature"]
    doc = budget.to_dict()
    assert doc["unit"] == "mm" and doc["value"] == pytest.approx(0.08, rel=1e-12)
    assert doc["combined_standard_uncertainty"] == pytest.approx(0.013, rel=1e-12)
    assert doc["expanded_uncertainty"] == pytest.approx(0.026, rel=1e-12)
    assert doc["coverage_factor"] == 2.0
    assert doc["contributions"][3]["standard_uncertainty"] is None
    assert [c["standard_uncertainty"] for c in doc["contributions"]][:3] == pytest.approx([0.003, 0.004, 0.012])
    assert [c["evaluation"] for c in doc["contributions"]] == [TYPE_B, TYPE_A, TYPE_A, TYPE_B]
    back = [Contribution.from_dict(c) for c in doc["contributions"]]
    assert [c.standard_uncertainty for c in back][:3] == pytest.approx([3 * UM, 4 * UM, 12 * UM], rel=1e-12)
    angle = UncertaintyBudget("AP_a", 1e-4, "rad", (Contribution("noise", 3e-5, "x"), Contribution("fit", 4e-5, "y")))
    doc = angle.to_dict()
    assert doc["unit"] == "rad" and doc["value"] == pytest.approx(1e-4)
    assert doc["expanded_uncertainty"] == pytest.approx(1e-4, rel=1e-12)  # 2 x 5e-5
    assert doc["contributions"][0]["standard_uncertainty"] == pytest.approx(3e-5, rel=1e-12)


def test_instrument_covariance_sigmas_noise_floor_and_whitening_by_hand():
    """A tracker of MPE 10 um + 0.3 um/m along the beam and 15 um + 6 um/m across, read as two
    standard deviations; a point 3 m along x: its covariance diag(s_r^2, s_t^2, s_t^2) with s =
    MPE / 2; for points anywhere, u^T Sigma u = s_r^2 along the line of sight and s_t^2 across it;
    the per-axis noise floor sqrt(mean(s_r^2 + 2 s_t^2) / 3); the whitening W, in the base frame of
    a turned tracker, is symmetric with W Sigma_base W = floor^2 I. Catches the sigmas' ``/ 2.0``
    as ``/ 3.0``, ``radial[1] * distance`` as ``+``, ``(np.eye(3) - along)`` with its sign
    dropped, the floor's ``/ 3.0`` and the whitening's ``along / radial`` as ``along * radial``."""
    tracker = INSTRUMENTS["leica-at9xx"]
    s_r, s_t = (10 * UM + 0.3 * UM * 3.0) / 2, (15 * UM + 6 * UM * 3.0) / 2
    got = tracker.sigmas(np.array([3.0]))
    assert (got[0][0], got[1][0]) == pytest.approx((s_r, s_t), rel=1e-12)
    np.testing.assert_allclose(tracker.covariances([[3.0, 0.0, 0.0]])[0], np.diag([s_r ** 2, s_t ** 2, s_t ** 2]),
                               rtol=1e-12, atol=1e-30)
    rng = np.random.default_rng(5)
    points = rng.normal(size=(7, 3)) * 2.0
    distance = np.linalg.norm(points, axis=1)
    sr, st = (10 * UM + 0.3 * UM * distance) / 2, (15 * UM + 6 * UM * distance) / 2
    cov = tracker.covariances(points)
    u = points / distance[:, None]
    across = np.cross(u, rng.normal(size=(7, 3)))
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    np.testing.assert_allclose(np.einsum("ni,nij,nj->n", u, cov, u), sr ** 2, rtol=1e-10)
    np.testing.assert_allclose(np.einsum("ni,nij,nj->n", across, cov, across), st ** 2, rtol=1e-10)
    floor = math.sqrt(np.mean(sr ** 2 + 2 * st ** 2) / 3)
    assert tracker.per_axis_noise(points) == pytest.approx(floor, rel=1e-12)
    angle = 0.6
    trackerRbase = np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]])
    w = tracker.whitening(points, trackerRbase)
    sigma_base = np.transpose(trackerRbase) @ cov @ trackerRbase
    np.testing.assert_allclose(w, np.transpose(w, (0, 2, 1)), atol=1e-12)
    np.testing.assert_allclose(w @ sigma_base @ w, np.broadcast_to(floor ** 2 * np.eye(3), (7, 3, 3)),
                               rtol=1e-9, atol=1e-9 * floor ** 2)


def test_instruments_as_their_makers_state_them_and_a_given_mpe():
    """The table's trackers and total station in um, as their manuals state them (Leica AT9xx/AT500:
    10 um + 0.3 um/m radial, 15 um + 6 um/m transverse; API Radian 15 + 6 both ways; Leica TS60
    0.6 mm + 1 ppm, 4.8 um/m across), in the dict and the one-line description; a given MPE is
    used across the beam and, without a radial one, along it. Catches any of the table's figures
    changed and ``* 1e6`` as ``/ 1e6`` in the dict."""
    expected = {"leica-at9xx": ([10, 0.3], [15, 6]), "leica-at500": ([10, 0.3], [15, 6]),
                "api-radian": ([15, 6], [15, 6]), "leica-ts60": ([600, 1], [0, 4.8])}
    assert set(INSTRUMENTS) == set(expected)
    for name, (radial, transverse) in expected.items():
        doc = INSTRUMENTS[name].to_dict()
        assert doc["radial_mpe_um"] == pytest.approx(radial, rel=1e-9)
        assert doc["transverse_mpe_um"] == pytest.approx(transverse, rel=1e-9)
    assert INSTRUMENTS["leica-at9xx"].describe().startswith(
        "leica-at9xx: MPE 10 um + 0.3 um/m along the beam, 15 um + 6 um/m across it (")
    given = instrument_from(mpe=(20 * UM, 2 * UM))
    assert given.radial == pytest.approx((20 * UM, 2 * UM)) and given.transverse == pytest.approx((20 * UM, 2 * UM))
    both = instrument_from(mpe=(20 * UM, 2 * UM), radial_mpe=(5 * UM, 0.5 * UM))
    assert both.radial == pytest.approx((5 * UM, 0.5 * UM)) and both.transverse == pytest.approx((20 * UM, 2 * UM))
    assert instrument_from("Leica-AT9XX ") is INSTRUMENTS["leica-at9xx"]
    assert instrument_from() is None
    assert isinstance(given, Instrument)


def test_distances_default_to_the_frames_origin():
    """A point set's distances without an origin are from (0, 0, 0): the RMS of the points' norms.
    Catches the default origin ``(0.0, 0.0, 0.0)`` with a 1.0 in it."""
    points = np.array([[1.0, 2.0, 2.0], [2.0, 3.0, 6.0]])  # norms 3 and 7
    rms, least, largest = PointSet.of(points).distance()
    assert rms == pytest.approx(math.sqrt((9 + 49) / 2), rel=1e-12)
    assert largest == pytest.approx(7.0, rel=1e-12)  # the box's far corner is the second point
    assert least == pytest.approx(3.0, rel=1e-12)  # its near corner the first
