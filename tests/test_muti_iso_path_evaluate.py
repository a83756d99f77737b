"""The closest-point frame of a measured path (``iso9283/path_evaluate.py``) on a long stream: the
readings it fits on (at most 2000 per run, drawn without replacement by a generator seeded 0) and
its residual RMS, the distance of each reading, in the fitted frame, to the commanded polyline,
found here by brute force over every segment. Each test names a planted change it was seen to catch.
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
