"""``clearance``: random joint play, which shows as scatter, never as a bias."""

from __future__ import annotations

import numpy as np

from ..model.clearance import ClearanceModel
from ..exceptions import InputError
from ..units import REVOLUTE
from .base import Effect, EffectOutput
from .fit_policy import FitPolicy


class Clearance(Effect):
    """Random joint play after the first seed paper's clearance model: scatter, not bias.

    In every joint with clearance, for each measurement independently, the journal
    moves in its bearing: an axial shift ``d ~ N(0, axial)`` along the joint axis, a
    radial shift of length ``s ~ N(0, radial)`` in a uniformly random direction
    perpendicular to the axis, and a tilt of the axis about the two perpendicular
    directions, each ``~ N(0, tilt)``: the exact model the Monte Carlo samples
    (:class:`~tcr_accuracy.model.clearance.ClearanceModel`, ``Trans * Rot`` on the placement). Parameters: the spreads ``clearance.axial`` [m],
    ``clearance.radial`` [m], ``clearance.tilt`` [rad], shared by the joints with play.
    ``joints``: names (default every revolute joint, as the seed); ``rng``: a numpy
    Generator (else ``context.rng`` is used; with neither, :meth:`perturb` gives the mean robot,
    which play leaves unmoved: an as-built model or a comparison predicts the mean TCP).
    """

    name = "clearance"
    in_words = "random joint play"
    summary = "random joint play (scatter, not bias)"
    non_negative = True
    stochastic = True
    family = "scatter"
    fit_policy = FitPolicy(order=90.0)

    def __init__(self, robot, *, joints=None, rng=None) -> None:
        super().__init__(robot)
        self.joints = joints
        self.rng = rng

    def parameter_names(self):
        return ["clearance.axial", "clearance.radial", "clearance.tilt"]

    def parameter_units(self):
        return ["m", "m", "rad"]

    def parameter_scales(self):
        return np.array([1e-5, 1e-5, 1e-5])

    def joint_indices(self) -> list[int]:
        """Indices of the joints with play."""
        if self.joints is None:
            return [j for j, k in enumerate(self.robot.joint_kinds) if k == REVOLUTE]
        unknown = [n for n in self.joints if n not in self.robot.joint_names]
        if unknown:
            raise InputError(f"clearance: unknown joints {unknown} (joints: {', '.join(self.robot.joint_names)})")
        return [self.robot.joint_names.index(n) for n in self.joints]

    def model(self, params) -> ClearanceModel:
        """The exact clearance model of the Monte Carlo (:class:`~tcr_accuracy.model.clearance.ClearanceModel`)
        with these spreads."""
        axial, radial, tilt = self.check_params(params)
        return ClearanceModel(self.error_model, tuple(self.joint_indices()), axial_std=float(axial),
                              radial_std=float(radial), deflection_std=float(tilt), name="clearance")

    def perturb(self, params, q, context) -> EffectOutput:
        q = np.atleast_2d(q)
        rng = self.rng or (context.rng if context is not None else None)
        if rng is None:  # no draw asked for: the mean robot, which play leaves where it is (scatter, not bias)
            self.check_params(params)
            return EffectOutput(x=np.zeros((q.shape[0], self.error_model.size)))
        return EffectOutput(x=self.model(params).sample(q.shape[0], rng))

    def twist_covariance(self, params) -> np.ndarray:
        """(n_error_params, n_error_params) covariance of the (linearised) x that perturb draws.

        Push it through the TCP Jacobian (d TCP / d x) to get the scatter at the TCP.
        """
        return self.model(params).parameter_covariance()
