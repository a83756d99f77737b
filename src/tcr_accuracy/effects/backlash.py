"""``backlash``: a dead band in each joint, taken up on the side gravity or the motion pushes."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.context import context_column
from ..model.gravity import gravity_torque
from ..units import REVOLUTE
from .base import PerJointEffect, joint_unit, link_mass_factors_option, per_joint_kind
from .fit_policy import FitPolicy
from .simulation_rules import SimulationRules


@dataclass(frozen=True)
class BacklashDraws(SimulationRules):
    """A dominant backlash: one band width per joint, 0.01-0.05 deg (or mm); beyond physics, joints
    that end ahead of their motion."""

    def dominant_spec(self, effect, rng):
        return {"backlash_deg": float(rng.uniform(0.01, 0.05)), "backlash_mm": float(rng.uniform(0.01, 0.05))}

    def finish_dominant(self, effect, params, rng):
        # one band width per joint, drawn in the range, not a single value
        per_unit = np.where(np.array(effect.parameter_units()) == "rad", math.pi / 180.0, 1e-3)
        return per_unit * rng.uniform(0.01, 0.05, size=effect.n_params)

    def beyond_physics(self, effect, params, rng):
        return -np.asarray(params, dtype=float) * rng.uniform(1.0, 1.5)  # ahead: lost-motion compensation too high


class Backlash(PerJointEffect):
    """A dead band per joint: ``dq_j = b_j / 2 * s_j``.

    The side of the band the joint rests on, ``s_j``, is ``-dir_j`` when the approach
    direction ``<joint>_dir`` is given (the output lags behind the motion), else the sign
    of the gravity torque on the joint (gravity pulls the output against one flank);
    a joint gravity does not load (|tau| below 1e-6 of the largest) and with no direction
    sits in the middle of the band (s = 0). Parameters ``backlash.<joint>`` = full band
    width b_j [rad or m]. ``link_mass_factors`` as for compliance.
    """

    name = "backlash"
    in_words = "backlash"
    summary = "dead band per joint, on the side of gravity or of the approach"
    context_columns = ("payload_kg", "<joint>_dir")
    non_negative = True
    family = "direction"
    physics = ("a dead band is a width (positive) and stays below 0.5 deg (0.5 mm) in any gearbox that still "
               "holds a load")
    fit_policy = FitPolicy(order=40.0)
    simulation = BacklashDraws(dominant_place=2)

    def __init__(self, robot, *, link_mass_factors=None) -> None:
        super().__init__(robot)
        self.link_mass_factors = link_mass_factors_option(robot, link_mass_factors)

    def parameter_units(self):
        return [joint_unit(k) for k in self.robot.joint_kinds]

    def parameter_scales(self):
        return np.array([math.radians(0.03) if k == REVOLUTE else 5e-5 for k in self.robot.joint_kinds])

    def side(self, q, context) -> np.ndarray:
        """(N, n_joints) side of the dead band, +1, -1 or 0."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        payload = context_column(context, "payload_kg", q.shape[0], 0.0)
        outside = None if context is None else context.outside_q
        tau = gravity_torque(self.robot, q, payload, self.link_mass_factors, outside)
        threshold = 1e-6 * max(float(np.abs(tau).max()), 1e-300)
        s = np.where(np.abs(tau) > threshold, np.sign(tau), 0.0)
        if context is not None and context.direction is not None:
            direction = np.asarray(context.direction, dtype=float)
            s = np.where(direction != 0, -direction, s)
        return s

    def physical_range(self):
        return np.zeros(self.n_params), per_joint_kind(self.robot, math.radians(0.5), 5e-4)

    def fit_range(self):
        _, upper = self.physical_range()  # a compensation set too high leads by up to a band's width
        return -2.0 * upper, upper

    def mechanisms(self):
        from .mechanisms import Mechanism

        _, upper = self.physical_range()
        return (Mechanism("dead_band", "a dead band (lost motion) in the gear train: joints that end behind their "
                          "motion", "reverse each joint slowly under the tracker or a dial gauge and measure the "
                          "lost motion", np.zeros_like(upper), upper),
                Mechanism("lost_motion_compensation", "joints that end ahead of their motion: the controller's "
                          "lost-motion (backlash) compensation set too high, or a time offset between the tracker "
                          "and the joint log", "check the controller's backlash-compensation parameters; check the "
                          "time stamps of the tracker and the joint log (measure with the robot at rest)",
                          -2.0 * upper, np.zeros_like(upper), False))

    def signal(self, q, context):
        return 0.5 * self.side(q, context)
