"""A survivor of a measuring sample of issue 36's mutation run (seed 462196), pinned by a fast direct test against
a computation written out here: the ISO 9283 rectangle path of a small cube sampled at its perimeter over the
fewest samples a path takes. The test names the planted change it was seen to catch."""

from __future__ import annotations

import math

import numpy as np

from tcr_accuracy.iso9283.path_plan import MIN_SAMPLES, SAMPLE_STEP, standard_paths
from tcr_accuracy.iso9283.plan import iso_points


def test_a_small_cubes_rectangle_is_sampled_at_its_perimeter_over_the_fewest_samples():
    """A cube of 20 mm edge: the rectangle P2-P3-P4-P5-P2 is 2 (|P3 - P2| + |P4 - P3|) long, less than 200 samples
    of 1 mm, so each side is cut into ceil(side / (perimeter / 200)) equal steps: 1 + the sum of those samples;
    the diagonal line P2-P4 likewise at its own length over 200. Seen failing on the perimeter's
    ``p[2] - p[1]`` turned to ``p[2] - p[0]`` (the centre: another step, another count)."""
    centre = np.array([0.4, 0.1, 0.5])
    p = iso_points(centre, 0.02)
    sides = [np.linalg.norm(b - a) for a, b in zip(p[[1, 2, 3, 4]], p[[2, 3, 4, 1]])]
    perimeter = 2 * (sides[0] + sides[1])
    assert math.isclose(perimeter, sum(sides), rel_tol=1e-12)  # a rectangle: opposite sides equal
    step = perimeter / MIN_SAMPLES
    assert step < SAMPLE_STEP  # the case this test is about
    paths = {path.name: path for path in standard_paths(centre, 0.02)}
    rectangle = np.asarray(paths["rectangle"].points)
    assert len(rectangle) == 1 + sum(math.ceil(side / step) for side in sides)
    gaps = np.linalg.norm(np.diff(rectangle, axis=0), axis=1)
    assert gaps.max() <= step * (1 + 1e-12)
    diagonal = np.linalg.norm(p[3] - p[1])
    assert len(paths["line"].points) == 1 + math.ceil(diagonal / (diagonal / MIN_SAMPLES))
