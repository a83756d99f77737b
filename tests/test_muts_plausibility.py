"""The fitted TCP offset against the given one and the checks of a geometry that moves nothing
(``diagnosis/plausibility.py``), against figures written out here (issue 36): the tool twist's translation
by the closed form of SE(3)'s exponential, the distance and its standard error, every figure of the words
in mm, the sentence a flagged offset adds, and no tilt listed for a geometry without one. Each test names a
planted change it was seen to catch."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.diagnosis.plausibility import _tcp_check, geometry_checks
from tcr_accuracy.model.errors import ErrorModel

MM = 1e-3


def _translation_of_twist(v, w):
    """The translation of exp([v, w]) in SE(3): V(w) v, V = I + (1 - cos t) / t^2 W + (t - sin t) / t^3 W^2."""
    t = np.linalg.norm(w)
    skew = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return (np.eye(3) + (1 - math.cos(t)) / t**2 * skew + (t - math.sin(t)) / t**3 * skew @ skew) @ v


def _mm(v):
    return "(" + ", ".join(f"{c / MM:.4g}" for c in v) + f") mm ({np.linalg.norm(v) / MM:.4g} mm away)"


def test_a_turned_tool_twists_offset_against_the_given_one_in_every_figure_of_its_words():
    """A tool twist of (30.1234, 1.5, -2) mm and a turn of (0.02, -0.01, 0.03) rad: the measured point sits at
    its exponential's translation (closed form); against a given (31, 0, 0) mm its distance, the standard error
    of that distance from the per-axis errors (NaN read as 0), the words with each coordinate and norm in mm to
    4 digits, the distance to 3 and its error to 2, the tolerance in mm, and the flagged sentence; the JSON in
    mm. Seen failing on the words' ``c * 1e3`` turned to ``* 1001.0``, ``np.linalg.norm(v) * 1e3`` to ``*
    999.0``, ``tolerance.tcp_offset * 1e3`` to ``* 1001.0`` and on the std's ``(difference / size) ** 2``
    turned to ``** 3``."""
    v, w = np.array([30.1234, 1.5, -2.0]) * MM, np.array([0.02, -0.01, 0.03])
    x = np.concatenate([np.zeros(4), v, w, [0.0]])
    given = np.array([31.0, 0.0, 0.0]) * MM
    sigma = {"tcp.dx": 0.01 * MM, "tcp.dy": float("nan"), "tcp.dz": 0.03 * MM}
    check = _tcp_check(x, SimpleNamespace(tool_slice=slice(4, 10)), sigma, "tcp", given,
                       SimpleNamespace(tcp_offset=1.2499 * MM), "tool0")
    fitted = _translation_of_twist(v, w)
    difference = fitted - given
    size = np.linalg.norm(difference)
    std = math.sqrt((difference[0] / size) ** 2 * (0.01 * MM) ** 2 + (difference[2] / size) ** 2 * (0.03 * MM) ** 2)
    assert check.value == pytest.approx(size, rel=1e-12) and check.std == pytest.approx(std, rel=1e-12)
    assert check.flagged and check.what == "tcp_offset" and check.subject == "tool0"
    assert check.text == (f"the measured point is fitted at {_mm(fitted)} from the tool frame tool0, the given offset "
                          f"is {_mm(given)}: {size / MM:.3g} mm apart (+- {std / MM:.2g}), beyond the 1.2 mm "
                          "plausible for a tool mounted from a drawing; the fit or the given offset is off (a tool or "
                          "reflector not where it is said to be, or the geometry fit taking up the tool's length)")
    doc = check.to_dict()
    assert doc["value_mm"] == pytest.approx(size / MM, rel=1e-12) and doc["std_mm"] == pytest.approx(std / MM)
    assert doc["tolerance_mm"] == pytest.approx(1.2499, rel=1e-12)
    np.testing.assert_allclose(doc["fitted_mm"], fitted / MM, rtol=1e-12)
    np.testing.assert_allclose(doc["given_mm"], [31.0, 0.0, 0.0], rtol=1e-12)


def test_an_offset_within_its_tolerance_without_errors_or_at_the_given_place():
    """Fitted (31.2, 0.4, 0) mm, no turn, given (31, 0, 0) mm, no errors known (no parameter name): 0.447 mm
    apart (+- 0), within the 1 mm, no further sentence; fitted at the given place: 0 apart, no error said.
    Seen failing on ``size > tolerance.tcp_offset`` fed ``size * 3`` and on ``if size > 0`` turned to
    ``> 1`` (0 / 0)."""
    x = np.zeros(6)
    x[:3] = [31.2 * MM, 0.4 * MM, 0.0]
    given = np.array([31.0, 0.0, 0.0]) * MM
    tolerance = SimpleNamespace(tcp_offset=1.0 * MM)
    within = _tcp_check(x, SimpleNamespace(tool_slice=slice(0, 6)), {}, None, given, tolerance, "flange")
    size = math.hypot(0.2, 0.4)
    assert within.value == pytest.approx(size * MM, rel=1e-12) and within.std == 0.0 and not within.flagged
    assert within.text.endswith(f"{size:.3g} mm apart (+- 0), within the 1 mm plausible for a tool mounted from a "
                                "drawing")
    x[:3] = given
    same = _tcp_check(x, SimpleNamespace(tool_slice=slice(0, 6)), {}, "tcp", given, tolerance, "flange")
    assert same.value == 0.0 and same.std is None and "0 mm apart, within" in same.text


def test_a_geometry_that_moves_nothing_lists_no_tilt(ur5):
    """The UR5's error vector all zeros, no poses: no axis tilt listed (each is 0), no tool frame checks; a
    given offset still checked (the fitted one 0). Seen failing on ``size == 0.0`` turned to ``== 1.0``."""
    em = ErrorModel(ur5)
    assert geometry_checks(ur5, np.zeros((0, 6)), em.zeros(), {}) == []
    only = geometry_checks(ur5, np.zeros((0, 6)), em.zeros(), {}, "frames.tool", np.array([0.0, 0.0, 0.031]))
    assert [c.what for c in only] == ["tcp_offset"]
    assert only[0].value == pytest.approx(0.031, rel=1e-12)
