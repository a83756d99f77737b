"""``encoder_scale``: a gear ratio that is not quite what the controller assumes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import PerJointEffect
from .fit_policy import FitPolicy
from .simulation_rules import SimulationRules


@dataclass(frozen=True)
class EncoderScaleDraws(SimulationRules):
    """A dominant scale error: 100-500 ppm per joint, either sign; beyond physics, a gear ratio wrong
    in the configuration (30-60 times that)."""

    def dominant_spec(self, effect, rng):
        return {"spread_ppm": float(rng.uniform(100.0, 500.0))}

    def finish_dominant(self, effect, params, rng):
        return rng.choice([-1.0, 1.0], effect.n_params) * rng.uniform(1e-4, 5e-4, size=effect.n_params)

    def beyond_physics(self, effect, params, rng):
        return np.asarray(params, dtype=float) * rng.uniform(30.0, 60.0)  # a gear ratio wrong in the configuration


class EncoderScale(PerJointEffect):
    """Gear ratio (scale) error: ``dq_j = s_j q_j``. Parameters ``encoder_scale.<joint>`` [1]."""

    name = "encoder_scale"
    in_words = "a gear-ratio error"
    summary = "gear ratio (scale) error per joint"
    family = "scale"
    physics = "a gear ratio the controller has wrong by more than 1 % would be seen as a joint that misses its end stops"
    fit_policy = FitPolicy(order=55.0)
    simulation = EncoderScaleDraws(dominant_place=5)

    def parameter_units(self):
        return ["1"] * self.n_params

    def parameter_scales(self):
        return np.full(self.n_params, 3e-4)

    def physical_range(self):
        return np.full(self.n_params, -0.01), np.full(self.n_params, 0.01)

    def fit_range(self):
        return np.full(self.n_params, -0.1), np.full(self.n_params, 0.1)

    def mechanisms(self):
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        wide_lower, wide_upper = self.fit_range()
        return (Mechanism("ratio_error", "a gear ratio slightly off what the controller assumes (an encoder scale)",
                          "drive the joint between two marks a known angle apart and compare", lower, upper),
                Mechanism("wrong_ratio", "a gear ratio wrong by more than 1 % in the controller's configuration (or "
                          "a coupling ratio, for a coupled joint)", "compare the configured gear ratio with the "
                          "gearbox's nameplate", wide_lower, wide_upper, False))

    def signal(self, q, context):
        return q
