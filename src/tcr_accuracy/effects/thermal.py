"""``thermal``: links that grow with the arm's temperature."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.context import REFERENCE_TEMPERATURE_C, context_column
from .base import EffectJacobian, LinearEffect
from .pose_entries import PoseEntries
from .fit_policy import FitPolicy
from .simulation_rules import SimulationRules


@dataclass(frozen=True)
class ThermalFitPolicy(FitPolicy):
    """Thermal is fitted growing from the rows' mean temperature (``requires_context``: only where they carry one)."""

    def options_for_data(self, robot, q, context) -> dict:
        """Links grow from the data's mean temperature: at one temperature a uniform scale of
        the links is a geometry question (geometry comes first in the vocabulary), so what
        thermal can claim is how the length changes with the temperature, across the rows
        (between sessions at different temperatures above all)."""
        temperature = np.asarray(context.temperature_c, dtype=float)
        return {"reference_temperature_c": float(np.round(temperature.mean(), 6))}


@dataclass(frozen=True)
class ThermalDraws(SimulationRules):
    """A dominant thermal growth: alpha of 1.0e-5 to 2.4e-5 per K (steel to aluminium); beyond
    physics, an instrument's scale (5-10 times that)."""

    def dominant_spec(self, effect, rng):
        return {"alpha_per_k": float(rng.uniform(1.0e-5, 2.4e-5))}

    def beyond_physics(self, effect, params, rng):
        return np.asarray(params, dtype=float) * rng.uniform(5.0, 10.0)  # the instrument's scale, not a metal


class Thermal(LinearEffect):
    """Links growing with temperature: every placement translation scaled by 1 + alpha (T - T_ref).

    A placement ``(R, t)`` becomes ``(R, t (1 + alpha dT))`` through the twist
    ``v = alpha dT R^T t`` on the right (exact: a pure translation). The TCP frame's
    offset grows the same way. Parameters: ``thermal.alpha`` [1/K] for the whole arm, or
    with ``per_link=True`` one ``thermal.alpha.<joint>`` per placement that has a length
    (and ``thermal.alpha.tool``); and ``thermal.base.dx, dy, dz`` [m/K], the robot's base moving
    with temperature in its own frame (a stand or a floor that grows; or, far beyond that, an
    instrument whose length scale changes about its own origin, which moves the base as seen
    from it). ``reference_temperature_c``: where the URDF holds (default 20 degC). Context:
    ``temperature_c`` per row.
    """

    name = "thermal"
    in_words = "links growing with temperature"
    summary = "links growing with temperature"
    context_columns = ("temperature_c",)
    family = "thermal"  # (not non_negative: the base may move either way; alpha's own lower bound is 0)
    physics = ("links expand with temperature, between invar (1.2e-6/K) and aluminium (2.3e-5/K): 0 to 2.5e-5 "
               "per K")
    fit_policy = ThermalFitPolicy(order=50.0, requires_context=True)
    simulation = ThermalDraws(dominant_place=3)

    def __init__(self, robot, *, per_link: bool = False,
                 reference_temperature_c: float = REFERENCE_TEMPERATURE_C) -> None:
        super().__init__(robot)
        self.per_link = per_link
        self.reference_temperature_c = reference_temperature_c

    def _links(self) -> list[tuple[str, int | None]]:
        """(label, joint index or None for the tool) of every placement with a length."""
        links = [(n, j) for j, (n, pl) in enumerate(zip(self.robot.joint_names, self.robot.joint_placements))
                 if np.linalg.norm(pl.translation) > 1e-9]
        if np.linalg.norm(self.robot.tool_placement.translation) > 1e-9:
            links.append(("tool", None))
        return links

    BASE = ("thermal.base.dx", "thermal.base.dy", "thermal.base.dz")

    def _alphas(self) -> list[str]:
        if self.per_link:
            return [f"thermal.alpha.{label}" for label, _ in self._links()]
        return ["thermal.alpha"]

    def parameter_names(self):
        return self._alphas() + list(self.BASE)

    def parameter_units(self):
        return ["1/K"] * len(self._alphas()) + ["m/K"] * 3

    def parameter_scales(self):
        return np.array([1.2e-5] * len(self._alphas()) + [1e-5] * 3)  # steel; a metre of steel stand

    def _per_kind(self, alpha: float, base: float) -> np.ndarray:
        return np.array([alpha] * len(self._alphas()) + [base] * 3)

    def physical_range(self):
        # links between invar and aluminium; the base moved by up to 2.5 m of steel stand or floor
        return self._per_kind(0.0, -3e-5), self._per_kind(2.5e-5, 3e-5)

    def fit_range(self):
        # an instrument's scale error with temperature: a weather station off by a few kelvin or a
        # refraction model off by a few ppm per kelvin, 40 times a metal's expansion at most, about
        # an origin up to a few metres from the base
        return self._per_kind(-1e-3, -2e-3), self._per_kind(1e-3, 2e-3)

    def mechanisms(self):
        from .mechanisms import Mechanism

        lower, upper = self.physical_range()
        wide_lower, wide_upper = self.fit_range()
        return (Mechanism("thermal_expansion", "links (and the robot's mount) expanding with temperature (steel "
                          "1.2e-5/K, aluminium 2.3e-5/K)", "measure at two temperatures after the arm has settled; "
                          "compare with the links' material", lower, upper),
                Mechanism("instrument_scale", "a length scale with temperature beyond any metal the arm is made of: "
                          "the instrument's scale (the tracker's weather station or its refraction compensation) or a "
                          "difference between sessions (another day, floor or station)", "check the tracker's "
                          "weather-station readings against an independent thermometer and barometer; measure a "
                          "calibrated scale bar at two temperatures", wide_lower, wide_upper, False))

    def growth_directions(self) -> np.ndarray:
        """(n_error_params, k): d(x)/d(alpha dT) for each parameter."""
        em = self.error_model
        links = self._links()
        out = np.zeros((em.size, len(links) if self.per_link else 1))
        for k, (label, j) in enumerate(links):
            col = k if self.per_link else 0
            if j is None:
                tool = self.robot.tool_placement
                out[em.tool_slice.start:em.tool_slice.start + 3, col] = tool.rotation.T @ tool.translation
            else:
                pl = self.robot.joint_placements[j]
                start = em.index(f"{label}.dx")
                out[start:start + 3, col] = pl.rotation.T @ pl.translation
        return out

    def parameter_jacobian(self, params, q, context):
        q = np.atleast_2d(q)
        t_ref = float(self.reference_temperature_c)
        temperature = context_column(context, "temperature_c", q.shape[0], t_ref)
        d_t = temperature - t_ref
        return EffectJacobian(x=d_t[:, None, None] * self._directions()[None])

    def _directions(self) -> np.ndarray:
        """(n_error_params, k) d(x)/d(parameter) per kelvin."""
        em = self.error_model
        directions = np.zeros((em.size, self.n_params))
        directions[:, :len(self._alphas())] = self.growth_directions()
        for a in range(3):  # the base translated in its own frame, per kelvin
            directions[em.base_slice.start + a, len(self._alphas()) + a] = 1.0
        return directions

    def sparse_parameter_jacobian(self, params, q, context) -> tuple[EffectJacobian, PoseEntries]:
        """:meth:`parameter_jacobian` as its nonzero entries (:class:`~tcr_accuracy.effects.pose_entries.PoseEntries`):
        each parameter grows a few entries of the error vector in proportion to the temperature."""
        q = np.atleast_2d(q)
        t_ref = float(self.reference_temperature_c)
        d_t = context_column(context, "temperature_c", q.shape[0], t_ref) - t_ref
        directions = self._directions()
        return EffectJacobian(), PoseEntries.of([(e, d_t[:, None] * directions[e, c], c)
                                                 for e, c in zip(*np.nonzero(directions))], q.shape[0])
