"""ISO 9283 path velocity figures (``iso9283/path.py``) on an L path run at a known speed per cycle,
against the closed form: on a straight edge every speed between neighbouring normal planes is the
cycle's speed, so v̄, AV, RV and FV are written out from the cycles' speeds alone, and a pair of
planes across a corner's left-out zone (whose chord is shorter than the path between) is no pair.
Each test names a planted change it was seen to catch.
"""

import math

import numpy as np
import pytest

from tcr_accuracy.iso9283.path import path_figures

#: The L: 0.2 m along x, then 0.2 m along y; its corner at sample 200.
EDGE = 0.2


def _l_path():
    u = np.linspace(0.0, 2 * EDGE, 401)
    points = np.column_stack([np.minimum(u, EDGE), np.maximum(u - EDGE, 0.0), np.zeros_like(u)])
    return points, u


def _cycle(speed, start, dt=0.002):
    """Readings of one run along the L at ``speed`` [m/s], from 10 mm before its start to 10 mm past
    its end, starting at time ``start``."""
    t = np.arange(0.0, (2 * EDGE + 0.02) / speed, dt)
    u = -0.01 + speed * t
    x = np.column_stack([np.minimum(u, EDGE), np.maximum(u - EDGE, 0.0), np.zeros_like(u)])
    return start + t, x


def test_speeds_between_planes_across_a_corners_zone_are_left_out():
    """Two cycles along the L at 0.10 and 0.11 m/s, a commanded speed of 0.1 m/s given without times
    (the middle half of the path counted): of 20 planes, those at 190 and 210 mm lie within 5 % of the
    length of the corner and are left out; the planes at 170 and 230 mm, on either side of the gap,
    are no neighbours (their chord, 42 mm, would read 0.0707 of the speed's 0.1). So every v_ij is its
    cycle's speed: v̄ = 0.105 m/s, AV = 5 %, RV = 3 S(0.10, 0.11) / 0.1, FV = 0. Catches the
    neighbours' test ``np.diff(s_i) < 1.5 * np.min(np.diff(s_i))`` as ``1.5 / np.min(...)`` or with
    1.5 changed to 3.5, and the middle half's lower bound 0.25 changed to 1.25."""
    points, s = _l_path()
    cycles = [_cycle(0.10, 0.0), _cycle(0.11, 10.0)]
    got = path_figures(points, s, cycles, planes=20, corners=(200,), speed=0.1)
    s_i = 0.4 * (np.arange(20) + 0.5) / 20
    kept = s_i[np.abs(s_i - EDGE) >= 0.05 * 0.4]
    np.testing.assert_allclose(got.s, kept, rtol=1e-12)
    assert got.v_mean == pytest.approx(0.105, rel=1e-9)
    assert got.av == pytest.approx(0.05, rel=1e-7)
    assert got.rv == pytest.approx(3 * np.std([0.10, 0.11], ddof=1) / 0.1, rel=1e-7)
    assert got.fv == pytest.approx(0.0, abs=1e-9)
    # the counted pairs: neighbouring planes both strictly inside (0.1, 0.3) m, not across the gap
    middle = kept[(kept > 0.1) & (kept < 0.3)]
    assert middle.tolist() == pytest.approx([0.11, 0.13, 0.15, 0.17, 0.23, 0.25, 0.27, 0.29])
    chord = math.hypot(EDGE - 0.17, 0.23 - EDGE)
    assert chord / 0.06 == pytest.approx(0.7071, rel=1e-4)  # what a pair across the gap would read


def test_a_crossing_farther_than_a_tenth_of_the_path_from_its_point_is_none():
    """A straight 0.4 m path along x, three cycles running parallel to it 35 mm, 39.9 mm and 40.1 mm off
    in y (a tenth of the length is 40 mm): the first two cross every one of the 10 planes at their
    offset, the third crosses none (10 missed, NaN). Catches the limit ``CROSSING_LIMIT * s[-1]`` as
    ``+`` (0.5 m) and ``CROSSING_LIMIT`` 0.10 changed."""
    s = np.linspace(0.0, 0.4, 401)
    points = np.column_stack([s, np.zeros_like(s), np.zeros_like(s)])
    cycles = []
    for j, off in enumerate((0.035, 0.0399, 0.0401)):
        t = np.linspace(0.0, 4.4, 221)
        cycles.append((t + 10 * j, np.column_stack([-0.02 + 0.1 * t, np.full_like(t, off), np.zeros_like(t)])))
    got = path_figures(points, s, cycles, planes=10)
    s_i = 0.4 * (np.arange(10) + 0.5) / 10
    np.testing.assert_allclose(got.attained[0], np.column_stack([s_i, np.full(10, 0.035), np.zeros(10)]), atol=1e-12)
    np.testing.assert_allclose(got.attained[1, :, 1], 0.0399, atol=1e-12)
    assert np.isnan(got.attained[2]).all() and np.isnan(got.times[2]).all()
    assert got.missed == 10
    assert got.at == pytest.approx(math.hypot(0.0, (0.035 + 0.0399) / 2), rel=1e-9)


def test_corner_deviations_use_the_pass_by_the_corner_not_an_earlier_visit_near_it():
    """A cycle first comes within 42 mm of the L's corner for two readings past it (60 mm beyond it
    along x), leaves, then runs up the x edge and cuts the corner by a quarter circle of 10 mm radius:
    its CR is the corner's distance to that arc (sqrt 2 - 1) x 10 mm and its CO 0, the earlier visit
    left out (it would read a CO of 60 mm). Catches the runs' split ``np.flatnonzero(np.diff(near) >
    1) + 1`` as ``** 1`` (the earlier visit's last reading joined to the pass)."""
    from tcr_accuracy.iso9283.path import corner_deviations

    points, _ = _l_path()
    stray = np.array([[0.26, 0.02, 0.0], [0.26, 0.03, 0.0]])
    away = np.array([[0.6, 0.6, 0.0], [0.0, 0.5, 0.0]])
    x_edge = np.column_stack([np.linspace(0.0, 0.19, 191), np.zeros(191), np.zeros(191)])
    angle = np.linspace(0.0, np.pi / 2, 91)[1:]
    arc = np.column_stack([0.19 + 0.01 * np.sin(angle), 0.01 - 0.01 * np.cos(angle), np.zeros(90)])
    y_edge = np.column_stack([np.full(190, EDGE), np.linspace(0.011, 0.2, 190), np.zeros(190)])
    cycle = np.vstack([stray, away, x_edge, arc, y_edge])
    (corner,) = corner_deviations(points, (200,), [cycle])
    np.testing.assert_allclose(corner.point, [EDGE, 0.0, 0.0], atol=1e-15)
    assert corner.cr[0] == pytest.approx((math.sqrt(2) - 1) * 0.01, rel=1e-3)
    assert corner.co[0] == 0.0
