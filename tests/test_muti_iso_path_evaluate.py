"""A measured path test's evaluation (``iso9283/path_evaluate.py``): the closest-point frame on a
long stream (the readings it fits on, at most 2000 per run drawn by a generator seeded 0, and its
residual RMS against a brute-force distance to the commanded polyline), the stream's runs and
cycles where a label is missing or a time repeats, and the notes on planes missed and speeds not
given. Each test names a planted change it was seen to catch.
"""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tcr_accuracy.iso9283.path_evaluate import ICP_SAMPLES, fit_stream_frame
from tcr_accuracy.iso9283.path_plan import arc_length


def _distance_to_polyline(point, polyline):
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    w = np.clip(np.sum((point - a) * ab, axis=1) / np.sum(ab * ab, axis=1), 0.0, 1.0)
    return float(np.min(np.linalg.norm(a + w[:, None] * ab - point, axis=1)))


def test_a_long_run_is_fitted_on_2000_readings_and_its_residual_is_their_rms_distance_to_the_path():
    """A helix commanded in 400 samples, read 2600 times along it (two cycles of 1300) 20-50 um off it
    across the path, in a tracker frame turned 1.2 rad and 2 m away: the frame is fitted on 2000 of
    the readings (those ``np.random.default_rng(0).choice`` picks, sorted), and its residual RMS is the
    RMS of their distances to the helix in the fitted frame, by brute force, to 1e-9 relative (a helix slides along
    itself: the frame itself is not asked for). Catches ``ICP_SAMPLES`` 2000 changed, the draw's seed 0 changed,
    and the residual's ``np.sqrt(np.mean(residual ** 2))`` with its 2 changed."""
    u = np.linspace(0.0, 1.0, 400)
    helix = np.column_stack([0.2 * np.cos(5 * u), 0.2 * np.sin(5 * u), 0.3 * u]) + [0.5, -0.2, 0.4]
    run = SimpleNamespace(points=helix, s=arc_length(helix))
    rng = np.random.default_rng(12)
    rotation = Rotation.from_rotvec([0.5, 0.2, -1.1]).as_matrix()
    translation = np.array([1.6, 1.1, -0.5])
    cycles, positions = [], []
    for c in range(2):
        s = np.sort(rng.uniform(0.0, run.s[-1], 1300))
        on = np.stack([np.interp(s, run.s, helix[:, a]) for a in range(3)], axis=1)
        radial = on - [0.5, -0.2, 0.0]
        radial[:, 2] = 0.0
        radial /= np.linalg.norm(radial, axis=1, keepdims=True)
        off = on + radial * rng.uniform(20e-6, 50e-6, (len(s), 1)) * rng.choice([-1.0, 1.0], (len(s), 1))
        positions.append(off @ rotation.T + translation)
        cycles.append(np.arange(c * 1300, (c + 1) * 1300))
    stream = SimpleNamespace(position=np.vstack(positions))
    frame = fit_stream_frame([run], stream, {0: cycles})
    assert ICP_SAMPLES == 2000 and frame.n_points == 2000
    picked = np.sort(np.random.default_rng(0).choice(np.arange(2600), 2000, replace=False))
    in_base = (stream.position[picked] - frame.translation) @ frame.rotation
    distances = np.array([_distance_to_polyline(p, helix) for p in in_base])
    assert 20e-6 < frame.residual_rms < 50e-6
    assert frame.residual_rms == pytest.approx(np.sqrt(np.mean(distances ** 2)), rel=1e-9)


def test_a_repeated_time_in_a_cycle_names_the_second_reading(tmp_path):
    """A stream of two cycles of a path, cycle 2's third and fourth readings (file rows 8 and 9) both at
    12.0 s: refused naming row 9, the time and the cycle. Catches ``rows[same[0] + 1]`` as ``+ 0``
    (the first of the two named) or ``+ 2``."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.io.tracker_stream import read_tracker_stream
    from tcr_accuracy.iso9283.path_evaluate import stream_cycles

    lines = ["time_s,x_mm,y_mm,z_mm,path,cycle"]
    times = [0.0, 1.0, 2.0, 3.0, 10.0, 11.0, 12.0, 12.0, 13.0]
    for k, t in enumerate(times):
        lines.append(f"{t},{400 + 10 * k},{-100 + 3 * k},{300 + k},line,{1 if t < 5 else 2}")
    path = tmp_path / "stream.csv"
    path.write_text("\n".join(lines) + "\n")
    stream = read_tracker_stream(str(path))
    run = SimpleNamespace(path="line", speed_pct=None, words=lambda: "line")
    with pytest.raises(InputError) as refused:
        stream_cycles(stream, [run])
    assert str(refused.value) == (f"{path}: row 9, column time_s: 12 s repeats a time of the same cycle (line, cycle 2)")


def _stream(n=9, labels=None, speed=None):
    from tcr_accuracy.io.tracker_stream import TrackerStream

    return TrackerStream(time_s=np.arange(n, dtype=float), position=np.zeros((n, 3)), labels=labels or {},
                         speed_pct=speed, rows=np.arange(n) + 2, source="s.csv", position_columns=((), "mm"))


def _run(path, speed_pct):
    return SimpleNamespace(path=path, speed_pct=speed_pct,
                           words=lambda: path + ("" if speed_pct is None else f" at {speed_pct:g} %"))


def test_a_stream_without_path_speed_or_cycle_columns_takes_what_the_commanded_file_leaves_one_of():
    """No path, speed or cycle column: with one path at one speed in the commanded file every reading is
    that run's, one cycle, said; with two paths refused naming both; without a speed column, a path at
    two speeds is refused, two paths at a speed each are told apart by the path alone. Catches ``len(names)
    > 1`` changed to 2 or 0, ``names[0]`` as ``[1]``, and ``len(v) > 1`` changed to 0 or 2."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.path_evaluate import stream_cycles

    cycles, notes = stream_cycles(_stream(), [_run("line", 50.0)])
    assert list(cycles) == [0] and [rows.tolist() for rows in cycles[0]] == [list(range(9))]
    assert notes == ["no cycle column: each run is one cycle (no RT, RV)"]
    with pytest.raises(InputError, match=r"^s\.csv: no path column, and the commanded file holds 2 paths \(circle, "
                                         r"line\); label each reading with its path$"):
        stream_cycles(_stream(), [_run("line", 50.0), _run("circle", 50.0)])
    path = np.array(["line"] * 5 + ["circle"] * 4, dtype=object)
    cycle = np.array(["1"] * 9, dtype=object)
    with pytest.raises(InputError, match=r"^s\.csv: no speed_pct column, and the commanded file runs its paths at 10, "
                                         r"50 %; label each reading with its speed$"):
        stream_cycles(_stream(labels={"path": path, "cycle": cycle}),
                      [_run("line", 50.0), _run("line", 10.0), _run("circle", 10.0)])
    cycles, notes = stream_cycles(_stream(labels={"path": path, "cycle": cycle}),
                                  [_run("line", 50.0), _run("circle", 10.0)])
    assert [rows.tolist() for rows in cycles[0]] == [[0, 1, 2, 3, 4]]
    assert [rows.tolist() for rows in cycles[1]] == [[5, 6, 7, 8]] and notes == []


def test_the_notes_count_the_planes_each_run_missed_and_name_runs_without_speed():
    """A run along a 0.4 m line, two cycles: one along it, one that leaves 50 mm sideways for its last
    three planes' stretch (beyond a tenth of the length from them): 3 planes missed, said with the run;
    no commanded time or speed: no velocity figures, said. Catches the missed count's sum and the
    note's concatenation changed."""
    from tcr_accuracy.iso9283.path_evaluate import CommandedRun, _figures

    s = np.linspace(0.0, 0.4, 401)
    points = np.column_stack([s, np.zeros_like(s), np.zeros_like(s)])
    run = CommandedRun("line", None, points, s, np.zeros((401, 6)), None, None, ())
    t = np.linspace(0.0, 4.4, 441)
    x = -0.02 + 0.1 * t
    along = np.column_stack([x, np.zeros_like(t), np.zeros_like(t)])
    away = along.copy()
    away[x > 0.28, 1] = 0.05
    position = np.vstack([along, away])
    stream = SimpleNamespace(time_s=np.concatenate([t, t + 10.0]), source="s.csv")
    cycles = {0: [np.arange(441), np.arange(441, 882)]}
    got = _figures([run], [0], cycles, stream, position, 10, "base", "not fitted", ["a note"])
    (_, figures), = got.runs
    assert figures.missed == 3
    assert got.notes == ["a note", "normal planes a cycle did not cross (left out of that plane's figures): line 3",
                         "no commanded time or speed: no AV, RV, FV for line"]
