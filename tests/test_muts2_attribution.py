"""What each chosen effect accounts for (``diagnosis/attribution.py``), second pass (issue 36): the TCP motion
its fitted parameters cause beyond a rigid frame change, against Pinocchio on a UR5 whose joint placements the
test perturbs itself (only whole diagnoses reached it before, too slow for a mutation run). Each test names a
planted change it was seen to catch."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import random_joint_values
from test_muteff_plausibility import _tool_frame_by_pinocchio

from tcr_accuracy.diagnosis.attribution import contributions
from tcr_accuracy.model.errors import ErrorModel


def test_each_effects_motion_beyond_a_shift_of_the_frame_is_pinocchios(ur5):
    """Two stand-in effects whose fitted parameters give placement twists of the UR5's joints (the shoulder's seat
    moved by a few mm, the elbow's axis turned by a mrad); the frame's columns a translation on each axis (g of
    the tracker's position rows, one orientation row beside them that must not count), so that what a rigid
    frame change absorbs is the mean motion: each contribution is the RMS over the 9 poses of the tool frame's
    displacement (Pinocchio, joint placements times exp6 of the twists) less its mean. Seen failing on
    ``np.mean(...) * 3`` turned to ``* 4``, on the frames' ``g[:, :3]`` turned to ``[:, :4]`` and on
    ``per_part[0]`` turned to ``[-1]``."""
    em = ErrorModel(ur5)
    q = random_joint_values(ur5, 9, np.random.default_rng(5))
    twists = {"seat": np.zeros((6, 6)), "turn": np.zeros((6, 6))}
    twists["seat"][1, :3] = [2e-3, -1e-3, 0.5e-3]
    twists["turn"][2, 3:] = [1e-3, 0.4e-3, 0.0]
    nominal, _ = _tool_frame_by_pinocchio(ur5, q, np.zeros((6, 6)))

    def effect(twist):
        x = em.zeros()
        x[em.placement_slice] = twist.ravel()
        wrong = SimpleNamespace(basis=SimpleNamespace(errors=lambda parameters: np.full_like(x, np.nan)))
        return SimpleNamespace(per_part=[SimpleNamespace(basis=SimpleNamespace(errors=lambda parameters: x *
                                                                                 parameters[0])), wrong])

    g = np.zeros((9, 4, 3))  # rows: x, y, z of the position, then an orientation row
    g[:, :3, :] = np.eye(3)
    g[:, 3, :] = 1.0
    bases = {"frames": SimpleNamespace(per_part=[SimpleNamespace(g=g)]),
             "seat": effect(twists["seat"]), "turn": effect(twists["turn"])}
    part = SimpleNamespace(robot=ur5, q=q)
    got = contributions(part, bases, ["seat", "turn"], {"seat": np.array([1.0]), "turn": np.array([1.0])}, nominal)
    for name, twist in twists.items():
        moved = _tool_frame_by_pinocchio(ur5, q, twist)[0] - nominal
        left = moved - moved.mean(axis=0)
        expected = math.sqrt(np.mean(np.sum(left**2, axis=1)))
        assert got[name] == pytest.approx(expected, rel=1e-9)
        assert expected > 0.3 * math.sqrt(np.mean(np.sum(moved**2, axis=1)))  # not all of it a shift
