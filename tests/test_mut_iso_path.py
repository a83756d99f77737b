"""ISO 9283 path characteristics (``iso9283/path.py``, clause 8) on paths built here, against the
standard's definitions written out on numpy: the normal planes at s_i = L (i - 1/2) / m, the
crossings by ``np.interp`` along a monotonic stream, AT, RT, AV, RV, FV and the corner
deviations CR and CO by hand. Each test names a planted change it was seen to catch.
"""

import math

import numpy as np
import pytest

from tcr_accuracy import load_robot
from tcr_accuracy.io.measurement_set import MeasurementSet
from tcr_accuracy.iso9283.path import CORNER_ZONE, CROSSING_LIMIT, path_figures

MM = 1e-3
L = 0.4


def _line(n=401):
    """A straight commanded path along x, 0.4 m, densely sampled: points (n, 3) and arc length."""
    s = np.linspace(0.0, L, n)
    return np.column_stack([s, np.zeros(n), np.zeros(n)]), s


def _cycles(rng, n_cycles=4, dt=0.004):
    """Each cycle's readings: x(t) monotonic at about 0.1 m/s with a cycle's own speed and a ripple,
    y and z off the line by a cycle's own offset and a wave along x (mm)."""
    out = []
    for j in range(n_cycles):
        t = np.arange(0.0, 4.6, dt) + 10.0 * j
        tau = t - t[0]
        speed = 0.1 * (1 + 0.01 * (j - 1.5))
        x = -0.02 + speed * tau + 0.0008 * np.sin(2 * np.pi * tau / 1.3 + j)
        y = (0.1 * (j - 1.5) + 0.3 * np.sin(2 * np.pi * x / L)) * MM + rng.normal(0, 0.01 * MM, len(t))
        z = (0.05 + 0.2 * x / L) * MM + rng.normal(0, 0.01 * MM, len(t))
        out.append((t, np.column_stack([x, y, z])))
    return out


def test_at_rt_and_velocity_figures_of_a_straight_path_written_out():
    """Four cycles along a 0.4 m line at about 0.1 m/s (their own speeds, a ripple), off it by mm
    waves: on m = 20 planes s_i = L (i - 1/2) / m, each cycle's crossing is ``np.interp`` of its
    readings at x = s_i; AT = max |bar_i - c_i|, RT = max (l̄_i + 3 S_li), v_ij between neighbouring
    planes, AV = (v̄ - v_c) / v_c, RV = 3 S(cycle means) / v_c, FV = max_j (max_i - min_i) v_ij,
    all to 1e-9. Catches the planes' ``(np.arange(m) + 0.5) / m`` as ``+ 1.5``, RT's ``3.0 *
    li.std`` as ``4.0 *`` and ``ddof=1`` as ``ddof=2``, AV's ``(v_mean - speed) / speed`` as
    ``(v_mean + speed)``, RV's ``3.0 *`` changed, the crossing's interpolation weight's sign flipped
    (``w = -d / ...`` as ``d / ...``) and the crossing time's ``t[k] + w * (...)`` as ``- w``."""
    rng = np.random.default_rng(101)
    points, s = _line()
    cycles = _cycles(rng)
    m = 20
    v_c = 0.1
    got = path_figures(points, s, cycles, planes=m, commanded_times=s / v_c)
    s_i = L * (np.arange(1, m + 1) - 0.5) / m
    np.testing.assert_allclose(got.s, s_i, rtol=1e-12)
    np.testing.assert_allclose(got.commanded, np.column_stack([s_i, np.zeros(m), np.zeros(m)]), atol=1e-15)
    attained = np.array([[[sx, np.interp(sx, x[:, 0], x[:, 1]), np.interp(sx, x[:, 0], x[:, 2])] for sx in s_i]
                         for _, x in cycles])
    when = np.array([[np.interp(sx, x[:, 0], t) for sx in s_i] for t, x in cycles])
    np.testing.assert_allclose(got.attained, attained, atol=1e-12)
    np.testing.assert_allclose(got.times, when, atol=1e-9)
    bar = attained.mean(axis=0)
    deviation = np.linalg.norm(bar - got.commanded, axis=1)
    assert got.at == pytest.approx(deviation.max(), rel=1e-9)
    assert got.at_s == pytest.approx(s_i[np.argmax(deviation)], rel=1e-12)
    l = np.linalg.norm(attained - bar, axis=2)
    rt_planes = l.mean(axis=0) + 3 * l.std(axis=0, ddof=1)
    np.testing.assert_allclose(got.rt_planes, rt_planes, rtol=1e-9)
    assert got.rt == pytest.approx(rt_planes.max(), rel=1e-9) and got.rt_s == pytest.approx(s_i[np.argmax(rt_planes)])
    v = np.linalg.norm(np.diff(attained, axis=1), axis=2) / np.diff(when, axis=1)
    assert got.speed == pytest.approx(v_c, rel=1e-9)
    assert got.v_mean == pytest.approx(v.mean(), rel=1e-9)
    assert got.av == pytest.approx((v.mean() - v_c) / v_c, rel=1e-7, abs=1e-12)
    assert got.rv == pytest.approx(3 * v.mean(axis=1).std(ddof=1) / v_c, rel=1e-7)
    assert got.fv == pytest.approx(max(row.max() - row.min() for row in v), rel=1e-9)
    assert got.missed == 0 and got.n_cycles == 4 and got.corners == []


def test_without_commanded_times_the_middle_half_is_taken_at_the_given_speed():
    """A speed given without commanded times: the velocity figures are taken over the planes in the
    middle half of the path (0.25 L < s_i < 0.75 L). Catches the bounds 0.25 and 0.75 changed (to
    1.25 or 1.75) and ``1.5 * np.min(np.diff(s_i))`` as ``0.5 *`` (no pair adjacent)."""
    rng = np.random.default_rng(5)
    points, s = _line()
    cycles = _cycles(rng, n_cycles=3)
    m = 40
    got = path_figures(points, s, cycles, planes=m, speed=0.1)
    s_i = L * (np.arange(1, m + 1) - 0.5) / m
    middle = np.flatnonzero((s_i > 0.25 * L) & (s_i < 0.75 * L))
    attained = np.array([[[sx, np.interp(sx, x[:, 0], x[:, 1]), np.interp(sx, x[:, 0], x[:, 2])] for sx in s_i]
                         for _, x in cycles])[:, middle]
    when = np.array([[np.interp(sx, x[:, 0], t) for sx in s_i] for t, x in cycles])[:, middle]
    v = np.linalg.norm(np.diff(attained, axis=1), axis=2) / np.diff(when, axis=1)
    assert got.v_mean == pytest.approx(v.mean(), rel=1e-9)
    assert got.fv == pytest.approx(max(row.max() - row.min() for row in v), rel=1e-9)
    assert got.av == pytest.approx((v.mean() - 0.1) / 0.1, rel=1e-7, abs=1e-12)
    assert path_figures(points, s, cycles, planes=m).av is None  # no speed: no velocity figures


def test_with_commanded_times_only_the_planes_at_constant_commanded_speed_count():
    """Commanded times of a trapezoidal speed profile (0.1 m/s, ramps over the first and last 40 mm):
    the velocity figures are over the planes where the commanded speed is within 0.1 % of 0.1 m/s
    (s_i from 50 to 350 mm of 20 planes), v_c the largest commanded speed. Catches
    ``CONSTANT_SPEED`` 0.001 as 1.001 (every plane counted)."""
    rng = np.random.default_rng(11)
    points, s = _line()
    cycles = _cycles(rng, n_cycles=3)
    speed = 0.1 * np.maximum(np.minimum(1.0, np.minimum(s, L - s) / 0.04), 0.2)
    commanded_times = np.concatenate([[0.0], np.cumsum(np.diff(s) / (0.5 * (speed[1:] + speed[:-1])))])
    m = 20
    got = path_figures(points, s, cycles, planes=m, commanded_times=commanded_times)
    s_i = L * (np.arange(1, m + 1) - 0.5) / m
    steady = np.flatnonzero((s_i > 0.04) & (s_i < L - 0.04))
    assert len(steady) == 16
    attained = np.array([[[sx, np.interp(sx, x[:, 0], x[:, 1]), np.interp(sx, x[:, 0], x[:, 2])] for sx in s_i]
                         for _, x in cycles])[:, steady]
    when = np.array([[np.interp(sx, x[:, 0], t) for sx in s_i] for t, x in cycles])[:, steady]
    v = np.linalg.norm(np.diff(attained, axis=1), axis=2) / np.diff(when, axis=1)
    assert got.speed == pytest.approx(0.1, rel=1e-9)
    assert got.v_mean == pytest.approx(v.mean(), rel=1e-9)
    assert got.fv == pytest.approx(max(row.max() - row.min() for row in v), rel=1e-9)


def _distance_to_segments(point, polyline):
    best = math.inf
    for a, b in zip(polyline[:-1], polyline[1:]):
        ab = b - a
        w = min(max(float(np.dot(point - a, ab) / np.dot(ab, ab)), 0.0), 1.0)
        best = min(best, float(np.linalg.norm(a + w * ab - point)))
    return best


def test_corner_round_off_overshoot_and_the_planes_left_out_near_a_corner():
    """An L path, 0.2 m along x then 0.2 m along y, its corner at (0.2, 0, 0); three cycles run up
    the x edge, overshoot beyond the corner by 0.3, 0.6 and 0 mm while turning, and go up the y edge.
    The planes within 5 % of the length of the corner are left out (s_i = 0.19 and 0.21 of 20); CR
    is the smallest distance from the corner to each cycle's polyline, CO its largest excursion
    along x past it (0 when it cuts the corner), by hand. Catches ``CORNER_ZONE`` 0.05 changed, CO's
    ``max(0.0, ...)``
    as ``max(1.0, ...)`` and the past-the-corner test ``> 0`` as ``> 1``."""
    n = 201
    leg = np.linspace(0.0, 0.2, n)
    points = np.vstack([np.column_stack([leg, np.zeros(n), np.zeros(n)]),
                        np.column_stack([np.full(n - 1, 0.2), leg[1:], np.zeros(n - 1)])])
    s = np.concatenate([leg, 0.2 + leg[1:]])
    corner = np.array([0.2, 0.0, 0.0])
    cycles = []
    for j, (over, cut) in enumerate(((0.3 * MM, 0.0), (0.6 * MM, 0.0), (0.0, 0.4 * MM))):
        up_x = np.column_stack([np.linspace(-0.01, 0.2 - 2 * MM - cut, 300), np.zeros(300), np.zeros(300)])
        turn = np.array([[0.2 + over - cut, 1.0 * MM + cut, 0.0], [0.2 + over / 3, 2.5 * MM, 0.0]])
        up_y = np.column_stack([np.full(300, 0.2), np.linspace(4 * MM, 0.21, 300), np.zeros(300)])
        x = np.vstack([up_x, turn, up_y])
        cycles.append((0.01 * np.arange(len(x)) + 100.0 * j, x))
    got = path_figures(points, s, cycles, planes=20, corners=[n - 1])
    s_i = 0.4 * (np.arange(1, 21) - 0.5) / 20
    kept = np.abs(s_i - 0.2) >= CORNER_ZONE * 0.4
    assert CORNER_ZONE == 0.05 and CROSSING_LIMIT == 0.10
    np.testing.assert_allclose(got.s, s_i[kept], rtol=1e-12)
    assert len(got.s) == 18
    (c,) = got.corners
    np.testing.assert_allclose(c.point, corner)
    for j, (_, x) in enumerate(cycles):
        near = x[np.linalg.norm(x - corner, axis=1) < 0.1]
        assert c.cr[j] == pytest.approx(_distance_to_segments(corner, near), rel=1e-9)
        past = near[near[:, 1] > 0]
        assert c.co[j] == pytest.approx(max(0.0, float(np.max(past[:, 0] - 0.2))), abs=1e-12)
    assert c.co[1] == pytest.approx(0.6 * MM, rel=1e-9) and c.co[2] == 0.0


def test_projection_on_a_sampled_path_is_the_nearest_point_of_its_segments():
    """Points scattered within 5 mm of a sampled circle arc: each foot point and its arc length equal
    a brute-force search over every segment of the polyline, written out here. Catches the foot's
    ``s[a] + w * (s[b] - s[a])`` as ``- w``, the neighbour ``k - 1`` as ``k - 2`` and the clip
    bound 1.0 as 2.0."""
    from tcr_accuracy.iso9283.path_evaluate import project_on_path
    from tcr_accuracy.iso9283.path_plan import arc_length

    angle = np.linspace(0.0, 1.5, 151)
    path = np.column_stack([0.2 * np.cos(angle), 0.2 * np.sin(angle), 0.01 * angle])
    s = arc_length(path)
    rng = np.random.default_rng(4)
    at = rng.uniform(-0.01, 1.51, 60)
    points = np.column_stack([0.2 * np.cos(at), 0.2 * np.sin(at), 0.01 * at]) + rng.normal(0, 2e-3, (60, 3))
    feet, arc = project_on_path(points, path, s)
    for point, foot, got_s in zip(points, feet, arc):
        best = (math.inf, None, None)
        for k in range(len(path) - 1):
            ab = path[k + 1] - path[k]
            w = min(max(float(np.dot(point - path[k], ab) / np.dot(ab, ab)), 0.0), 1.0)
            candidate = path[k] + w * ab
            d = float(np.linalg.norm(point - candidate))
            if d < best[0]:
                best = (d, candidate, s[k] + w * (s[k + 1] - s[k]))
        np.testing.assert_allclose(foot, best[1], atol=1e-12)
        assert got_s == pytest.approx(best[2], abs=1e-12)


@pytest.mark.parametrize("ratio, words", [(1e-3, "the times look like ms"), (1e3, "the times look like s where"),
                                          (0.02, "check the unit of time_s"), (40.0, "check the unit of time_s"),
                                          (0.3e-3, "look like ms"), (3e3, "look like s where"),
                                          (0.25e-3, "check the unit"), (3.5e-3, "check the unit"),
                                          (0.25e3, "check the unit"), (3.5e3, "check the unit")])
def test_a_stream_at_an_impossible_speed_names_the_unit_it_looks_like(ratio, words):
    """A stream measured moving ``ratio`` times the commanded 100 mm/s: beyond 30 times either way it
    is refused naming the time unit it looks like (ms where 1e-3, s against ms where 1e3, within a
    factor 3.3 of those), quoting both speeds in mm/s; within 30 times it passes. Catches
    ``SPEED_RATIO_LIMIT`` 30 changed, the hint's bounds ``0.3e-3`` / ``3e3`` moved and the speeds'
    ``* 1e3`` as ``/ 1e3``."""
    from types import SimpleNamespace

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.path_evaluate import SPEED_RATIO_LIMIT, CommandedRun, _check_speed

    run = CommandedRun("line", 50.0, np.zeros((2, 3)), np.zeros(2), np.zeros((2, 6)), None, 0.1, ())
    stream = SimpleNamespace(source="stream.csv")
    assert SPEED_RATIO_LIMIT == 30.0
    _check_speed(stream, run, SimpleNamespace(v_mean=0.1 * 29.0, speed=0.1))
    _check_speed(stream, run, SimpleNamespace(v_mean=0.1 / 29.0, speed=0.1))
    with pytest.raises(InputError) as refused:
        _check_speed(stream, run, SimpleNamespace(v_mean=0.1 * ratio, speed=0.1))
    message = str(refused.value)
    assert words in message and "line at 50 %" in message
    assert f"{100 * ratio:.4g} mm/s where it is commanded at 100 mm/s" in message


def test_interleaved_cycles_are_refused_at_the_first_reading_of_the_later_one():
    """Cycle 2's readings (rows 12-15 of the file, from 3.0 s) start before cycle 1's last reading
    (at 3.5 s): refused naming cycle 2's first row and time and cycle 1's end. Catches ``inside =
    b[0]`` as ``b[-1]`` (the last reading named)."""
    from types import SimpleNamespace

    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.path_evaluate import CommandedRun, _check_apart

    time_s = np.array([0.0, 1.0, 2.0, 3.5, 3.0, 4.0, 5.0, 6.0])
    stream = SimpleNamespace(source="stream.csv", time_s=time_s, rows=np.arange(8) + 8)
    run = CommandedRun("circle_small", 10.0, np.zeros((2, 3)), np.zeros(2), np.zeros((2, 6)), None, 0.1, ())
    _check_apart(stream, run, [("1", np.array([0, 1, 2])), ("2", np.array([4, 5, 6, 7]))])  # apart: passes
    with pytest.raises(InputError) as refused:
        _check_apart(stream, run, [("2", np.array([4, 5, 6, 7])), ("1", np.array([0, 1, 2, 3]))])
    assert str(refused.value) == ("stream.csv: row 12, column cycle: cycle 2 of the circle_small at 10 % starts at 3 s, "
                                  "before cycle 1 ends (3.5 s): a cycle is one run along the path, one block of "
                                  "readings in time; label each run's readings with its cycle")


def test_commanded_runs_name_the_row_at_fault_and_read_the_speed_in_m_per_s():
    """A path of 2 points is refused naming it; a commanded file of two paths (rows 2-7 and 8-12, CSV rows): each a run with its speed_mm_s read
    in m/s; a path resumed after the other is refused at its first resumed row; a point repeated at
    the row repeating it; a commanded time that does not increase at its row. Catches each
    ``argmax(...) + 1`` as ``+ 2`` or ``- 1`` (the row before or after named) and ``* 1e-3`` of the
    speed as ``* 1e-2``."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.path_evaluate import commanded_runs

    ur5 = load_robot("ur5")
    base = np.array([0.3, -1.2, 1.4, -1.8, -1.57, 0.2])
    q = base + np.outer(np.arange(11), [0.02, 0.01, -0.01, 0.0, 0.0, 0.0])
    path = np.array(["line"] * 6 + ["circle_small"] * 5, dtype=object)

    def file(q, path, time_s=None):
        return MeasurementSet(joint_names=list(ur5.joint_names), q=q, position=np.zeros((len(q), 3)), source="c.csv",
                              rows=np.arange(len(q)) + 2, time_s=time_s,
                              annotations={"path": path, "speed_mm_s": np.full(len(q), 250.0)})

    with pytest.raises(InputError, match=r"^c\.csv: row 2: the line path has 2 point\(s\); a commanded path needs"):
        commanded_runs(ur5, file(q[:2], path[:2]))
    runs = commanded_runs(ur5, file(q, path))
    assert [(r.path, len(r.s)) for r in runs] == [("line", 6), ("circle_small", 5)]
    assert runs[0].speed == pytest.approx(0.25, rel=1e-12)
    mixed = path.copy()
    mixed[8] = "line"
    with pytest.raises(InputError, match=r"^c\.csv: row 10: the line path continues after other rows"):
        commanded_runs(ur5, file(q, mixed))
    repeated = q.copy()
    repeated[3] = repeated[2]
    with pytest.raises(InputError, match=r"^c\.csv: row 5: the same commanded point as the row before"):
        commanded_runs(ur5, file(repeated, path))
    times = np.arange(11) * 0.1
    times[4] = times[3]
    with pytest.raises(InputError, match=r"^c\.csv: row 6, column time_s: the commanded time does not increase"):
        commanded_runs(ur5, file(q, path, times))
