"""How the diagnosis treats an effect: its fitting policy, kept beside the effect's physics.

An effect class (:class:`~tcr_accuracy.effects.base.Effect`) says what the effect is; its
``fit_policy`` attribute, one :class:`FitPolicy`, says how ``diagnose`` tries it. None of this
changes what the effect does to the model: two policies for one physics fit the same parameters,
in another order or under other conditions.

==========================  ===========================================================
policy value                meaning
==========================  ===========================================================
``order``                   position in the vocabulary: identifiability takes effects in
                            this order (what an earlier effect explains, a later one cannot)
``in_vocabulary``           False for effects only ``simulate`` can hide (a diagnosis must
                            admit what it cannot name, so it never tries them)
``last_resort``             a flexible effect the diagnosis tries only once the others leave
                            structure in joint space (it could otherwise stand in for them)
``requires_context``        not tried when the data lack the effect's ``context_columns``
                            (without them it has nothing to fit: thermal at one assumed
                            temperature)
==========================  ===========================================================

==========================  ===========================================================
policy hook                 meaning
==========================  ===========================================================
``options_for_data``        the options the diagnosis builds the effect with for the data
                            at hand (how many terms a flexible effect may have, from which
                            temperature links grow)
``penalty_weights``         the weights of a smoothness penalty the fit adds (a Fourier
                            series' roughness), or None
==========================  ===========================================================

An effect with hooks of its own subclasses :class:`FitPolicy` in its own module (a frozen
dataclass too) and attaches one instance: ``fit_policy = CyclicFitPolicy(order=65.0,
last_resort=True)``.

What stays with the physics, and why: ``stochastic`` (the effect *is* random scatter; predictions
of the mean pose leave it out, whatever a fit does), ``non_negative`` (its parameters are
magnitudes: a dead band has a width), :meth:`~tcr_accuracy.effects.base.Effect.fit_range` (the
union of the ranges of the mechanisms the effect's signature can stand for, read by the
diagnosis as its box but defined by the mechanisms) and ``analytic_jacobian`` (a fact of the
effect's code, read from whether it writes its own ``parameter_jacobian``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.context import MeasurementContext
from ..model.robot import RobotModel


@dataclass(frozen=True)
class FitPolicy:
    """How ``diagnose`` treats one effect class (the table of :mod:`~tcr_accuracy.effects.fit_policy`).

    Parameters
    ----------
    order : float, default=100.0
        Position in the vocabulary; effects are tried in increasing order (then by name).
    in_vocabulary : bool, default=True
        False for an effect the diagnosis never tries (``simulate`` may still hide it).
    last_resort : bool, default=False
        Tried only once the other effects leave structure in joint space.
    requires_context : bool, default=False
        Not tried when the data lack the effect's ``context_columns``.
    """

    order: float = 100.0
    in_vocabulary: bool = True
    last_resort: bool = False
    requires_context: bool = False

    def options_for_data(self, robot: RobotModel, q: np.ndarray, context: MeasurementContext) -> dict:
        """Options the diagnosis builds the effect with for measurements at joints q (N, n) [rad, m]
        with their context (default none): how many terms a flexible effect may have, or from
        which temperature links grow, is a question of the data."""
        return {}

    def penalty_weights(self, effect) -> np.ndarray | None:
        """(k,) weights of a smoothness penalty on the effect's parameters, or None (no penalty).

        The fit adds ``lambda * sum(w * (theta / scale)^2)`` to its cost, with lambda chosen
        by held-out error inside the training rows: for effects with many parameters whose
        higher terms the data may not support (a Fourier series' roughness, ``cyclic``).
        """
        return None
