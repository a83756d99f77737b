"""``transmission``: periodic gear error, harmonics of each joint angle."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..units import REVOLUTE
from .base import EffectJacobian, LinearEffect
from .fit_policy import FitPolicy
from .simulation_rules import SimulationRules


@dataclass(frozen=True)
class TransmissionDraws(SimulationRules):
    """A dominant gear error: harmonics spread by 0.005-0.02 deg; beyond physics, an eccentric
    encoder (30-80 times that: degrees)."""

    def dominant_spec(self, effect, rng):
        return {"spread_deg": float(rng.uniform(0.005, 0.02))}

    def beyond_physics(self, effect, params, rng):
        return np.asarray(params, dtype=float) * rng.uniform(30.0, 80.0)  # an eccentric encoder: degrees


class Transmission(LinearEffect):
    """Periodic gear error per revolute joint, first and second harmonic of the joint angle.

    ``dq_j = a1 sin(q_j) + b1 cos(q_j) + a2 sin(2 q_j) + b2 cos(2 q_j)``. Parameters
    ``transmission.<joint>.a1, b1, a2, b2`` [rad]. Prismatic joints have none (their
    period is not a joint angle). ``harmonics``: which harmonics (default (1, 2)).
    """

    name = "transmission"
    in_words = "periodic gear errors"
    summary = "periodic gear error (harmonics of each joint angle)"
    family = "periodic"
    physics = ("cyclic gear and encoder errors are arc-minutes; more than 0.25 deg (15 arc-min) per harmonic is a "
               "damaged gear or a loose encoder, not a periodic error")
    fit_policy = FitPolicy(order=60.0)
    simulation = TransmissionDraws(dominant_place=4)

    def __init__(self, robot, *, harmonics=(1, 2)) -> None:
        super().__init__(robot)
        self.harmonics = harmonics

    def _terms(self):
        harmonics = tuple(self.harmonics)
        return [(j, name, h, trig) for j, (name, kind) in enumerate(zip(self.robot.joint_names, self.robot.joint_kinds))
                if kind == REVOLUTE for h in harmonics for trig in ("a", "b")]

    def parameter_names(self):
        return [f"transmission.{name}.{trig}{h}" for _, name, h, trig in self._terms()]

    def parameter_units(self):
        return ["rad"] * self.n_params

    def parameter_scales(self):
        return np.full(self.n_params, math.radians(0.01))

    def physical_range(self):
        return np.full(self.n_params, -math.radians(0.25)), np.full(self.n_params, math.radians(0.25))

    def fit_range(self):
        return np.full(self.n_params, -math.radians(5.0)), np.full(self.n_params, math.radians(5.0))

    def mechanisms(self):
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        wide_lower, wide_upper = self.fit_range()
        return (Mechanism("gear_error", "periodic transmission error of the gears, once and twice per revolution",
                          "compare with the gearbox maker's transmission error; measure the joint with an "
                          "output-side encoder", lower, upper),
                Mechanism("eccentric_encoder", "a periodic error of degrees: an eccentric or loose encoder, or a "
                          "wrong gear ratio", "check the encoder's mounting and the configured gear ratio",
                          wide_lower, wide_upper, False))

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(np.asarray(q, dtype=float))
        terms = self._terms()
        ddq = np.zeros((q.shape[0], self.robot.n_joints, len(terms)))
        for k, (j, _, h, trig) in enumerate(terms):
            ddq[:, j, k] = np.sin(h * q[:, j]) if trig == "a" else np.cos(h * q[:, j])
        return EffectJacobian(dq=ddq)
