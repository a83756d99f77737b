"""``unmodelled`` (simulate only): a distortion no effect of the vocabulary expresses.

Hidden by ``simulate`` to check that a diagnosis reports structure it cannot explain
instead of claiming a fit; ``diagnose`` never tries it (``FitPolicy(in_vocabulary=False)``).
"""

from __future__ import annotations

import numpy as np

from ..model.robot import RobotModel
from .base import Effect, EffectOutput
from .fit_policy import FitPolicy


def longest_link(robot: RobotModel) -> int:
    """Index of the joint whose placement carries the longest link (after the first)."""
    lengths = [np.linalg.norm(pl.translation) for pl in robot.joint_placements]
    if len(lengths) > 1:
        lengths[0] = -1.0  # the pedestal trades with the base frame; bend an arm link
    return int(np.argmax(lengths))


class Unmodelled(Effect):
    """A smooth distortion of the longest link that depends on three joints at once.

    The distal joint of the longest link is shifted (translation in its own frame) by
    ``A * (sin(2 q_a + q_b), sin(q_b - 2 q_c + 0.5), cos(3 q_a - q_c))`` with a, b, c the
    first three joints. No effect of the vocabulary has this shape: the distortion
    moves a joint placement with a mix of other joints' angles. Parameter
    ``unmodelled.amplitude`` [m].
    """

    name = "unmodelled"
    in_words = "a distortion no effect expresses"
    summary = "a smooth distortion of one link driven by three joints (simulate only)"
    fit_policy = FitPolicy(order=200.0, in_vocabulary=False)

    def parameter_names(self):
        return ["unmodelled.amplitude"]

    def parameter_units(self):
        return ["m"]

    def parameter_scales(self):
        return np.array([3e-4])

    def perturb(self, params, q, context):
        (amplitude,) = self.check_params(params)
        q = np.atleast_2d(q)
        n = self.robot.n_joints
        a, b, c = 0, 1 % n, 2 % n
        shift = amplitude * np.stack([np.sin(2 * q[:, a] + q[:, b]), np.sin(q[:, b] - 2 * q[:, c] + 0.5),
                                      np.cos(3 * q[:, a] - q[:, c])], axis=1)
        em = self.error_model
        x = np.zeros((q.shape[0], em.size))
        start = em.index(f"{self.robot.joint_names[longest_link(self.robot)]}.dx")
        x[:, start:start + 3] = shift
        return EffectOutput(x=x)
