"""``joint_offsets``: encoder zero offsets, the classic first term of a calibration."""

from __future__ import annotations

import math

import numpy as np

from ..units import REVOLUTE
from .base import PerJointEffect, joint_unit, per_joint_kind
from .fit_policy import FitPolicy


class JointOffsets(PerJointEffect):
    """Encoder zero offsets: ``dq_j = offset_j`` [rad or m]. Parameters ``joint_offsets.<joint>``."""

    name = "joint_offsets"
    in_words = "encoder zero offsets"
    summary = "encoder zero offsets"
    geometric = True
    family = "geometric"
    physics = ("an encoder zero off by more than 10 deg (20 mm on a prismatic joint) is a joint mastered on the "
               "wrong mark, not a calibration error")
    fit_policy = FitPolicy(order=10.0)

    def parameter_units(self):
        return [joint_unit(k) for k in self.robot.joint_kinds]

    def parameter_scales(self):
        # 0.03 deg, 0.05 mm
        return np.array([math.radians(0.03) if k == REVOLUTE else 5e-5 for k in self.robot.joint_kinds])

    def physical_range(self):
        bound = per_joint_kind(self.robot, math.radians(10.0), 0.02)
        return -bound, bound

    def fit_range(self):
        bound = per_joint_kind(self.robot, math.radians(45.0), 0.1)
        return -bound, bound

    def mechanisms(self):
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        wide_lower, wide_upper = self.fit_range()
        return (Mechanism("encoder_zero", "encoder zero offsets: joints mastered a little off their marks",
                          "re-master the joints on their marks and compare the offsets", lower, upper),
                Mechanism("wrong_mark", "a joint mastered on the wrong mark (more than 10 deg or 20 mm off)",
                          "check each joint's mastering position against its mark", wide_lower, wide_upper, False))

    def signal(self, q, context):
        return np.ones_like(q)
