"""How ``simulate`` and the blind benchmark draw an effect as a hidden truth, kept beside its physics.

An effect class (:class:`~tcr_accuracy.effects.base.Effect`) says what the effect is; its
``simulation`` attribute, one :class:`SimulationRules`, says how
:func:`~tcr_accuracy.analysis.simulate.random_scenario` draws it when it is to dominate a
scenario. None of this changes what the effect does to the model or how a diagnosis fits it.

==========================  ===========================================================
rule                        meaning
==========================  ===========================================================
``dominant_place``          ``random_scenario`` may make it the dominant hidden effect: its
                            place in the draw (1, 2, ...; fixed so that a seed keeps drawing
                            the same scenarios when effects are added), or None (never)
``dominant_spec``           scenario settings (as in a scenario YAML) of a realistic dominant
                            draw
``finish_dominant``         the last touch on the parameters resolved from those settings
``beyond_physics``          a dominant draw turned into the other mechanism with the same
                            signature (a sign or a size the effect's own physics does not
                            have), or None
==========================  ===========================================================

An effect that can dominate subclasses :class:`SimulationRules` in its own module (a frozen
dataclass too) and attaches one instance: ``simulation = ThermalDraws(dominant_place=3)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SimulationRules:
    """How ``random_scenario`` draws one effect class (the table of
    :mod:`~tcr_accuracy.effects.simulation_rules`); the default never makes it dominant.

    Parameters
    ----------
    dominant_place : int or None, default=None
        Its place in the draw of dominant effects (1, 2, ...), or None.
    """

    dominant_place: int | None = None

    def dominant_spec(self, effect, rng: np.random.Generator) -> dict:
        """Scenario settings (as in a scenario YAML) of a realistic dominant draw of ``effect``.

        Only for effects with a ``dominant_place``; ``random_scenario`` calls it.
        """
        raise NotImplementedError(f"effect {effect.name} is not a dominant candidate")

    def finish_dominant(self, effect, params: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Last touch on the (k,) parameters [SI] resolved from :meth:`dominant_spec` (default: as they are)."""
        return params

    def beyond_physics(self, effect, params: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
        """A dominant draw (k,) [SI] turned into the other mechanism with the same signature (a sign
        or a size the effect's own physics does not have: a controller's compensation, the
        instrument), for ``random_scenario``; None when the effect has no such draw."""
        return None
