"""ISO 9283 pose-test bookkeeping by hand (``iso9283/formulas.py``, ``evaluate.py``): the notes on
poses read fewer times than the standard asks, word for word at the counts' bounds, and the grouping of
readings into poses by their joint values at the grouping tolerance and just past it. Each test names
a planted change it was seen to catch (issue 36)."""

from types import SimpleNamespace

import numpy as np
import pytest

from tcr_accuracy.iso9283.evaluate import group_by_joints
from tcr_accuracy.iso9283.formulas import cycle_notes


class _Readings(SimpleNamespace):
    """A measurement set's times, file rows and source, as many readings long as it has times."""

    def __len__(self):
        return len(self.time_s)


def _poses(counts):
    return [SimpleNamespace(pose_id=str(k + 1), approach="a", n=n) for k, n in enumerate(counts)]


def test_cycle_notes_name_the_poses_read_once_or_twice_and_count_those_short_of_30():
    """Seven poses read once (five named, "and 2 more"), one twice, one 29 times, two 30 times: the once- and
    twice-read poses each said with what they lack (RP needs 3 readings), 9 of 11 read fewer times than
    the standard's 30 cycles (1-29 readings); all read 30 times: no note; three read 5 times: "5 readings
    each". Seen failing on ``STANDARD_CYCLES = 30`` turned to 31 or 29, ``MIN_REPEATS`` changed, the
    names' ``few[:5]`` turned to ``[:6]`` and ``len(few) - 5`` to ``- 6``."""
    notes = cycle_notes(_poses([1] * 7 + [2, 29, 30, 30]))
    assert notes == ["7 pose(s) read once: AP only (RP needs at least 3 readings): P1, P2, P3, P4, P5 and 2 more",
                     "1 pose(s) read twice: AP, l̄ and S_l, no RP (RP needs at least 3 readings): P8",
                     "9 of 11 pose(s) read fewer times than the standard's 30 cycles (1-29 readings): evaluated, "
                     "their figures less certain than the standard's"]
    assert cycle_notes(_poses([30, 30, 31])) == []
    assert cycle_notes(_poses([5, 5, 5]), labelled=True) == [
        "3 of 3 pose(s) read fewer times than the standard's 30 cycles (5 readings each): evaluated, their figures "
        "less certain than the standard's"]
    assert cycle_notes(_poses([1, 2]), labelled=True)[0].endswith("readings): P1 (a)")


def test_readings_are_grouped_into_poses_within_a_milliradian_of_a_poses_first_reading():
    """Readings 0.999 mrad from a pose's first reading on one joint belong to it, 1.001 mrad
    away start a new pose; a reading near the second pose's first joins it, numbered in order of first
    visit. Seen failing on ``POSE_GROUP_TOL = 1e-3`` turned to 1.001 or -0.999 and ``out[i] = k + 1``
    turned to ``k + 2``."""
    first = np.array([0.1, -1.2, 1.5, -1.9, -1.57, 0.0])
    step = np.zeros(6)
    step[2] = 1.0
    q = np.array([first, first + 0.999e-3 * step, first - 1.001e-3 * step, first + 0.5e-3 * step,
                  first - 1.001e-3 * step - 0.9e-3 * step, first - 1e-3 * step * 3])
    assert group_by_joints(q).tolist() == [1, 1, 2, 1, 2, 3]


def test_a_poses_joints_are_its_readings_mean_and_a_reading_off_by_more_names_its_joint():
    """Pose 1 read three times within 0.9 mrad of its first reading (encoder scatter): its joints are the mean
    of the three; pose 2's second reading 20 mrad off on wrist_1 (the fourth joint) only: refused naming
    that row and column and the pose's first row. Seen failing on the column's ``np.abs(mset.q[r] -
    q[0])`` turned to ``** q[0]`` and ``rows[np.argmax(far)]`` picking another row."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.evaluate import pose_joints

    names = ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"]
    base = np.array([0.3, -1.2, 1.5, -1.9, -1.57, 0.2])
    scatter = np.array([[0.0] * 6, [0.9e-3, 0, 0, 0, 0, -0.5e-3], [0, 0.4e-3, 0, 0, 0, 0.9e-3]])
    q = np.vstack([base + scatter, base + 0.5, base + 0.5 + [0, 0, 0, 0.02, 0, 0]])
    mset = SimpleNamespace(q=q, rows=np.arange(2, 7), joint_names=names, source="test.csv")
    pose_id = np.array(["1", "1", "1", "2", "2"])
    good = pose_joints(SimpleNamespace(q=q[:4], rows=mset.rows[:4], joint_names=names, source="test.csv"),
                       pose_id[:4])
    np.testing.assert_allclose(good["1"], base + scatter.mean(axis=0), rtol=0, atol=1e-15)
    with pytest.raises(InputError) as refused:
        pose_joints(mset, pose_id)
    assert str(refused.value) == ("test.csv: row 6, column wrist_1: pose 2 is commanded with other joint values than "
                                  "in row 5; one pose_id is one commanded pose")


def test_a_streamed_visit_whose_time_repeats_is_refused_at_the_second_reading():
    """Pose 1, cycle 1 streamed at 0.0, 0.5, 0.5 s (rows 2, 3, 4 of the file): refused at row 4, the reading
    that repeats the time before it; a visit read in order gives its rows in time order, the last its
    attained reading. Seen failing on ``rows[same[0] + 1]`` turned to ``+ 0`` (row 3 named)."""
    from tcr_accuracy.exceptions import InputError
    from tcr_accuracy.iso9283.evaluate import PoseLabels, visits_of

    labels = PoseLabels(np.array(["1", "1", "1"], dtype=object), np.array(["1", "1", "1"], dtype=object), None)
    mset = _Readings(time_s=np.array([0.0, 0.5, 0.5]), rows=np.array([2, 3, 4]), source="stream.csv")
    ordered_visit = _Readings(time_s=np.array([0.2, 0.0, 0.5]), rows=np.array([2, 3, 4]), source="stream.csv")
    visits = visits_of(ordered_visit, labels)
    assert [rows.tolist() for rows in visits.streams] == [[1, 0, 2]] and visits.attained.tolist() == [2]
    with pytest.raises(InputError) as refused:
        visits_of(mset, labels)
    assert str(refused.value) == ("stream.csv: row 4, column time_s: 0.5 s repeats a time of the same visit (pose 1, "
                                  "cycle 1); the readings of one visit are a stream in time")
