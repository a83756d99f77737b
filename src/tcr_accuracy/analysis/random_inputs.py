"""The independent scalar random inputs behind an error sampler, and their map to error vectors.

An :class:`~tcr_accuracy.model.errors.ErrorBudget` draws its error vector as a linear map of
independent sources; a :class:`~tcr_accuracy.model.clearance.ClearanceModel` draws, per joint
with play, an axial movement d, a radial rod s at an angle theta and two deflections
w_x, w_y, and maps them non-linearly. :func:`random_inputs` lists those inputs with
their distributions (``ErrorSource.ppf``, ``variance``) so that global analyses can
drive them directly: Sobol indices (:mod:`tcr_accuracy.analysis.sobol`) through the inverse CDF
of uniform draws, tolerance allocation (:mod:`tcr_accuracy.analysis.tolerance`) by scaling them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..model.errors import ErrorBudget, ErrorModel, ErrorSource
from ..exceptions import InputError


@dataclass(frozen=True)
class RandomInputs:
    """The independent scalar random inputs behind a sampler and their map to x.

    Attributes
    ----------
    sources : list of ErrorSource
        One per input: name, group, unit and distribution (``ppf``, ``variance``).
        Their ``direction`` is only meaningful when ``matrix`` is not None.
    scalable : ndarray of shape (n_inputs,), bool
        Whether a tolerance factor scales the input (a clearance angle theta does not).
    to_parameters : callable, (N, n_inputs) values -> (N, n_params) error vectors
    matrix : ndarray of shape (n_params, n_inputs) or None
        The linear map when x = matrix @ values (error budgets); None otherwise.
    error_model : ErrorModel
    sampler : the ErrorBudget or ClearanceModel they come from
    """

    sources: list[ErrorSource]
    scalable: np.ndarray
    to_parameters: Callable[[np.ndarray], np.ndarray]
    matrix: np.ndarray | None
    error_model: ErrorModel
    sampler: object

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.sources]

    @property
    def groups(self) -> list[str]:
        return [s.group for s in self.sources]

    def values_from_unit(self, u: np.ndarray) -> np.ndarray:
        """Map uniform draws u (N, n_inputs) in (0, 1) to input values (N, n_inputs).

        Column k goes through input k's inverse CDF; u is clipped away from 0 and 1
        so that unbounded distributions stay finite.
        """
        u = np.clip(np.asarray(u, dtype=float), 1e-12, 1.0 - 1e-12)
        return np.column_stack([s.ppf(u[:, k]) for k, s in enumerate(self.sources)])

    def scaled_sampler(self, factor: float, groups: set[str] | None):
        """The sampler with the spreads of ``groups`` (None: all) multiplied by factor."""
        if isinstance(self.sampler, ErrorBudget):
            return self.sampler.scaled(factor, groups)
        spreads = {}
        for group, key in (("axial", "axial_std"), ("radial", "radial_std"), ("deflection", "deflection_std")):
            if groups is None or group in groups:
                spreads[key] = getattr(self.sampler, key) * factor
        return self.sampler.with_spreads(**spreads)


def random_inputs(sampler) -> RandomInputs:
    """The independent inputs of an ErrorBudget or a ClearanceModel."""
    if isinstance(sampler, ErrorBudget):
        a = sampler.matrix
        return RandomInputs(list(sampler.sources), np.ones(len(sampler.sources), bool),
                            lambda values: values @ a.T, a, sampler.error_model, sampler)
    from ..model.clearance import ClearanceModel, ClearanceSample

    if not isinstance(sampler, ClearanceModel):
        raise InputError(f"no sensitivity analysis for {type(sampler).__name__} (need an error budget "
                         "or a clearance model)")
    em, zero = sampler.error_model, np.zeros(sampler.error_model.size)
    sources, scalable = [], []
    fields = (("axial d", "axial", "m", sampler.axial_std), ("radial s", "radial", "m", sampler.radial_std),
              ("radial angle", "radial_angle", "rad", None),
              ("deflection w_x", "deflection", "rad", sampler.deflection_std),
              ("deflection w_y", "deflection", "rad", sampler.deflection_std))
    for j in sampler.joints:
        for label, group, unit, std in fields:
            name = f"{sampler.robot.joint_names[j]} {label}"
            if std is None:  # theta: uniform on [0, 2 pi)
                sources.append(ErrorSource(name, group, zero, unit, "uniform", low=0.0, high=2.0 * math.pi))
            else:
                sources.append(ErrorSource(name, group, zero, unit, "normal", std=std))
            scalable.append(std is not None)
    k = len(sampler.joints)

    def to_parameters(values: np.ndarray) -> np.ndarray:
        v = values.reshape(values.shape[0], k, 5)
        return sampler.to_parameters(ClearanceSample(axial=v[..., 0], radial=v[..., 1], angle=v[..., 2],
                                                     deflection_u=v[..., 3], deflection_v=v[..., 4]))

    return RandomInputs(sources, np.array(scalable), to_parameters, None, em, sampler)
