"""An ISO 9283 result file written before its optional keys existed (``iso9283/result_file.py``):
what the reader makes of a key that is not there, written out here (three NaN coordinates, counts
of 0, AP absolute in the base frame). Each test names a planted change it was seen to catch.
"""

import math

import numpy as np
import pytest

from tcr_accuracy.iso9283.evaluate import IsoEvaluation
from tcr_accuracy.iso9283.formulas import DistanceFigures, IsoFigures, PoseFigures, Stabilisation
from tcr_accuracy.iso9283.result_file import evaluation_dict, evaluation_from_dict


def _doc():
    pose = PoseFigures("3", None, 4, np.array([0.1, 0.2, 0.3]), np.array([0.1002, 0.2, 0.3]), 0.2e-3,
                       np.array([0.2e-3, 0.0, 0.0]), 0.05e-3, 0.02e-3, 0.01e-3)
    other = PoseFigures("4", None, 4, np.array([0.2, 0.2, 0.3]), np.array([0.2, 0.2001, 0.3]), 0.1e-3,
                        np.array([0.0, 0.1e-3, 0.0]), 0.04e-3, 0.02e-3, 0.007e-3)
    figures = IsoFigures(poses=[pose, other],
                         distances=[DistanceFigures("3", "4", 4, 0.1, 0.1001, 0.1e-3, np.array([0.1e-3, 0, 0]),
                                                    0.03e-3)],
                         stabilisation=[Stabilisation("3", None, 4, 0.05e-3, 0.2, 0.3, 0.01e-3, 0.02e-3, 0)])
    evaluation = IsoEvaluation(figures=figures, frame="fit", registration=None, how="fitted", orientation_offset=None,
                               n_readings=8, pose_q={}, n_visits=8, frame_source="x", absolute=False)
    return evaluation_dict(evaluation)


def test_a_file_without_the_optional_keys_reads_back_with_their_defaults():
    """The pose's ``commanded_mm`` and ``barycentre_mm``, the distance's ``ad_y_mm``, the stabilisation's
    ``never_entered``, the counts and the frame's source and absoluteness left out: read back, the
    positions are three NaN coordinates each (shape (3,)), ``ad_y`` NaN, nothing never entered, 0
    readings and visits, AP in the base frame and absolute; what is there reads in SI. Catches
    ``[np.nan] * 3`` as ``* 4`` (either), ``never_entered`` default 0 as 1, and the counts' default 0
    as 1."""
    doc = _doc()
    for pose in doc["poses"]:
        del pose["commanded_mm"], pose["barycentre_mm"]
    del doc["distances"][0]["ad_y_mm"], doc["stabilisation"][0]["never_entered"]
    for key in ("n_readings", "n_visits", "frame_source", "ap_absolute"):
        del doc[key]
    back = evaluation_from_dict(doc)
    for pose in back.figures.poses:
        assert pose.commanded.shape == (3,) and pose.barycentre.shape == (3,)
        assert np.isnan(pose.commanded).all() and np.isnan(pose.barycentre).all()
    assert back.figures.poses[0].ap == pytest.approx(0.2e-3, rel=1e-12)
    (distance,) = back.figures.distances
    assert math.isnan(distance.ad_xyz[1]) and distance.ad_xyz[0] == pytest.approx(0.1e-3, rel=1e-12)
    (stab,) = back.figures.stabilisation
    assert stab.never_entered == 0 and stab.n == 4
    assert (back.n_readings, back.n_visits, back.frame_source, back.absolute) == (0, 0, "base", True)
    assert back.instrument_distance is None and back.registration is None and back.pose_q is None
