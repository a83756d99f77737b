"""Three survivors of a measuring sample of issue 36's mutation run (seed 462196), pinned by fast direct tests
against computations written out here: the ISO 9283 rectangle path of a small cube sampled at its perimeter over
the fewest samples a path takes, a series of exactly two test conditions refused by the one-condition evaluation,
and the identifiability of a block measured at one pose (its motions worked by hand). Each test names the
planted change it was seen to catch."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

import tcr_accuracy as tcr
from tcr_accuracy.diagnosis.identifiability import identifiability
from tcr_accuracy.exceptions import InputError
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


def test_a_series_of_exactly_two_test_conditions_is_refused_by_the_one_condition_evaluation():
    """A UR5 cube's series at 100 % load and 100 % then 50 % speed, read exactly through Pinocchio (written out
    here): two conditions, so one set of figures would mix them: refused, naming both (the four-condition case
    is tested elsewhere; two is the edge). Seen failing on ``len(blocks) > 1`` turned to ``> 2``."""
    robot = tcr.load_robot("ur5")
    plan = tcr.plan_iso_cube(robot, random_state=0, centre=[-0.13, -0.44, 0.32], size=0.3)
    two = plan.series(cycles=2, conditions=[(100, 100), (100, 50)])
    data, frame = robot.model.createData(), robot.model.getFrameId(robot.tool_frame)
    positions = []
    for row in two.q:
        pin.framesForwardKinematics(robot.model, data, row)
        positions.append(data.oMf[frame].translation.copy())
    assert len(two) == 20
    with pytest.raises(InputError, match=r"2 test conditions \(.*100.*; .*50.*\)"):
        tcr.evaluate_pose_test(robot, dataclasses.replace(two, position=np.array(positions)))


def test_a_block_measured_at_one_pose_is_judged_on_that_pose_alone():
    """One pose, two orthogonal columns moving the TCP 1 mm and 2 mm: their RMS motions over the one pose are
    1 mm and 2 mm, so with 1.6 mm resolved the 2 mm column is kept and the 1 mm one dropped, its words in um
    (1e+03 of 1e+03 um); counted as two poses the 2 mm column would move 1.41 mm RMS and be dropped too. Seen
    failing on ``max(b.g.shape[0], 1)`` turned to ``max(b.g.shape[0], 2)``."""
    g = np.zeros((1, 3, 2))
    g[0, 0, 0], g[0, 1, 1] = 1e-3, 2e-3
    keep, report = identifiability({"e": SimpleNamespace(g=g, scales=np.ones(2), names=["a", "b"])}, ["e"],
                                   min_motion=1.6e-3)
    assert keep["e"].tolist() == [1]
    assert report["effects"]["e"]["removed"] == [
        {"parameter": "a", "reason": "only 1e+03 um RMS of its 1e+03 um TCP motion (at its typical size) is its own: "
                                     "below what the measurements resolve", "duplicates": []}]
