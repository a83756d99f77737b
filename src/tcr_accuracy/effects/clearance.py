"""``clearance``: random joint play, which shows as scatter, never as a bias."""

from __future__ import annotations

import math

import numpy as np

from ..exceptions import InputError
from ..units import REVOLUTE
from .base import Effect, EffectOutput


class Clearance(Effect):
    """Random joint play after the first seed paper's clearance model: scatter, not bias.

    In every joint with clearance, for each measurement independently, the journal
    moves in its bearing: an axial shift ``d ~ N(0, axial)`` along the joint axis, a
    radial shift of length ``s ~ N(0, radial)`` in a uniformly random direction
    perpendicular to the axis, and a tilt of the axis about the two perpendicular
    directions, each ``~ N(0, tilt)``. These form the twist on the joint placement (in
    the joint frame). Parameters: the spreads ``clearance.axial`` [m],
    ``clearance.radial`` [m], ``clearance.tilt`` [rad], shared by the joints with play.
    ``joints``: names (default every revolute joint, as the seed); ``rng``: a numpy
    Generator (else ``context.rng`` is used).
    """

    name = "clearance"
    order = 90.0
    summary = "random joint play (scatter, not bias)"
    non_negative = True
    stochastic = True
    analytic_jacobian = False

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

    def _frames(self, j: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unit axis and two perpendicular unit vectors of joint j (its own frame)."""
        axis = self.robot.joint_axis(j)
        helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
        u = np.cross(axis, helper)
        u /= np.linalg.norm(u)
        return axis, u, np.cross(axis, u)

    def perturb(self, params, q, context) -> EffectOutput:
        params = self.check_params(params)
        q = np.atleast_2d(q)
        rng = self.rng or (context.rng if context is not None else None)
        if rng is None:
            raise InputError("clearance: a random generator is needed (option rng= or context.rng)")
        axial, radial, tilt = params
        em = self.error_model
        n = q.shape[0]
        x = np.zeros((n, em.size))
        for j in self.joint_indices():
            axis, u, w = self._frames(j)
            d = axial * rng.standard_normal(n)
            s = radial * rng.standard_normal(n)
            theta = rng.uniform(0.0, 2 * math.pi, n)
            tu, tw = tilt * rng.standard_normal(n), tilt * rng.standard_normal(n)
            start = em.index(f"{self.robot.joint_names[j]}.dx")
            x[:, start:start + 3] = (d[:, None] * axis + (s * np.cos(theta))[:, None] * u
                                     + (s * np.sin(theta))[:, None] * w)
            x[:, start + 3:start + 6] = tu[:, None] * u + tw[:, None] * w
        return EffectOutput(x=x)

    def twist_covariance(self, params) -> np.ndarray:
        """(n_error_params, n_error_params) covariance of the x that perturb draws.

        Radial shift: s cos(theta), s sin(theta) each have variance radial^2 / 2.
        Push it through the TCP Jacobian (d TCP / d x) to get the scatter at the TCP.
        """
        axial, radial, tilt = self.check_params(params)
        em = self.error_model
        cov = np.zeros((em.size, em.size))
        for j in self.joint_indices():
            axis, u, w = self._frames(j)
            start = em.index(f"{self.robot.joint_names[j]}.dx")
            t = slice(start, start + 3)
            r = slice(start + 3, start + 6)
            cov[t, t] = axial**2 * np.outer(axis, axis) + radial**2 / 2 * (np.outer(u, u) + np.outer(w, w))
            cov[r, r] = tilt**2 * (np.outer(u, u) + np.outer(w, w))
        return cov
