"""``joint_offsets``: encoder zero offsets, the classic first term of a calibration."""

from __future__ import annotations

import math

import numpy as np

from ..units import REVOLUTE
from .base import PerJointEffect, joint_unit


class JointOffsets(PerJointEffect):
    """Encoder zero offsets: ``dq_j = offset_j`` [rad or m]. Parameters ``joint_offsets.<joint>``."""

    name = "joint_offsets"
    order = 10.0
    summary = "encoder zero offsets"
    geometric = True

    def parameter_units(self):
        return [joint_unit(k) for k in self.robot.joint_kinds]

    def parameter_scales(self):
        # 0.03 deg, 0.05 mm
        return np.array([math.radians(0.03) if k == REVOLUTE else 5e-5 for k in self.robot.joint_kinds])

    def signal(self, q, context):
        return np.ones_like(q)
