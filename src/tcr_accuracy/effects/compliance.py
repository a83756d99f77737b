"""``compliance``: joints that give under the gravity torque they carry (arm, payload, other arms)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.context import context_column
from ..model.gravity import gravity_torque
from ..units import REVOLUTE
from .base import PerJointEffect, link_mass_factors_option, loaded_joint_scales, reference_poses
from .fit_policy import FitPolicy
from .simulation_rules import SimulationRules


@dataclass(frozen=True)
class ComplianceDraws(SimulationRules):
    """A dominant compliance: each joint turned by a similar angle under its typical torque, then
    scaled to a TCP RMS of 0.5-3 mm; beyond physics, against gravity."""

    def dominant_spec(self, effect, rng):
        # each joint turned by a similar angle under its typical torque, then scaled
        pattern = effect.parameter_scales() * np.exp(0.5 * rng.standard_normal(effect.robot.n_joints))
        return {"parameters": {f"compliance.{j}": float(c) for j, c in zip(effect.robot.joint_names, pattern)},
                "tcp_rms_mm": rng.uniform(0.5, 3.0), "options": {"link_mass_spread": 0.05}}

    def beyond_physics(self, effect, params, rng):
        return -np.asarray(params, dtype=float)  # against gravity: a gravity compensation that over-corrects


class Compliance(PerJointEffect):
    """Joint elasticity under gravity and payload: ``dq_j = c_j * tau_g,j(q, payload)``.

    ``tau_g`` is the torque gravity exerts on each joint (:func:`~tcr_accuracy.model.gravity.gravity_torque`,
    on the robot's whole tree, the payload a point mass at the TCP and the joints outside
    the TCP chain at their measured values), so a positive compliance lets the arm sag the
    way gravity pulls. Parameters ``compliance.<joint>`` = 1/k_j [rad/Nm, or m/N for a
    prismatic joint]. Context: ``payload_kg`` per row. ``link_mass_factors``
    (n_joints,): the real link masses relative to the URDF's (simulate draws them; a fit
    uses the URDF's).
    """

    name = "compliance"
    in_words = "joints giving way under gravity"
    summary = "joint elasticity about each axis under gravity and payload"
    context_columns = ("payload_kg",)
    non_negative = True
    family = "gravity"
    physics = ("a joint gives way to gravity (positive), by less than 2 deg (10 mm) under its typical gravity load "
               "(200 x the typical compliance): a softer joint would be felt by hand")
    fit_policy = FitPolicy(order=30.0)
    simulation = ComplianceDraws(dominant_place=1)

    def __init__(self, robot, *, link_mass_factors=None) -> None:
        super().__init__(robot)
        self.link_mass_factors = link_mass_factors_option(robot, link_mass_factors)

    def parameter_units(self):
        return ["rad/Nm" if k == REVOLUTE else "m/N" for k in self.robot.joint_kinds]

    def parameter_scales(self):
        """Compliances that turn each joint by 0.01 deg (or 0.05 mm) under a typical torque.

        The typical torque is the RMS gravity torque over a fixed set of poses inside the
        limits with the robot's typical payload; joints gravity never loads get the median
        of the others' scales.
        """
        tau = gravity_torque(self.robot, reference_poses(self.robot), self.robot.typical_payload_kg,
                             self.link_mass_factors)
        return loaded_joint_scales(self.robot, np.sqrt(np.mean(tau**2, axis=0)), math.radians(0.01), 5e-5)

    def physical_range(self):
        return np.zeros(self.n_params), 200.0 * self.parameter_scales()

    def fit_range(self):
        _, upper = self.physical_range()  # as far against gravity as an elastic joint goes with it
        return -upper, upper

    def mechanisms(self):
        from .mechanisms import Mechanism

        _, upper = self.physical_range()
        return (Mechanism("elastic_joint", "joints that give way to the gravity torque they carry: gear and bearing "
                          "elasticity", "hang a known load at the tool and measure the sag with the tracker (a static "
                          "load test); compare with the gearboxes' torsional stiffness", np.zeros_like(upper), upper),
                Mechanism("gravity_compensation", "joints that end against the gravity torque they carry: the "
                          "controller's gravity compensation over-corrects (its payload or gain set too high), or the "
                          "URDF's masses and centres of mass are far from the real ones",
                          "check the payload and gravity-compensation settings in the controller; compare the URDF's "
                          "link masses with the real ones", -upper, np.zeros_like(upper), False))

    def signal(self, q, context):
        payload = context_column(context, "payload_kg", q.shape[0], 0.0)
        outside = None if context is None else context.outside_q
        return gravity_torque(self.robot, q, payload, self.link_mass_factors, outside)
