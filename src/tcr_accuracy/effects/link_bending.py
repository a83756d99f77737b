"""``link_bending`` (simulate only): the longest link sagging as a beam."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .base import Effect, EffectOutput
from .fit_policy import FitPolicy
from .unmodelled import longest_link


class LinkBending(Effect):
    """The longest link sags under gravity like a cantilever: its far end drops.

    The distal joint of the longest link moves, without turning, by ``A cos(e)`` in the
    direction of gravity's component perpendicular to the link, e = the link's elevation
    above the horizontal. Parameter ``link_bending.tip`` [m]: the drop with the link
    horizontal. Joint compliance turns the distal frames as well; a bending beam
    translates them, so the vocabulary explains this only in part.
    """

    name = "link_bending"
    in_words = "a link bending under gravity"
    summary = "the longest link sagging as a beam (simulate only)"
    family = "gravity"
    fit_policy = FitPolicy(order=210.0, in_vocabulary=False)

    def parameter_names(self):
        return ["link_bending.tip"]

    def parameter_units(self):
        return ["m"]

    def parameter_scales(self):
        return np.array([5e-4])

    def perturb(self, params, q, context):
        (tip,) = self.check_params(params)
        q = np.atleast_2d(q)
        robot = self.robot
        k = longest_link(robot)
        model = robot.model
        data = model.createData()
        parent = model.parents[k + 1]
        placement = robot.joint_placements[k]
        g = model.gravity.linear / np.linalg.norm(model.gravity.linear)
        em = self.error_model
        x = np.zeros((q.shape[0], em.size))
        start = em.index(f"{robot.joint_names[k]}.dx")
        for i, qi in enumerate(q):
            pin.forwardKinematics(model, data, robot.to_pinocchio_q(qi))
            frame = data.oMi[parent] * placement  # the link's distal end, before its joint moves
            link = data.oMi[parent].rotation @ placement.translation
            u = link / np.linalg.norm(link)
            drop = g - (g @ u) * u  # gravity across the link; |drop| = cos(elevation)
            x[i, start:start + 3] = frame.rotation.T @ (tip * drop)
        return EffectOutput(x=x)
