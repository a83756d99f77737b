"""The ISO 9283 pose formulas (``iso9283/formulas.py``) at the counts where they change, written out
from clause 7.2 on plain Python: a pose read once has AP alone, twice AP with l̄ (S_l and RP need
three), three times everything; orientation figures likewise; and labels in natural order (whole
numbers by value first, then names with their digit runs as numbers, digits before letters).
Each test names a planted change it was seen to catch.
"""

import math

import numpy as np
import pytest

from tcr_accuracy.iso9283.formulas import iso_figures, label_key, ordered, pose_figures, pose_name


def _distances(points):
    n = len(points)
    bar = [sum(p[a] for p in points) / n for a in range(3)]
    return bar, [math.dist(p, bar) for p in points]


def test_a_pose_read_once_twice_and_three_times_by_hand():
    """Readings (mm) of a pose commanded at (100, 200, 300) mm: once, AP only (l̄, S_l, RP None); twice,
    AP and l̄ = half their distance (S_l, RP None); three times, l̄, S_l (n - 1) and RP = l̄ + 3 S_l;
    with orientation deviations, AP_a.. their mean, RP_a.. three standard deviations (n - 1) from
    three readings on, None below. Catches ``n >= 2`` for l̄ changed to 1 or 3, ``MIN_REPEATS`` 3
    changed, ``3.0 * l_std`` and ``3.0 * deviations.std`` changed, and the ddof 1 changed."""
    commanded = [0.1, 0.2, 0.3]
    readings = [[0.1004, 0.1998, 0.3011], [0.1001, 0.2003, 0.3006], [0.0998, 0.2001, 0.3013]]
    turns = [[1e-4, -2e-4, 3e-4], [2e-4, 0.0, 1e-4], [-1e-4, 1e-4, 2e-4]]
    for n in (1, 2, 3):
        got = pose_figures(readings[:n], commanded, turns[:n], pose_id="7")
        bar, l = _distances(readings[:n])
        ap = [bar[a] - commanded[a] for a in range(3)]
        assert got.n == n and got.pose_id == "7"
        assert got.ap == pytest.approx(math.sqrt(sum(v * v for v in ap)), rel=1e-12)
        np.testing.assert_allclose(got.ap_xyz, ap, rtol=1e-10)
        np.testing.assert_allclose(got.ap_abc, [sum(t[a] for t in turns[:n]) / n for a in range(3)], rtol=1e-12)
        if n == 1:
            assert got.l_mean is None and got.l_std is None and got.rp is None and got.rp_abc is None
            continue
        l_mean = sum(l) / n
        assert got.l_mean == pytest.approx(l_mean, rel=1e-12)
        if n == 2:
            assert got.l_mean == pytest.approx(math.dist(readings[0], readings[1]) / 2, rel=1e-12)
            assert got.l_std is None and got.rp is None and got.rp_abc is None
            continue
        s_l = math.sqrt(sum((v - l_mean) ** 2 for v in l) / (n - 1))
        assert got.l_std == pytest.approx(s_l, rel=1e-10)
        assert got.rp == pytest.approx(l_mean + 3 * s_l, rel=1e-12)
        for a in range(3):
            mean = sum(t[a] for t in turns) / n
            std = math.sqrt(sum((t[a] - mean) ** 2 for t in turns) / (n - 1))
            assert got.rp_abc[a] == pytest.approx(3 * std, rel=1e-10)


def test_labels_in_natural_order_whole_numbers_first_digits_before_letters():
    """Whole numbers by value (-3, 2, +4 as 4, 10), then names part by part, digit runs as numbers and a
    digit run before a letter run at the same place (2b before a, P2, P10, PA; S01.P5 before S02.P1); a pose named
    by a number is P<number>. Catches ``(0, int(text), ())`` with its 0 changed to 1 (numbers among
    names) and ``(0, int(part), "")`` with its 0 changed to 1 or 2 (digits after letters)."""
    labels = ["PA", "P10", "10", "S02.P1", "P2", "+4", "S01.P5", "-3", "2", "P", "a", "2b"]
    assert ordered(labels) == ["-3", "2", "+4", "10", "2b", "P", "P2", "P10", "PA", "S01.P5", "S02.P1", "a"]
    assert label_key("+4") == (0, 4, ())
    assert pose_name("3") == "P3" and pose_name("P3") == "P3" and pose_name("-3") == "-3"


def test_directions_of_one_pose_and_a_pose_of_one_direction():
    """Pose 1 approached from +x and -x (two readings each), pose 2 from +x only: a vAP for pose 1 (the
    distance of its two barycentres) and none for pose 2 (one direction). Catches ``len(group) < 2``
    changed to 1 (a vAP of one direction, 0) or to 3 (none for two)."""
    positions = np.array([[0.0, 0.0, 0.0], [0.0002, 0.0, 0.0], [0.001, 0.0003, 0.0], [0.0012, 0.0001, 0.0],
                          [0.5, 0.0, 0.0], [0.5, 0.0001, 0.0]])
    pose = ["1", "1", "1", "1", "2", "2"]
    approach = ["+x", "+x", "-x", "-x", "+x", "+x"]
    commanded = np.array([[0.0, 0.0, 0.0]] * 4 + [[0.5, 0.0, 0.0]] * 2)
    figures = iso_figures(pose, positions, commanded, approach=approach)
    (variation,) = figures.directional
    assert variation.pose_id == "1" and variation.approaches == ("+x", "-x")
    assert variation.vap == pytest.approx(math.dist([0.0001, 0.0, 0.0], [0.0011, 0.0002, 0.0]), rel=1e-12)
